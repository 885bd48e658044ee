//! Tracked spawning (issue 37): where a pixel of a spawning frame is wrong, find the 3D point
//! and velocity that explain its residual in the frame's temporal neighbours too, so the
//! transient starts on the object's path instead of where the object was at one instant.
//!
//! Why: a zero-velocity transient for an object that moves most of its size per frame sits in
//! the wrong place in every other frame of its life (each seen by another camera); the only
//! gradient it gets there is "fade", so it fades. Under a constant velocity over a few frames,
//! a point P at the frame's time and a velocity v are six unknowns; the pixel's ray (two
//! constraints per frame) over the frame and its neighbours pins them. Hypothesise from the
//! nearest neighbour (a depth along the pixel's ray, a wrong pixel of the neighbour with the
//! same ground-truth patch about it and a depth along its ray give P and v), verify on the
//! others: P + v·(t_j − t) must land on a wrong pixel of frame j whose ground-truth patch is
//! the pixel's. A ghost (the model draws the object where it is not) is wrong too, but its
//! ground truth is the background: the patch test tells it from the missing object. The rays
//! leave a moving point's depth free when the camera's path is nearly straight; the slowest
//! track is taken then ([`SPEED_COST`], [`solve::solve_slowest`]).

use super::ray::{pixel_ray, ray_box};
use super::residual::{pixel_errors, threshold};
use crate::data::Bounds;
use crate::kernels::raster::Camera;

mod solve;

/// Depths sampled along each ray (the hypothesis grid; the optimiser refines the rest).
pub const TRACK_DEPTHS: usize = 32;
/// Mean absolute RGB difference under which two ground-truth patches are the same surface.
pub const COLOUR_TOL: f32 = 0.15;
/// The compared patch's radius (pixels each side). A pixel's colour alone is no correspondence
/// on a textured scene (a checkered wall has the sphere's colours everywhere): on the built-in
/// scene single pixels put the tracks' velocities off by 7× the true speed, 5×5 patches by 1×
/// (docs/measurements.md, last section).
pub const PATCH_RADIUS: i64 = 2;
const PATCH_LEN: usize = ((2 * PATCH_RADIUS + 1) * (2 * PATCH_RADIUS + 1)) as usize;
/// The rays of a camera that moves along a nearly straight path leave a one-parameter family of
/// tracks — every (P, v) scaled about the camera's path — that project onto the same pixels, so
/// the rays do not pin a moving point's depth (monocular ambiguity). The grid then prefers the
/// slowest hypothesis (`SPEED_COST` × speed / `v_max` added to its patch cost) and the
/// refinement the slowest solution in the directions the rays leave free
/// ([`solve::solve_slowest`]). A still surface is then tracked still, and a moving one at a
/// depth that projects right in the neighbours, not necessarily its own.
pub const SPEED_COST: f32 = 0.3;

/// A ground-truth patch about a pixel (edge pixels repeated), RGB.
#[derive(Clone, Debug, PartialEq)]
pub struct Patch([[f32; 3]; PATCH_LEN]);

impl Patch {
    pub fn of(gt: &[[f32; 4]], w: u32, h: u32, x: u32, y: u32) -> Self {
        let mut p = [[0.0; 3]; PATCH_LEN];
        let side = 2 * PATCH_RADIUS + 1;
        for (k, px) in p.iter_mut().enumerate() {
            let (dx, dy) = (
                k as i64 % side - PATCH_RADIUS,
                k as i64 / side - PATCH_RADIUS,
            );
            let xx = (x as i64 + dx).clamp(0, w as i64 - 1);
            let yy = (y as i64 + dy).clamp(0, h as i64 - 1);
            let g = gt[(yy * w as i64 + xx) as usize];
            *px = [g[0], g[1], g[2]];
        }
        Patch(p)
    }

    /// The larger of the centre pixels' and the whole patches' mean absolute RGB difference:
    /// the patch tells texture apart, the centre keeps a small object's colour (a ball of a few
    /// pixels is mostly background in its patch).
    pub fn distance(&self, o: &Patch) -> f32 {
        let l1 = |a: &[f32; 3], b: &[f32; 3]| {
            (a[0] - b[0]).abs() + (a[1] - b[1]).abs() + (a[2] - b[2]).abs()
        };
        let all: f32 = self.0.iter().zip(&o.0).map(|(a, b)| l1(a, b)).sum();
        let c = PATCH_LEN / 2;
        (l1(&self.0[c], &o.0[c]) / 3.0).max(all / (3 * PATCH_LEN) as f32)
    }
}

