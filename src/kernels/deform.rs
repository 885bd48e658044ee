//! Composition of canonical Gaussians with the deformation (`glsl/deform/*.comp`); CPU twin:
//! `reference::deform`. Deformable-3DGS: mean = x + dx, scale = exp(min(s, LOG_SCALE_MAX)) + ds,
//! rot = normalize(q) + dr. During warm-up (`deform = None`) D ≡ 0 and nothing is read.

use bytemuck::{Pod, Zeroable};

use crate::error::Result;
use crate::shaders;
use crate::vk::{BufSlice, ComputePipeline, Gpu, Recorder};

/// Log-scales above this are clamped before `exp` (mirrors `LOG_SCALE_MAX` in
/// glsl/include/common.glsl): f32 `exp` overflows from 88.72 on, and 44 is the largest integer
/// whose `exp` still squares to a finite f32 (the rasteriser builds Σ from s²). Far above any
/// scene (a scale of 1e4 is a log-scale of 9.2); the log-scale gets no gradient above it.
pub const LOG_SCALE_MAX: f32 = 44.0;

/// Mirrors `DeformParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct DeformParams {
    pub n: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

/// Canonical parameters: `means` [N,3], `log_scales` [N,3], `quats` [N,4].
#[derive(Clone, Copy, Debug)]
pub struct Canonical<'a> {
    pub means: BufSlice<'a>,
    pub log_scales: BufSlice<'a>,
    pub quats: BufSlice<'a>,
}

/// What the rasteriser draws (or their gradients): `means` [N,3], `scales` [N,3], `quats` [N,4].
#[derive(Clone, Copy, Debug)]
pub struct Drawn<'a> {
    pub means: BufSlice<'a>,
    pub scales: BufSlice<'a>,
    pub quats: BufSlice<'a>,
}

/// Two stages per direction: with the MLP output (`deform_apply*`) and with D ≡ 0
/// (`deform_static*`, the warm-up), which binds no MLP buffer at all.
pub struct DeformApply {
    fwd: ComputePipeline,
    fwd_static: ComputePipeline,
    bwd: ComputePipeline,
    bwd_static: ComputePipeline,
    bwd_add: ComputePipeline,
}

impl DeformApply {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        use shaders::deform as d;
        Ok(DeformApply {
            fwd: gpu.pipeline(&d::DEFORM_APPLY)?,
            fwd_static: gpu.pipeline(&d::DEFORM_STATIC)?,
            bwd: gpu.pipeline(&d::DEFORM_APPLY_BWD)?,
            bwd_static: gpu.pipeline(&d::DEFORM_STATIC_BWD)?,
            bwd_add: gpu.pipeline(&d::DEFORM_APPLY_BWD_ACC)?,
        })
    }

    /// `deform`: the MLP output [N,10] (dx, dr, ds), or `None` for D ≡ 0.
    pub fn forward(
        &self,
        rec: &mut Recorder<'_>,
        n: u32,
        c: &Canonical<'_>,
        deform: Option<BufSlice<'_>>,
        out: &Drawn<'_>,
    ) {
        let pc = DeformParams {
            n,
            ..Default::default()
        };
        let mut binds = vec![
            c.means,
            c.log_scales,
            c.quats,
            out.means,
            out.scales,
            out.quats,
        ];
        let pipe = match deform {
            Some(d) => {
                binds.push(d);
                &self.fwd
            }
            None => &self.fwd_static,
        };
        rec.dispatch_rows(pipe, &pc, &binds, n);
    }

    /// Gradients wrt the canonical parameters (`grads`) and, when `d_deform` is given, wrt the
    /// MLP output [N,10], from the gradients wrt what was drawn (`d_drawn`).
    pub fn backward(
        &self,
        rec: &mut Recorder<'_>,
        n: u32,
        c: &Canonical<'_>,
        d_drawn: &Drawn<'_>,
        grads: &Canonical<'_>,
        d_deform: Option<BufSlice<'_>>,
    ) {
        let pipe = match d_deform {
            Some(_) => &self.bwd,
            None => &self.bwd_static,
        };
        Self::record_bwd(rec, pipe, n, c, d_drawn, grads, d_deform);
    }

    /// [`DeformApply::backward`] with the MLP output, added to `grads` and `d_deform`
    /// instead of written (a second render of the same step).
    pub fn backward_add(
        &self,
        rec: &mut Recorder<'_>,
        n: u32,
        c: &Canonical<'_>,
        d_drawn: &Drawn<'_>,
        grads: &Canonical<'_>,
        d_deform: BufSlice<'_>,
    ) {
        Self::record_bwd(rec, &self.bwd_add, n, c, d_drawn, grads, Some(d_deform));
    }

    /// One backward dispatch: the three variants share their bindings (the MLP-output
    /// gradient last, when bound).
    fn record_bwd(
        rec: &mut Recorder<'_>,
        pipe: &ComputePipeline,
        n: u32,
        c: &Canonical<'_>,
        d_drawn: &Drawn<'_>,
        grads: &Canonical<'_>,
        d_deform: Option<BufSlice<'_>>,
    ) {
        let pc = DeformParams {
            n,
            ..Default::default()
        };
        let mut binds = vec![
            c.log_scales,
            c.quats,
            d_drawn.means,
            d_drawn.scales,
            d_drawn.quats,
            grads.means,
            grads.log_scales,
            grads.quats,
        ];
        binds.extend(d_deform);
        rec.dispatch_rows(pipe, &pc, &binds, n);
    }
}
