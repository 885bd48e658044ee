//! Scoring a frame: per-frame scores of a model (PSNR, SSIM, L1; the displacement flow's AP
//! against the motion mask for MMAP; DRC; the AP of the optical flow the motion loss would
//! learn from; dynamic/static PSNR; the displacement EPE probe; LPIPS). Training's test probe
//! and the `eval`/`render`/`signal` commands (`crate::eval`, above this) share it. The
//! [`Evaluator`] owns its scratch: evaluating never touches a training buffer.
//! Over 600 lines because it is one type: the Evaluator's scoring paths share its scratch.

pub mod epe;
pub mod lpips;
pub mod regions;

use std::rc::Rc;

use serde::Serialize;

use crate::error::Result;
use crate::kernels::dispflow::DispFlow;
use crate::kernels::flow::{FlowConfig, FlowEstimator, FlowScratch, TvL1Flow};
use crate::kernels::loss::LossValues;
use crate::kernels::metrics::{MetricBuffers, MotionMetrics};
use crate::kernels::motion::{MotionNorm, NormBuffers, NormConfig};
use crate::kernels::raster::{Camera, Rasterizer, RenderOpts};
use crate::model::deform::MlpConfig;
use crate::model::gaussians::HostGaussians;
use crate::model::rows::Rows;
use crate::model::state::Model;
use crate::train::frames::GpuFrame;
use crate::train::passes::{
    row, DeformPass, OverflowWatch, PhotoLoss, RenderPass, Slot, StepSizes,
};
use crate::train::population::Population;
use crate::train::step::ALPHA_MAX;
use crate::vk::{BufSlice, Buffer, Gpu, Recorder};

/// How the model is drawn at some iteration: whether the deformation runs, the SH degree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ModelView {
    pub deform_active: bool,
    pub sh_degree: u32,
}

/// One evaluated view: its scores (the per-frame rows of `metrics.json`) and, on request, its
/// pictures.
#[derive(Clone, Debug, Serialize)]
pub struct FrameEval {
    pub id: String,
    pub time: f32,
    pub psnr: f64,
    pub ssim: f64,
    pub l1: f64,
    /// The frame has a motion mask with at least one moving pixel.
    pub has_mask: bool,
    /// PSNR inside the motion mask dilated by [`regions::MASK_DILATE_PX`] (`None`: no mask or
    /// an empty one): where a smeared, ghosted or missing moving object shows.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dynamic_psnr: Option<f64>,
    /// PSNR outside that dilated mask (`None` likewise).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub static_psnr: Option<f64>,
    /// Share of the frame's pixels inside that dilated mask (`None` likewise).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dynamic_share: Option<f64>,
    /// AP of the normalised displacement flow against the mask (`None`: no mask, an empty
    /// mask, or no earlier time in the dataset).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ap: Option<f64>,
    /// DRC (`None` without an earlier time).
    pub drc: Option<f64>,
    /// AP of the optical-flow magnitude (frozen render → ground truth) against the mask: the
    /// quality of the signal the motion loss learns from.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flow_ap: Option<f64>,
    /// LPIPS (AlexNet) of the render against the ground truth, when `eval` was given weights.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lpips: Option<f64>,
    #[serde(skip)]
    pub images: Option<FrameImages>,
}

/// Pictures of one evaluated view (host copies).
#[derive(Clone, Debug)]
pub struct FrameImages {
    pub width: u32,
    pub height: u32,
    pub render: Vec<[f32; 4]>,
    /// Ground truth (empty for a view without a frame).
    pub gt: Vec<[f32; 4]>,
    /// Min-max normalised displacement-flow magnitude F̂ ∈ [0, 1] (zeros without `t−1`).
    pub motion: Vec<f32>,
    /// Min-max normalised optical-flow magnitude frozen render → ground truth.
    pub scene_motion: Option<Vec<f32>>,
    pub mask: Option<Vec<u8>>,
    /// Blend weight on dynamic Gaussians per pixel (see [`Evaluator::dynamic_mask`]), when
    /// the caller asked for it.
    pub dynamic: Option<Vec<f32>>,
}

