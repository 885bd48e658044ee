//! One training iteration as a list of pass calls over explicit state: the Deformable-3DGS
//! step, with the DispFlow-GS motion term in the `if let Some(..)` blocks.

use super::frames::GpuFrame;
use super::passes::{
    AdamPass, DeformPass, DensifyPass, MotionTerm, OverflowWatch, PhotoLoss, RenderPass, Slot,
};
use super::plan::StepPlan;
use crate::kernels::raster::{OutputGrads, RenderOpts};
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
}

/// Records iteration `p` into `rec`. Reads nothing back: the host learns about overflows
/// from `s.watch` after the submit (the optimiser already skipped an overflowed step).
pub fn record_step(
    rec: &mut Recorder<'_>,
    p: &StepPlan,
    model: &Model,
    s: &mut StepPasses,
    frames: &[GpuFrame],
    lambda_ssim: f32,
) {
    let (a, g) = (&frames[p.frame], &model.gaussians);
    let motion = p.motion.as_ref().zip(s.motion.as_mut());
    let pair = motion.as_ref().map(|(mp, _)| (a, &frames[mp.pair]));
    let opts = RenderOpts {
        background: p.background,
        alpha_max: ALPHA_MAX,
    };
    rec.set_zone("deform");
    s.deform
        .forward(rec, model, Slot::T1, p.deform_active.then_some(p.t1));
    if let Some((mp, m)) = &motion {
        s.deform.mlp_forward(rec, model, Slot::T2, mp.t2);
        m.displacement(rec, &s.deform, g.n);
        if m.roles.inter_at_t2 {
            s.deform.apply(rec, model, Slot::T2, true);
        }
    }
    rec.set_zone("raster");
    let photo_splats = motion.as_ref().is_some_and(|(_, m)| m.roles.photo_splats);
    let splats = g.splats(s.deform.drawn(Slot::T1), p.sh_degree);
    let photo = match &motion {
        Some((_, m)) => m.splat_on(splats, photo_splats),
        None => splats,
    };
    s.render.forward(rec, &a.camera, &photo, &opts);
    rec.set_zone("loss");
    s.loss.record(rec, &s.render, a.target.all(), lambda_ssim);
    if let (Some((mp, m)), Some(pair)) = (motion, pair) {
        rec.set_zone("intermediate");
        m.render_intermediate(rec, model, &s.deform, pair, p.sh_degree, &opts);
        rec.set_zone("flow");
        m.scene_motion(rec, pair.0, pair.1);
        rec.set_zone("motion");
        m.loss(rec, &s.render, mp);
    }
    let m = s.motion.as_ref().filter(|_| p.motion.is_some());
    rec.set_zone("raster bwd");
    let d_photo = OutputGrads {
        rgba: s.loss.d_render(),
        depth: None,
        features: m.filter(|_| photo_splats).map(|m| m.flow_grad()),
    };
    let photo = match m {
        Some(m) => m.splat_on(
            g.splats(s.deform.drawn(Slot::T1), p.sh_degree),
            photo_splats,
        ),
        None => g.splats(s.deform.drawn(Slot::T1), p.sh_degree),
    };
    s.render.backward(rec, &a.camera, &photo, &opts, &d_photo);
    if let (Some(m), Some(pair)) = (m, pair) {
        m.intermediate_backward(rec, model, &s.deform, pair, p.sh_degree, &opts);
    }
    rec.set_zone("deform bwd");
    s.deform.backward(
        rec,
        model,
        Slot::T1,
        &s.render.drawn_grads(),
        p.deform_active,
    );
    s.render.copy_appearance_grads(rec, g);
    if let Some(m) = m {
        m.displacement_backward(rec, &s.deform, &s.render, g.n);
    }
    if p.deform_active {
        rec.set_zone("mlp bwd");
        s.deform.mlp_backward(rec, model, Slot::T1, false);
        if m.is_some() {
            s.deform.mlp_backward(rec, model, Slot::T2, true);
        }
    }
    rec.set_zone("densify stats");
    if p.densify_stats {
        s.densify.record_stats(rec, &s.render, g.n);
    }
    rec.set_zone("adam");
    s.adam
        .record(rec, model, &p.lr, p.iteration, s.render.overflow_flag());
    s.watch.record(rec, 0, &s.render);
    if let Some(m) = m {
        s.watch.record(rec, 1, &m.inter);
    }
}
