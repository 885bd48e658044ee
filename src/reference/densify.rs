//! Twin of `glsl/densify/*`: 3DGS adaptive density control on host Gaussians, plain loops.
//!
//! Decisions (dense / clone / split / budget / prune) use exactly the f32 comparisons of the
//! kernels, on the thresholds [`DensifySettings::params`] derives, so GPU and twin pick the same
//! rows. Values follow the GPU where it is exact (copies, zeroed moments, the split log-scale
//! `log_scale − LN_1_6` as one f32 subtraction); split means are sampled in f64 (the GPU's
//! `exp`, `log`, `sin`, `cos` are approximate, so those agree to a tolerance only).
//!
//! Output row order: originals in index order, each contributing its surviving rows
//! (keep: [original]; clone: [original, copy]; split: [child 0, child 1]).
//!
//! Adam moments are [`HostGaussians`] too: each field holds that section's m (or v).

use crate::kernels::densify::{reset_logit, DensifyParams, DensifySettings, LN_1_6};
use crate::model::gaussians::HostGaussians;

/// What was decided for one original Gaussian.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action {
    Keep,
    Clone,
    Split,
}

impl Action {
    /// Code used by the kernels (`ACT_*` in glsl/densify/densify.glsl).
    pub fn code(self) -> u32 {
        match self {
            Action::Keep => 0,
            Action::Clone => 1,
            Action::Split => 2,
        }
    }
}

/// Per-original outcome: the demanded action, the action after the budget, and which of its
/// output rows survive pruning (row 1 exists for clone and split only).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Decision {
    pub demanded: Action,
    pub action: Action,
    pub keep: [bool; 2],
}

impl Decision {
    /// The kernels' encoding: `code | keep0 << 2 | keep1 << 3`.
    pub fn encoded(&self) -> u32 {
        self.action.code() | (self.keep[0] as u32) << 2 | (self.keep[1] as u32) << 3
    }
}

/// Counts of every case, for tests and logs. A pruned row counts once per reason it meets.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DensifyReport {
    pub kept: u32,
    pub cloned: u32,
    pub split: u32,
    /// Clone/split demanded but downgraded to keep by the budget.
    pub downgraded: u32,
    pub pruned_rows: u32,
    pub pruned_opacity: u32,
    pub pruned_screen: u32,
    pub pruned_world: u32,
    pub rows_out: u32,
}

/// Densification statistics ([capacity] each; only the first N are read).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DensifyStats {
    pub grad_accum: Vec<f32>,
    pub denom: Vec<f32>,
    pub max_radii: Vec<f32>,
}

impl DensifyStats {
    pub fn zeros(n: usize) -> Self {
        DensifyStats {
            grad_accum: vec![0.0; n],
            denom: vec![0.0; n],
            max_radii: vec![0.0; n],
        }
    }
}

/// Parameters and Adam moments after a densify step.
#[derive(Clone, Debug, PartialEq)]
pub struct DensifyOut {
    pub params: HostGaussians,
    pub m: HostGaussians,
    pub v: HostGaussians,
    pub decisions: Vec<Decision>,
    pub report: DensifyReport,
}

/// Twin of `densify_stats`: for Gaussians `i < n` with screen radius `splats[3i+1][3] > 0`,
/// `grad_accum += ‖(gx·W/2, gy·H/2)‖` (0 if not finite in f32; saturating at f32::MAX),
/// `denom += 1`, `max_radii = max(max_radii, radius)`. `(gx, gy)` are `grad2d`'s slots 0-1, or
/// 10-11 (Σ|∂L/∂mean2d|) with `abs_grad`.
pub fn accumulate_stats(
    stats: &mut DensifyStats,
    grad2d: &[f32],
    splats: &[[f32; 4]],
    (width, height): (u32, u32),
    n: usize,
    abs_grad: bool,
) {
    let (hw, hh) = (0.5 * width as f32, 0.5 * height as f32);
    let at = if abs_grad { 10 } else { 0 };
    let stride = crate::kernels::raster::G2D_STRIDE as usize;
    for i in 0..n {
        let radius = splats[3 * i + 1][3];
        if radius.is_nan() || radius <= 0.0 {
            continue;
        }
        let gx = grad2d[stride * i + at] * hw;
        let gy = grad2d[stride * i + at + 1] * hh;
        let mut norm = 0.0f32;
        if gx.is_finite() && gy.is_finite() {
            norm = (gx as f64).hypot(gy as f64) as f32;
            if !norm.is_finite() {
                norm = 0.0;
            }
        }
        stats.grad_accum[i] = (stats.grad_accum[i] + norm).min(f32::MAX);
        stats.denom[i] += 1.0;
        if radius > stats.max_radii[i] {
            stats.max_radii[i] = radius;
        }
    }
}

/// Same NaN semantics as `max_log_scale` in densify.glsl.
fn max_log_scale(s: [f32; 3]) -> f32 {
    let mut m = s[0];
    if s[1] > m {
        m = s[1];
    }
    if s[2] > m {
        m = s[2];
    }
    m
}

