//! CPU twin of the differentiable 3D Gaussian splatting tile rasteriser (gsplat "classic"
//! conventions): `project` → `blend_fwd`, and the reverse-mode pair `blend_bwd` → `project_bwd`.
//!
//! This module *defines* what the GPU stages compute. It is written for clarity, not speed: plain
//! loops, every Gaussian walked for every pixel (brute force over the depth-sorted list, filtered
//! by tile rectangle exactly as a tile list would be), all arithmetic in f64. Forward outputs are
//! rounded to f32 (what the GPU stores); gradients are returned in f64.
//!
//! Every stage also has an `_f64` variant working on [`Gaussians64`] / [`Projected64`] without
//! any rounding, so finite differences of the whole pipeline are meaningful; the f32 entry points
//! are thin wrappers (widen → f64 path → round). The only computation done in f32 on purpose is
//! the tile rectangle, which follows the GPU bit for bit (see [`project`]).
//!
//! Conventions (shared with the GLSL side, see the crate's design notes and
//! `../shared/data/gsplat-reference/README.md`):
//! - camera: OpenCV (x right, y down, z forward), `p_cam = rot · p + trans`, pinhole `fx, fy, cx,
//!   cy`, pixel centres at `(px + 0.5, py + 0.5)`;
//! - EWA projection with the Jacobian's `x/z`, `y/z` clamped to 1.3× the half-fov (gsplat's
//!   asymmetric limits for an off-centre principal point), 2D covariance dilated by `0.3·I`;
//! - colour `max(SH(dir) + 0.5, 0)` with the view direction detached; opacity `sigmoid(logit)`;
//! - front-to-back blending with `α = min(alpha_max, o·exp(−σ))`, `σ` clamped at 0 from below
//!   (a negative σ is rounding of a near-singular conic; gsplat skips such a pixel), skip
//!   `α < 1/255`,
//!   stop (without blending) when the transmittance would drop below `1e-4`.

// Index loops on purpose: they read like the GLSL they define.
#![allow(clippy::needless_range_loop)]

pub mod bin;
mod blend;
mod project;

pub use blend::{blend_bwd, blend_bwd_f64, blend_fwd, blend_fwd_f64, BlendOut64};
pub use project::{
    alpha_extent, opacity_rect, project, project_bwd, project_bwd_f64, project_f64,
    project_scaled_bwd_f64, project_scaled_f64, quat_to_rot, radius_rect,
};

/// Tile edge in pixels.
pub const TILE: u32 = 16;
/// Added to the diagonal of the projected 2D covariance (gsplat's `eps2d`).
pub const DILATION: f64 = 0.3;
/// Gaussians whose α at a pixel is below this are skipped there.
pub const ALPHA_MIN: f64 = 1.0 / 255.0;
/// A pixel stops (without blending the Gaussian) when its transmittance would drop below this.
pub const T_MIN: f64 = 1e-4;
/// Quaternions with a norm below this are replaced by the identity (and get no gradient).
pub const QUAT_EPS: f64 = 1e-12;

/// The camera is the GPU side's type: both stages read the same struct.
pub use crate::kernels::raster::Camera;

/// Raw (pre-activation) Gaussian parameters, borrowed, f32 as stored on the GPU. N = `means.len()`.
#[derive(Clone, Copy, Debug)]
pub struct Gaussians<'a> {
    pub means: &'a [[f32; 3]],
    /// LINEAR scales (not log); the sign is irrelevant since Σ uses s².
    pub scales: &'a [[f32; 3]],
    /// (w, x, y, z), unnormalised.
    pub quats: &'a [[f32; 4]],
    pub opacity_logits: &'a [f32],
    /// `[N][sh_coeffs][3]`: coefficient k of Gaussian i, channel c at `(i*sh_coeffs + k)*3 + c`.
    pub sh: &'a [f32],
    /// Coefficients stored per Gaussian: 1, 4, 9 or 16.
    pub sh_coeffs: u32,
    /// Active degree, `(sh_degree+1)² <= sh_coeffs`.
    pub sh_degree: u32,
}

impl Gaussians<'_> {
    pub fn len(&self) -> usize {
        self.means.len()
    }
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }
}

/// Owned f64 copy of [`Gaussians`], for the unrounded (`_f64`) pipeline and finite differences.
#[derive(Clone, Debug, Default)]
pub struct Gaussians64 {
    pub means: Vec<[f64; 3]>,
    pub scales: Vec<[f64; 3]>,
    pub quats: Vec<[f64; 4]>,
    pub opacity_logits: Vec<f64>,
    pub sh: Vec<f64>,
    pub sh_coeffs: u32,
    pub sh_degree: u32,
}