/// One evaluated view: camera and time, the predecessor time for the displacement flow, and
/// the test frame when the view is scored against one.
#[derive(Clone, Copy)]
struct Shot<'a> {
    cam: &'a Camera,
    t: f32,
    prev: Option<f32>,
    frame: Option<&'a GpuFrame>,
}

impl<'a> Shot<'a> {
    /// Test frame `f` at its view and time, with the displacement flow since `prev`.
    fn of_frame(f: &'a GpuFrame, prev: Option<f32>) -> Self {
        Shot {
            cam: &f.camera,
            t: f.time,
            prev,
            frame: Some(f),
        }
    }
}

/// Scratch of evaluation, sized like training's (one image size, the Gaussian budget).
pub struct Evaluator {
    deform: DeformPass,
    render: RenderPass,
    loss: PhotoLoss,
    /// The render at (v, D(t)) kept while the same buffers draw the frozen (v, D(t−1)).
    full: Buffer,
    dispflow: DispFlow,
    delta: Buffer,
    norm: MotionNorm,
    norm_bufs: NormBuffers,
    metrics: MotionMetrics,
    metric_bufs: MetricBuffers,
    flow: TvL1Flow,
    flow_scratch: FlowScratch,
    scene_flow: Buffer,
    scene_norm: NormBuffers,
    scene_metric_bufs: MetricBuffers,
    /// Overflow of the full render (slot 0) and the frozen one (slot 1).
    watch: OverflowWatch,
    lambda_ssim: f32,
    /// The colour the ground truth was composited on (the dataset's background): what a
    /// render must show where nothing is drawn for the scores to compare like with like.
    background: [f32; 3],
}

impl Evaluator {
    pub fn new(
        gpu: &Gpu,
        raster: Rc<Rasterizer>,
        mlp: &MlpConfig,
        field: Option<&crate::model::nodes::FieldConfig>,
        s: &StepSizes,
        flow: FlowConfig,
        lambda_ssim: f32,
    ) -> Result<Self> {
        let (w, h) = (s.width, s.height);
        let norm = MotionNorm::new(gpu)?;
        let metrics = MotionMetrics::new(gpu)?;
        let flow = TvL1Flow::new(gpu, flow)?;
        Ok(Evaluator {
            deform: DeformPass::new(gpu, mlp, field, s, 2, false)?,
            render: RenderPass::new(raster, gpu, s, 3)?,
            loss: PhotoLoss::new(gpu, s)?,
            full: gpu.buffer("eval full render", s.pixels() * 16)?,
            dispflow: DispFlow::new(gpu)?,
            delta: gpu.buffer("eval displacement", s.capacity as u64 * row::VEC3 * 4)?,
            norm_bufs: norm.buffers(gpu, w, h, 3)?,
            metric_bufs: metrics.buffers(gpu, w, h)?,
            flow_scratch: flow.scratch(gpu, w, h)?,
            flow,
            scene_flow: gpu.buffer("eval scene flow", s.pixels() * 8)?,
            scene_norm: norm.buffers(gpu, w, h, 2)?,
            scene_metric_bufs: metrics.buffers(gpu, w, h)?,
            norm,
            metrics,
            watch: OverflowWatch::new(gpu, "eval overflow flags", 2)?,
            lambda_ssim,
            background: [0.0; 3],
        })
    }

    /// Renders on `background` (the colour the dataset's images were composited on; black
    /// until set).
    pub fn on_background(mut self, background: [f32; 3]) -> Self {
        self.background = background;
        self
    }

    /// Evaluates test frame `f` at its view and time (on the dataset's background): photometric
    /// values; with a predecessor time `t−1`, the displacement flow δ = dx(t) − dx(t−1) splatted with
    /// the weights of the render at (v, t), min-max normalised, scored against the mask (AP)
    /// and by DRC against the frozen render (v, D(t−1)), plus the optical flow frozen → ground
    /// truth scored the same way.
    pub fn frame(
        &mut self,
        gpu: &Gpu,
        model: &Model,
        view: ModelView,
        f: &GpuFrame,
        want_images: bool,
    ) -> Result<FrameEval> {
        self.evaluate(
            gpu,
            model,
            view,
            Shot::of_frame(f, f.prev_time),
            want_images,
        )
    }