/// The PCG hash of densify.glsl.
pub fn pcg(v: u32) -> u32 {
    let s = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let w = ((s >> ((s >> 28) + 4)) ^ s).wrapping_mul(277_803_737);
    (w >> 22) ^ w
}

/// Uniform `k` (0..3) of child `c` of original `i`, exactly as `split_uniform`:
/// `h = pcg(seed ^ pcg(iteration ^ pcg(8i + 4c + k)))`, `u = ((h >> 9) + 0.5) / 2^23` ∈ (0, 1).
pub fn split_uniform(seed: u32, iteration: u32, i: u32, c: u32, k: u32) -> f64 {
    let h = pcg(seed ^ pcg(iteration ^ pcg(i.wrapping_mul(8).wrapping_add(4 * c + k))));
    ((h >> 9) as f64 + 0.5) / 8_388_608.0
}

/// The three standard normals of child `c` of original `i` (Box–Muller on uniforms 0,1 and 2,3).
pub fn split_normals(seed: u32, iteration: u32, i: u32, c: u32) -> [f64; 3] {
    let u: [f64; 4] = std::array::from_fn(|k| split_uniform(seed, iteration, i, c, k as u32));
    let tau = std::f64::consts::TAU;
    let r0 = (-2.0 * u[0].ln()).sqrt();
    let r1 = (-2.0 * u[2].ln()).sqrt();
    [
        r0 * (tau * u[1]).cos(),
        r0 * (tau * u[1]).sin(),
        r1 * (tau * u[3]).cos(),
    ]
}

/// Rotation of the normalised quaternion (w, x, y, z), identity below norm 1e-12 (as the
/// rasteriser); `r[row][col]`.
fn quat_to_rot(q: [f32; 4]) -> [[f64; 3]; 3] {
    let q = q.map(|x| x as f64);
    let len = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    crate::reference::raster::quat_to_rot(if len > 1e-12 {
        q.map(|c| c / len)
    } else {
        [1.0, 0.0, 0.0, 0.0]
    })
}

/// Mean of split child `c` of Gaussian `i`: `R(q̂)·(exp(min(log_scale, LOG_SCALE_MAX)) ⊙ z) +
/// mean`, f64 inside (the clamp keeps a runaway log-scale's children finite).
pub fn split_mean(g: &HostGaussians, i: usize, c: u32, seed: u32, iteration: u32) -> [f32; 3] {
    let z = split_normals(seed, iteration, i as u32, c);
    let r = quat_to_rot(g.quats[i]);
    let max = crate::kernels::deform::LOG_SCALE_MAX as f64;
    let s = g.log_scales[i].map(|l| (l as f64).min(max).exp());
    std::array::from_fn(|row| {
        let off: f64 = (0..3).map(|col| r[row][col] * s[col] * z[col]).sum();
        (g.means[i][row] as f64 + off) as f32
    })
}

/// Twin of the prune test in `densify_mark`.
fn prune_reasons(p: &DensifyParams, logit: f32, radius: f32, ls: f32) -> [bool; 3] {
    [
        logit < p.min_opacity_logit,
        p.screen_prune & 1 != 0 && radius > p.max_screen_size,
        p.screen_prune & 2 != 0 && ls > p.log_max_world_size,
    ]
}

/// The decisions of `densify_grow` + the budget + `densify_mark` for the first `n = params.len()`
/// Gaussians.
pub fn decide(
    params: &HostGaussians,
    stats: &DensifyStats,
    s: &DensifySettings,
) -> (Vec<Decision>, DensifyReport) {
    decide_pruning(params, stats, s, None)
}

/// [`decide`] with the prune's logits given (`record_densify_pruning`'s override: the
/// transients' peak opacity); `None`: the parameters' own.
pub fn decide_pruning(
    params: &HostGaussians,
    stats: &DensifyStats,
    s: &DensifySettings,
    prune_logits: Option<&[f32]>,
) -> (Vec<Decision>, DensifyReport) {
    let n = params.len();
    let p = s.params(n as u32);
    let budget = p.capacity.saturating_sub(n as u32);
    let mut grown = 0u32; // accepted growth so far (running total − N)
    let mut rep = DensifyReport::default();
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let d = stats.denom[i];
        let dense = d > 0.0 && stats.grad_accum[i] >= p.grad_threshold * d;
        let ls = max_log_scale(params.log_scales[i]);
        let demanded = if dense && ls <= p.log_dense_scale {
            Action::Clone
        } else if dense && ls > p.log_dense_scale {
            Action::Split
        } else {
            Action::Keep
        };
        // Budget: the +1 of a clone or split must fit in the running total.
        let action = if demanded != Action::Keep && grown + 1 > budget {
            rep.downgraded += 1;
            Action::Keep
        } else {
            if demanded != Action::Keep {
                grown += 1;
            }
            demanded
        };
        let logit = prune_logits.map_or(params.opacity[i], |l| l[i]);
        let rows: Vec<[bool; 3]> = match action {
            Action::Keep => vec![prune_reasons(&p, logit, stats.max_radii[i], ls)],
            Action::Clone => vec![
                prune_reasons(&p, logit, stats.max_radii[i], ls),
                prune_reasons(&p, logit, 0.0, ls),
            ],
            Action::Split => vec![prune_reasons(&p, logit, 0.0, ls - LN_1_6); 2],
        };
        let mut keep = [false; 2];
        for (r, why) in rows.iter().enumerate() {
            keep[r] = !why.iter().any(|&b| b);
            if keep[r] {
                rep.rows_out += 1;
            } else {
                rep.pruned_rows += 1;
                rep.pruned_opacity += why[0] as u32;
                rep.pruned_screen += why[1] as u32;
                rep.pruned_world += why[2] as u32;
            }
        }
        match action {
            Action::Keep => rep.kept += 1,
            Action::Clone => rep.cloned += 1,
            Action::Split => rep.split += 1,
        }
        out.push(Decision {
            demanded,
            action,
            keep,
        });
    }
    (out, rep)
}