impl Gaussians64 {
    /// Exact widening of `g`.
    pub fn from_f32(g: &Gaussians) -> Self {
        let w3 = |v: &[[f32; 3]]| v.iter().map(|a| a.map(f64::from)).collect();
        Self {
            means: w3(g.means),
            scales: w3(g.scales),
            quats: g.quats.iter().map(|a| a.map(f64::from)).collect(),
            opacity_logits: g.opacity_logits.iter().map(|&x| x as f64).collect(),
            sh: g.sh.iter().map(|&x| x as f64).collect(),
            sh_coeffs: g.sh_coeffs,
            sh_degree: g.sh_degree,
        }
    }

    pub fn len(&self) -> usize {
        self.means.len()
    }
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// Panics with a message naming the field when shapes disagree.
    pub fn check(&self) {
        let n = self.len();
        assert_eq!(
            self.scales.len(),
            n,
            "Gaussians: scales.len() != means.len()"
        );
        assert_eq!(self.quats.len(), n, "Gaussians: quats.len() != means.len()");
        assert_eq!(
            self.opacity_logits.len(),
            n,
            "Gaussians: opacity_logits.len() != means.len()"
        );
        assert!(
            matches!(self.sh_coeffs, 1 | 4 | 9 | 16),
            "Gaussians: sh_coeffs = {}, expected 1, 4, 9 or 16",
            self.sh_coeffs
        );
        assert!(
            crate::reference::sh::num_coeffs(self.sh_degree) <= self.sh_coeffs as usize,
            "Gaussians: sh_degree {} needs {} coefficients, only {} stored",
            self.sh_degree,
            crate::reference::sh::num_coeffs(self.sh_degree),
            self.sh_coeffs
        );
        assert_eq!(
            self.sh.len(),
            n * self.sh_coeffs as usize * 3,
            "Gaussians: sh.len() != N * sh_coeffs * 3"
        );
    }
}

/// Output of [`project`], one entry per Gaussian (culled ones: radius 0, empty rect, zeros).
#[derive(Clone, Debug, Default)]
pub struct Projected {
    /// Pixel coordinates of the projected mean.
    pub mean2d: Vec<[f32; 2]>,
    /// (a, b, c) of the inverse of the dilated 2D covariance `[[a, b], [b, c]]`.
    pub conic: Vec<[f32; 3]>,
    /// Camera-space z.
    pub depth: Vec<f32>,
    /// `ceil(3·sqrt(λ_max))` pixels; 0 = culled.
    pub radius: Vec<u32>,
    /// `[x0, y0, x1, y1)` in tiles (the opacity-aware box, [`opacity_rect`]); all zero when
    /// culled or fainter than 1/255.
    pub tile_rect: Vec<[u32; 4]>,
    pub color: Vec<[f32; 3]>,
    /// `sigmoid(logit)`.
    pub opacity: Vec<f32>,
}

/// f64 counterpart of [`Projected`] (from [`project_f64`], or widened from a [`Projected`]).
#[derive(Clone, Debug, Default)]
pub struct Projected64 {
    pub mean2d: Vec<[f64; 2]>,
    pub conic: Vec<[f64; 3]>,
    pub depth: Vec<f64>,
    pub radius: Vec<u32>,
    pub tile_rect: Vec<[u32; 4]>,
    pub color: Vec<[f64; 3]>,
    pub opacity: Vec<f64>,
    /// Hash of every discrete decision of the projection (culling, tile rects, Jacobian clamps,
    /// colour clamps). Two parameter sets with equal signatures lie on the same smooth piece of
    /// the projection; finite-difference tests use it to detect straddled thresholds. 0 when
    /// widened from a [`Projected`].
    pub signature: u64,
}

impl Projected64 {
    /// Exact widening.
    pub fn from_f32(p: &Projected) -> Self {
        Self {
            mean2d: p.mean2d.iter().map(|a| a.map(f64::from)).collect(),
            conic: p.conic.iter().map(|a| a.map(f64::from)).collect(),
            depth: p.depth.iter().map(|&x| x as f64).collect(),
            radius: p.radius.clone(),
            tile_rect: p.tile_rect.clone(),
            color: p.color.iter().map(|a| a.map(f64::from)).collect(),
            opacity: p.opacity.iter().map(|&x| x as f64).collect(),
            signature: 0,
        }
    }

