//! The trainer-side stages of the DispFlow-GS motion term (`glsl/dispflow/*.comp`); CPU twin:
//! `reference::dispflow`. The displacement δ = dx(t2) − dx(t1) that the rasteriser splats as
//! three feature channels, its backward into both MLP passes, and the L1 motion loss between
//! the normalised magnitude maps.

use bytemuck::{Pod, Zeroable};

use crate::error::Result;
use crate::shaders;
use crate::vk::{BufSlice, ComputePipeline, Gpu, Recorder};

/// Mirrors `DispFlowParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct DispFlowParams {
    pub n: u32,
    pub weight: f32,
    pub pad0: u32,
    pub pad1: u32,
}

pub struct DispFlow {
    displacement: ComputePipeline,
    displacement_bwd: ComputePipeline,
    motion_l1: ComputePipeline,
}

impl DispFlow {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        Ok(DispFlow {
            displacement: gpu.pipeline(&shaders::dispflow::DISPLACEMENT)?,
            displacement_bwd: gpu.pipeline(&shaders::dispflow::DISPLACEMENT_BWD)?,
            motion_l1: gpu.pipeline(&shaders::dispflow::MOTION_L1)?,
        })
    }

    /// δ [N,3] from the MLP outputs at t1 and t2 ([N,10] each).
    pub fn displacement(
        &self,
        rec: &mut Recorder<'_>,
        n: u32,
        out_t1: BufSlice<'_>,
        out_t2: BufSlice<'_>,
        delta: BufSlice<'_>,
    ) {
        let pc = DispFlowParams {
            n,
            ..Default::default()
        };
        rec.dispatch_rows(&self.displacement, &pc, &[out_t1, out_t2, delta], n);
    }

    /// Backward of δ: subtracts ∂L/∂δ from the dx part of `d_out_t1` and writes `d_out_t2`.
    pub fn displacement_bwd(
        &self,
        rec: &mut Recorder<'_>,
        n: u32,
        d_delta: BufSlice<'_>,
        d_out_t1: BufSlice<'_>,
        d_out_t2: BufSlice<'_>,
    ) {
        let pc = DispFlowParams {
            n,
            ..Default::default()
        };
        rec.dispatch_rows(
            &self.displacement_bwd,
            &pc,
            &[d_delta, d_out_t1, d_out_t2],
            n,
        );
    }

    /// `weight · mean |m_scene − m_disp|` over `pixels` values: gradient wrt `m_disp` into
    /// `d_disp` and per-workgroup partial sums of |·| (unweighted) into `sums`
    /// ([ceil(pixels / 256)] f32). `degenerate` holds two u32 flags (disp, scene): either set
    /// skips the term.
    #[allow(clippy::too_many_arguments)] // the stage's bindings, each one named
    pub fn motion_l1(
        &self,
        rec: &mut Recorder<'_>,
        pixels: u32,
        weight: f32,
        m_disp: BufSlice<'_>,
        m_scene: BufSlice<'_>,
        degenerate: BufSlice<'_>,
        d_disp: BufSlice<'_>,
        sums: BufSlice<'_>,
    ) {
        let pc = DispFlowParams {
            n: pixels,
            weight,
            ..Default::default()
        };
        rec.dispatch_threads(
            &self.motion_l1,
            &pc,
            &[m_disp, m_scene, degenerate, d_disp, sums],
            [pixels, 1, 1],
        );
    }
}
