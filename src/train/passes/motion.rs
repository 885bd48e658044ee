//! The motion term (DESIGN §2): the DispFlow-GS displacement δ = dx(t2) − dx(t1), splatted by
//! the render the decomposition names, or the Gaussian flow of GaussianFlow/MotionGS (issue
//! 17, `kernels::gflow`), splatted by the render at (v1, t1); the intermediate render (whole,
//! its projection only, or none, as the variant needs); the scene motion from a
//! [`SceneMotion`] source (direct, or MotionGS's indirect) made robust by a [`SceneSignal`];
//! α_t·(confidence-weighted) L1 between the normalised magnitude maps (displacement) or the
//! scaled vectors (Gaussian flow), and its gradient back to both MLP passes.

use std::rc::Rc;

use super::deform::{DeformPass, Slot};
use super::render::RenderPass;
use super::signal::SceneSignal;
use super::{row, StepSizes};
use crate::error::Result;
use crate::kernels::dispflow::{CameraFlowParams, DispFlow};
use crate::kernels::flow::{FlowConfig, FlowEstimator, FlowScratch, TvL1Flow};
use crate::kernels::gflow::{GFlowLossIo, GaussianFlow, GF_FEAT};
use crate::kernels::motion::{MotionNorm, NormBuffers, NormConfig};
use crate::kernels::raster::{Camera, OutputGrads, Rasterizer, RenderOpts, SplatInputs};
use crate::model::state::Model;
use crate::train::frames::GpuFrame;
use crate::train::method::{MotionRepresentation, SceneMotionKind};
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
    /// The render at (v1, t1): colour and alpha, and Σ w·z (the indirect source's depth).
    pub render_t1: BufSlice<'a>,
    pub depth_t1: BufSlice<'a>,
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

/// MotionGS's indirect scene motion: the flow photo a → photo b minus the camera flow of the
/// render (v1, t1)'s depth reprojected into v2 (`subtract`), or the raw pair flow (the "no
/// decomposition" ablation, camera motion included).
pub struct IndirectFlow {
    flow: OpticalFlow,
    kernel: DispFlow,
    raw: Buffer,
    subtract: bool,
}

/// Render alpha below which the depth is not used for the camera flow.
pub const INDIRECT_MIN_ALPHA: f32 = 0.5;

impl IndirectFlow {
    pub fn new(gpu: &Gpu, cfg: FlowConfig, s: &StepSizes, subtract: bool) -> Result<Self> {
        Ok(IndirectFlow {
            flow: OpticalFlow::new(gpu, cfg, s)?,
            kernel: DispFlow::new(gpu)?,
            raw: gpu.buffer("pair flow photo a to photo b", s.pixels() * 8)?,
            subtract,
        })
    }
}

impl SceneMotion for IndirectFlow {
    fn name(&self) -> &str {
        if self.subtract {
            "tvl1-indirect"
        } else {
            "tvl1-pair"
        }
    }

    fn record(&self, rec: &mut Recorder<'_>, p: &MotionPair<'_>, out: BufSlice<'_>) {
        let (a, b) = (p.a, p.b);
        let f = &self.flow;
        f.flow.record(
            rec,
            &f.scratch,
            a.target.all(),
            b.target.all(),
            self.raw.all(),
        );
        let params = CameraFlowParams::new(&a.camera, &b.camera, INDIRECT_MIN_ALPHA, self.subtract);
        let (rgba, depth) = (p.render_t1, p.depth_t1);
        self.kernel
            .camera_flow(rec, &params, self.raw.all(), rgba, depth, out);
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

/// How much of the intermediate render a motion step draws: the whole image (direct scene
/// motion, or the reverse order's δ), its projection only (Gaussian flow needs the splats at
/// t2, not their image) or nothing (displacement flow with indirect scene motion).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Intermediate {
    Full,
    ProjectOnly,
    None,
}

/// The variant of a motion term: decomposition order, representation, scene motion.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MotionVariant {
    pub roles: Decomposition,
    pub representation: MotionRepresentation,
    pub scene: SceneMotionKind,
}

