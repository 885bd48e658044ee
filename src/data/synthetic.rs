//! Built-in synthetic scene: analytic primitives (not Gaussians) ray-cast on the CPU, with exact
//! motion masks and ground-truth 2D scene flow, written in the nerfies format so the same loader
//! is exercised. Over 600 lines: the scene's geometry, its exact motion and flow, and the
//! nerfies writer are one generator whose parts must agree frame by frame.
//!
//! The scene (world y up, raw units):
//! - a static room (box interior) with a checker + value-noise texture on every wall;
//! - a rigid textured sphere that translates along a curve and rotates about a tilted axis;
//! - a non-rigid blob: a sphere whose radius is modulated by travelling waves; a surface point
//!   keeps its direction `u` from the blob centre (its material coordinate) and moves radially.
//!
//! A monocular camera moves slowly along an arc while time advances (frame `k` at
//! `t_k = k/(N−1)`). The objects are posed at the scene time `motion.warp(t_k)` of the motion
//! kind ([`SceneMotion`]): `moving` (scene time = frame time, the default), `static` (frozen at
//! their `t = 0` pose), `late` (at rest for the first half, then their whole trajectory in the
//! second half) or `events` (as `moving`, plus three small spheres that appear, vanish and split
//! in two: [`events`], whose module doc gives their masks, flow and points); the camera arc is
//! the same in every kind. Outputs, next to the nerfies files:
//! - `mask/1x/<id>.png.png`: 255 where the pixel sees an object (rigid sphere or blob) that moves
//!   between `t_k` and `t_{k+1}` (its warped time changes), so all zero in the `static` kind;
//! - `flow/<id>.npy`: `H×W×2` f32, for each of those pixels, the projection **by the same camera
//!   `v_k`** of that surface point at `warp(t_{k+1})` minus its projection at `warp(t_k)` (scene
//!   motion without camera motion; occlusion at `t_{k+1}` is ignored; the last frame extrapolates
//!   to `t_N`), exactly zero wherever the mask is;
//! - `points.npy`: points sampled on the surfaces at `t = 0` with ±0.01 uniform noise (raw units;
//!   the same in every kind, since `warp(0) = 0`);
//! - `synthetic.json`: preset, seed, motion kind and these conventions.
//!
//! Cameras have zero distortion and a slightly off-centre principal point; `scene.json`
//! normalises with a non-trivial centre and scale. Everything is deterministic by seed.
//!
//! Over 600 lines: the primitives, their motion, the ray caster and the writer of every output
//! file share one scene description; they split along those lines if the scene grows (the
//! motion kinds' time warp lives in `synthetic/motion.rs`, the `events` kind's spheres in
//! `synthetic/events.rs`).

pub mod events;
mod motion;

use std::path::{Path, PathBuf};

use glam::{DMat3, DVec2, DVec3};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use serde_json::json;

use super::{image as img, points, progress_bar, DataError, DataResult};

pub use events::Ball;
pub use motion::SceneMotion;

/// Size presets.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Preset {
    /// 64×64, 24 frames (tests).
    Tiny,
    /// 160×120, 60 frames.
    Small,
    /// 480×270, 150 frames.
    Medium,
}

impl Preset {
    /// `(width, height, frames, points)`.
    pub fn dims(self) -> (u32, u32, usize, usize) {
        match self {
            Preset::Tiny => (64, 64, 24, 3000),
            Preset::Small => (160, 120, 60, 8000),
            Preset::Medium => (480, 270, 150, 20000),
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Preset::Tiny => "tiny",
            Preset::Small => "small",
            Preset::Medium => "medium",
        }
    }
}

/// What [`generate_with`] wrote.
#[derive(Clone, Debug)]
pub struct Summary {
    pub dir: PathBuf,
    pub preset: Preset,
    pub seed: u64,
    pub motion: SceneMotion,
    pub width: u32,
    pub height: u32,
    pub frames: usize,
    pub train: usize,
    pub val: usize,
    pub points: usize,
}

const ROOM_MIN: DVec3 = DVec3::new(-5.0, -1.2, -4.0);
const ROOM_MAX: DVec3 = DVec3::new(5.0, 5.0, 8.0);
const RIGID_RADIUS: f64 = 0.5;
const BLOB_CENTRE: DVec3 = DVec3::new(0.95, 0.0, -0.2);
const BLOB_R0: f64 = 0.55;
const BLOB_A: f64 = 0.12;
const BLOB_B: f64 = 0.06;

