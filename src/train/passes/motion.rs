//! The DispFlow-GS motion term (DESIGN §2): the displacement δ = dx(t2) − dx(t1), splatted by
//! the render the decomposition names; the intermediate render; the scene motion from a
//! [`SceneMotion`] source made robust by a [`SceneSignal`]; both magnitude maps normalised;
//! α_t·(confidence-weighted) L1 between them and its gradient back to the blended
//! displacement flow and, through δ, to both MLP passes.

use std::rc::Rc;

use super::deform::{DeformPass, Slot};
use super::render::RenderPass;
use super::signal::SceneSignal;
use super::{row, StepSizes};
use crate::error::Result;
use crate::kernels::dispflow::DispFlow;
use crate::kernels::flow::{FlowConfig, FlowEstimator, FlowScratch, TvL1Flow};
use crate::kernels::motion::{MotionNorm, NormBuffers, NormConfig};
use crate::kernels::raster::{OutputGrads, Rasterizer, RenderOpts, SplatInputs};
use crate::model::state::Model;
use crate::train::frames::GpuFrame;
use crate::train::plan::{Decomposition, MotionPlan};
use crate::vk::{BufSlice, Buffer, Gpu, Recorder};

/// The two frames of a motion step and the two images the scene motion is measured between.
#[derive(Clone, Copy)]
pub struct MotionPair<'a> {
    pub a: &'a GpuFrame,
    pub b: &'a GpuFrame,
    /// Scene motion goes from `from` to `to` ([H·W] vec4 each): the photo of `a` and the
    /// intermediate render (direct order), or the intermediate and the photo of `b` (reverse).
    pub from: BufSlice<'a>,
    pub to: BufSlice<'a>,
}

/// A source of scene motion ([H·W] vec2, pixels) for a motion pair.
pub trait SceneMotion {
    fn name(&self) -> &str;
    fn record(&self, rec: &mut Recorder<'_>, pair: &MotionPair<'_>, out: BufSlice<'_>);
}

/// The GPU optical-flow estimator between the pair's two images (the method).
pub struct OpticalFlow {
    flow: TvL1Flow,
    scratch: FlowScratch,
}

impl OpticalFlow {
    pub fn new(gpu: &Gpu, cfg: FlowConfig, s: &StepSizes) -> Result<Self> {
        let flow = TvL1Flow::new(gpu, cfg)?;
        Ok(OpticalFlow {
            scratch: flow.scratch(gpu, s.width, s.height)?,
            flow,
        })
    }
}

impl SceneMotion for OpticalFlow {
    fn name(&self) -> &str {
        "tvl1"
    }

    fn record(&self, rec: &mut Recorder<'_>, p: &MotionPair<'_>, out: BufSlice<'_>) {
        self.flow.record(rec, &self.scratch, p.from, p.to, out);
    }
}

/// The synthetic scene's ground-truth flow of frame `a` under its own view (an ablation that
/// isolates the supervision from the estimator; direct order only).
pub struct OracleFlow;

impl SceneMotion for OracleFlow {
    fn name(&self) -> &str {
        "oracle"
    }

    fn record(&self, rec: &mut Recorder<'_>, p: &MotionPair<'_>, out: BufSlice<'_>) {
        let gt =
            p.a.gt_flow
                .as_ref()
                .expect("oracle frames carry their flow");
        rec.copy(gt.all(), out.buf.slice(out.offset, gt.all().size));
    }
}

/// A fixed field, whatever the pair (tests: the step without an estimator in the loop).
pub struct FixedMotion(pub Buffer);

impl SceneMotion for FixedMotion {
    fn name(&self) -> &str {
        "fixed"
    }

