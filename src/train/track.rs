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
//! same ground-truth colour and a depth along its ray give P and v), verify on the others:
//! P + v·(t_j − t) must land on a wrong pixel of frame j whose ground truth has the pixel's
//! colour. A ghost (the model draws the object where it is not) is wrong too, but its ground
//! truth is the background: the colour test tells it from the missing object.

use crate::data::Bounds;
use crate::kernels::raster::Camera;
use crate::train::transients::{pixel_errors, pixel_ray, ray_box, threshold};

/// Depths sampled along each ray (the hypothesis grid; the optimiser refines the rest).
pub const TRACK_DEPTHS: usize = 32;
/// Mean absolute RGB difference under which two ground-truth pixels are the same surface.
pub const COLOUR_TOL: f32 = 0.15;
/// Neighbour pixels a wrong pixel may lie from the projection (the depth grid's slack).
const SLACK: i64 = 1;
/// The most anchor pixels one track tries (evenly strided over those of its colour): a
/// hypothesis costs `TRACK_DEPTHS²` × neighbours projections, and a large wrong region (a
/// ghost, a big object at 800 px) would make a spawn cost seconds; the least-squares
/// refinement takes the track from the nearest hypothesis to the rays it explains.
pub const MAX_HYPOTHESES: usize = 48;

/// A frame's residual, as tracking reads it.
pub struct Residual<'a> {
    pub camera: &'a Camera,
    pub time: f32,
    pub gt: &'a [[f32; 4]],
    /// Per pixel: wrong enough to spawn (the same rule as `transients::worst_pixels`).
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

    /// The closest-coloured hot pixel within [`SLACK`] of where `p` projects and its colour
    /// distance from `c`; `None` when it projects behind the camera, outside, or onto no hot
    /// pixel of that colour.
    fn explains(&self, p: [f32; 3], c: [f32; 3]) -> Option<(f32, u32, u32)> {
        let cam = self.camera;
        let q: [f32; 3] = std::array::from_fn(|r| {
            (0..3).map(|a| cam.rot[r][a] * p[a]).sum::<f32>() + cam.trans[r]
        });
        if q[2].is_nan() || q[2] <= cam.near {
            return None;
        }
        let u = (cam.fx * q[0] / q[2] + cam.cx).floor() as i64;
        let v = (cam.fy * q[1] / q[2] + cam.cy).floor() as i64;
        let (w, h) = (cam.width as i64, cam.height as i64);
        let mut best: Option<(f32, u32, u32)> = None;
        for y in (v - SLACK).max(0)..=(v + SLACK).min(h - 1) {
            for x in (u - SLACK).max(0)..=(u + SLACK).min(w - 1) {
                let i = (y * w + x) as usize;
                if !self.hot[i] {
                    continue;
                }
                let d = colour_distance(self.gt[i], c);
                if d < COLOUR_TOL && best.map_or(true, |b| d < b.0) {
                    best = Some((d, x as u32, y as u32));
                }
            }
        }
        best
    }
}