/// The analytic scene for one seed and motion kind.
///
/// The associated trajectory functions ([`Scene::rigid_centre`], [`Scene::rigid_rotation`],
/// [`Scene::blob_radius`], [`Scene::advect`]) take *scene* time; the methods ([`Scene::cast`],
/// [`Scene::shade`], [`render_view`]) take *frame* time and warp it by the scene's
/// [`SceneMotion`].
#[derive(Clone, Debug)]
pub struct Scene {
    seed: u64,
    motion: SceneMotion,
    wall_colors: [[DVec3; 2]; 6],
    rigid_colors: [DVec3; 2],
    blob_colors: [DVec3; 2],
}

/// What a ray hit (`Event`: one of the `events` kind's spheres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Hit {
    Room { p: DVec3, n: DVec3, face: usize },
    Rigid { p: DVec3 },
    Blob { p: DVec3 },
    Event { p: DVec3, ball: Ball },
}

impl Scene {
    /// The moving scene ([`SceneMotion::Moving`]).
    pub fn new(seed: u64) -> Self {
        Self::with_motion(seed, SceneMotion::Moving)
    }

    /// The scene with the given motion kind (textures and colours depend on `seed` only).
    pub fn with_motion(seed: u64, motion: SceneMotion) -> Self {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        let mut col = |lo: f64, hi: f64| {
            DVec3::new(
                rng.gen_range(lo..hi),
                rng.gen_range(lo..hi),
                rng.gen_range(lo..hi),
            )
        };
        let mut wall_colors = [[DVec3::ZERO; 2]; 6];
        for w in wall_colors.iter_mut() {
            *w = [col(0.45, 0.9), col(0.1, 0.45)];
        }
        Scene {
            seed,
            motion,
            wall_colors,
            rigid_colors: [col(0.7, 1.0), col(0.0, 0.3)],
            blob_colors: [col(0.5, 1.0), col(0.05, 0.4)],
        }
    }

    pub fn motion(&self) -> SceneMotion {
        self.motion
    }

    /// Rigid sphere centre at scene time `t`.
    pub fn rigid_centre(t: f64) -> DVec3 {
        use std::f64::consts::PI;
        DVec3::new(
            -1.0 + 0.8 * t,
            -0.2 + 0.3 * (2.0 * PI * t).sin(),
            0.2 * (PI * t).sin(),
        )
    }

    /// Rigid sphere rotation (object to world) at scene time `t`.
    pub fn rigid_rotation(t: f64) -> DMat3 {
        DMat3::from_axis_angle(
            DVec3::new(0.3, 1.0, 0.2).normalize(),
            std::f64::consts::PI * t,
        )
    }

    /// Blob radius along unit direction `u` at scene time `t`.
    pub fn blob_radius(u: DVec3, t: f64) -> f64 {
        use std::f64::consts::PI;
        let phi = u.z.atan2(u.x);
        BLOB_R0
            * (1.0
                + BLOB_A * (3.0 * PI * u.y - 4.0 * PI * t).sin()
                + BLOB_B * (2.0 * phi + 2.0 * PI * t).sin())
    }

    /// Where the surface point hit at scene time `t` is at scene time `t2`.
    pub fn advect(hit: &Hit, t: f64, t2: f64) -> DVec3 {
        match *hit {
            Hit::Room { p, .. } => p,
            Hit::Rigid { p } => {
                let l = Self::rigid_rotation(t).transpose() * (p - Self::rigid_centre(t));
                Self::rigid_centre(t2) + Self::rigid_rotation(t2) * l
            }
            Hit::Blob { p } => {
                let u = (p - BLOB_CENTRE).normalize();
                BLOB_CENTRE + Self::blob_radius(u, t2) * u
            }
            Hit::Event { p, ball } => events::advect(ball, p, t, t2),
        }
    }

    fn blob_sdf(p: DVec3, t: f64) -> f64 {
        let d = p - BLOB_CENTRE;
        let len = d.length();
        if len < 1e-12 {
            return -BLOB_R0;
        }
        len - Self::blob_radius(d / len, t)
    }