/// Neighbour pixels a wrong pixel may lie from the projection (the depth grid's slack).
const SLACK: i64 = 1;
/// The most anchor pixels one track tries (evenly strided over those of its patch): a
/// hypothesis costs `TRACK_DEPTHS²` × neighbours projections, and a large wrong region (a
/// ghost, a big object at 800 px) would make a spawn cost seconds; the least-squares
/// refinement takes the track from the nearest hypothesis to the rays it explains.
pub const MAX_HYPOTHESES: usize = 48;

/// A frame's residual, as tracking reads it.
pub struct Residual<'a> {
    pub camera: &'a Camera,
    pub time: f32,
    pub gt: &'a [[f32; 4]],
    /// Per pixel: wrong enough to spawn (the same rule as `super::residual::worst_pixels`).
    pub hot: Vec<bool>,
}

impl<'a> Residual<'a> {
    pub fn new(
        camera: &'a Camera,
        time: f32,
        render: &[[f32; 4]],
        gt: &'a [[f32; 4]],
        min_error: f32,
    ) -> Self {
        let err = pixel_errors(render, gt);
        let thr = threshold(&err, min_error);
        Residual {
            camera,
            time,
            gt,
            hot: err.iter().map(|&e| e >= thr).collect(),
        }
    }

    /// The hot pixels (x, y).
    fn hot_pixels(&self) -> Vec<(u32, u32)> {
        let w = self.camera.width;
        (0..self.hot.len() as u32)
            .filter(|&i| self.hot[i as usize])
            .map(|i| (i % w, i / w))
            .collect()
    }

    /// The ground-truth patch about pixel (x, y).
    fn patch(&self, x: u32, y: u32) -> Patch {
        Patch::of(self.gt, self.camera.width, self.camera.height, x, y)
    }

    /// The pixel `p` projects to (possibly outside the image); `None` behind the camera.
    fn project(&self, p: [f32; 3]) -> Option<(i64, i64)> {
        let cam = self.camera;
        let q: [f32; 3] = std::array::from_fn(|r| {
            (0..3).map(|a| cam.rot[r][a] * p[a]).sum::<f32>() + cam.trans[r]
        });
        if q[2].is_nan() || q[2] <= cam.near {
            return None;
        }
        let u = (cam.fx * q[0] / q[2] + cam.cx).floor() as i64;
        let v = (cam.fy * q[1] / q[2] + cam.cy).floor() as i64;
        Some((u, v))
    }

    /// Whether `p` projects inside the image, in front of the camera.
    fn sees(&self, p: [f32; 3]) -> bool {
        let (w, h) = (self.camera.width as i64, self.camera.height as i64);
        self.project(p)
            .is_some_and(|(u, v)| (0..w).contains(&u) && (0..h).contains(&v))
    }

    /// The hot pixel within [`SLACK`] of where `p` projects whose patch is closest to `c`, and
    /// its distance from `c`; `None` when it projects behind the camera, outside, or onto no
    /// hot pixel with a patch within [`COLOUR_TOL`].
    fn explains(&self, p: [f32; 3], c: &Patch) -> Option<(f32, u32, u32)> {
        let (u, v) = self.project(p)?;
        let (w, h) = (self.camera.width as i64, self.camera.height as i64);
        let mut best: Option<(f32, u32, u32)> = None;
        for y in (v - SLACK).max(0)..=(v + SLACK).min(h - 1) {
            for x in (u - SLACK).max(0)..=(u + SLACK).min(w - 1) {
                let i = (y * w + x) as usize;
                if !self.hot[i] {
                    continue;
                }
                let d = self.patch(x as u32, y as u32).distance(c);
                if d < COLOUR_TOL && best.map_or(true, |b| d < b.0) {
                    best = Some((d, x as u32, y as u32));
                }
            }
        }
        best
    }
}

/// Points along a pixel's ray inside the scene's bounds, [`TRACK_DEPTHS`] of them, with their
/// depths.
fn ray_points(cam: &Camera, x: u32, y: u32, bounds: &Bounds) -> Vec<([f32; 3], f32)> {
    let (o, d) = pixel_ray(cam, x, y);
    let Some((z0, z1)) = ray_box(o, d, bounds, cam.near.max(1e-3)) else {
        return Vec::new();
    };
    (0..TRACK_DEPTHS)
        .map(|j| {
            let z = z0 + (z1 - z0) * (j as f32 + 0.5) / TRACK_DEPTHS as f32;
            (std::array::from_fn(|a| o[a] + d[a] * z), z)
        })
        .collect()
}