/// Appends row `i` of `src` to `dst` (every section; the temporal ones when `src` has them).
fn push_row(dst: &mut HostGaussians, src: &HostGaussians, i: usize) {
    let r = 3 * (src.sh_coeffs as usize - 1);
    if !src.time.is_empty() {
        dst.time.push(src.time[i]);
        dst.velocity.push(src.velocity[i]);
    }
    dst.means.push(src.means[i]);
    dst.log_scales.push(src.log_scales[i]);
    dst.quats.push(src.quats[i]);
    dst.opacity.push(src.opacity[i]);
    dst.sh_dc.push(src.sh_dc[i]);
    dst.sh_rest
        .extend_from_slice(&src.sh_rest[i * r..(i + 1) * r]);
}

/// Appends a zero row (every section; the temporal ones when `temporal`).
fn push_zero(dst: &mut HostGaussians, temporal: bool) {
    let r = 3 * (dst.sh_coeffs as usize - 1);
    if temporal {
        dst.time.push([0.0; 2]);
        dst.velocity.push([0.0; 3]);
    }
    dst.means.push([0.0; 3]);
    dst.log_scales.push([0.0; 3]);
    dst.quats.push([0.0; 4]);
    dst.opacity.push(0.0);
    dst.sh_dc.push([0.0; 3]);
    dst.sh_rest.extend(std::iter::repeat(0.0).take(r));
}

/// Twin of `record_densify`: the step over all Gaussians of `params` (moments `m`, `v` of the
/// same length), statistics `stats` (at least N entries). Statistics are reset by the caller
/// (the GPU zeroes them).
pub fn densify(
    params: &HostGaussians,
    m: &HostGaussians,
    v: &HostGaussians,
    stats: &DensifyStats,
    s: &DensifySettings,
) -> DensifyOut {
    densify_pruning(params, m, v, stats, s, None)
}

/// Twin of `record_densify_pruning`: [`densify`] deciding the prune by `prune_logits` (rows
/// are written as they are). The temporal sections go with their rows when `params` has
/// them; the last rows of `params` that are transients stay the last rows written.
pub fn densify_pruning(
    params: &HostGaussians,
    m: &HostGaussians,
    v: &HostGaussians,
    stats: &DensifyStats,
    s: &DensifySettings,
    prune_logits: Option<&[f32]>,
) -> DensifyOut {
    let (decisions, report) = decide_pruning(params, stats, s, prune_logits);
    let temporal = !params.time.is_empty();
    let first_transient = params.populations().transient.start as usize;
    let empty = || HostGaussians {
        sh_coeffs: params.sh_coeffs,
        ..Default::default()
    };
    let (mut po, mut mo, mut vo) = (empty(), empty(), empty());
    for (i, d) in decisions.iter().enumerate() {
        for (r, &keep) in d.keep.iter().enumerate() {
            if !keep {
                continue;
            }
            po.transients += (i >= first_transient) as usize;
            match (d.action, r) {
                (Action::Split, c) => {
                    push_row(&mut po, params, i);
                    let last = po.len() - 1;
                    po.means[last] = split_mean(params, i, c as u32, s.seed, s.iteration);
                    po.log_scales[last] = params.log_scales[i].map(|l| l - LN_1_6);
                    push_zero(&mut mo, temporal);
                    push_zero(&mut vo, temporal);
                }
                (_, 0) => {
                    push_row(&mut po, params, i);
                    push_row(&mut mo, m, i);
                    push_row(&mut vo, v, i);
                }
                _ => {
                    push_row(&mut po, params, i);
                    push_zero(&mut mo, temporal);
                    push_zero(&mut vo, temporal);
                }
            }
        }
    }
    DensifyOut {
        params: po,
        m: mo,
        v: vo,
        decisions,
        report,
    }
}

/// Twin of `record_opacity_reset`: logit ← min(logit, logit(0.01)) (NaN → logit(0.01)),
/// opacity m, v ← 0.
pub fn opacity_reset(params: &mut HostGaussians, m: &mut HostGaussians, v: &mut HostGaussians) {
    let r = reset_logit();
    for x in params.opacity.iter_mut() {
        *x = if *x < r { *x } else { r };
    }
    m.opacity.iter_mut().for_each(|x| *x = 0.0);
    v.opacity.iter_mut().for_each(|x| *x = 0.0);
}