    /// Casts a ray (unit `d`) from `o` inside the room at frame time `t`.
    pub fn cast(&self, o: DVec3, d: DVec3, t: f64) -> Hit {
        self.cast_at(o, d, self.motion.warp(t))
    }

    /// Shaded colour of a hit at frame time `t`.
    pub fn shade(&self, hit: &Hit, t: f64) -> DVec3 {
        self.shade_at(hit, self.motion.warp(t))
    }

    /// [`Scene::cast`] at scene time `t`.
    fn cast_at(&self, o: DVec3, d: DVec3, t: f64) -> Hit {
        // Room: exit distance of the box interior.
        let mut best = f64::INFINITY;
        let mut face = 0;
        for a in 0..3 {
            let (da, oa) = (d[a], o[a]);
            if da.abs() < 1e-12 {
                continue;
            }
            let (s, f) = if da > 0.0 {
                ((ROOM_MAX[a] - oa) / da, 2 * a + 1)
            } else {
                ((ROOM_MIN[a] - oa) / da, 2 * a)
            };
            if s > 0.0 && s < best {
                best = s;
                face = f;
            }
        }
        let mut hit = {
            let mut n = DVec3::ZERO;
            n[face / 2] = if face % 2 == 1 { -1.0 } else { 1.0 };
            Hit::Room {
                p: o + best * d,
                n,
                face,
            }
        };
        // Rigid sphere.
        if let Some(s) = ray_sphere(o, d, Self::rigid_centre(t), RIGID_RADIUS) {
            if s < best {
                best = s;
                hit = Hit::Rigid { p: o + s * d };
            }
        }
        // Blob: march inside its bounding sphere, then bisect the first sign change.
        let bound = BLOB_R0 * (1.0 + BLOB_A + BLOB_B) + 1e-3;
        if let Some((s0, s1)) = ray_sphere_span(o, d, BLOB_CENTRE, bound) {
            let s0 = s0.max(0.0);
            if s0 < best {
                let steps = 64;
                let ds = (s1 - s0) / steps as f64;
                let mut a = s0;
                let mut fa = Self::blob_sdf(o + a * d, t);
                for i in 1..=steps {
                    let b = s0 + ds * i as f64;
                    let fb = Self::blob_sdf(o + b * d, t);
                    if fa > 0.0 && fb <= 0.0 {
                        let (mut lo, mut hi) = (a, b);
                        for _ in 0..40 {
                            let m = 0.5 * (lo + hi);
                            if Self::blob_sdf(o + m * d, t) > 0.0 {
                                lo = m;
                            } else {
                                hi = m;
                            }
                        }
                        let s = 0.5 * (lo + hi);
                        if s < best {
                            best = s;
                            hit = Hit::Blob { p: o + s * d };
                        }
                        break;
                    }
                    a = b;
                    fa = fb;
                }
            }
        }
        if self.motion == SceneMotion::Events {
            if let Some((s, ball)) = events::cast(o, d, t) {
                if s < best {
                    hit = Hit::Event { p: o + s * d, ball };
                }
            }
        }
        hit
    }

