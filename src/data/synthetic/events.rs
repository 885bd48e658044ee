//! The `events` motion kind ([`super::SceneMotion::Events`]): the rigid sphere and the blob move
//! as in `moving`, and three small textured spheres (radius [`RADIUS`], half the rigid sphere's)
//! change in ways that one canonical space plus a deformation cannot draw:
//!
//! - [`Ball::Appearing`] (orange/red latitude bands) is absent for `t <` [`T_APPEAR`], present
//!   from then on, translating and rotating slowly from where it appeared;
//! - [`Ball::Vanishing`] (cyan/navy longitude segments) translates and rotates slowly while
//!   `t <` [`T_VANISH`], and is absent from then on;
//! - [`Ball::Splitting`] (magenta/yellow checker) rests as one sphere while `t <` [`T_SPLIT`];
//!   from then on it is two spheres, [`Ball::PieceNeg`] and [`Ball::PiecePos`], each of half its
//!   volume (radius `RADIUS·2^(−1/3)`), whose centres leave the split point in opposite
//!   directions along the split plane's normal [`SPLIT_NORMAL`] at [`SPLIT_SPEED`] each (they
//!   overlap at first and separate from `t ≈ 0.70`). A piece wears the whole sphere's texture,
//!   shrunk: the point of material direction `u` from the centre is drawn in the same colour.
//!
//! All three sit above the existing objects, seen by the whole camera arc in every preset (fully
//! in frame, not in front of nor behind the sphere or the blob), and never touch the other
//! objects or each other. Times are scene times (the kind's warp is the identity, as `moving`).
//!
//! Masks and flow (frame `k` at `t_k`, towards `t_{k+1}`), for pixels that see one of these:
//! - a sphere present at `t_k` that moves, vanishes or splits before `t_{k+1}` is masked; the
//!   resting whole [`Ball::Splitting`] is masked only at the frame whose interval holds the split
//!   (`t_k < T_SPLIT ≤ t_{k+1}`); a sphere absent at `t_k` sees no pixel, so the frame in which
//!   [`Ball::Appearing`] appears masks nothing of it (its pixels still see what is behind);
//! - flow, as for the other objects, projects by camera `k` the surface point at `t_{k+1}` minus
//!   at `t_k`; a point without a counterpart at `t_{k+1}` (the vanishing sphere's, across
//!   [`T_VANISH`]) has flow exactly 0 under a mask of 255; a point of the whole splitting sphere
//!   across [`T_SPLIT`] follows its piece, the side of the split plane (through the centre,
//!   normal [`SPLIT_NORMAL`]) it lies on (`≥ 0`: [`Ball::PiecePos`]), to the piece's point of the
//!   same material direction: `c_piece(t_{k+1}) + 2^(−1/3)·(p − c)`.
//! - `points.npy` (sampled at `t = 0`) covers the vanishing and the whole splitting sphere, not
//!   the appearing one (absent then): [`sample_points`] gives the last `N/8` points of the kind.

use glam::{DMat3, DVec3};
use rand::{Rng, SeedableRng};

/// Radius of the three spheres (half the rigid sphere's 0.5).
pub const RADIUS: f64 = 0.25;
/// `2^(−1/3)`: a piece of the split sphere has half its volume.
pub const PIECE_SCALE: f64 = 0.793_700_525_984_099_8;
/// [`Ball::Appearing`] exists for `t ≥ T_APPEAR`.
pub const T_APPEAR: f64 = 0.35;
/// [`Ball::Vanishing`] exists for `t < T_VANISH`.
pub const T_VANISH: f64 = 0.65;
/// [`Ball::Splitting`] exists for `t < T_SPLIT`, its two pieces for `t ≥ T_SPLIT`.
pub const T_SPLIT: f64 = 0.5;
/// Normal of the split plane (world); [`Ball::PiecePos`] moves along it, [`Ball::PieceNeg`] against.
pub const SPLIT_NORMAL: DVec3 = DVec3::X;
/// Speed of each piece's centre away from the split point (world units per unit time).
pub const SPLIT_SPEED: f64 = 1.0;