    /// Photometric scores of test frame `f` alone (PSNR, SSIM, L1 and the region PSNRs; no
    /// motion metrics, no pictures).
    pub fn photometric(
        &mut self,
        gpu: &Gpu,
        model: &Model,
        view: ModelView,
        f: &GpuFrame,
    ) -> Result<FrameEval> {
        self.evaluate(gpu, model, view, Shot::of_frame(f, None), false)
    }

    /// Renders `(camera, t)` (on the dataset's background) and, with `prev`, the displacement flow since
    /// `prev` (no scores: no ground truth).
    #[allow(clippy::too_many_arguments)] // the view's parts, each one named
    pub fn view(
        &mut self,
        gpu: &Gpu,
        model: &Model,
        view: ModelView,
        camera: &Camera,
        t: f32,
        prev: Option<f32>,
    ) -> Result<FrameEval> {
        let v = Shot {
            cam: camera,
            t,
            prev,
            frame: None,
        };
        self.evaluate(gpu, model, view, v, true)
    }

    /// The dynamic mask of view `(camera, t)`: each pixel's blend weight on dynamic Gaussians
    /// ([H·W], 0 where only static Gaussians are seen, the coverage where the model is dense).
    /// Transients move (by their velocity) and count as dynamic.
    pub fn dynamic_mask(
        &mut self,
        gpu: &Gpu,
        model: &Model,
        view: ModelView,
        camera: &Camera,
        t: f32,
    ) -> Result<Vec<f32>> {
        let g = &model.gaussians;
        let n = g.n as usize;
        let mut flags = match model.dynamic.download(gpu, g.canonical_rows().len())? {
            Some(s) => s.flags,
            None => vec![1; n],
        };
        flags.resize(n, 1);
        let feats: Vec<[f32; 3]> = flags.iter().map(|&f| [f as f32; 3]).collect();
        let f = self.blend_features(gpu, model, view, camera, t, &feats)?;
        Ok(f.chunks_exact(3).map(|c| c[0]).collect())
    }

    /// The displacement EPE probe of test frame `f` ([`epe`]): `None` unless the frame has a
    /// mask and ground-truth flow towards a next time.
    pub fn motion_probe(
        &mut self,
        gpu: &Gpu,
        model: &Model,
        view: ModelView,
        f: &GpuFrame,
    ) -> Result<Option<epe::MotionProbe>> {
        let (Some((t_next, gt)), Some((_, mask))) = (&f.next_flow, &f.mask) else {
            return Ok(None);
        };
        let n = model.gaussians.n as usize;
        let mut rec = Recorder::new(gpu)?;
        let active = view.deform_active;
        self.deform
            .forward(&mut rec, model, Slot::T1, f.time, active);
        self.deform
            .forward(&mut rec, model, Slot::T2, *t_next, active);
        rec.finish()?;
        let a: Vec<[f32; 3]> = gpu.read(self.deform.drawn(Slot::T1)[0])?;
        let b: Vec<[f32; 3]> = gpu.read(self.deform.drawn(Slot::T2)[0])?;
        let motion = epe::projected_motion(&f.camera, &a[..n], &b[..n]);
        let blended = self.blend_features(gpu, model, view, &f.camera, f.time, &motion)?;
        Ok(Some(epe::MotionProbe {
            epe: epe::masked_epe(&blended, gt, mask),
            gt_len: epe::masked_len(gt, mask),
            p50: epe::motion_quantile(&motion, 0.5),
            p99: epe::motion_quantile(&motion, 0.99),
        }))
    }