impl MotionVariant {
    pub fn intermediate(&self) -> Intermediate {
        let gf = self.representation == MotionRepresentation::GaussianFlow;
        match (self.scene, gf) {
            (SceneMotionKind::Direct, _) => Intermediate::Full,
            _ if !self.roles.photo_splats => Intermediate::Full,
            (_, true) => Intermediate::ProjectOnly,
            (_, false) => Intermediate::None,
        }
    }

    fn gaussian_flow(&self) -> bool {
        self.representation == MotionRepresentation::GaussianFlow
    }

    /// Channels the photometric render blends for the motion term.
    pub fn photo_features(&self) -> u32 {
        if self.gaussian_flow() {
            GF_FEAT
        } else if self.roles.photo_splats {
            3
        } else {
            0
        }
    }
}

/// The representation's own buffers.
enum Rep {
    /// δ [N,3], the normalisation of its magnitude map and ∂L/∂m̂_disp.
    Displacement {
        delta: Buffer,
        norm_disp: Box<NormBuffers>,
        d_mhat: Buffer,
    },
    /// The six channels per Gaussian.
    Gaussian { kernel: GaussianFlow, feat: Buffer },
}

pub struct MotionTerm {
    dispflow: DispFlow,
    rep: Rep,
    /// The intermediate render (no photometric gradient), when the variant draws one.
    inter: Option<RenderPass>,
    signal: SceneSignal,
    norm: MotionNorm,
    norm_cfg: NormConfig,
    norm_scene: NormBuffers,
    /// The two degenerate flags (disp, scene) the L1 reads.
    flags: Buffer,
    /// ∂L/∂(blended motion channels) per pixel.
    d_feat: Buffer,
    sums: Buffer,
    /// Zero colour gradients of the intermediate render when it splats δ (reverse order: it
    /// is supervised through its displacement-flow channels only).
    zero_rgba: Option<Buffer>,
    pub variant: MotionVariant,
    pub roles: Decomposition,
}

impl MotionTerm {
    pub fn new(
        gpu: &Gpu,
        raster: Rc<Rasterizer>,
        s: &StepSizes,
        variant: MotionVariant,
        norm_cfg: NormConfig,
        signal: SceneSignal,
    ) -> Result<Self> {
        let (px, roles) = (s.pixels(), variant.roles);
        let norm = MotionNorm::new(gpu)?;
        let inter_feats = if roles.photo_splats { 0 } else { 3 };
        let inter = match variant.intermediate() {
            Intermediate::None => None,
            _ => Some(RenderPass::new(raster, gpu, s, inter_feats)?),
        };
        let rep = if variant.gaussian_flow() {
            Rep::Gaussian {
                kernel: GaussianFlow::new(gpu)?,
                feat: gpu.buffer(
                    "gaussian flow channels",
                    s.capacity as u64 * GF_FEAT as u64 * 4,
                )?,
            }
        } else {
            Rep::Displacement {
                delta: gpu.buffer("displacement", s.capacity as u64 * row::VEC3 * 4)?,
                norm_disp: Box::new(norm.buffers(gpu, s.width, s.height, 3)?),
                d_mhat: gpu.buffer("d normalised displacement magnitude", px * 4)?,
            }
        };
        let channels = variant.photo_features().max(3) as u64;
        Ok(MotionTerm {
            dispflow: DispFlow::new(gpu)?,
            rep,
            inter,
            signal,
            norm_scene: norm.buffers(gpu, s.width, s.height, 2)?,
            norm,
            norm_cfg,
            flags: gpu.buffer("motion degenerate flags", 16)?,
            d_feat: gpu.buffer("d motion channels", px * channels * 4)?,
            sums: gpu.buffer("motion partial sums", px.div_ceil(256) * 4)?,
            zero_rgba: (!roles.photo_splats)
                .then(|| gpu.buffer_from("zero rgba grads", &vec![[0f32; 4]; px as usize]))
                .transpose()?,
            variant,
            roles,
        })
    }

