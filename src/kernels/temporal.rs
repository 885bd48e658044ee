//! Transient (time-local) Gaussians (`glsl/temporal/*.comp`); CPU twin:
//! `reference::temporal`. The model's rows `first..n` are transients with a time centre c, a
//! log temporal width τ (σ = exp(max(τ, ln σ_floor))) and a velocity v. At time t a transient is
//! drawn at μ + v·(t − c), unrotated and unscaled by any deformation, and its opacity is
//! multiplied by w(t) = exp(−½ (t − c)²/σ²); where w < `cutoff` it is culled (w = 0: the
//! projection skips it before any work). Rows `0..first` are the canonical population.
//!
//! - `forward`: the transient rows of the drawn geometry and the opacity factor of every row.
//! - `backward`: the transient rows' gradients (mean, log-scale, quaternion, c, τ, v) from the
//!   drawn-geometry gradients and the opacity factor's (`project_bwd`'s `d_op_scale`).
//! - `displacement` / `displacement_backward`: DispFlow's δ = v·(t2 − t1) of the transient
//!   rows and its gradient into v.
//! - `peak`: the logit densification prunes by, σ(o)·max over the sequence of w.

use bytemuck::{Pod, Zeroable};

use super::deform::Drawn;
use crate::error::Result;
use crate::shaders;
use crate::vk::{BufSlice, ComputePipeline, Gpu, Recorder};

/// Mirrors `TemporalParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct TemporalParams {
    /// Rows: every live Gaussian.
    pub n: u32,
    /// First transient row (the canonical population's size).
    pub first: u32,
    /// The time drawn (t1 of a displacement).
    pub t: f32,
    /// ln σ_floor.
    pub log_floor: f32,
    /// Opacity factors below this are culled.
    pub cutoff: f32,
    /// The pair's time of a displacement.
    pub t2: f32,
    /// The time range `peak` takes the largest weight over.
    pub t_lo: f32,
    pub t_hi: f32,
}

/// The model's sections a temporal stage reads: `means`, `log_scales` [N,3], `quats` [N,4],
/// `centre`, `log_width` [N], `velocity` [N,3].
#[derive(Clone, Copy, Debug)]
pub struct TemporalInputs<'a> {
    pub means: BufSlice<'a>,
    pub log_scales: BufSlice<'a>,
    pub quats: BufSlice<'a>,
    pub centre: BufSlice<'a>,
    pub log_width: BufSlice<'a>,
    pub velocity: BufSlice<'a>,
}

/// The gradient sections the backward writes (rows `first..n` only).
#[derive(Clone, Copy, Debug)]
pub struct TemporalGrads<'a> {
    pub means: BufSlice<'a>,
    pub log_scales: BufSlice<'a>,
    pub quats: BufSlice<'a>,
    pub centre: BufSlice<'a>,
    pub log_width: BufSlice<'a>,
    pub velocity: BufSlice<'a>,
}

pub struct Temporal {
    fwd: ComputePipeline,
    bwd: ComputePipeline,
    disp: ComputePipeline,
    disp_bwd: ComputePipeline,
    peak: ComputePipeline,
}

fn check(p: &TemporalParams, what: &str, slices: &[(BufSlice<'_>, u64)]) {
    assert!(
        p.first <= p.n,
        "temporal {what}: first {} > n {}",
        p.first,
        p.n
    );
    for (s, floats) in slices {
        assert!(
            s.size >= p.n as u64 * floats * 4,
            "temporal {what}: a binding of {} bytes for {} rows of {floats} floats",
            s.size,
            p.n
        );
    }
}

impl Temporal {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        use shaders::temporal as t;
        Ok(Temporal {
            fwd: gpu.pipeline(&t::TEMPORAL_FWD)?,
            bwd: gpu.pipeline(&t::TEMPORAL_BWD)?,
            disp: gpu.pipeline(&t::TEMPORAL_DISP)?,
            disp_bwd: gpu.pipeline(&t::TEMPORAL_DISP_BWD)?,
            peak: gpu.pipeline(&t::TEMPORAL_PEAK)?,
        })
    }

    /// The transient rows of `drawn` at time `p.t` and the opacity factor `op_scale` [N] of
    /// every row.
    pub fn forward(
        &self,
        rec: &mut Recorder<'_>,
        p: &TemporalParams,
        x: &TemporalInputs<'_>,
        drawn: &Drawn<'_>,
        op_scale: BufSlice<'_>,
    ) {
        check(
            p,
            "forward",
            &[
                (x.means, 3),
                (x.velocity, 3),
                (drawn.means, 3),
                (op_scale, 1),
            ],
        );
        rec.dispatch_rows(
            &self.fwd,
            p,
            &[
                x.means,
                x.log_scales,
                x.quats,
                x.centre,
                x.log_width,
                x.velocity,
                drawn.means,
                drawn.scales,
                drawn.quats,
                op_scale,
            ],
            p.n,
        );
    }

    /// The transient rows' gradients from the drawn-geometry gradients `d_drawn` and the
    /// opacity factor's `d_op_scale` [N].
    pub fn backward(
        &self,
        rec: &mut Recorder<'_>,
        p: &TemporalParams,
        x: &TemporalInputs<'_>,
        d_drawn: &Drawn<'_>,
        d_op_scale: BufSlice<'_>,
        g: &TemporalGrads<'_>,
    ) {
        check(
            p,
            "backward",
            &[(d_drawn.means, 3), (d_op_scale, 1), (g.velocity, 3)],
        );
        rec.dispatch_rows(
            &self.bwd,
            p,
            &[
                x.log_scales,
                x.quats,
                x.centre,
                x.log_width,
                x.velocity,
                d_drawn.means,
                d_drawn.scales,
                d_drawn.quats,
                d_op_scale,
                g.means,
                g.log_scales,
                g.quats,
                g.centre,
                g.log_width,
                g.velocity,
            ],
            p.n,
        );
    }

    /// δ [N,3] of the transient rows: v·(p.t2 − p.t).
    pub fn displacement(
        &self,
        rec: &mut Recorder<'_>,
        p: &TemporalParams,
        velocity: BufSlice<'_>,
        delta: BufSlice<'_>,
    ) {
        check(p, "displacement", &[(velocity, 3), (delta, 3)]);
        rec.dispatch_rows(&self.disp, p, &[velocity, delta], p.n);
    }

    /// Adds ∂L/∂δ·(t2 − t1) to the transient rows of the velocity gradient.
    pub fn displacement_backward(
        &self,
        rec: &mut Recorder<'_>,
        p: &TemporalParams,
        d_delta: BufSlice<'_>,
        g_velocity: BufSlice<'_>,
    ) {
        check(p, "displacement backward", &[(d_delta, 3), (g_velocity, 3)]);
        rec.dispatch_rows(&self.disp_bwd, p, &[d_delta, g_velocity], p.n);
    }

    /// The logit densification prunes by [N] (see the module doc).
    pub fn peak(
        &self,
        rec: &mut Recorder<'_>,
        p: &TemporalParams,
        logits: BufSlice<'_>,
        centre: BufSlice<'_>,
        log_width: BufSlice<'_>,
        out: BufSlice<'_>,
    ) {
        check(p, "peak", &[(logits, 1), (centre, 1), (out, 1)]);
        rec.dispatch_rows(&self.peak, p, &[logits, centre, log_width, out], p.n);
    }
}