/// A hot pixel of the anchor: the pixel, its ground-truth patch and its ray's points.
type Anchor = ((u32, u32), Patch, Vec<([f32; 3], f32)>);
/// A hypothesis: an anchor pixel's patch distance from the tracked pixel's, the pixel, and
/// its ray's points.
type Hypothesis<'t> = (f32, (u32, u32), &'t [([f32; 3], f32)]);

/// A tracked point: where the pixel's surface is at the frame's time, how fast it moves, its
/// depth in the frame's camera, and how many neighbours it explains.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Track {
    pub mean: [f32; 3],
    pub velocity: [f32; 3],
    pub depth: f32,
    pub explained: usize,
}

/// The frames tracking reads: the spawning frame and its temporal neighbours, nearest first.
pub struct Tracker<'a> {
    pub frame: Residual<'a>,
    /// Neighbours at another time than the frame's, nearest in time first.
    pub neighbours: Vec<Residual<'a>>,
    /// The anchor's hot pixels (the first neighbour's) and their rays: the hypotheses, built
    /// once for every pixel tracked.
    anchor: Vec<Anchor>,
    bounds: Bounds,
    /// The fastest motion accepted, in world units per time unit.
    pub v_max: f32,
}

impl<'a> Tracker<'a> {
    /// `v_max`: see [`Tracker::v_max`]; points are sampled inside `bounds`. Neighbours at the
    /// frame's own time are dropped (they say nothing of a velocity).
    pub fn new(
        frame: Residual<'a>,
        mut neighbours: Vec<Residual<'a>>,
        v_max: f32,
        bounds: &Bounds,
    ) -> Self {
        let t = frame.time;
        neighbours.retain(|n| (n.time - t).abs() > 1e-9);
        neighbours.sort_by(|a, b| (a.time - t).abs().total_cmp(&(b.time - t).abs()));
        let anchor = neighbours.first().map_or(Vec::new(), |a| {
            a.hot_pixels()
                .into_iter()
                .map(|(u, v)| ((u, v), a.patch(u, v), ray_points(a.camera, u, v, bounds)))
                .collect()
        });
        Tracker {
            frame,
            neighbours,
            anchor,
            bounds: *bounds,
            v_max,
        }
    }

    /// Whether a still point `p` on pixel (x, y)'s ray is worth spawning: some neighbour that
    /// sees it is wrong there with the pixel's patch (the evidence a track needs, for one still
    /// point in one view), or no neighbour sees it. A depth hypothesis on a surface another
    /// view draws right is a floater there (D-NeRF trex: a spawn's hypotheses cost test views
    /// at its time 0.7–2.7 dB, docs/measurements.md).
    pub fn confirms_still(&self, x: u32, y: u32, p: [f32; 3]) -> bool {
        let c = &self.frame.patch(x, y);
        let mut seen = false;
        for n in &self.neighbours {
            if !n.sees(p) {
                continue;
            }
            seen = true;
            if n.explains(p, c).is_some() {
                return true;
            }
        }
        !seen
    }

    /// Neighbours besides the anchor that a track must explain.
    pub fn required(&self) -> usize {
        let others = self.neighbours.len().saturating_sub(1);
        others - others / 3
    }

    /// The track of pixel (x, y) of the frame, if one explains the anchor and
    /// [`Tracker::required`] of the other neighbours (the most explained, then the closest
    /// patches and the slowest, win).
    pub fn track(&self, x: u32, y: u32) -> Option<Track> {
        let anchor = self.neighbours.first()?;
        let dt = anchor.time - self.frame.time;
        let f = self.frame.camera;
        let c = &self.frame.patch(x, y);
        let here = ray_points(f, x, y, &self.bounds);
        // The anchor's hot pixels with the same patch (at most MAX_HYPOTHESES, strided).
        let mut there: Vec<Hypothesis<'_>> = self
            .anchor
            .iter()
            .filter_map(|(at, gt, ray)| {
                let d = gt.distance(c);
                (d < COLOUR_TOL).then_some((d, *at, ray.as_slice()))
            })
            .collect();
        let stride = there.len().div_ceil(MAX_HYPOTHESES).max(1);
        if stride > 1 {
            there = there.into_iter().step_by(stride).collect();
        }
        let need = self.required();
        let mut best: Option<(Track, f32, (u32, u32))> = None;
        for &(p, z) in &here {
            for &(d0, at, ray) in &there {
                for &(p2, _) in ray {
                    let v: [f32; 3] = std::array::from_fn(|k| (p2[k] - p[k]) / dt);
                    let speed = v.iter().map(|x| x * x).sum::<f32>().sqrt();
                    if speed > self.v_max {
                        continue;
                    }
                    let (mut n, mut cost, mut missed) = (0, d0, 0);
                    for nb in &self.neighbours[1..] {
                        let s = nb.time - self.frame.time;
                        match nb.explains(std::array::from_fn(|k| p[k] + v[k] * s), c) {
                            Some((d, ..)) => {
                                n += 1;
                                cost += d;
                            }
                            None => missed += 1,
                        }
                        if self.neighbours.len() - 1 - missed < need {
                            break;
                        }
                    }
                    if n < need {
                        continue;
                    }
                    // The rays of a slowly turning camera leave a family of (P, v) scaled about
                    // its path that project alike: prefer the slowest member.
                    let cost = cost + SPEED_COST * speed / self.v_max;
                    let better = best.map_or(true, |(b, bc, _)| {
                        n > b.explained || (n == b.explained && cost < bc)
                    });
                    if better {
                        let t = Track {
                            mean: p,
                            velocity: v,
                            depth: z,
                            explained: n,
                        };
                        best = Some((t, cost, at));
                    }
                }
            }
        }
        let (t, _, at) = best?;
        Some(self.refine(t, (x, y), at, c))
    }