    /// [`Scene::shade`] at scene time `t`.
    fn shade_at(&self, hit: &Hit, t: f64) -> DVec3 {
        let light = DVec3::new(0.4, 1.0, 0.6).normalize();
        let (albedo, n) = match *hit {
            Hit::Room { p, n, face } => {
                let (a, b) = match face / 2 {
                    0 => (p.y, p.z),
                    1 => (p.x, p.z),
                    _ => (p.x, p.y),
                };
                let check = ((a / 0.5).floor() as i64 + (b / 0.5).floor() as i64).rem_euclid(2);
                let c = self.wall_colors[face][check as usize];
                let noise = value_noise(self.seed, a * 4.0, b * 4.0, face as u64) - 0.5;
                (c * (1.0 + 0.3 * noise), n)
            }
            Hit::Rigid { p } => {
                let c = Self::rigid_centre(t);
                let l = Self::rigid_rotation(t).transpose() * (p - c) / RIGID_RADIUS;
                let lon = l.z.atan2(l.x);
                let lat = l.y.clamp(-1.0, 1.0).asin();
                let k = ((lon / (std::f64::consts::PI / 4.0)).floor() as i64
                    + (lat / (std::f64::consts::PI / 6.0)).floor() as i64)
                    .rem_euclid(2);
                (self.rigid_colors[k as usize], (p - c).normalize())
            }
            Hit::Blob { p } => {
                let u = (p - BLOB_CENTRE).normalize();
                let stripe = 0.5 + 0.5 * (10.0 * u.y).sin();
                let phi = u.z.atan2(u.x);
                let band = ((phi / (std::f64::consts::PI / 5.0)).floor() as i64).rem_euclid(2);
                let c = self.blob_colors[0] * stripe + self.blob_colors[1] * (1.0 - stripe);
                let c = if band == 1 { c * 0.8 } else { c };
                let e = 1e-4;
                let g = DVec3::new(
                    Self::blob_sdf(p + DVec3::X * e, t) - Self::blob_sdf(p - DVec3::X * e, t),
                    Self::blob_sdf(p + DVec3::Y * e, t) - Self::blob_sdf(p - DVec3::Y * e, t),
                    Self::blob_sdf(p + DVec3::Z * e, t) - Self::blob_sdf(p - DVec3::Z * e, t),
                );
                (c, g.normalize_or_zero())
            }
            Hit::Event { p, ball } => events::shade(ball, p, t),
        };
        let lambert = n.dot(light).max(0.0);
        (albedo * (0.4 + 0.6 * lambert)).clamp(DVec3::ZERO, DVec3::ONE)
    }
}

fn ray_sphere_span(o: DVec3, d: DVec3, c: DVec3, r: f64) -> Option<(f64, f64)> {
    let oc = o - c;
    let b = oc.dot(d);
    let disc = b * b - (oc.length_squared() - r * r);
    if disc < 0.0 {
        return None;
    }
    let q = disc.sqrt();
    let (s0, s1) = (-b - q, -b + q);
    (s1 > 0.0).then_some((s0, s1))
}

fn ray_sphere(o: DVec3, d: DVec3, c: DVec3, r: f64) -> Option<f64> {
    let (s0, s1) = ray_sphere_span(o, d, c, r)?;
    Some(if s0 > 1e-9 { s0 } else { s1 })
}