    /// The Gaussians at t2 are drawn (composed into slot T2) for the intermediate render.
    pub fn draws_t2(&self) -> bool {
        self.inter.is_some() && self.roles.inter_at_t2
    }

    /// The intermediate render when the step draws its image (its overflow flag is live).
    pub fn rendered_intermediate(&self) -> Option<&RenderPass> {
        self.inter
            .as_ref()
            .filter(|_| self.variant.intermediate() == Intermediate::Full)
    }

    /// Grows the intermediate render's buffers after an overflow (the caller re-runs).
    pub fn grow_intermediate(&mut self, gpu: &Gpu, needed: u32) -> Result<()> {
        match &mut self.inter {
            Some(r) => r.grow(gpu, needed),
            None => Ok(()),
        }
    }

    /// δ = dx(t2) − dx(t1) from the deformation pass's two slots (displacement flow only).
    pub fn displacement(
        &self,
        rec: &mut Recorder<'_>,
        d: &DeformPass,
        model: &Model,
        (t1, t2): (f32, f32),
    ) {
        if let Rep::Displacement { delta, .. } = &self.rep {
            let n = model.gaussians.n;
            let (o1, o2) = (d.output(Slot::T1), d.output(Slot::T2));
            self.dispflow.displacement(rec, n, o1, o2, delta.all());
            // A transient moves by v·(t2 − t1): its rows replace the deformation's.
            d.transient_displacement(rec, model, (t1, t2), delta.all());
        }
    }

    /// `g` blending the motion channels when `splats`.
    fn splat_on<'a>(&'a self, g: SplatInputs<'a>, splats: bool) -> SplatInputs<'a> {
        let f = match &self.rep {
            Rep::Displacement { delta, .. } => (delta.all(), 3),
            Rep::Gaussian { feat, .. } => (feat.all(), GF_FEAT),
        };
        SplatInputs {
            features: splats.then_some(f),
            ..g
        }
    }

    /// The photometric render's splat inputs: `g` with the channels it blends for the term.
    pub fn photo_inputs<'a>(&'a self, g: SplatInputs<'a>) -> SplatInputs<'a> {
        self.splat_on(g, self.variant.photo_features() > 0)
    }