    /// Renders `(camera, t)` with per-Gaussian 3-channel `feats` and returns the blended
    /// features ([H·W] × 3): Σ_i w_i f_i with the render's own weights.
    #[allow(clippy::too_many_arguments)] // the view's parts, each one named
    pub fn blend_features(
        &mut self,
        gpu: &Gpu,
        model: &Model,
        view: ModelView,
        camera: &Camera,
        t: f32,
        feats: &[[f32; 3]],
    ) -> Result<Vec<f32>> {
        let n = model.gaussians.n as usize;
        assert_eq!(feats.len(), n, "one feature row per Gaussian");
        if n > 0 {
            gpu.upload(
                self.delta.elems::<f32>(0, 3 * n as u64),
                bytemuck::cast_slice::<[f32; 3], f32>(feats),
            )?;
        }
        let opts = RenderOpts {
            background: self.background,
            alpha_max: ALPHA_MAX,
            abs_grad: false,
            detach_feature_weights: false,
        };
        loop {
            let mut rec = Recorder::new(gpu)?;
            self.deform
                .forward(&mut rec, model, Slot::T1, t, view.deform_active);
            let mut splats = self.deform.splats(model, Slot::T1, view.sh_degree);
            splats.features = Some((self.delta.all(), 3));
            self.render.forward(&mut rec, camera, &splats, &opts);
            self.watch.record(&mut rec, 0, &self.render);
            self.watch.publish(&mut rec);
            rec.finish()?;
            let o = self.watch.read(0, "displacement-flow render")?;
            if o.overflowed {
                self.render.grow(gpu, o.needed)?;
                continue;
            }
            let px = camera.width as u64 * camera.height as u64;
            return gpu.read(self.render.features().buf.elems::<f32>(0, 3 * px));
        }
    }

