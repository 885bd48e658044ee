//! Gaussian flow, the motion representation of GaussianFlow and MotionGS (`glsl/gflow/*`;
//! CPU twin: `reference::gflow`). Per Gaussian, the affine map of its projection from t1 to
//! t2 under one view is six channels (`gflow_feat`), which the render at (v1, t1) blends with
//! its own weights; per pixel, `F = G·p + B` is compared with the scene motion by an L1 on the
//! vectors (`gflow_l1`), and `gflow_feat_bwd` takes the channels' gradient to both
//! projections' 2D gradient records, from where the rasteriser's projection backward carries
//! it to the Gaussians drawn at t1 and at t2.

use bytemuck::{Pod, Zeroable};

use crate::error::Result;
use crate::shaders;
use crate::vk::{BufSlice, ComputePipeline, Gpu, Recorder};

/// Channels per Gaussian and per pixel (mirrors `GF_FEAT`).
pub const GF_FEAT: u32 = 6;

/// Mirrors `GFlowParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct GFlowParams {
    pub n: u32,
    pub width: u32,
    pub weight: f32,
    pub conf: u32,
}

/// The buffers of one `gflow_l1` dispatch.
pub struct GFlowLossIo<'a> {
    /// [H·W, 6] the blended channels.
    pub feat: BufSlice<'a>,
    /// [H·W] vec2 the scene motion.
    pub scene: BufSlice<'a>,
    /// The scene motion's normalisation statistics (`NormBuffers::stats`).
    pub stats: BufSlice<'a>,
    /// [H·W, 6] out: ∂L/∂channels.
    pub d_feat: BufSlice<'a>,
    /// [ceil(H·W / 256)] out: partial sums.
    pub sums: BufSlice<'a>,
    pub conf: Option<BufSlice<'a>>,
}

pub struct GaussianFlow {
    feat: ComputePipeline,
    feat_bwd: ComputePipeline,
    l1: ComputePipeline,
}

impl GaussianFlow {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        use shaders::gflow as g;
        Ok(GaussianFlow {
            feat: gpu.pipeline(&g::GFLOW_FEAT)?,
            feat_bwd: gpu.pipeline(&g::GFLOW_FEAT_BWD)?,
            l1: gpu.pipeline(&g::GFLOW_L1)?,
        })
    }

    /// [N,6] channels from the splat records at t1 and t2 ([N,3] vec4 each, same view).
    pub fn features(
        &self,
        rec: &mut Recorder<'_>,
        n: u32,
        splats_t1: BufSlice<'_>,
        splats_t2: BufSlice<'_>,
        feat: BufSlice<'_>,
    ) {
        let pc = GFlowParams {
            n,
            ..Default::default()
        };
        rec.dispatch_rows(&self.feat, &pc, &[splats_t1, splats_t2, feat], n);
    }

    /// ∂L/∂channels [N,6] added to the 2D gradient records ([N, G2D_STRIDE]) at t1 and t2.
    pub fn features_bwd(
        &self,
        rec: &mut Recorder<'_>,
        n: u32,
        splats: [BufSlice<'_>; 2],
        d_feat: BufSlice<'_>,
        grad2d: [BufSlice<'_>; 2],
    ) {
        let pc = GFlowParams {
            n,
            ..Default::default()
        };
        let [s1, s2] = splats;
        let [g1, g2] = grad2d;
        rec.dispatch_rows(&self.feat_bwd, &pc, &[s1, s2, d_feat, g1, g2], n);
    }

    /// `weight · (1/N) Σ c·|F − F_scene|₁ / s` over a `width`-wide image of `pixels`.
    pub fn l1(
        &self,
        rec: &mut Recorder<'_>,
        pixels: u32,
        width: u32,
        weight: f32,
        io: &GFlowLossIo<'_>,
    ) {
        let pc = GFlowParams {
            n: pixels,
            width,
            weight,
            conf: io.conf.is_some() as u32,
        };
        // Without a confidence the binding is never read; any buffer fills it.
        let c = io.conf.unwrap_or(io.scene);
        rec.dispatch_threads(
            &self.l1,
            &pc,
            &[io.feat, io.scene, io.stats, io.d_feat, io.sums, c],
            [pixels, 1, 1],
        );
    }
}