    /// The intermediate render's splat inputs (drawn at t2 or t1, δ when it splats it).
    fn inter_inputs<'a>(&'a self, model: &'a Model, d: &'a DeformPass, sh: u32) -> SplatInputs<'a> {
        let slot = if self.roles.inter_at_t2 {
            Slot::T2
        } else {
            Slot::T1
        };
        let g = d.splats(model, slot, sh);
        self.splat_on(g, !self.roles.photo_splats)
    }

    /// The intermediate render (no photometric gradient): whole, projected only, or nothing.
    pub fn render_intermediate(
        &self,
        rec: &mut Recorder<'_>,
        model: &Model,
        d: &DeformPass,
        pair: (&GpuFrame, &GpuFrame),
        sh: u32,
        opts: &RenderOpts,
    ) {
        let Some(inter) = &self.inter else {
            return;
        };
        let cam = self.inter_camera(pair);
        let g = self.inter_inputs(model, d, sh);
        match self.variant.intermediate() {
            Intermediate::Full => inter.forward(rec, &cam, &g, opts),
            _ => inter.project(rec, &cam, &g),
        }
    }

    fn inter_camera(&self, (a, b): (&GpuFrame, &GpuFrame)) -> Camera {
        if self.roles.inter_at_pair_view {
            b.camera
        } else {
            a.camera
        }
    }

    /// The photometric render (v1, t1) with its motion channels: for Gaussian flow its
    /// projection, the channels from both projections, then its blend.
    pub fn photo_forward(
        &self,
        rec: &mut Recorder<'_>,
        photo: &RenderPass,
        cam: &Camera,
        g: &SplatInputs<'_>,
        opts: &RenderOpts,
    ) {
        let (Rep::Gaussian { kernel, feat }, Some(inter)) = (&self.rep, &self.inter) else {
            photo.forward(rec, cam, g, opts);
            return;
        };
        photo.project(rec, cam, g);
        kernel.features(rec, g.n, photo.splats(), inter.splats(), feat.all());
        photo.blend(rec, cam, g, opts);
    }

    /// Scene motion of the pair into the signal's buffers; `photo` is the photometric render
    /// (v1, t1) the residual correction, the confidence and the indirect source read.
    pub fn scene_motion(
        &self,
        rec: &mut Recorder<'_>,
        a: &GpuFrame,
        b: &GpuFrame,
        photo: &RenderPass,
    ) {
        let (from, to) = match (&self.inter, self.roles.flow_from_photo) {
            (Some(inter), true) if self.variant.scene == SceneMotionKind::Direct => {
                (a.target.all(), inter.rgba())
            }
            (Some(inter), false) => (inter.rgba(), b.target.all()),
            _ => (a.target.all(), b.target.all()),
        };
        let pair = MotionPair {
            a,
            b,
            from,
            to,
            render_t1: photo.rgba(),
            depth_t1: photo.depth(),
        };
        self.signal.record(rec, &pair, photo.rgba());
    }

    /// The loss of the blended motion channels (the photometric render's, or the
    /// intermediate's in the reverse order) against the scene motion, and its gradient wrt
    /// them. Displacement: normalised magnitudes, α_t·mean c·|m̂_scene − m̂_disp|. Gaussian
    /// flow: α_t·mean c·|F − F_scene|₁ / s with s the scene map's normalisation denominator.
    /// A degenerate (flat) scene map skips the term on the GPU.
    pub fn loss(&mut self, rec: &mut Recorder<'_>, photo: &RenderPass, p: &MotionPlan) {
        let feat = match (&self.inter, self.roles.photo_splats) {
            (Some(inter), false) => inter.features(),
            _ => photo.features(),
        };
        let cfg = self.norm_cfg;
        self.norm
            .record(rec, &mut self.norm_scene, self.signal.flow(), cfg);
        match &mut self.rep {
            Rep::Gaussian { kernel, .. } => {
                let io = GFlowLossIo {
                    feat,
                    scene: self.signal.flow(),
                    stats: self.norm_scene.stats(),
                    d_feat: self.d_feat.all(),
                    sums: self.sums.all(),
                    conf: self.signal.confidence(),
                };
                let (px, w) = (self.norm_scene.pixels(), photo.bufs.width);
                kernel.l1(rec, px, w, p.weight, &io);
            }
            Rep::Displacement {
                norm_disp, d_mhat, ..
            } => {
                self.norm.record(rec, norm_disp, feat, cfg);
                rec.copy(flag_word(norm_disp), self.flags.slice(0, 4));
                rec.copy(flag_word(&self.norm_scene), self.flags.slice(4, 4));
                self.dispflow.motion_l1(
                    rec,
                    norm_disp.pixels(),
                    p.weight,
                    norm_disp.m_hat(),
                    self.norm_scene.m_hat(),
                    self.flags.all(),
                    d_mhat.all(),
                    self.sums.all(),
                    self.signal.confidence(),
                );
                let d_feat = self.d_feat.slice(0, self.norm_scene.pixels() as u64 * 12);
                self.norm
                    .record_backward(rec, norm_disp, feat, d_mhat.all(), d_feat);
            }
        }
    }

    /// ∂L/∂(blended motion channels) of the last [`MotionTerm::loss`].
    pub fn flow_grad(&self) -> BufSlice<'_> {
        let px = self.norm_scene.pixels() as u64;
        let ch = match self.rep {
            Rep::Displacement { .. } => 3,
            Rep::Gaussian { .. } => GF_FEAT as u64,
        };
        self.d_feat.slice(0, px * ch * 4)
    }

    /// The photometric render's backward; for Gaussian flow the channels' gradient goes to
    /// the 2D gradient records at t1 (this render's) and at t2 (the intermediate's) between
    /// the blend and the projection backward.
    pub fn photo_backward(
        &self,
        rec: &mut Recorder<'_>,
        photo: &RenderPass,
        cam: &Camera,
        g: &SplatInputs<'_>,
        opts: &RenderOpts,
        grads: &OutputGrads<'_>,
    ) {
        let (Rep::Gaussian { kernel, .. }, Some(inter)) = (&self.rep, &self.inter) else {
            photo.backward(rec, cam, g, opts, grads);
            return;
        };
        photo.backward_blend(rec, cam, g, opts, grads);
        rec.fill(inter.grad2d(), 0);
        let splats = [photo.splats(), inter.splats()];
        let grad2d = [photo.grad2d(), inter.grad2d()];
        kernel.features_bwd(rec, g.n, splats, photo.feature_grads(), grad2d);
        photo.backward_project(rec, cam, g, opts);
    }

    /// The second render's backward: the reverse order's intermediate (its displacement-flow
    /// gradient through the blend, colour gradient zero) or, for Gaussian flow, the projection
    /// at t2 (from the 2D gradients [`MotionTerm::photo_backward`] left there).
    pub fn intermediate_backward(
        &self,
        rec: &mut Recorder<'_>,
        model: &Model,
        d: &DeformPass,
        pair: (&GpuFrame, &GpuFrame),
        sh: u32,
        opts: &RenderOpts,
    ) {
        let Some(inter) = &self.inter else {
            return;
        };
        let g = self.inter_inputs(model, d, sh);
        let cam = self.inter_camera(pair);
        if let Rep::Gaussian { .. } = self.rep {
            inter.backward_project(rec, &cam, &g, opts);
            return;
        }
        let Some(zero) = &self.zero_rgba else {
            return;
        };
        let grads = OutputGrads {
            rgba: zero.all(),
            depth: None,
            features: Some(self.d_feat.slice(0, self.norm_scene.pixels() as u64 * 12)),
        };
        inter.backward(rec, &cam, &g, opts, &grads);
    }

    /// The second render's geometry gradients into the deformation pass (after the
    /// photometric render's [`DeformPass::backward`] and the appearance-gradient copy): the
    /// reverse order's intermediate draws the Gaussians at t1, so its blend-weight gradients
    /// add to slot T1 and to the opacity logits; Gaussian flow's projection at t2 writes slot
    /// T2.
    pub fn second_render_grads(&self, rec: &mut Recorder<'_>, model: &Model, d: &DeformPass) {
        let Some(inter) = &self.inter else {
            return;
        };
        match self.rep {
            Rep::Gaussian { .. } => {
                d.clear_output_grad(rec, Slot::T2);
                d.backward_add(rec, model, Slot::T2, &inter.drawn_grads());
            }
            Rep::Displacement { .. } if !self.roles.photo_splats => {
                d.backward_add(rec, model, Slot::T1, &inter.drawn_grads());
                let g = &model.gaussians;
                let opacity = g.grad(crate::model::gaussians::Section::Opacity);
                let src = inter.bufs.d_opacity_logits.slice(0, g.n as u64 * 4);
                self.dispflow.grad_add(rec, g.n, src, opacity);
            }
            Rep::Displacement { .. } => {}
        }
    }

    /// ∂L/∂δ (from the render that splatted δ) into both MLP-output gradients: subtracted from
    /// t1's dx gradient, written as t2's. Nothing for Gaussian flow.
    pub fn displacement_backward(
        &self,
        rec: &mut Recorder<'_>,
        d: &DeformPass,
        photo: &RenderPass,
        model: &Model,
        times: (f32, f32),
    ) {
        if let Rep::Gaussian { .. } = self.rep {
            return;
        }
        let splatting = match (&self.inter, self.roles.photo_splats) {
            (Some(inter), false) => inter,
            _ => photo,
        };
        let (d1, d2) = (d.output_grad(Slot::T1), d.output_grad(Slot::T2));
        let n = model.gaussians.n;
        self.dispflow
            .displacement_bwd(rec, n, splatting.feature_grads(), d1, d2);
        d.transient_displacement_backward(rec, model, times, splatting.feature_grads());
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