fn hash(seed: u64, x: i64, y: i64, z: u64) -> f64 {
    let mut h = seed
        ^ (x as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ z.wrapping_mul(0x1656_67B1_9E37_79F9);
    h ^= h >> 33;
    h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
    h ^= h >> 33;
    h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
    h ^= h >> 33;
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// Smooth value noise in `[0, 1]`.
fn value_noise(seed: u64, x: f64, y: f64, z: u64) -> f64 {
    let (xi, yi) = (x.floor() as i64, y.floor() as i64);
    let (fx, fy) = (x - xi as f64, y - yi as f64);
    let s = |v: f64| v * v * (3.0 - 2.0 * v);
    let (sx, sy) = (s(fx), s(fy));
    let a = hash(seed, xi, yi, z);
    let b = hash(seed, xi + 1, yi, z);
    let c = hash(seed, xi, yi + 1, z);
    let d = hash(seed, xi + 1, yi + 1, z);
    (a * (1.0 - sx) + b * sx) * (1.0 - sy) + (c * (1.0 - sx) + d * sx) * sy
}

/// A pinhole camera of the generator (f64, OpenCV convention, raw world units).
#[derive(Clone, Copy, Debug)]
pub struct GenCamera {
    /// World-to-camera rotation (rows = camera axes).
    pub rotation: DMat3,
    pub centre: DVec3,
    pub f: f64,
    pub cx: f64,
    pub cy: f64,
    pub width: u32,
    pub height: u32,
}

impl GenCamera {
    /// The camera of frame `k` of `n`.
    pub fn for_frame(k: usize, n: usize, width: u32, height: u32) -> Self {
        let s = if n > 1 {
            k as f64 / (n - 1) as f64
        } else {
            0.0
        };
        let theta = -0.35 + 0.7 * s;
        let target = DVec3::new(0.0, 0.0, 0.0);
        let centre = target
            + DVec3::new(
                4.0 * theta.sin(),
                0.9 + 0.15 * (std::f64::consts::PI * s).sin(),
                4.0 * theta.cos(),
            );
        let fwd = (target - centre).normalize();
        let right = fwd.cross(DVec3::Y).normalize();
        let down = fwd.cross(right);
        let rotation = DMat3::from_cols(right, down, fwd).transpose();
        let fov_x = 55f64.to_radians();
        let f = 0.5 * width as f64 / (0.5 * fov_x).tan();
        GenCamera {
            rotation,
            centre,
            f,
            cx: 0.5 * width as f64 + 0.031 * width as f64,
            cy: 0.5 * height as f64 - 0.023 * height as f64,
            width,
            height,
        }
    }

    pub fn project(&self, p: DVec3) -> Option<DVec2> {
        let q = self.rotation * (p - self.centre);
        (q.z > 1e-9).then(|| DVec2::new(self.f * q.x / q.z + self.cx, self.f * q.y / q.z + self.cy))
    }

    /// Unit world ray through continuous pixel position `px`.
    pub fn ray(&self, px: DVec2) -> DVec3 {
        let d = DVec3::new((px.x - self.cx) / self.f, (px.y - self.cy) / self.f, 1.0);
        (self.rotation.transpose() * d).normalize()
    }
}

/// One rendered frame: RGB `[0,1]`, mask (0/1), flow (pixels).
pub struct Rendered {
    pub rgb: Vec<f32>,
    pub mask: Vec<u8>,
    pub flow: Vec<f32>,
}

/// Renders frame `k` of `n` at the given size (camera of frame `k`, time `t_k`, flow towards
/// `t_{k+1}`).
pub fn render_frame(scene: &Scene, k: usize, n: usize, width: u32, height: u32) -> Rendered {
    let cam = GenCamera::for_frame(k, n, width, height);
    let dt = 1.0 / (n.max(2) - 1) as f64;
    render_view(scene, &cam, k as f64 * dt, (k + 1) as f64 * dt)
}

/// Renders the scene at frame time `t` from `cam`, with the scene flow towards `t_next` seen by
/// the same camera. Both times are warped by the scene's motion kind; the mask and the flow are
/// zero everywhere when the warped times are equal (nothing moves in between).
pub fn render_view(scene: &Scene, cam: &GenCamera, t: f64, t_next: f64) -> Rendered {
    let (w, h) = (cam.width as usize, cam.height as usize);
    let (s, s_next) = (scene.motion.warp(t), scene.motion.warp(t_next));
    let moving = s != s_next;
    let mut rgb = vec![0.0f32; w * h * 3];
    let mut mask = vec![0u8; w * h];
    let mut flow = vec![0.0f32; w * h * 2];
    for j in 0..h {
        for i in 0..w {
            let px = DVec2::new(i as f64 + 0.5, j as f64 + 0.5);
            let hit = scene.cast_at(cam.centre, cam.ray(px), s);
            let c = scene.shade_at(&hit, s);
            let o = j * w + i;
            rgb[o * 3..o * 3 + 3].copy_from_slice(&[c.x as f32, c.y as f32, c.z as f32]);
            let changes = match hit {
                Hit::Room { .. } => false,
                Hit::Rigid { .. } | Hit::Blob { .. } => moving,
                Hit::Event { ball, .. } => events::changes(ball, s, s_next),
            };
            if changes {
                mask[o] = 1;
                let p = match hit {
                    Hit::Rigid { p }
                    | Hit::Blob { p }
                    | Hit::Room { p, .. }
                    | Hit::Event { p, .. } => p,
                };
                let p2 = Scene::advect(&hit, s, s_next);
                if let (Some(a), Some(b)) = (cam.project(p), cam.project(p2)) {
                    flow[o * 2] = (b.x - a.x) as f32;
                    flow[o * 2 + 1] = (b.y - a.y) as f32;
                }
            }
        }
    }
    Rendered { rgb, mask, flow }
}

/// [`sample_points`] of the kind: the same for every kind but `events`, whose last `n/8` points
/// lie on its spheres present at `t = 0` ([`events::sample_points`]).
pub fn sample_points_with(seed: u64, n: usize, motion: SceneMotion) -> Vec<DVec3> {
    if motion != SceneMotion::Events {
        return sample_points(seed, n);
    }
    let m = n / 8;
    let mut out = sample_points(seed, n - m);
    out.extend(events::sample_points(seed, m));
    out
}

/// Points on the surfaces at `t = 0` (raw world units), with ±0.01 uniform noise; `t = 0` is the
/// rest pose of every motion kind (the `events` kind adds its spheres: [`sample_points_with`]).
pub fn sample_points(seed: u64, n: usize) -> Vec<DVec3> {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed ^ 0xB0B);
    let noise = 0.01;
    let unit = |rng: &mut rand_pcg::Pcg64| loop {
        let v = DVec3::new(
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
            rng.gen_range(-1.0..1.0),
        );
        let l = v.length();
        if l > 1e-3 && l <= 1.0 {
            return v / l;
        }
    };
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let p = match i % 4 {
            0 => Scene::rigid_centre(0.0) + RIGID_RADIUS * unit(&mut rng),
            1 => {
                let u = unit(&mut rng);
                BLOB_CENTRE + Scene::blob_radius(u, 0.0) * u
            }
            _ => {
                // Room: floor, back wall or a side wall.
                let a: f64 = rng.gen();
                let b: f64 = rng.gen();
                match rng.gen_range(0..4) {
                    0 => DVec3::new(
                        ROOM_MIN.x + a * (ROOM_MAX.x - ROOM_MIN.x),
                        ROOM_MIN.y,
                        ROOM_MIN.z + b * (ROOM_MAX.z - ROOM_MIN.z),
                    ),
                    1 => DVec3::new(
                        ROOM_MIN.x + a * (ROOM_MAX.x - ROOM_MIN.x),
                        ROOM_MIN.y + b * (ROOM_MAX.y - ROOM_MIN.y),
                        ROOM_MIN.z,
                    ),
                    2 => DVec3::new(
                        ROOM_MIN.x,
                        ROOM_MIN.y + a * (ROOM_MAX.y - ROOM_MIN.y),
                        ROOM_MIN.z + b * (ROOM_MAX.z - ROOM_MIN.z),
                    ),
                    _ => DVec3::new(
                        ROOM_MAX.x,
                        ROOM_MIN.y + a * (ROOM_MAX.y - ROOM_MIN.y),
                        ROOM_MIN.z + b * (ROOM_MAX.z - ROOM_MIN.z),
                    ),
                }
            }
        };
        let jitter = DVec3::new(
            rng.gen_range(-noise..noise),
            rng.gen_range(-noise..noise),
            rng.gen_range(-noise..noise),
        );
        out.push(p + jitter);
    }
    out
}