    /// The grid's best hypothesis refined: the point and velocity closest (least squares) to
    /// the rays of the pixels it explains (the frame's, the anchor's and each other
    /// neighbour's), so the depth grid's step does not become a velocity error of a step per
    /// frame spacing; where the rays leave a direction free, the slowest solution. The
    /// hypothesis stays when the solution is unusable (too fast, behind the camera) or none.
    fn refine(&self, t: Track, here: (u32, u32), at: (u32, u32), c: &Patch) -> Track {
        let anchor = &self.neighbours[0];
        let mut rays = vec![
            (self.frame.camera, here, 0.0f32),
            (anchor.camera, at, anchor.time - self.frame.time),
        ];
        for nb in &self.neighbours[1..] {
            let s = nb.time - self.frame.time;
            let p = std::array::from_fn(|k| t.mean[k] + t.velocity[k] * s);
            if let Some((_, x, y)) = nb.explains(p, c) {
                rays.push((nb.camera, (x, y), s));
            }
        }
        // Σ_j A_jᵀA_j x = Σ_j A_jᵀ M_j o_j with A_j = M_j [I, s_j I], M_j = I − d̂d̂ᵀ.
        let mut n = [[0f64; 6]; 6];
        let mut b = [0f64; 6];
        let mut ss = 0f64;
        let rays_n = rays.len();
        for (cam, (x, y), s) in rays {
            let (o, d) = pixel_ray(cam, x, y);
            let len = d.iter().map(|v| (*v as f64).powi(2)).sum::<f64>().sqrt();
            let d: [f64; 3] = std::array::from_fn(|k| d[k] as f64 / len);
            let m: [[f64; 3]; 3] = std::array::from_fn(|i| {
                std::array::from_fn(|j| (i == j) as u8 as f64 - d[i] * d[j])
            });
            let mo: [f64; 3] = std::array::from_fn(|i| (0..3).map(|j| m[i][j] * o[j] as f64).sum());
            let s = s as f64;
            ss += s * s;
            // M is a projector (MᵀM = M): AᵀA = [[M, sM], [sM, s²M]], Aᵀ M o = [Mo, s Mo].
            for i in 0..3 {
                for j in 0..3 {
                    n[i][j] += m[i][j];
                    n[i][j + 3] += s * m[i][j];
                    n[i + 3][j] += s * m[i][j];
                    n[i + 3][j + 3] += s * s * m[i][j];
                }
                b[i] += mo[i];
                b[i + 3] += s * mo[i];
            }
        }
        // The rays leave the depth of a moving point free when the camera's path is nearly
        // straight: there, the slowest track (`solve::solve_slowest`).
        let s_rms = (ss / rays_n as f64).sqrt();
        match solve::solve_slowest(n, b, s_rms) {
            Some(x) => {
                let mean = std::array::from_fn(|k| x[k] as f32);
                let velocity: [f32; 3] = std::array::from_fn(|k| x[k + 3] as f32);
                let speed = velocity.iter().map(|v| v * v).sum::<f32>().sqrt();
                let cam = self.frame.camera;
                let depth = (0..3).map(|a| cam.rot[2][a] * mean[a]).sum::<f32>() + cam.trans[2];
                if speed > self.v_max || depth.is_nan() || depth <= cam.near {
                    return t;
                }
                Track {
                    mean,
                    velocity,
                    depth,
                    explained: t.explained,
                }
            }
            None => t,
        }
    }
}

#[cfg(test)]
mod tests;
