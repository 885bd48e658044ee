//! What the trainer renders and scores outside a step: test frames, probes, any view, the
//! model of one instant, and a training frame as drawn now (the transients' spawn). Each
//! goes through the [`Evaluator`] with its own scratch and never changes training state.

use super::{curve, node_cfg, Shot, Trainer};
use crate::error::Result;
use crate::kernels::loss::LossValues;
use crate::kernels::raster::Camera;
use crate::model::gaussians::HostGaussians;
use crate::train::passes::Slot;
use crate::train::score::lpips::LpipsScorer;
use crate::train::score::{Evaluator, FrameEval, ModelView};

impl Trainer<'_> {
    /// Training frame `i` rendered as the model is drawn now, with its ground truth (`None`
    /// when the evaluator gives no image).
    pub(super) fn shot(&mut self, i: usize, view: ModelView) -> Result<Option<Shot>> {
        let f = &self.frames[i];
        let (camera, time) = (f.camera, f.time);
        let gt: Vec<[f32; 4]> = self.gpu.read(f.target.all())?;
        let gpu = self.gpu;
        self.evaluator()?;
        let e = self.eval.as_mut().expect("built");
        let shot = e.view(gpu, &self.model, view, &camera, time, None)?;
        Ok(shot.images.map(|im| (im.render, gt)))
    }

    /// How the model is drawn now: the deformation and SH degree of the last iteration.
    pub fn view(&self) -> ModelView {
        let p = self.plan(self.iteration.max(1));
        ModelView {
            deform_active: p.deform_active,
            sh_degree: p.sh_degree,
        }
    }

    /// The evaluator (built once, with its own scratch).
    pub fn evaluator(&mut self) -> Result<&mut Evaluator> {
        if self.eval.is_none() {
            let e = Evaluator::new(
                self.gpu,
                self.raster.clone(),
                &self.model.deform.cfg,
                node_cfg(&self.model),
                &self.sizes,
                self.cfg.scene_motion.flow_config(&self.cfg.flow_preset)?,
                self.cfg.lambda_ssim,
            )?
            .on_background(self.background);
            self.eval = Some(e);
        }
        Ok(self.eval.as_mut().expect("just built"))
    }

    /// Evaluates every test frame (see [`Evaluator::frame`]); never changes training state.
    pub fn evaluate(&mut self, want_images: bool) -> Result<Vec<FrameEval>> {
        (0..self.val.len())
            .map(|i| self.evaluate_one(i, want_images))
            .collect()
    }

    /// ∂L/∂(MLP output at t2) [N,10] of the last step when it ran a motion term: the motion
    /// term's only way into the MLP's second pass (tests: "the term reaches the deformation").
    pub fn motion_output_grad(&self) -> Result<Option<Vec<f32>>> {
        let ran = self.last_plan.is_some_and(|p| p.motion.is_some());
        match self.passes.as_ref().filter(|_| ran) {
            Some(p) => {
                let n = self.model.gaussians.n as u64;
                let g = p.deform.output_grad(Slot::T2);
                Ok(Some(self.gpu.read(g.buf.slice(g.offset, n * 40))?))
            }
            None => Ok(None),
        }
    }

    /// Loss values and frame id of the last step (read from host memory after its submit).
    pub fn last_loss(&self) -> Option<(LossValues, &str)> {
        let p = self.last_plan?;
        let s = self.passes.as_ref()?;
        Some((s.loss.values(), &self.frames[p.frame].id))
    }

    /// Mean test PSNR over the test frames `which` (render and photometric loss only: the
    /// cheap probe of the PSNR-vs-time curve).
    pub fn test_psnr(&mut self, which: &[usize]) -> Result<f64> {
        Ok(self.probe(which, false)?.psnr)
    }

    /// The periodic probe over test frames `which`: mean PSNR and region PSNRs and, with
    /// `motion` on frames with ground-truth flow, the displacement EPE and the Gaussians'
    /// projected-motion quantiles (means over the frames that have each).
    pub fn probe(&mut self, which: &[usize], motion: bool) -> Result<curve::Probe> {
        let view = self.view();
        let gpu = self.gpu;
        self.evaluator()?;
        let e = self.eval.as_mut().expect("built");
        let mut frames = Vec::with_capacity(which.len());
        let mut probes = Vec::new();
        for &i in which {
            frames.push(e.photometric(gpu, &self.model, view, &self.val[i])?);
            if motion {
                probes.extend(e.motion_probe(gpu, &self.model, view, &self.val[i])?);
            }
        }
        Ok(curve::Probe::of(&frames, &probes))
    }

    /// PSNR of training frame `i` rendered as the model stands (the collapse guard's probe
    /// views; render and photometric loss only, no training state changes).
    pub fn train_view_psnr(&mut self, i: usize) -> Result<f64> {
        let view = self.view();
        let gpu = self.gpu;
        self.evaluator()?;
        let e = self.eval.as_mut().expect("built");
        Ok(e.photometric(gpu, &self.model, view, &self.frames[i])?.psnr)
    }

    /// The displacement EPE probe of test frame `i` (`None` without a mask and ground-truth
    /// flow towards a next time).
    pub fn motion_probe(
        &mut self,
        i: usize,
    ) -> Result<Option<crate::train::score::epe::MotionProbe>> {
        let view = self.view();
        let gpu = self.gpu;
        self.evaluator()?;
        let e = self.eval.as_mut().expect("built");
        e.motion_probe(gpu, &self.model, view, &self.val[i])
    }

    /// Evaluates test frame `i`.
    pub fn evaluate_one(&mut self, i: usize, want_images: bool) -> Result<FrameEval> {
        let view = self.view();
        let gpu = self.gpu;
        self.evaluator()?;
        let e = self.eval.as_mut().expect("built");
        e.frame(gpu, &self.model, view, &self.val[i], want_images)
    }

    /// LPIPS of the last [`Self::evaluate_one`]'s render against test frame `i`'s image.
    pub fn lpips_one(&mut self, i: usize, scorer: &mut LpipsScorer) -> Result<f64> {
        let gpu = self.gpu;
        self.evaluator()?;
        let e = self.eval.as_ref().expect("built");
        let f = &self.val[i];
        let size = (f.camera.width, f.camera.height);
        scorer.score(gpu, size, e.last_render(), f.target.all())
    }

    /// Renders any view `(camera, t)` with the displacement flow since `prev` (pictures only).
    pub fn render_view(&mut self, camera: &Camera, t: f32, prev: Option<f32>) -> Result<FrameEval> {
        let view = self.view();
        let gpu = self.gpu;
        self.evaluator()?;
        let e = self.eval.as_mut().expect("built");
        e.view(gpu, &self.model, view, camera, t, prev)
    }

    /// Each pixel's blend weight on dynamic Gaussians at view `(camera, t)` ([H·W]).
    pub fn dynamic_mask(&mut self, camera: &Camera, t: f32) -> Result<Vec<f32>> {
        let view = self.view();
        let gpu = self.gpu;
        self.evaluator()?;
        let e = self.eval.as_mut().expect("built");
        e.dynamic_mask(gpu, &self.model, view, camera, t)
    }

    /// The Gaussians as drawn at time `t` (a standard 3DGS model of that instant).
    pub fn deformed_gaussians(&mut self, t: f32) -> Result<HostGaussians> {
        let view = self.view();
        let gpu = self.gpu;
        self.evaluator()?;
        let e = self.eval.as_mut().expect("built");
        e.deformed_gaussians(gpu, &self.model, view, t)
    }
}