const APPEAR_AT: DVec3 = DVec3::new(-1.5, 0.85, 0.0);
const APPEAR_VEL: DVec3 = DVec3::new(0.3, 0.0, 0.1);
const VANISH_AT_0: DVec3 = DVec3::new(1.6, 0.85, -0.2);
const VANISH_VEL: DVec3 = DVec3::new(-0.15, 0.0, 0.1);
const SPLIT_AT: DVec3 = DVec3::new(0.1, 0.85, -0.6);

/// One of the `events` kind's spheres (the splitting one's two pieces are their own spheres).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ball {
    Appearing,
    Vanishing,
    /// The splitting sphere while whole (`t < T_SPLIT`).
    Splitting,
    /// The piece on the negative side of the split plane (`t ≥ T_SPLIT`).
    PieceNeg,
    /// The piece on the positive side of the split plane (`t ≥ T_SPLIT`).
    PiecePos,
}

impl Ball {
    pub const ALL: [Ball; 5] = [
        Ball::Appearing,
        Ball::Vanishing,
        Ball::Splitting,
        Ball::PieceNeg,
        Ball::PiecePos,
    ];

    /// Whether the sphere exists at scene time `t`.
    pub fn present(self, t: f64) -> bool {
        match self {
            Ball::Appearing => t >= T_APPEAR,
            Ball::Vanishing => t < T_VANISH,
            Ball::Splitting => t < T_SPLIT,
            Ball::PieceNeg | Ball::PiecePos => t >= T_SPLIT,
        }
    }

    pub fn radius(self) -> f64 {
        match self {
            Ball::PieceNeg | Ball::PiecePos => RADIUS * PIECE_SCALE,
            _ => RADIUS,
        }
    }

    /// Centre at scene time `t` (the trajectory, also where the sphere is absent).
    pub fn centre(self, t: f64) -> DVec3 {
        match self {
            Ball::Appearing => APPEAR_AT + APPEAR_VEL * (t - T_APPEAR),
            Ball::Vanishing => VANISH_AT_0 + VANISH_VEL * t,
            Ball::Splitting => SPLIT_AT,
            Ball::PieceNeg => SPLIT_AT - SPLIT_NORMAL * (SPLIT_SPEED * (t - T_SPLIT)),
            Ball::PiecePos => SPLIT_AT + SPLIT_NORMAL * (SPLIT_SPEED * (t - T_SPLIT)),
        }
    }

    /// Rotation (object to world) at scene time `t`; the split sphere and its pieces do not turn.
    pub fn rotation(self, t: f64) -> DMat3 {
        use std::f64::consts::FRAC_PI_2;
        match self {
            Ball::Appearing => DMat3::from_axis_angle(
                DVec3::new(0.0, 1.0, 0.3).normalize(),
                FRAC_PI_2 * (t - T_APPEAR),
            ),
            Ball::Vanishing => {
                DMat3::from_axis_angle(DVec3::new(1.0, 0.4, 0.0).normalize(), FRAC_PI_2 * t)
            }
            _ => DMat3::IDENTITY,
        }
    }

    /// Unit object-frame direction of surface point `p` at scene time `t` (material coordinate).
    fn local(self, p: DVec3, t: f64) -> DVec3 {
        (self.rotation(t).transpose() * (p - self.centre(t)) / self.radius()).normalize_or_zero()
    }
}

/// Nearest hit `(distance, sphere)` at scene time `t` of the ray from `o` along unit `d`.
pub fn cast(o: DVec3, d: DVec3, t: f64) -> Option<(f64, Ball)> {
    Ball::ALL
        .into_iter()
        .filter(|b| b.present(t))
        .filter_map(|b| Some((super::ray_sphere(o, d, b.centre(t), b.radius())?, b)))
        .min_by(|a, b| a.0.total_cmp(&b.0))
}

/// Whether the surface of `ball`, present at `t`, changes by `t2`: the resting whole splitting
/// sphere only when `t2` reaches the split; every other sphere moves whenever `t2 ≠ t`.
pub fn changes(ball: Ball, t: f64, t2: f64) -> bool {
    match ball {
        Ball::Splitting => t2 >= T_SPLIT,
        _ => t2 != t,
    }
}

