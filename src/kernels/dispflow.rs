//! The trainer-side stages of the DispFlow-GS motion term (`glsl/dispflow/*.comp`); CPU twin:
//! `reference::dispflow`. The displacement δ = dx(t2) − dx(t1) that the rasteriser splats as
//! three feature channels, its backward into both MLP passes, the scene motion's residual
//! correction, confidence and motion-mask filter (`scene_signal`), the indirect scene motion
//! of MotionGS (`camera_flow`), the L1 motion loss between the normalised magnitude maps, and
//! `grad_add` (a second render's opacity gradients).

use bytemuck::{Pod, Zeroable};

use crate::error::Result;
use crate::kernels::raster::Camera;
use crate::shaders;
use crate::vk::{BufSlice, ComputePipeline, Gpu, Recorder};

/// Mirrors `DispFlowParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct DispFlowParams {
    pub n: u32,
    pub weight: f32,
    /// Motion L1: 1 = weight each pixel by the confidence binding.
    pub conf: u32,
    pub pad1: u32,
}

/// Mirrors `SceneSignalParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct SceneSignalParams {
    pub n: u32,
    /// 1: subtract the flow photo → render(v1, t1).
    pub residual: u32,
    /// Confidence scale σ on the mean |photo − render(v1, t1)| (RGB in [0, 1]); 0 = c ≡ 1.
    pub sigma: f32,
    /// Motion-mask filtering: |s| below this many pixels becomes 0; 0 = off.
    pub mask_px: f32,
}

/// Mirrors `CameraFlowParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct CameraFlowParams {
    /// Rows of M = R2·R1ᵀ; w: m = t2 − M·t1 (a point in v1's camera frame → v2's).
    pub rel0: [f32; 4],
    pub rel1: [f32; 4],
    pub rel2: [f32; 4],
    pub intr_a: [f32; 4],
    pub intr_b: [f32; 4],
    pub width: u32,
    pub height: u32,
    pub min_alpha: f32,
    /// 0: the raw pair flow passes through (no decomposition).
    pub subtract: u32,
    pub near_b: f32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

impl CameraFlowParams {
    /// v1 = `a`, v2 = `b` (same image size); `subtract`: remove the camera flow. The relative
    /// pose is composed in f64.
    pub fn new(a: &Camera, b: &Camera, min_alpha: f32, subtract: bool) -> Self {
        let (ra, rb) = (
            a.rot.map(|r| r.map(f64::from)),
            b.rot.map(|r| r.map(f64::from)),
        );
        // M[i][j] = Σ_k R2[i][k]·R1[j][k]
        let m: [[f64; 3]; 3] = std::array::from_fn(|i| {
            std::array::from_fn(|j| (0..3).map(|k| rb[i][k] * ra[j][k]).sum())
        });
        let t =
            |i: usize| b.trans[i] as f64 - (0..3).map(|j| m[i][j] * a.trans[j] as f64).sum::<f64>();
        let row = |i: usize| [m[i][0] as f32, m[i][1] as f32, m[i][2] as f32, t(i) as f32];
        let k = |c: &Camera| [c.fx, c.fy, c.cx, c.cy];
        CameraFlowParams {
            rel0: row(0),
            rel1: row(1),
            rel2: row(2),
            intr_a: k(a),
            intr_b: k(b),
            width: a.width,
            height: a.height,
            min_alpha,
            subtract: subtract as u32,
            near_b: b.near,
            ..Default::default()
        }
    }
}

/// The buffers of one `scene_signal` dispatch ([H·W] each): the two flows out of the photo,
/// the photo and the render at (v1, t1) in, the scene motion and its confidence out.
pub struct SignalIo<'a> {
    pub flow_t2: BufSlice<'a>,
    pub flow_t1: BufSlice<'a>,
    pub photo: BufSlice<'a>,
    pub render_t1: BufSlice<'a>,
    pub scene: BufSlice<'a>,
    pub conf: BufSlice<'a>,
}

pub struct DispFlow {
    camera_flow: ComputePipeline,
    grad_add: ComputePipeline,
    displacement: ComputePipeline,
    displacement_bwd: ComputePipeline,
    motion_l1: ComputePipeline,
    scene_signal: ComputePipeline,
}

impl DispFlow {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        Ok(DispFlow {
            camera_flow: gpu.pipeline(&shaders::dispflow::CAMERA_FLOW)?,
            grad_add: gpu.pipeline(&shaders::dispflow::GRAD_ADD)?,
            displacement: gpu.pipeline(&shaders::dispflow::DISPLACEMENT)?,
            displacement_bwd: gpu.pipeline(&shaders::dispflow::DISPLACEMENT_BWD)?,
            motion_l1: gpu.pipeline(&shaders::dispflow::MOTION_L1)?,
            scene_signal: gpu.pipeline(&shaders::dispflow::SCENE_SIGNAL)?,
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

    /// `weight · (1/N) Σ c·|m_scene − m_disp|` over `pixels` values (`c` ≡ 1 without `conf`):
    /// gradient wrt `m_disp` into `d_disp` and per-workgroup partial sums of c·|·| (without
    /// the weight) into `sums` ([ceil(pixels / 256)] f32). `degenerate` holds two u32 flags
    /// (disp, scene): either set skips the term.
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
        conf: Option<BufSlice<'_>>,
    ) {
        let pc = DispFlowParams {
            n: pixels,
            weight,
            conf: conf.is_some() as u32,
            ..Default::default()
        };
        // Without a confidence the binding is never read; any buffer fills it.
        let c = conf.unwrap_or(m_scene);
        rec.dispatch_threads(
            &self.motion_l1,
            &pc,
            &[m_disp, m_scene, degenerate, d_disp, sums, c],
            [pixels, 1, 1],
        );
    }

    /// The scene motion `flow_t2 − residual·flow_t1` (0 where shorter than `mask_px`) and its
    /// confidence `exp(−mean|photo − render_t1| / sigma)` (1 when `sigma` = 0) over `pixels`.
    pub fn scene_signal(
        &self,
        rec: &mut Recorder<'_>,
        pixels: u32,
        residual: bool,
        sigma: f32,
        mask_px: f32,
        io: &SignalIo<'_>,
    ) {
        let pc = SceneSignalParams {
            n: pixels,
            residual: residual as u32,
            sigma,
            mask_px,
        };
        rec.dispatch_threads(
            &self.scene_signal,
            &pc,
            &[
                io.flow_t2,
                io.flow_t1,
                io.photo,
                io.render_t1,
                io.scene,
                io.conf,
            ],
            [pixels, 1, 1],
        );
    }

    /// Indirect scene motion: `flow` (photo a → photo b) minus the camera flow of the render
    /// (v1, t1)'s depth reprojected from v1 into v2 (`p.subtract`), into `scene` ([H·W] vec2).
    pub fn camera_flow(
        &self,
        rec: &mut Recorder<'_>,
        p: &CameraFlowParams,
        flow: BufSlice<'_>,
        rgba: BufSlice<'_>,
        depth: BufSlice<'_>,
        scene: BufSlice<'_>,
    ) {
        rec.dispatch_threads(
            &self.camera_flow,
            p,
            &[flow, rgba, depth, scene],
            [p.width * p.height, 1, 1],
        );
    }

    /// `dst += src` over `n` floats.
    pub fn grad_add(&self, rec: &mut Recorder<'_>, n: u32, src: BufSlice<'_>, dst: BufSlice<'_>) {
        let pc = DispFlowParams {
            n,
            ..Default::default()
        };
        rec.dispatch_rows(&self.grad_add, &pc, &[src, dst], n);
    }
}