/// The `scene.json` normalisation used by the generator: `(p − center)·scale`.
pub const SCENE_CENTER: [f64; 3] = [0.0, 0.3, 0.5];
pub const SCENE_SCALE: f64 = 0.3;

fn write_json(path: &Path, v: &serde_json::Value) -> DataResult<()> {
    let s = serde_json::to_string_pretty(v).map_err(|e| DataError::file(path, e.to_string()))?;
    std::fs::write(path, s).map_err(|e| DataError::write(path, e))
}

fn mkdir(p: &Path) -> DataResult<()> {
    std::fs::create_dir_all(p).map_err(|e| DataError::write(p, e))
}

/// The frame id of frame `k`.
pub fn frame_id(k: usize) -> String {
    format!("{k:06}")
}

/// Whether frame `k` is a validation frame (every 8th, starting at 4).
pub fn is_val(k: usize) -> bool {
    k % 8 == 4
}

/// Generates the moving scene into `out` (created if needed; existing files are overwritten).
pub fn generate(preset: Preset, seed: u64, out: &Path) -> DataResult<Summary> {
    generate_with(preset, seed, SceneMotion::Moving, out)
}

/// Generates the scene with the given motion kind into `out` (created if needed; existing files
/// are overwritten).
pub fn generate_with(
    preset: Preset,
    seed: u64,
    motion: SceneMotion,
    out: &Path,
) -> DataResult<Summary> {
    let (w, h, n, n_points) = preset.dims();
    let scene = Scene::with_motion(seed, motion);
    for d in ["camera", "rgb/1x", "mask/1x", "flow"] {
        mkdir(&out.join(d))?;
    }
    let ids: Vec<String> = (0..n).map(frame_id).collect();
    let train: Vec<&String> = ids
        .iter()
        .enumerate()
        .filter(|(k, _)| !is_val(*k))
        .map(|(_, i)| i)
        .collect();
    let val: Vec<&String> = ids
        .iter()
        .enumerate()
        .filter(|(k, _)| is_val(*k))
        .map(|(_, i)| i)
        .collect();
    write_json(
        &out.join("dataset.json"),
        &json!({"count": n, "num_exemplars": train.len(), "ids": ids,
                "train_ids": train, "val_ids": val}),
    )?;
    let meta: serde_json::Map<String, serde_json::Value> = ids
        .iter()
        .enumerate()
        .map(|(k, id)| {
            (
                id.clone(),
                json!({"time_id": k, "warp_id": k, "appearance_id": k, "camera_id": 0}),
            )
        })
        .collect();
    write_json(&out.join("metadata.json"), &serde_json::Value::Object(meta))?;
    write_json(
        &out.join("scene.json"),
        &json!({"scale": SCENE_SCALE, "center": SCENE_CENTER,
                "near": 0.5 * SCENE_SCALE, "far": 16.0 * SCENE_SCALE,
                "bbox": [ROOM_MIN.to_array(), ROOM_MAX.to_array()]}),
    )?;
    let mut info = json!({
        "generator": "dispflow-vk data gen",
        "preset": preset.name(), "seed": seed, "width": w, "height": h, "frames": n,
        "motion": motion.name(),
        "time": "frame k at t = k/(N-1); metadata time_id = k; the camera follows t, the objects are posed at warp(t)",
        "warp": "moving: t; static: 0; late: 0 for t <= 0.5, else (t - 0.5) * 2",
        "mask": "mask/1x/<id>.png.png: 255 = pixel sees an object (rigid sphere or deforming blob) whose warped time changes between t_k and t_{k+1}",
        "flow": "flow/<id>.npy: HxWx2 f32 pixels; projection by camera k of the surface point at warp(t_{k+1}) minus at warp(t_k); 0 where the mask is 0",
        "points": "points.npy: Nx3 f32 raw world positions on the surfaces at t=0, +-0.01 noise",
    });
    if motion == SceneMotion::Events {
        events::describe(&mut info);
    }
    write_json(&out.join("synthetic.json"), &info)?;
    let pb = progress_bar(n as u64, "rendering", true);
    (0..n).into_par_iter().try_for_each(|k| -> DataResult<()> {
        let cam = GenCamera::for_frame(k, n, w, h);
        let rows = cam.rotation.transpose();
        let id = &ids[k];
        write_json(
            &out.join(format!("camera/{id}.json")),
            &json!({
                "orientation": [rows.x_axis.to_array(), rows.y_axis.to_array(), rows.z_axis.to_array()],
                "position": cam.centre.to_array(),
                "focal_length": cam.f,
                "principal_point": [cam.cx, cam.cy],
                "skew": 0.0,
                "pixel_aspect_ratio": 1.0,
                "radial_distortion": [0.0, 0.0, 0.0],
                "tangential_distortion": [0.0, 0.0],
                "image_size": [w, h],
            }),
        )?;
        let r = render_frame(&scene, k, n, w, h);
        img::save_rgb(&out.join(format!("rgb/1x/{id}.png")), w, h, &r.rgb)?;
        let m: Vec<u8> = r.mask.iter().map(|&v| v * 255).collect();
        img::save_gray(&out.join(format!("mask/1x/{id}.png.png")), w, h, &m)?;
        points::write_npy_f32(
            &out.join(format!("flow/{id}.npy")),
            &[h as u64, w as u64, 2],
            &r.flow,
        )?;
        pb.inc(1);
        Ok(())
    })?;
    pb.finish_and_clear();
    let pts = sample_points_with(seed, n_points, motion);
    let flat: Vec<f32> = pts
        .iter()
        .flat_map(|p| [p.x as f32, p.y as f32, p.z as f32])
        .collect();
    points::write_npy_f32(&out.join("points.npy"), &[pts.len() as u64, 3], &flat)?;
    Ok(Summary {
        dir: out.to_path_buf(),
        preset,
        seed,
        motion,
        width: w,
        height: h,
        frames: n,
        train: train.len(),
        val: val.len(),
        points: pts.len(),
    })
}