    /// Rounds to f32.
    pub fn to_f32(&self) -> Projected {
        Projected {
            mean2d: self.mean2d.iter().map(|a| a.map(|x| x as f32)).collect(),
            conic: self.conic.iter().map(|a| a.map(|x| x as f32)).collect(),
            depth: self.depth.iter().map(|&x| x as f32).collect(),
            radius: self.radius.clone(),
            tile_rect: self.tile_rect.clone(),
            color: self.color.iter().map(|a| a.map(|x| x as f32)).collect(),
            opacity: self.opacity.iter().map(|&x| x as f32).collect(),
        }
    }

    pub fn len(&self) -> usize {
        self.mean2d.len()
    }
    pub fn is_empty(&self) -> bool {
        self.mean2d.is_empty()
    }
}

/// Image-level parameters of the blend.
#[derive(Clone, Copy, Debug)]
pub struct BlendParams {
    pub width: u32,
    pub height: u32,
    /// Upper clamp of α: 0.99 in 3DGS (the default), 0.999 in gsplat.
    pub alpha_max: f32,
    pub background: [f32; 3],
    /// K extra per-Gaussian channels blended with the same weights (features are `[N][K]`).
    pub feature_dims: u32,
}

impl BlendParams {
    /// 3DGS defaults: `alpha_max` 0.99, black background, no features.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            alpha_max: 0.99,
            background: [0.0; 3],
            feature_dims: 0,
        }
    }
}

/// Output of [`blend_fwd`]; per pixel, `H·W` row-major.
#[derive(Clone, Debug, Default)]
pub struct BlendOut {
    /// Σ wᵢ cᵢ + T·background.
    pub rgb: Vec<[f32; 3]>,
    /// 1 − T_final.
    pub alpha: Vec<f32>,
    /// Σ wᵢ zᵢ (not normalised by alpha).
    pub depth: Vec<f32>,
    /// `[H·W][K]`: Σ wᵢ f_ik.
    pub features: Vec<f32>,
    pub final_t: Vec<f32>,
    /// Number of Gaussians of the pixel's tile list (sorted order), up to and including the last
    /// one blended; 0 if none was blended.
    pub n_contrib: Vec<u32>,
}

/// Gradients of [`blend_bwd`], per Gaussian (zeros for culled ones).
#[derive(Clone, Debug, Default)]
pub struct BlendGrads {
    pub mean2d: Vec<[f64; 2]>,
    /// Σ over pixels of |each pixel's term of `mean2d`|, per component (what `blend_bwd`
    /// writes to `grad2d`'s slots 10-11 with `abs_grad`: the official Deformable-3DGS
    /// rasteriser's densification statistic).
    pub mean2d_abs: Vec<[f64; 2]>,
    /// Wrt (a, b, c) of the conic, with `σ = ½(a dx² + c dy²) + b dx dy` (gsplat's convention).
    pub conic: Vec<[f64; 3]>,
    /// Wrt the sigmoid output.
    pub opacity: Vec<f64>,
    /// The feature channels' share of `opacity` (what `blend_bwd` writes to `grad2d`'s slot
    /// 12 with `feat_op`): the gradient the features' blend alone passes to the opacity.
    pub opacity_features: Vec<f64>,
    pub color: Vec<[f64; 3]>,
    pub depth: Vec<f64>,
    /// `[N][K]`.
    pub features: Vec<f64>,
}

/// Gradients of [`project_bwd`] wrt the raw parameters of [`Gaussians`].
#[derive(Clone, Debug, Default)]
pub struct ProjectGrads {
    pub means: Vec<[f64; 3]>,
    /// Wrt the LINEAR scales (multiply by the scale for log-scales).
    pub scales: Vec<[f64; 3]>,
    /// Wrt the raw (unnormalised) quaternion.
    pub quats: Vec<[f64; 4]>,
    pub opacity_logits: Vec<f64>,
    /// Same layout as `Gaussians::sh`; coefficients above the active degree get 0.
    pub sh: Vec<f64>,
}

/// Numerically stable logistic function (exact 0/1 saturation, never NaN for finite input).
pub fn sigmoid(x: f64) -> f64 {
    if x >= 0.0 {
        1.0 / (1.0 + (-x).exp())
    } else {
        let e = x.exp();
        e / (1.0 + e)
    }
}

/// `sigmoid'(x) = σ(x)(1 − σ(x))`, computed without cancellation: `e/(1+e)²`, `e = exp(−|x|)`.
pub fn sigmoid_grad(x: f64) -> f64 {
    let e = (-x.abs()).exp();
    e / ((1.0 + e) * (1.0 + e))
}