/// Where surface point `p` of `ball` at `t` is at `t2`; `p` itself when it has no counterpart
/// there (so its flow is exactly zero): the vanishing sphere at `t2 ≥ T_VANISH`, the appearing
/// one at `t2 < T_APPEAR`. Across the split, a point follows the piece on its side of the plane.
pub fn advect(ball: Ball, p: DVec3, t: f64, t2: f64) -> DVec3 {
    let rigid =
        |b: Ball| b.centre(t2) + b.rotation(t2) * (b.rotation(t).transpose() * (p - b.centre(t)));
    match ball {
        Ball::Appearing | Ball::Vanishing if ball.present(t2) => rigid(ball),
        Ball::Appearing | Ball::Vanishing => p,
        Ball::Splitting if t2 < T_SPLIT => p,
        Ball::Splitting => {
            let piece = if (p - SPLIT_AT).dot(SPLIT_NORMAL) >= 0.0 {
                Ball::PiecePos
            } else {
                Ball::PieceNeg
            };
            piece.centre(t2) + PIECE_SCALE * (p - SPLIT_AT)
        }
        Ball::PieceNeg | Ball::PiecePos if t2 >= T_SPLIT => rigid(ball),
        // Back across the split: the whole sphere's point of the same material direction.
        Ball::PieceNeg | Ball::PiecePos => SPLIT_AT + (p - ball.centre(t)) / PIECE_SCALE,
    }
}

/// Albedo and unit normal of surface point `p` of `ball` at scene time `t`.
pub fn shade(ball: Ball, p: DVec3, t: f64) -> (DVec3, DVec3) {
    use std::f64::consts::PI;
    let l = ball.local(p, t);
    let lon = l.z.atan2(l.x);
    let lat = l.y.clamp(-1.0, 1.0).asin();
    let (pair, k) = match ball {
        Ball::Appearing => (
            [DVec3::new(0.95, 0.55, 0.1), DVec3::new(0.45, 0.05, 0.05)],
            (lat / (PI / 6.0)).floor() as i64,
        ),
        Ball::Vanishing => (
            [DVec3::new(0.1, 0.85, 0.9), DVec3::new(0.05, 0.15, 0.45)],
            (lon / (PI / 3.0)).floor() as i64,
        ),
        Ball::Splitting | Ball::PieceNeg | Ball::PiecePos => (
            [DVec3::new(0.9, 0.1, 0.75), DVec3::new(0.95, 0.9, 0.15)],
            (lon / (PI / 3.0)).floor() as i64 + (lat / (PI / 4.0)).floor() as i64,
        ),
    };
    let n = (p - ball.centre(t)).normalize_or_zero();
    (pair[k.rem_euclid(2) as usize], n)
}

/// `n` points on the spheres present at `t = 0` (the vanishing and the whole splitting one,
/// alternately) with ±0.01 uniform noise, deterministic by seed.
pub fn sample_points(seed: u64, n: usize) -> Vec<DVec3> {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed ^ 0xE7E75);
    let noise = 0.01;
    (0..n)
        .map(|i| {
            let u = loop {
                let v = DVec3::new(
                    rng.gen_range(-1.0..1.0),
                    rng.gen_range(-1.0..1.0),
                    rng.gen_range(-1.0..1.0),
                );
                let l = v.length();
                if l > 1e-3 && l <= 1.0 {
                    break v / l;
                }
            };
            let b = if i % 2 == 0 {
                Ball::Vanishing
            } else {
                Ball::Splitting
            };
            let jitter = DVec3::new(
                rng.gen_range(-noise..noise),
                rng.gen_range(-noise..noise),
                rng.gen_range(-noise..noise),
            );
            b.centre(0.0) + b.radius() * u + jitter
        })
        .collect()
}