    fn record(&self, rec: &mut Recorder<'_>, _: &MotionPair<'_>, out: BufSlice<'_>) {
        rec.copy(self.0.all(), out.buf.slice(out.offset, self.0.size()));
    }
}

pub struct MotionTerm {
    dispflow: DispFlow,
    delta: Buffer,
    /// The intermediate render (no photometric gradient).
    pub inter: RenderPass,
    signal: SceneSignal,
    norm: MotionNorm,
    norm_cfg: NormConfig,
    norm_disp: NormBuffers,
    norm_scene: NormBuffers,
    /// The two degenerate flags (disp, scene) the L1 reads.
    flags: Buffer,
    d_mhat: Buffer,
    d_feat: Buffer,
    sums: Buffer,
    /// Zero colour gradients of the intermediate render when it splats δ (reverse order: it
    /// is supervised through its displacement-flow channels only).
    zero_rgba: Option<Buffer>,
    pub roles: Decomposition,
}

impl MotionTerm {
    pub fn new(
        gpu: &Gpu,
        raster: Rc<Rasterizer>,
        s: &StepSizes,
        roles: Decomposition,
        norm_cfg: NormConfig,
        signal: SceneSignal,
    ) -> Result<Self> {
        let px = s.pixels();
        let norm = MotionNorm::new(gpu)?;
        let inter_feats = if roles.photo_splats { 0 } else { 3 };
        Ok(MotionTerm {
            dispflow: DispFlow::new(gpu)?,
            delta: gpu.buffer("displacement", s.capacity as u64 * row::VEC3 * 4)?,
            inter: RenderPass::new(raster, gpu, s, inter_feats)?,
            signal,
            norm_disp: norm.buffers(gpu, s.width, s.height, 3)?,
            norm_scene: norm.buffers(gpu, s.width, s.height, 2)?,
            norm,
            norm_cfg,
            flags: gpu.buffer("motion degenerate flags", 16)?,
            d_mhat: gpu.buffer("d normalised displacement magnitude", px * 4)?,
            d_feat: gpu.buffer("d displacement flow", px * 12)?,
            sums: gpu.buffer("motion partial sums", px.div_ceil(256) * 4)?,
            zero_rgba: (!roles.photo_splats)
                .then(|| gpu.buffer_from("zero rgba grads", &vec![[0f32; 4]; px as usize]))
                .transpose()?,
            roles,
        })
    }

    /// δ = dx(t2) − dx(t1) from the deformation pass's two slots.
    pub fn displacement(&self, rec: &mut Recorder<'_>, d: &DeformPass, n: u32) {
        let (t1, t2) = (d.output(Slot::T1), d.output(Slot::T2));
        self.dispflow.displacement(rec, n, t1, t2, self.delta.all());
    }

    /// `g` blending δ as three feature channels when `splats` (the render the roles name).
    pub fn splat_on<'a>(&'a self, g: SplatInputs<'a>, splats: bool) -> SplatInputs<'a> {
        SplatInputs {
            features: splats.then(|| (self.delta.all(), 3)),
            ..g
        }
    }