    /// The render at (v, D(t)) of the last evaluated view, [H·W] RGBA.
    pub fn last_render(&self) -> BufSlice<'_> {
        self.full.all()
    }

    /// The Gaussians as drawn at time `t` in the canonical layout: a standard 3DGS model of
    /// that instant (log of |scale|: the rasteriser squares it).
    pub fn deformed_gaussians(
        &mut self,
        gpu: &Gpu,
        model: &Model,
        view: ModelView,
        t: f32,
    ) -> Result<HostGaussians> {
        let mut rec = Recorder::new(gpu)?;
        self.deform
            .forward(&mut rec, model, Slot::T1, t, view.deform_active);
        rec.finish()?;
        let mut g = model.gaussians.download(gpu)?;
        let n = model.gaussians.n as usize;
        let [m, s, q] = self.deform.drawn(Slot::T1);
        let means: Vec<[f32; 3]> = gpu.read(m)?;
        let scales: Vec<[f32; 3]> = gpu.read(s)?;
        let quats: Vec<[f32; 4]> = gpu.read(q)?;
        g.means = means[..n].to_vec();
        g.log_scales = scales[..n]
            .iter()
            .map(|s| s.map(|v| v.abs().max(1e-12).ln()))
            .collect();
        g.quats = quats[..n]
            .iter()
            .map(|q| {
                let l = q.iter().map(|v| v * v).sum::<f32>().sqrt();
                if l > 1e-12 {
                    q.map(|v| v / l)
                } else {
                    [1.0, 0.0, 0.0, 0.0]
                }
            })
            .collect();
        if Population::any_scales_opacity(&model.gaussians) {
            // Transients as they are at `t`: opacity times the temporal weight, culled ones
            // dropped (a standard model of that instant has no time).
            let w: Vec<f32> =
                gpu.read(self.deform.opacity_scale(Slot::T1, Rows::new(0, n as u32)))?;
            let keep: Vec<usize> = (0..n).filter(|&i| w[i] > 0.0).collect();
            let r = 3 * (g.sh_coeffs as usize - 1);
            let sig = |l: f32| 1.0 / (1.0 + (-l).exp());
            g = HostGaussians {
                sh_coeffs: g.sh_coeffs,
                means: keep.iter().map(|&i| g.means[i]).collect(),
                log_scales: keep.iter().map(|&i| g.log_scales[i]).collect(),
                quats: keep.iter().map(|&i| g.quats[i]).collect(),
                opacity: keep
                    .iter()
                    .map(|&i| {
                        let p = (sig(g.opacity[i]) * w[i]).clamp(1e-7, 1.0 - 1e-7);
                        (p / (1.0 - p)).ln()
                    })
                    .collect(),
                sh_dc: keep.iter().map(|&i| g.sh_dc[i]).collect(),
                sh_rest: keep
                    .iter()
                    .flat_map(|&i| g.sh_rest[i * r..(i + 1) * r].to_vec())
                    .collect(),
                ..Default::default()
            };
        }
        Ok(g)
    }

    /// Records everything for one view and reads its scores; re-runs with grown buffers when a
    /// render overflowed.
    fn evaluate(
        &mut self,
        gpu: &Gpu,
        model: &Model,
        view: ModelView,
        v: Shot<'_>,
        want_images: bool,
    ) -> Result<FrameEval> {
        let frozen = v.prev.is_some() && v.frame.is_some();
        loop {
            let mut rec = Recorder::new(gpu)?;
            self.record(&mut rec, model, view, v);
            self.watch.publish(&mut rec);
            rec.finish()?;
            let full = self.watch.read(0, "evaluation render")?;
            let froz = if frozen {
                Some(self.watch.read(1, "evaluation render (frozen)")?)
            } else {
                None
            };
            if full.overflowed || froz.is_some_and(|o| o.overflowed) {
                let need = full.needed.max(froz.map_or(0, |o| o.needed));
                self.render.grow(gpu, need)?;
                continue;
            }
            return self.scores(gpu, v, want_images);
        }
    }

    fn record(&mut self, rec: &mut Recorder<'_>, model: &Model, view: ModelView, v: Shot<'_>) {
        let Shot {
            cam,
            t,
            prev,
            frame,
        } = v;
        let g = &model.gaussians;
        let opts = RenderOpts {
            background: self.background,
            alpha_max: ALPHA_MAX,
            abs_grad: false,
            detach_feature_weights: false,
        };
        let active = view.deform_active;
        self.deform.forward(rec, model, Slot::T1, t, active);
        let mut splats = self.deform.splats(model, Slot::T1, view.sh_degree);
        if let Some(tp) = prev {
            if active {
                self.deform.mlp_forward(rec, model, Slot::T2, tp);
                let (a, b) = (self.deform.output(Slot::T2), self.deform.output(Slot::T1));
                self.dispflow.displacement(rec, g.n, a, b, self.delta.all());
            } else {
                // No deformation yet: D ≡ 0 at every time, δ = 0.
                rec.fill(self.delta.all(), 0);
            }
            // Transients move by v·(t − t_prev) whatever the deformation does.
            self.deform
                .transient_displacement(rec, model, (tp, t), self.delta.all());
            self.deform.apply(rec, model, Slot::T2, tp, active);
            splats.features = Some((self.delta.all(), 3));
        }
        self.render.forward(rec, cam, &splats, &opts);
        self.watch.record(rec, 0, &self.render);
        if let Some(f) = frame {
            self.loss
                .record(rec, &self.render, f.target.all(), self.lambda_ssim);
        }
        let bytes = cam.width as u64 * cam.height as u64 * 16;
        rec.copy(
            self.render.bufs.out_rgba.slice(0, bytes),
            self.full.slice(0, bytes),
        );
        if prev.is_some() {
            let feat = self.render.features();
            let cfg = NormConfig::default();
            self.norm.record(rec, &mut self.norm_bufs, feat, cfg);
            if let Some((mask, _)) = frame.and_then(|f| f.mask.as_ref()) {
                let m_hat = self.norm_bufs.m_hat();
                self.metrics
                    .record_ap(rec, &self.metric_bufs, m_hat, mask.all());
            }
        }
        let (Some(f), Some(_)) = (frame, prev) else {
            return;
        };
        // The frozen render: the same view with the deformation of t−1.
        let frozen = self.deform.splats(model, Slot::T2, view.sh_degree);
        self.render.forward(rec, cam, &frozen, &opts);
        self.watch.record(rec, 1, &self.render);
        self.metrics.record_drc(
            rec,
            &self.metric_bufs,
            self.norm_bufs.m_hat(),
            self.render.rgba(),
            self.full.all(),
            f.target.all(),
        );
        let sf = self.scene_flow.all();
        self.flow.record(
            rec,
            &self.flow_scratch,
            self.render.rgba(),
            f.target.all(),
            sf,
        );
        self.norm
            .record(rec, &mut self.scene_norm, sf, NormConfig::default());
        if let Some((mask, _)) = &f.mask {
            let m_hat = self.scene_norm.m_hat();
            self.metrics
                .record_ap(rec, &self.scene_metric_bufs, m_hat, mask.all());
        }
    }

    fn scores(&self, gpu: &Gpu, v: Shot<'_>, want_images: bool) -> Result<FrameEval> {
        let Shot {
            cam,
            t,
            prev,
            frame,
        } = v;
        let px = cam.width as u64 * cam.height as u64;
        let values = match frame {
            Some(_) => self.loss.values(),
            None => LossValues::new(f64::NAN, f64::NAN, f64::NAN, self.lambda_ssim as f64),
        };
        let mask = frame.and_then(|f| f.mask.as_ref());
        let ap = match (mask, prev) {
            (Some(_), Some(_)) => self.metric_bufs.ap(gpu)?,
            _ => None,
        };
        let (drc, flow_ap) = match frame.zip(prev) {
            Some(_) => (
                Some(self.metric_bufs.drc(gpu)?),
                match mask {
                    Some(_) => self.scene_metric_bufs.ap(gpu)?,
                    None => None,
                },
            ),
            None => (None, None),
        };
        let has_mask = mask.is_some_and(|m| m.1.iter().any(|&v| v != 0));
        type Pair = (Vec<[f32; 4]>, Vec<[f32; 4]>);
        let host = |want: bool| -> Result<Pair> {
            if !want {
                return Ok((Vec::new(), Vec::new()));
            }
            let render: Vec<[f32; 4]> = gpu.read(self.full.elems::<[f32; 4]>(0, px))?;
            let gt: Vec<[f32; 4]> = match frame {
                Some(f) => gpu.read(f.target.elems::<[f32; 4]>(0, px))?,
                None => Vec::new(),
            };
            Ok((render, gt))
        };
        let (render, gt) = host(want_images || has_mask)?;
        let regions = match mask {
            Some((_, m)) if has_mask => regions::region_psnr(
                &render,
                &gt,
                m,
                cam.width,
                cam.height,
                regions::MASK_DILATE_PX,
            ),
            _ => regions::RegionPsnr::default(),
        };
        let images = if want_images {
            let n = px as usize;
            let motion: Vec<f32> = match prev {
                Some(_) => gpu.read(self.norm_bufs.m_hat())?,
                None => vec![0.0; n],
            };
            let scene_motion = match frame.zip(prev) {
                Some(_) => {
                    let v: Vec<f32> = gpu.read(self.scene_norm.m_hat())?;
                    Some(v[..n].to_vec())
                }
                None => None,
            };
            Some(FrameImages {
                width: cam.width,
                height: cam.height,
                render,
                gt,
                motion: motion[..n].to_vec(),
                scene_motion,
                mask: mask.map(|m| m.1.clone()),
                dynamic: None,
            })
        } else {
            None
        };
        Ok(FrameEval {
            id: frame.map_or_else(|| format!("t{t:.4}"), |f| f.id.clone()),
            time: t,
            psnr: values.psnr,
            ssim: values.ssim,
            l1: values.l1,
            has_mask,
            dynamic_psnr: regions.dynamic,
            static_psnr: regions.static_,
            dynamic_share: regions.dynamic.and(regions.dynamic_share),
            ap,
            drc,
            flow_ap,
            lpips: None,
            images,
        })
    }
}