/// Adds this kind's entries to (or replaces the common ones of) the `synthetic.json` object.
pub fn describe(info: &mut serde_json::Value) {
    info["warp"] =
        "moving: t; static: 0; late: 0 for t <= 0.5, else (t - 0.5) * 2; events: t".into();
    info["events"] = serde_json::json!({
        "radius": RADIUS, "piece_radius": RADIUS * PIECE_SCALE,
        "appearing": {"present": format!("t >= {T_APPEAR}"), "centre_at_appearance": APPEAR_AT.to_array(),
                      "velocity": APPEAR_VEL.to_array(), "texture": "orange/red latitude bands"},
        "vanishing": {"present": format!("t < {T_VANISH}"), "centre_at_t0": VANISH_AT_0.to_array(),
                      "velocity": VANISH_VEL.to_array(), "texture": "cyan/navy longitude segments"},
        "splitting": {"whole": format!("t < {T_SPLIT}, at rest"), "centre": SPLIT_AT.to_array(),
                      "pieces": format!("t >= {T_SPLIT}: two spheres of half the volume, centres at centre +- split_normal * {SPLIT_SPEED} * (t - {T_SPLIT})"),
                      "split_normal": SPLIT_NORMAL.to_array(),
                      "texture": "magenta/yellow checker (each piece the whole texture, shrunk)"},
    });
    info["mask"] = "mask/1x/<id>.png.png: 255 = pixel sees an object (rigid sphere, deforming blob, event sphere) present at t_k that changes by t_{k+1}: moves, vanishes or splits (the resting whole splitting sphere only across the split; an appearing sphere absent at t_k has no pixel)".into();
    info["flow"] = "flow/<id>.npy: HxWx2 f32 pixels; projection by camera k of the surface point at t_{k+1} minus at t_k; 0 where the mask is 0 and for points without a counterpart at t_{k+1} (vanishing); across the split a point follows the piece on its side of the split plane (same material direction on the piece)".into();
    info["points"] = "points.npy: Nx3 f32 raw world positions on the surfaces at t=0, +-0.01 noise; the last N/8 on the vanishing and the whole splitting sphere (the appearing one is absent at t=0)".into();
}

#[cfg(test)]
mod tests {
    use super::super::{Scene, BLOB_A, BLOB_B, BLOB_CENTRE, BLOB_R0, RIGID_RADIUS};
    use super::*;

    #[test]
    fn spheres_keep_clear_of_the_other_objects() {
        let blob_bound = BLOB_R0 * (1.0 + BLOB_A + BLOB_B);
        // Up to the last frame's flow target, t_N = 1 + 1/(N−1).
        for i in 0..=110 {
            let t = i as f64 / 100.0;
            let here: Vec<Ball> = Ball::ALL.into_iter().filter(|b| b.present(t)).collect();
            for &b in &here {
                let (c, r) = (b.centre(t), b.radius());
                assert!(
                    c.distance(Scene::rigid_centre(t)) > RIGID_RADIUS + r + 0.1,
                    "{b:?} {t}"
                );
                assert!(c.distance(BLOB_CENTRE) > blob_bound + r + 0.1, "{b:?} {t}");
                for &o in &here {
                    let pieces = matches!(o, Ball::PieceNeg | Ball::PiecePos)
                        && matches!(b, Ball::PieceNeg | Ball::PiecePos);
                    if b != o && !pieces {
                        assert!(
                            c.distance(o.centre(t)) > r + o.radius() + 0.1,
                            "{b:?} {o:?}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn pieces_have_half_the_volume_and_follow_their_side() {
        assert!((PIECE_SCALE.powi(3) - 0.5).abs() < 1e-15);
        let p = SPLIT_AT + DVec3::new(0.2, 0.15, 0.0).normalize() * RADIUS;
        let q = advect(Ball::Splitting, p, 0.45, 0.6);
        let c = Ball::PiecePos.centre(0.6);
        assert!(((q - c).length() - RADIUS * PIECE_SCALE).abs() < 1e-12);
        assert!((q - c)
            .normalize()
            .abs_diff_eq((p - SPLIT_AT).normalize(), 1e-12));
        let r = advect(Ball::Splitting, SPLIT_AT - (p - SPLIT_AT), 0.45, 0.6);
        assert!((r - Ball::PieceNeg.centre(0.6)).dot(SPLIT_NORMAL) < 0.0);
        // Before the split the whole sphere rests; the vanishing one leaves its points in place.
        assert_eq!(advect(Ball::Splitting, p, 0.1, 0.4), p);
        assert_eq!(advect(Ball::Vanishing, p, 0.6, 0.7), p);
        assert!(!changes(Ball::Splitting, 0.1, 0.4) && changes(Ball::Splitting, 0.45, 0.5));
    }
}