    /// The intermediate render's splat inputs (drawn at t2 or t1, δ when it splats it).
    fn inter_inputs<'a>(&'a self, model: &'a Model, d: &'a DeformPass, sh: u32) -> SplatInputs<'a> {
        let slot = if self.roles.inter_at_t2 {
            Slot::T2
        } else {
            Slot::T1
        };
        let g = model.gaussians.splats(d.drawn(slot), sh);
        self.splat_on(g, !self.roles.photo_splats)
    }

    /// Renders the intermediate image (no photometric gradient).
    pub fn render_intermediate(
        &self,
        rec: &mut Recorder<'_>,
        model: &Model,
        d: &DeformPass,
        pair: (&GpuFrame, &GpuFrame),
        sh: u32,
        opts: &RenderOpts,
    ) {
        let cam = self.inter_camera(pair);
        let g = self.inter_inputs(model, d, sh);
        self.inter.forward(rec, &cam, &g, opts);
    }

    fn inter_camera(&self, (a, b): (&GpuFrame, &GpuFrame)) -> crate::kernels::raster::Camera {
        if self.roles.inter_at_pair_view {
            b.camera
        } else {
            a.camera
        }
    }

    /// Scene motion of the pair into the signal's buffers; `photo` is the photometric render
    /// (v1, t1) the residual correction and the confidence compare with the photo of `a`.
    pub fn scene_motion(
        &self,
        rec: &mut Recorder<'_>,
        a: &GpuFrame,
        b: &GpuFrame,
        photo: &RenderPass,
    ) {
        let inter = self.inter.rgba();
        let (from, to) = if self.roles.flow_from_photo {
            (a.target.all(), inter)
        } else {
            (inter, b.target.all())
        };
        let pair = MotionPair { a, b, from, to };
        self.signal.record(rec, &pair, photo.rgba());
    }

    /// Normalised magnitudes of the displacement flow (blended by the photometric render or
    /// the intermediate, as the roles say) and of the scene motion; α_t·mean|m̂_scene − m̂_disp|
    /// and its gradient back to ∂L/∂F_disp. A degenerate (flat) map skips the term on the GPU.
    pub fn loss(&mut self, rec: &mut Recorder<'_>, photo: &RenderPass, p: &MotionPlan) {
        let feat = if self.roles.photo_splats {
            photo.features()
        } else {
            self.inter.features()
        };
        let cfg = self.norm_cfg;
        self.norm.record(rec, &mut self.norm_disp, feat, cfg);
        self.norm
            .record(rec, &mut self.norm_scene, self.signal.flow(), cfg);
        rec.copy(flag_word(&self.norm_disp), self.flags.slice(0, 4));
        rec.copy(flag_word(&self.norm_scene), self.flags.slice(4, 4));
        self.dispflow.motion_l1(
            rec,
            self.norm_disp.pixels(),
            p.weight,
            self.norm_disp.m_hat(),
            self.norm_scene.m_hat(),
            self.flags.all(),
            self.d_mhat.all(),
            self.sums.all(),
            self.signal.confidence(),
        );
        self.norm.record_backward(
            rec,
            &self.norm_disp,
            feat,
            self.d_mhat.all(),
            self.d_feat.all(),
        );
    }

    /// ∂L/∂F_disp of the last [`MotionTerm::loss`].
    pub fn flow_grad(&self) -> BufSlice<'_> {
        self.d_feat.all()
    }

    /// Reverse order: the intermediate render's backward with its displacement-flow gradient
    /// only. Its blend-weight gradients are not added to the Gaussians.
    pub fn intermediate_backward(
        &self,
        rec: &mut Recorder<'_>,
        model: &Model,
        d: &DeformPass,
        pair: (&GpuFrame, &GpuFrame),
        sh: u32,
        opts: &RenderOpts,
    ) {
        let Some(zero) = &self.zero_rgba else {
            return;
        };
        let g = self.inter_inputs(model, d, sh);
        let grads = OutputGrads {
            rgba: zero.all(),
            depth: None,
            features: Some(self.d_feat.all()),
        };
        self.inter
            .backward(rec, &self.inter_camera(pair), &g, opts, &grads);
    }

    /// ∂L/∂δ (from the render that splatted δ) into both MLP-output gradients: subtracted from
    /// t1's dx gradient, written as t2's.
    pub fn displacement_backward(
        &self,
        rec: &mut Recorder<'_>,
        d: &DeformPass,
        photo: &RenderPass,
        n: u32,
    ) {
        let splatting = if self.roles.photo_splats {
            photo
        } else {
            &self.inter
        };
        let (d1, d2) = (d.output_grad(Slot::T1), d.output_grad(Slot::T2));
        self.dispflow
            .displacement_bwd(rec, n, splatting.feature_grads(), d1, d2);
    }

    /// The scene-motion source's name (for logs).
    pub fn source_name(&self) -> &str {
        self.signal.source_name()
    }
}

/// The degenerate flag: the first u32 of a normalisation's statistics.
fn flag_word(b: &NormBuffers) -> BufSlice<'_> {
    let s = b.stats();
    s.buf.slice(s.offset, 4)
}
