//! Composition of canonical Gaussians with the deformation (`glsl/deform/*.comp`); CPU twin:
//! `reference::deform`. Deformable-3DGS: mean = x + dx, scale = exp(s) + ds,
//! rot = normalize(q) + dr. During warm-up (`deform = None`) D ≡ 0 and nothing is read.

use bytemuck::{Pod, Zeroable};

use super::raster::grid;
use crate::error::Result;
use crate::shaders;
use crate::vk::{BufSlice, ComputePipeline, Gpu, Recorder};

/// Mirrors `DeformParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct DeformParams {
    pub n: u32,
    pub use_deform: u32,
    pub pad0: u32,
    pub pad1: u32,
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

pub struct DeformApply {
    fwd: ComputePipeline,
    bwd: ComputePipeline,
}

impl DeformApply {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        Ok(DeformApply {
            fwd: gpu.pipeline(&shaders::deform::DEFORM_APPLY)?,
            bwd: gpu.pipeline(&shaders::deform::DEFORM_APPLY_BWD)?,
        })
    }

    /// `deform`: the MLP output [N,10] (dx, dr, ds), or `None` for D ≡ 0. `dummy` is bound in
    /// its place (any buffer).
    pub fn forward(
        &self,
        rec: &mut Recorder<'_>,
        n: u32,
        c: &Canonical<'_>,
        deform: Option<BufSlice<'_>>,
        dummy: BufSlice<'_>,
        out: &Drawn<'_>,
    ) {
        let pc = DeformParams {
            n,
            use_deform: deform.is_some() as u32,
            ..Default::default()
        };
        rec.dispatch(
            &self.fwd,
            &pc,
            &[
                c.means,
                c.log_scales,
                c.quats,
                deform.unwrap_or(dummy),
                out.means,
                out.scales,
                out.quats,
            ],
            grid(n),
        );
    }

    /// Gradients wrt the canonical parameters (`grads`) and, when `d_deform` is given, wrt the
    /// MLP output [N,10], from the gradients wrt what was drawn (`d_drawn`).
    #[allow(clippy::too_many_arguments)] // the stage's bindings, each one named
    pub fn backward(
        &self,
        rec: &mut Recorder<'_>,
        n: u32,
        c: &Canonical<'_>,
        d_drawn: &Drawn<'_>,
        grads: &Canonical<'_>,
        d_deform: Option<BufSlice<'_>>,
        dummy: BufSlice<'_>,
    ) {
        let pc = DeformParams {
            n,
            use_deform: d_deform.is_some() as u32,
            ..Default::default()
        };
        rec.dispatch(
            &self.bwd,
            &pc,
            &[
                c.log_scales,
                c.quats,
                d_drawn.means,
                d_drawn.scales,
                d_drawn.quats,
                grads.means,
                grads.log_scales,
                grads.quats,
                d_deform.unwrap_or(dummy),
            ],
            grid(n),
        );
    }
}