fn colour_distance(g: [f32; 4], c: [f32; 3]) -> f32 {
    ((g[0] - c[0]).abs() + (g[1] - c[1]).abs() + (g[2] - c[2]).abs()) / 3.0
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

/// A hot pixel of the anchor: the pixel, its ground-truth colour and its ray's points.
type Anchor = ((u32, u32), [f32; 4], Vec<([f32; 3], f32)>);
/// A hypothesis: an anchor pixel's colour distance from the tracked pixel's, the pixel, and
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
            let w = a.camera.width;
            a.hot_pixels()
                .into_iter()
                .map(|(u, v)| {
                    (
                        (u, v),
                        a.gt[(v * w + u) as usize],
                        ray_points(a.camera, u, v, bounds),
                    )
                })
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

    /// Neighbours besides the anchor that a track must explain.
    pub fn required(&self) -> usize {
        let others = self.neighbours.len().saturating_sub(1);
        others - others / 3
    }

    /// The track of pixel (x, y) of the frame, if one explains the anchor and
    /// [`Tracker::required`] of the other neighbours (the most explained, then the closest
    /// colours, win).
    pub fn track(&self, x: u32, y: u32) -> Option<Track> {
        let anchor = self.neighbours.first()?;
        let dt = anchor.time - self.frame.time;
        let f = self.frame.camera;
        let g = self.frame.gt[(y * f.width + x) as usize];
        let c = [g[0], g[1], g[2]];
        let here = ray_points(f, x, y, &self.bounds);
        // The anchor's hot pixels of the same colour (at most MAX_HYPOTHESES, strided).
        let mut there: Vec<Hypothesis<'_>> = self
            .anchor
            .iter()
            .filter_map(|(at, gt, ray)| {
                let d = colour_distance(*gt, c);
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
                    if v.iter().map(|x| x * x).sum::<f32>().sqrt() > self.v_max {
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
    /// frame spacing. The hypothesis stays when the system is degenerate.
    fn refine(&self, t: Track, here: (u32, u32), at: (u32, u32), c: [f32; 3]) -> Track {
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
        for (cam, (x, y), s) in rays {
            let (o, d) = pixel_ray(cam, x, y);
            let len = d.iter().map(|v| (*v as f64).powi(2)).sum::<f64>().sqrt();
            let d: [f64; 3] = std::array::from_fn(|k| d[k] as f64 / len);
            let m: [[f64; 3]; 3] = std::array::from_fn(|i| {
                std::array::from_fn(|j| (i == j) as u8 as f64 - d[i] * d[j])
            });
            let mo: [f64; 3] = std::array::from_fn(|i| (0..3).map(|j| m[i][j] * o[j] as f64).sum());
            let s = s as f64;
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
        match solve6(n, b) {
            Some(x) if x.iter().all(|v| v.is_finite()) => {
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
            _ => t,
        }
    }
}

/// Gaussian elimination with partial pivoting; `None` when (nearly) singular.
fn solve6(mut a: [[f64; 6]; 6], mut b: [f64; 6]) -> Option<[f64; 6]> {
    let scale = a.iter().flatten().fold(0f64, |m, v| m.max(v.abs()));
    for c in 0..6 {
        let p = (c..6).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[p][c].abs() <= 1e-9 * scale {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..6 {
            let f = a[r][c] / a[c][c];
            let pivot = a[c];
            for (x, p) in a[r][c..].iter_mut().zip(&pivot[c..]) {
                *x -= f * p;
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = [0f64; 6];
    for c in (0..6).rev() {
        let s: f64 = (c + 1..6).map(|k| a[c][k] * x[k]).sum();
        x[c] = (b[c] - s) / a[c][c];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera at `centre` looking at the origin (world z up), 64×64.
    fn look_at(centre: [f32; 3]) -> Camera {
        let c = glam::Vec3::from(centre);
        let fwd = (-c).normalize();
        let right = fwd.cross(glam::Vec3::Z).normalize();
        let down = fwd.cross(right);
        let rot = [right.to_array(), down.to_array(), fwd.to_array()];
        let trans = std::array::from_fn(|r| -glam::Vec3::from(rot[r]).dot(c));
        Camera {
            rot,
            trans,
            fx: 60.0,
            fy: 60.0,
            cx: 32.0,
            cy: 32.0,
            width: 64,
            height: 64,
            near: 0.01,
        }
    }

    const ORANGE: [f32; 4] = [0.9, 0.5, 0.1, 1.0];

    /// The scene's bounds: the cube of side 4 about the origin.
    fn cube() -> Bounds {
        Bounds {
            min: glam::Vec3::splat(-2.0),
            max: glam::Vec3::splat(2.0),
        }
    }

    /// Five cameras around the origin, one per frame.
    fn five_cameras() -> [Camera; 5] {
        [
            [6.0, 0.0, 3.0],
            [0.0, 6.0, 3.0],
            [-6.0, 0.5, 3.0],
            [0.5, -6.0, 3.0],
            [4.0, 4.0, 4.0],
        ]
        .map(look_at)
    }

    /// The pixel `p` projects into.
    fn pixel_of(cam: &Camera, p: [f32; 3]) -> (u32, u32) {
        let q: [f32; 3] = std::array::from_fn(|r| {
            (0..3).map(|a| cam.rot[r][a] * p[a]).sum::<f32>() + cam.trans[r]
        });
        (
            (cam.fx * q[0] / q[2] + cam.cx) as u32,
            (cam.fy * q[1] / q[2] + cam.cy) as u32,
        )
    }

    /// The ground truth of a ball of radius 0.15 at `p` on black, and a render without it.
    fn frame(cam: &Camera, p: [f32; 3], colour: [f32; 4]) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
        ball(cam, p, 0.15, colour)
    }

    /// The same, radius `r`.
    fn ball(cam: &Camera, p: [f32; 3], r: f32, colour: [f32; 4]) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
        let n = (cam.width * cam.height) as usize;
        let mut gt = vec![[0.0, 0.0, 0.0, 1.0]; n];
        let q: [f32; 3] = std::array::from_fn(|r| {
            (0..3).map(|a| cam.rot[r][a] * p[a]).sum::<f32>() + cam.trans[r]
        });
        let (u, v) = (cam.fx * q[0] / q[2] + cam.cx, cam.fy * q[1] / q[2] + cam.cy);
        let rad = cam.fx * r / q[2];
        for y in 0..cam.height {
            for x in 0..cam.width {
                let (dx, dy) = (x as f32 + 0.5 - u, y as f32 + 0.5 - v);
                if dx * dx + dy * dy <= rad * rad {
                    gt[(y * cam.width + x) as usize] = colour;
                }
            }
        }
        (gt, vec![[0.0, 0.0, 0.0, 1.0]; n])
    }

    #[test]
    fn a_ball_missing_from_every_frame_is_tracked_with_its_velocity() {
        let bounds = cube();
        // Five frames, each from another camera, the ball moving 0.37 per frame (more than
        // its diameter) along a slanted line.
        let cams = five_cameras();
        let (p0, vel) = ([-0.3f32, 0.2, 0.1], [3.0f32, -1.5, 1.0]);
        let speed = 3.5f32;
        let times: Vec<f32> = (0..5).map(|i| i as f32 * 0.1).collect();
        let pos = |t: f32| -> [f32; 3] { std::array::from_fn(|k| p0[k] + vel[k] * (t - 0.2)) };
        let dist =
            |a: [f32; 3], b: [f32; 3]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f32>().sqrt();
        let (x, y) = pixel_of(&cams[2], p0);
        let run = |places: &dyn Fn(usize) -> [f32; 3], v_max: f32| {
            let imgs: Vec<_> = (0..5).map(|i| frame(&cams[i], places(i), ORANGE)).collect();
            let res = |i: usize| Residual::new(&cams[i], times[i], &imgs[i].1, &imgs[i].0, 0.1);
            let tr = Tracker::new(res(2), vec![res(4), res(1), res(3), res(0)], v_max, &bounds);
            assert_eq!(tr.neighbours.len(), 4);
            assert!(
                (tr.neighbours[0].time - 0.1).abs() < 1e-6
                    || (tr.neighbours[0].time - 0.3).abs() < 1e-6,
                "nearest first"
            );
            assert_eq!(tr.required(), 2, "3 others: one may miss");
            tr.track(x, y)
        };
        let t = run(&|i| pos(times[i]), 100.0).expect("tracked");
        assert!(t.explained >= 2, "{t:?}");
        assert!(dist(t.mean, p0) < 0.15, "mean {:?} vs {p0:?}", t.mean);
        assert!(
            dist(t.velocity, vel) < 0.15 * speed,
            "velocity {:?} vs {vel:?}",
            t.velocity
        );
        // A ball at places no constant velocity explains is not tracked.
        let jumps = [
            [1.5, 1.5, 0.0],
            [-1.5, 1.2, 1.0],
            p0,
            [1.4, -1.5, -1.0],
            [-1.2, -1.2, 1.5],
        ];
        assert_eq!(run(&|i| jumps[i], 100.0), None);
        // Nor is one faster than v_max.
        assert_eq!(run(&|i| pos(times[i]), 0.5 * speed), None);
    }

    #[test]
    fn a_track_keeps_its_colour() {
        // The same motion, but the neighbours' wrong pixels are another colour (a blue ball
        // where the frame's is orange): not one object, no track.
        let bounds = cube();
        let cams = [[6.0, 0.0, 3.0], [0.0, 6.0, 3.0], [-6.0, 0.5, 3.0]].map(look_at);
        let p = [0.1f32, -0.2, 0.3];
        let imgs: Vec<_> = (0..3)
            .map(|i| {
                let colour = if i == 1 { ORANGE } else { [0.1, 0.2, 0.9, 1.0] };
                frame(&cams[i], p, colour)
            })
            .collect();
        let res = |i: usize| Residual::new(&cams[i], i as f32, &imgs[i].1, &imgs[i].0, 0.1);
        let (x, y) = pixel_of(&cams[1], p);
        let tr = Tracker::new(res(1), vec![res(0), res(2)], 100.0, &bounds);
        assert!(tr.track(x, y).is_none());
        // Same colour everywhere: a still ball is tracked with no velocity.
        let imgs: Vec<_> = (0..3).map(|i| frame(&cams[i], p, ORANGE)).collect();
        let res = |i: usize| Residual::new(&cams[i], i as f32, &imgs[i].1, &imgs[i].0, 0.1);
        let tr = Tracker::new(res(1), vec![res(0), res(2)], 100.0, &bounds);
        let t = tr.track(x, y).expect("tracked");
        let speed = t.velocity.iter().map(|v| v * v).sum::<f32>().sqrt();
        assert!(speed < 0.2, "{t:?}");
    }

    #[test]
    fn a_big_ball_is_tracked_from_a_strided_subset_of_its_pixels() {
        // A ball whose image in the anchor has several times MAX_HYPOTHESES wrong pixels: the
        // strided hypotheses and the refinement still find a path on it.
        let (bounds, cams) = (cube(), five_cameras());
        let (p0, vel, r) = ([-0.3f32, 0.2, 0.1], [3.0f32, -1.5, 1.0], 0.8f32);
        let times: Vec<f32> = (0..5).map(|i| i as f32 * 0.1).collect();
        let pos = |t: f32| -> [f32; 3] { std::array::from_fn(|k| p0[k] + vel[k] * (t - 0.2)) };
        let imgs: Vec<_> = (0..5)
            .map(|i| ball(&cams[i], pos(times[i]), r, ORANGE))
            .collect();
        let res = |i: usize| Residual::new(&cams[i], times[i], &imgs[i].1, &imgs[i].0, 0.1);
        let tr = Tracker::new(res(2), vec![res(4), res(1), res(3), res(0)], 100.0, &bounds);
        assert!(
            tr.anchor.len() > 3 * MAX_HYPOTHESES,
            "{} anchor pixels",
            tr.anchor.len()
        );
        let (x, y) = pixel_of(&cams[2], p0);
        let t = tr.track(x, y).expect("tracked");
        // Silhouettes of one colour do not pin a surface point (any point inside the ball at
        // every time explains them): what matters is that the transient sits on the ball in
        // every frame of its life.
        for &ti in &times {
            let q: [f32; 3] = std::array::from_fn(|k| t.mean[k] + t.velocity[k] * (ti - 0.2));
            let c = pos(ti);
            let d = (0..3).map(|k| (q[k] - c[k]).powi(2)).sum::<f32>().sqrt();
            assert!(
                d < 1.2 * r,
                "at t = {ti}: {q:?} is {d} from the centre {c:?}; {t:?}"
            );
        }
    }
}
