//! One training iteration as a list of pass calls over explicit state: the Deformable-3DGS
//! step, with the motion term (DispFlow-GS or a baseline's, `passes::motion`) in the
//! `if let Some(..)` blocks.

use super::frames::GpuFrame;
use super::passes::sparsity::Classifier;
use super::passes::{
    AdamPass, DeformPass, DensifyPass, MotionTerm, OverflowWatch, PhotoLoss, RenderPass, Slot,
};
use super::plan::StepPlan;
use super::population::Population;
use crate::kernels::raster::{OutputGrads, RenderOpts, SplatInputs};
use crate::model::state::Model;
use crate::vk::Recorder;

/// 3DGS's α clamp.
pub const ALPHA_MAX: f32 = 0.99;

/// The passes of a training step and their scratch.
pub struct StepPasses {
    pub deform: DeformPass,
    /// The photometrically supervised render (v1, t1).
    pub render: RenderPass,
    pub loss: PhotoLoss,
    pub motion: Option<MotionTerm>,
    pub adam: AdamPass,
    pub densify: DensifyPass,
    /// Overflow of the render (slot 0) and of the intermediate render (slot 1).
    pub watch: OverflowWatch,
    /// The motion probe that splits the model (sparsity on, deformation on).
    pub classifier: Option<Classifier>,
}

impl StepPasses {
    /// The motion term of step `p`, when it has one.
    fn motion_of(&self, p: &StepPlan) -> Option<&MotionTerm> {
        self.motion.as_ref().filter(|_| p.motion.is_some())
    }

    /// What the photometric render draws: the Gaussians at t1, blending the motion channels
    /// when this step's motion term splats them there.
    fn photo<'a>(&'a self, model: &'a Model, p: &StepPlan) -> SplatInputs<'a> {
        let g = self.deform.splats(model, Slot::T1, p.sh_degree);
        match self.motion_of(p) {
            Some(m) => m.photo_inputs(g),
            None => g,
        }
    }

    /// Upstream gradients of the photometric render: the loss's, plus the motion channels'
    /// when it splatted them.
    fn photo_grads(&self, p: &StepPlan) -> OutputGrads<'_> {
        let m = self.motion_of(p).filter(|m| m.variant.photo_features() > 0);
        OutputGrads {
            rgba: self.loss.d_render(),
            depth: None,
            features: m.map(|m| m.flow_grad()),
        }
    }
}

/// Records iteration `p` into `rec`. Reads nothing back: the host learns about overflows
/// from `s.watch` after the submit (the optimiser and the statistics already ignored an
/// overflowed step, which the host re-runs with grown buffers).
pub fn record_step(
    rec: &mut Recorder<'_>,
    p: &StepPlan,
    model: &Model,
    s: &mut StepPasses,
    frames: &[GpuFrame],
    lambda_ssim: f32,
) {
    let (a, g) = (&frames[p.frame], &model.gaussians);
    let pair = p.motion.map(|mp| (a, &frames[mp.pair]));
    let opts = RenderOpts {
        background: p.background,
        alpha_max: ALPHA_MAX,
        abs_grad: p.abs_grad,
        detach_feature_weights: p.detach_motion_weights && Population::any_scales_opacity(g),
    };
    rec.set_zone("deform");
    s.deform
        .forward(rec, model, Slot::T1, p.t1, p.deform_active);
    if let (Some(mp), Some(m)) = (p.motion, s.motion_of(p)) {
        s.deform.mlp_forward(rec, model, Slot::T2, mp.t2);
        m.displacement(rec, &s.deform, model, (p.t1, mp.t2));
        if m.draws_t2() {
            s.deform.apply(rec, model, Slot::T2, mp.t2, true);
        }
    }
    // The intermediate render first: Gaussian flow's channels need its projection at t2
    // before the photometric render blends them.
    if let (Some(m), Some(pair)) = (s.motion_of(p), pair) {
        rec.set_zone("intermediate");
        m.render_intermediate(rec, model, &s.deform, pair, p.sh_degree, &opts);
    }
    rec.set_zone("raster");
    let photo = s.photo(model, p);
    match s.motion_of(p) {
        Some(m) => m.photo_forward(rec, &s.render, &a.camera, &photo, &opts),
        None => s.render.forward(rec, &a.camera, &photo, &opts),
    }
    rec.set_zone("loss");
    s.loss.record(rec, &s.render, a.target.all(), lambda_ssim);
    if let (Some(mp), Some(m), Some(pair)) = (p.motion, s.motion.as_mut(), pair) {
        rec.set_zone("flow");
        m.scene_motion(rec, pair.0, pair.1, &s.render);
        rec.set_zone("motion");
        m.loss(rec, &s.render, &mp);
    }
    rec.set_zone("raster bwd");
    let photo = s.photo(model, p);
    let grads = s.photo_grads(p);
    match s.motion_of(p) {
        Some(m) => m.photo_backward(rec, &s.render, &a.camera, &photo, &opts, &grads),
        None => s.render.backward(rec, &a.camera, &photo, &opts, &grads),
    }
    if let (Some(m), Some(pair)) = (s.motion_of(p), pair) {
        m.intermediate_backward(rec, model, &s.deform, pair, p.sh_degree, &opts);
    }
    rec.set_zone("deform bwd");
    s.deform.backward(
        rec,
        model,
        Slot::T1,
        &s.render.drawn_grads(),
        p.deform_active,
        p.t1,
        s.render.bufs.d_op_scale.all(),
    );
    s.render.copy_appearance_grads(rec, g);
    if let Some(m) = s.motion_of(p) {
        m.second_render_grads(rec, model, &s.deform);
        let t2 = p.motion.map_or(p.t1, |mp| mp.t2);
        m.displacement_backward(rec, &s.deform, &s.render, model, (p.t1, t2));
    }
    if p.deform_active {
        rec.set_zone("mlp bwd");
        s.deform.mlp_backward(rec, model, Slot::T1, false);
        if s.motion_of(p).is_some() {
            s.deform.mlp_backward(rec, model, Slot::T2, true);
        }
    }
    rec.set_zone("densify stats");
    // An overflow of either render discards the step (the host grows and re-runs it).
    s.watch.record(rec, 0, &s.render);
    let inter = s.motion_of(p).and_then(|m| m.rendered_intermediate());
    if let Some(r) = inter {
        s.watch.record(rec, 1, r);
    }
    let guard = s.watch.guard(1 + inter.is_some() as u64);
    if p.densify_stats {
        s.densify.record_stats(rec, &s.render, g.n, guard);
    }
    rec.set_zone("adam");
    s.adam.record(rec, model, &p.lr, p.iteration, guard);
    s.watch.publish(rec);
}
