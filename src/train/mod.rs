//! Training: the Deformable-3DGS step as a list of kernel calls over explicit buffers, the
//! recipe around it (schedules, densification, SH growth, time noise), evaluation and outputs.

pub mod checkpoint;
pub mod cli;
pub mod config;
pub mod eval;

use std::path::Path;

use crate::data::{Dataset, Frame};
use crate::error::{Error, Result};
use crate::kernels::adam::{Adam, AdamBuffers, AdamGroup};
use crate::kernels::deform::{Canonical, DeformApply, Drawn};
use crate::kernels::densify::{Densifier, DensifyBuffers, DensifySettings, GaussianBuffers};
use crate::kernels::dispflow::DispFlow;
use crate::kernels::flow::{FlowConfig, FlowEstimator, FlowScratch, TvL1Flow};
use crate::kernels::loss::{LossBuffers, LossValues, PhotometricLoss};
use crate::kernels::metrics::{MetricBuffers, MotionMetrics};
use crate::kernels::mlp::{Mlp, MlpBuffers, MlpTime};
use crate::kernels::motion::{MotionNorm, NormBuffers, NormConfig};
use crate::kernels::raster::{
    Camera, OutputGrads, RasterBuffers, RasterSize, Rasterizer, RenderOpts, SplatInputs,
};
use crate::model::deform::{MlpConfig, TimeEncoding};
use crate::model::gaussians::{GaussianLayout, HostGaussians, Section};
use crate::model::optim::{AdamHyper, ExpLr};
use crate::vk::{Buffer, Gpu, Recorder, Timings};
use checkpoint::Checkpoint;
use config::{Background, MotionOrder, TrainConfig};

/// A frame on the GPU: raster camera, time and the target image as [H·W] vec4.
pub struct GpuFrame {
    pub id: String,
    pub camera: Camera,
    pub time: f32,
    pub target: Buffer,
    /// Motion mask as [H·W] u32 (moving = 1) with its host copy, when the dataset has one.
    pub mask: Option<(Buffer, Vec<u8>)>,
    /// The latest earlier time of any frame in the dataset (the MMAP/DRC predecessor `t−1`).
    pub prev_time: Option<f32>,
    /// Ground-truth scene flow [H·W] vec2 (training frames, oracle motion flow only).
    pub gt_flow: Option<Buffer>,
}

/// Converts a loaded camera (OpenCV, glam) to the rasteriser's.
pub fn raster_camera(c: &crate::data::camera::Camera, near: f32) -> Camera {
    let r = c.rotation;
    Camera {
        rot: [
            r.row(0).to_array(),
            r.row(1).to_array(),
            r.row(2).to_array(),
        ],
        trans: c.translation.to_array(),
        fx: c.fx,
        fy: c.fy,
        cx: c.cx,
        cy: c.cy,
        width: c.width,
        height: c.height,
        near,
    }
}

/// Uploads a frame; `times` (of every frame) give its predecessor. Only evaluation frames
/// (`with_mask`) carry their motion mask: training never reads it.
fn upload_frame(
    gpu: &Gpu,
    f: &Frame,
    near: f32,
    times: &[f32],
    with_mask: bool,
) -> Result<GpuFrame> {
    let px = (f.image.width * f.image.height) as usize;
    if f.image.data.len() != 3 * px {
        return Err(Error::Invalid(format!(
            "{}: image holds {} values, expected {}",
            f.image_path.display(),
            f.image.data.len(),
            3 * px
        )));
    }
    let rgba: Vec<[f32; 4]> = f
        .image
        .data
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2], 1.0])
        .collect();
    let mask = match f.mask.as_ref().filter(|_| with_mask) {
        Some(m) if m.len() == px => {
            let words: Vec<u32> = m.iter().map(|&v| (v != 0) as u32).collect();
            Some((
                gpu.buffer_from(&format!("mask {}", f.id), &words)?,
                m.clone(),
            ))
        }
        Some(m) if !m.is_empty() => {
            return Err(Error::Invalid(format!(
                "{}: motion mask holds {} values, expected {px}",
                f.image_path.display(),
                m.len()
            )))
        }
        _ => None,
    };
    Ok(GpuFrame {
        id: f.id.clone(),
        camera: raster_camera(&f.camera, near),
        time: f.time,
        target: gpu.buffer_from(&format!("target {}", f.id), &rgba)?,
        mask,
        gt_flow: None,
        prev_time: times
            .iter()
            .copied()
            .filter(|&t| t < f.time)
            .reduce(f32::max),
    })
}

/// 3DGS's camera extent: 1.1 × the largest distance of a camera centre from their mean.
pub fn camera_extent(frames: &[Frame]) -> f32 {
    let centres: Vec<glam::Vec3> = frames.iter().map(|f| f.camera.centre()).collect();
    let mean = centres.iter().copied().sum::<glam::Vec3>() / centres.len().max(1) as f32;
    let r = centres
        .iter()
        .map(|c| c.distance(mean))
        .fold(0.0f32, f32::max);
    1.1 * r.max(1e-3)
}

/// Mean colour of each point over up to 8 evenly spaced views it projects into (grey if none).
pub fn colors_from_views(points: &[[f32; 3]], frames: &[Frame]) -> Vec<[f32; 3]> {
    let k = frames.len().clamp(1, 8);
    let views: Vec<&Frame> = (0..k)
        .filter_map(|i| frames.get(i * frames.len() / k))
        .collect();
    points
        .iter()
        .map(|p| {
            let (mut sum, mut n) = ([0.0f32; 3], 0);
            for f in &views {
                let Some((px, _)) = f.camera.project(glam::Vec3::from_array(*p)) else {
                    continue;
                };
                if !f.camera.contains(px) || f.image.data.is_empty() {
                    continue;
                }
                let (x, y) = (px.x as usize, px.y as usize);
                let o = 3 * (y * f.image.width as usize + x);
                for (c, sc) in sum.iter_mut().enumerate() {
                    *sc += f.image.data[o + c];
                }
                n += 1;
            }
            if n == 0 {
                [0.5; 3]
            } else {
                sum.map(|s| s / n as f32)
            }
        })
        .collect()
}

/// SplitMix-style hash → uniform in (0, 1), for per-iteration choices that must not depend on
/// how many random numbers were drawn before (so a resumed run makes the same choices).
fn hash_uniform(seed: u64, a: u64, b: u64) -> f64 {
    let mut z =
        seed ^ a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
}

/// Training frame of 1-based `iteration`: a fresh shuffle of all frames every epoch, as 3DGS
/// draws cameras, but seeded by (seed, epoch) so it depends on the iteration alone.
pub fn frame_for_iteration(seed: u64, iteration: u32, frames: usize) -> usize {
    let i = (iteration as usize).saturating_sub(1);
    let (epoch, k) = (i / frames, i % frames);
    let mut perm: Vec<usize> = (0..frames).collect();
    for j in (1..frames).rev() {
        let r = (hash_uniform(seed, epoch as u64, j as u64) * (j + 1) as f64) as usize;
        perm.swap(j, r.min(j));
    }
    perm[k]
}

/// Numbers reported per logged step.
#[derive(Clone, Debug, Default)]
pub struct StepLog {
    pub iteration: u32,
    pub loss: LossValues,
    pub num_gaussians: u32,
    pub timings: Timings,
}

impl Default for LossValues {
    fn default() -> Self {
        LossValues::new(0.0, 0.0, 0.0, 0.2)
    }
}

/// Buffers of the DispFlow-GS motion term, allocated only when the motion weight is > 0.
struct MotionState {
    dispflow: DispFlow,
    mlp_bufs2: MlpBuffers,
    deform_out2: Buffer,
    d_deform2: Buffer,
    delta: Buffer,
    drawn2: [Buffer; 3],
    inter: RasterBuffers,
    /// Zero colour gradients of the intermediate render (reverse order: it is supervised
    /// through its displacement-flow channels only).
    zero_rgba: Option<Buffer>,
    flow: TvL1Flow,
    flow_scratch: FlowScratch,
    scene_flow: Buffer,
    norm: MotionNorm,
    norm_disp: NormBuffers,
    norm_scene: NormBuffers,
    flags: Buffer,
    d_mhat: Buffer,
    d_feat: Buffer,
    sums: Buffer,
    norm_cfg: NormConfig,
    /// Training frames sorted by time (indices into `frames`) and each frame's rank in it.
    by_time: Vec<usize>,
    rank: Vec<usize>,
}

/// Buffers of evaluation (renders with the displacement flow, the frozen render, motion
/// metrics), allocated on the first `evaluate`.
struct EvalState {
    bufs: RasterBuffers,
    deform_prev: Buffer,
    delta: Buffer,
    drawn_prev: [Buffer; 3],
    full: Buffer,
    dispflow: DispFlow,
    norm: MotionNorm,
    norm_bufs: NormBuffers,
    metrics: MotionMetrics,
    metric_bufs: MetricBuffers,
    flags: Buffer,
    /// Optical flow frozen render (v, t−1) → ground truth (v, t): what the motion loss would
    /// see, scored like the displacement flow (how good the supervision signal is).
    flow: TvL1Flow,
    flow_scratch: FlowScratch,
    scene_flow: Buffer,
    scene_norm: NormBuffers,
    scene_metric_bufs: MetricBuffers,
}

/// One evaluated validation frame.
#[derive(Clone, Debug)]
pub struct FrameEval {
    pub id: String,
    pub time: f32,
    /// Photometric values of the render at the frame's view and time.
    pub values: LossValues,
    /// Whether the frame has a motion mask with at least one moving pixel.
    pub has_mask: bool,
    /// AP of the normalised displacement flow against the mask (`None`: no mask, an empty
    /// mask, or no earlier time in the dataset).
    pub ap: Option<f64>,
    /// DRC (`None` without an earlier time).
    pub drc: Option<f64>,
    /// AP of the optical-flow magnitude (frozen render → ground truth) against the mask: the
    /// quality of the signal the motion loss learns from (`None` like `ap`).
    pub scene_ap: Option<f64>,
    pub images: Option<FrameImages>,
}

/// Pictures of one evaluated frame (host copies).
#[derive(Clone, Debug)]
pub struct FrameImages {
    pub width: u32,
    pub height: u32,
    pub render: Vec<[f32; 4]>,
    pub gt: Vec<[f32; 4]>,
    /// Min-max normalised displacement-flow magnitude F̂ ∈ [0, 1] (zeros without `t−1`).
    pub motion: Vec<f32>,
    /// Min-max normalised optical-flow magnitude frozen render → ground truth (evaluation
    /// frames with `t−1` only).
    pub scene_motion: Option<Vec<f32>>,
    pub mask: Option<Vec<u8>>,
}

/// Everything the training step reads and writes, allocated once for the Gaussian budget.
pub struct Trainer<'g> {
    pub gpu: &'g Gpu,
    pub cfg: TrainConfig,
    pub mlp_cfg: MlpConfig,
    raster: Rasterizer,
    deform: DeformApply,
    loss: PhotometricLoss,
    mlp: Mlp,
    adam: Adam,
    densifier: Densifier,
    pub layout: GaussianLayout,
    /// Live Gaussians (rows 0..n of every section).
    pub n: u32,
    pub params: Buffer,
    grads: Buffer,
    m: Buffer,
    v: Buffer,
    /// Densification writes the next generation here; the two are swapped after.
    next: [Buffer; 3],
    densify_bufs: DensifyBuffers,
    pub mlp_params: Buffer,
    mlp_grads: Buffer,
    mlp_m: Buffer,
    mlp_v: Buffer,
    mlp_bufs: MlpBuffers,
    drawn: [Buffer; 3],
    d_drawn_dummy: Buffer,
    deform_out: Buffer,
    d_deform: Buffer,
    pub raster_bufs: RasterBuffers,
    loss_bufs: LossBuffers,
    d_render: Buffer,
    zero_depth: Buffer,
    /// Overflow flag and needed intersection count, copied here at the end of every step.
    step_flags: Buffer,
    pub frames: Vec<GpuFrame>,
    pub val: Vec<GpuFrame>,
    pub extent: f32,
    time_interval: f32,
    time_noise: bool,
    motion: Option<MotionState>,
    eval: Option<EvalState>,
    /// Iterations completed.
    pub iteration: u32,
}

impl<'g> Trainer<'g> {
    /// Allocates everything for `cfg.densify.budget` Gaussians and initialises them from the
    /// dataset's points. Fails with a clear error before any training on a bad dataset.
    pub fn new(gpu: &'g Gpu, cfg: &TrainConfig, data: &Dataset) -> Result<Self> {
        cfg.validate()?;
        if data.train.is_empty() {
            return Err(Error::Invalid(format!(
                "{}: the dataset has no training frames",
                data.root.display()
            )));
        }
        let (w, h) = (data.train[0].camera.width, data.train[0].camera.height);
        if let Some(f) = data
            .frames()
            .find(|f| (f.camera.width, f.camera.height) != (w, h))
        {
            return Err(Error::Invalid(format!(
                "{}: frame {} is {}×{}, the first training frame {w}×{h}: all frames must share one size",
                data.root.display(),
                f.id,
                f.camera.width,
                f.camera.height
            )));
        }
        let blender = matches!(data.format, crate::data::Format::Blender);
        let base = if blender {
            MlpConfig::synthetic()
        } else {
            MlpConfig::real()
        };
        let time = match base.time {
            TimeEncoding::TimeNet { freqs, out, .. } => TimeEncoding::TimeNet {
                freqs,
                hidden: cfg.mlp_width,
                out,
            },
            t => t,
        };
        let mlp_cfg = MlpConfig {
            depth: cfg.mlp_depth,
            width: cfg.mlp_width,
            skip: (cfg.mlp_depth >= 3)
                .then_some(cfg.mlp_depth / 2)
                .filter(|&s| s + 1 < cfg.mlp_depth),
            x_freqs: base.x_freqs,
            time,
        };
        let near = data.near_far.map_or(0.01, |(n, _)| (0.5 * n).max(1e-3));
        let times: Vec<f32> = data.frames().map(|f| f.time).collect();
        let frames = data
            .train
            .iter()
            .map(|f| upload_frame(gpu, f, near, &times, false))
            .collect::<Result<Vec<_>>>()?;
        let val = data
            .val
            .iter()
            .map(|f| upload_frame(gpu, f, near, &times, true))
            .collect::<Result<Vec<_>>>()?;
        let mut frames = frames;
        if cfg.motion_weight > 0.0 && cfg.motion_flow == config::MotionFlow::Oracle {
            if cfg.motion_order == MotionOrder::Reverse {
                return Err(Error::Invalid(
                    "config field motion_flow: oracle gives the flow under the frame's own view                      (direct order); use motion_order = direct"
                        .into(),
                ));
            }
            for (g, f) in frames.iter_mut().zip(&data.train) {
                let px = (f.camera.width * f.camera.height) as usize;
                let flow = f.flow.as_ref().filter(|v| v.len() == 2 * px).ok_or_else(|| {
                    Error::Invalid(format!(
                        "config field motion_flow: oracle needs ground-truth scene flow ({} has none; synthetic scenes from `dispflow-vk data gen` do)",
                        f.image_path.display()
                    ))
                })?;
                g.gt_flow = Some(gpu.buffer_from(&format!("gt flow {}", f.id), flow)?);
            }
        }

        let points: Vec<[f32; 3]> = data.points.positions.iter().map(|p| p.to_array()).collect();
        let mut host =
            HostGaussians::from_points(&points, data.points.colors.as_deref(), cfg.sh_degree)?;
        let budget = cfg.densify.budget;
        if host.len() > budget as usize {
            // Keep an even subsample: the budget bounds every buffer.
            let step = host.len() as f64 / budget as f64;
            let keep: Vec<usize> = (0..budget as usize)
                .map(|i| (i as f64 * step) as usize)
                .collect();
            host = subsample(&host, &keep);
        }
        let layout = GaussianLayout::new(budget, cfg.sh_degree);
        let floats = layout.total_floats() * 4;
        let mk = |name: &str| gpu.buffer(name, floats);
        let params = mk("gaussian params")?;
        host.upload(gpu, &layout, &params)?;
        let m = mk("gaussian adam m")?;
        let v = mk("gaussian adam v")?;
        let mut rec = Recorder::new(gpu)?;
        rec.fill(m.all(), 0);
        rec.fill(v.all(), 0);
        rec.finish()?;

        let mlp = Mlp::new(gpu, &mlp_cfg)?;
        let mut mlp_init = mlp.layout.init_params(cfg.seed);
        if cfg.zero_deform_head {
            // D starts at exactly 0, continuing the warm-up's static model instead of jolting
            // every Gaussian by the random head (PyTorch-init displacements ~0.1–0.5 scene units,
            // and ds ≫ exp(s) inflates every Gaussian). The head still gets gradients at once.
            let h = mlp.layout.head();
            mlp_init[h.w_off..h.w_off + h.fan_in * h.fan_out].fill(0.0);
            mlp_init[h.b_off..h.b_off + h.fan_out].fill(0.0);
        }
        let mlp_params = gpu.buffer_from("mlp params", &mlp_init)?;
        let zeros = vec![0f32; mlp_init.len()];
        let cap = budget as u64;
        let raster = Rasterizer::new(gpu)?;
        let size = RasterSize {
            max_gaussians: budget,
            width: w,
            height: h,
            sh_coeffs: layout.sh_coeffs,
            feature_dims: 0,
            isect_capacity: (4 * host.len() as u32).max(1 << 16),
        };
        let motion_on = cfg.motion_weight > 0.0;
        let reverse = cfg.motion_order == MotionOrder::Reverse;
        // The displacement flow needs 3 feature channels in the render that splats it: the
        // photometric one (direct order) or the intermediate (reverse); none without motion.
        let size = RasterSize {
            feature_dims: if motion_on && !reverse { 3 } else { 0 },
            ..size
        };
        let raster_bufs = raster.buffers(gpu, &size)?;
        let loss = PhotometricLoss::new(gpu)?;
        let loss_bufs = loss.buffers(gpu, w, h)?;
        let densifier = Densifier::new(gpu)?;
        let densify_bufs = densifier.buffers(gpu, budget)?;
        let n = host.len() as u32;
        let motion = if motion_on {
            let px = (w * h) as u64;
            let mut by_time: Vec<usize> = (0..frames.len()).collect();
            by_time.sort_by(|&a, &b| frames[a].time.total_cmp(&frames[b].time).then(a.cmp(&b)));
            let mut rank = vec![0; frames.len()];
            for (r, &i) in by_time.iter().enumerate() {
                rank[i] = r;
            }
            let flow = TvL1Flow::new(gpu, FlowConfig::preset(&cfg.flow_preset)?)?;
            let norm = MotionNorm::new(gpu)?;
            let ncfg = NormConfig {
                detach_stats: cfg.motion_norm_grad == config::NormGrad::Detached,
                ..NormConfig::new(cfg.motion_normalize, 1e-6)?
            };
            let norm_disp = norm.buffers(gpu, w, h, 3)?;
            let norm_scene = norm.buffers(gpu, w, h, 2)?;
            Some(MotionState {
                dispflow: DispFlow::new(gpu)?,
                mlp_bufs2: mlp.buffers(gpu, budget)?,
                deform_out2: gpu.buffer("deformation t2", cap * 40)?,
                d_deform2: gpu.buffer("deformation grads t2", cap * 40)?,
                delta: gpu.buffer("displacement", cap * 12)?,
                drawn2: [
                    gpu.buffer("drawn means t2", cap * 12)?,
                    gpu.buffer("drawn scales t2", cap * 12)?,
                    gpu.buffer("drawn quats t2", cap * 16)?,
                ],
                inter: raster.buffers(
                    gpu,
                    &RasterSize {
                        feature_dims: if reverse { 3 } else { 0 },
                        ..size
                    },
                )?,
                zero_rgba: if reverse {
                    Some(gpu.buffer_from("zero rgba grads", &vec![[0f32; 4]; px as usize])?)
                } else {
                    None
                },
                flow_scratch: flow.scratch(gpu, w, h)?,
                flow,
                scene_flow: gpu.buffer("scene flow", px * 8)?,
                norm,
                norm_disp,
                norm_scene,
                flags: gpu.buffer("motion degenerate flags", 16)?,
                d_mhat: gpu.buffer("d normalised displacement magnitude", px * 4)?,
                d_feat: gpu.buffer("d displacement flow", px * 12)?,
                sums: gpu.buffer("motion partial sums", px.div_ceil(256) * 4)?,
                norm_cfg: ncfg,
                by_time,
                rank,
            })
        } else {
            None
        };
        let time_noise = match cfg.time_noise {
            config::TimeNoise::Auto => !blender,
            config::TimeNoise::On => true,
            config::TimeNoise::Off => false,
        };
        let distinct_times = {
            let mut t: Vec<u32> = data.train.iter().map(|f| f.time.to_bits()).collect();
            t.sort_unstable();
            t.dedup();
            t.len().max(1)
        };
        Ok(Trainer {
            gpu,
            cfg: cfg.clone(),
            mlp_cfg,
            deform: DeformApply::new(gpu)?,
            adam: Adam::new(gpu)?,
            next: [
                mk("gaussian params next")?,
                mk("gaussian adam m next")?,
                mk("gaussian adam v next")?,
            ],
            grads: mk("gaussian grads")?,
            params,
            m,
            v,
            layout,
            n,
            densify_bufs,
            densifier,
            mlp_grads: gpu.buffer_from("mlp grads", &zeros)?,
            mlp_m: gpu.buffer_from("mlp adam m", &zeros)?,
            mlp_v: gpu.buffer_from("mlp adam v", &zeros)?,
            mlp_bufs: mlp.buffers(gpu, budget)?,
            mlp_params,
            mlp,
            drawn: [
                gpu.buffer("drawn means", cap * 12)?,
                gpu.buffer("drawn scales", cap * 12)?,
                gpu.buffer("drawn quats", cap * 16)?,
            ],
            d_drawn_dummy: gpu.buffer("unused binding", 16)?,
            deform_out: gpu.buffer("deformation", cap * 40)?,
            d_deform: gpu.buffer("deformation grads", cap * 40)?,
            raster,
            raster_bufs,
            loss,
            loss_bufs,
            d_render: gpu.buffer("d render", (w * h) as u64 * 16)?,
            zero_depth: gpu.buffer_from("zero depth grads", &vec![0f32; (w * h) as usize])?,
            step_flags: gpu.host_buffer("step flags", 16)?,
            frames,
            val,
            extent: camera_extent(&data.train),
            time_interval: 1.0 / distinct_times as f32,
            time_noise,
            motion,
            eval: None,
            iteration: 0,
        })
    }

    /// Whether the deformation network is active at 1-based `iteration`.
    pub fn deform_active(&self, iteration: u32) -> bool {
        iteration > self.cfg.warm_up
    }

    fn sh_degree_at(&self, iteration: u32) -> u32 {
        self.cfg
            .sh_degree
            .min((iteration.saturating_sub(1)) / self.cfg.sh_interval)
    }

    /// Records the deformed Gaussians at time `t` into `self.drawn` (D ≡ 0 when inactive).
    fn record_deform(&self, rec: &mut Recorder<'_>, t: f32, active: bool) {
        if active {
            let means = self.layout.slice(&self.params, Section::Means, self.n);
            self.mlp.forward(
                rec,
                &self.mlp_bufs,
                self.n,
                means,
                MlpTime::Batch(t),
                self.mlp_params.all(),
                self.deform_out.all(),
            );
        }
        let d = active.then(|| self.deform_out.all());
        self.deform.forward(
            rec,
            self.n,
            &canonical(&self.layout, &self.params, self.n),
            d,
            self.d_drawn_dummy.all(),
            &drawn_of(&self.drawn),
        );
    }

    /// One training iteration. Returns the loss values when `want_values` (read after the
    /// submit, never mid-step). An iteration whose tile intersections overflowed is discarded
    /// on the GPU (the optimiser skips it) and re-run with grown buffers.
    pub fn step(&mut self, want_values: bool, timed: bool) -> Result<Option<StepLog>> {
        let it = self.iteration + 1;
        let fi = frame_for_iteration(self.cfg.seed, it, self.frames.len());
        let active = self.deform_active(it);
        let mut t = self.frames[fi].time;
        if self.time_noise && active {
            // Deformable-3DGS AST: N(0,1) · (1 / frames) · a decaying factor.
            let (u1, u2) = (
                hash_uniform(self.cfg.seed, it as u64, 1),
                hash_uniform(self.cfg.seed, it as u64, 2),
            );
            let z = (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos();
            let decay = ExpLr {
                lr_init: 0.1,
                lr_final: 1e-15,
                lr_delay_steps: 0,
                lr_delay_mult: 0.01,
                max_steps: 20_000,
            };
            t += (z * self.time_interval as f64 * decay.at(it as i64)) as f32;
        }
        let bg = match self.cfg.background {
            Background::Black => [0.0; 3],
            Background::White => [1.0; 3],
            Background::Random => {
                [1, 2, 3].map(|k| hash_uniform(self.cfg.seed ^ 0xb9, it as u64, k) as f32)
            }
        };
        let opts = RenderOpts {
            background: bg,
            alpha_max: 0.99,
        };
        let sh_degree = self.sh_degree_at(it);
        let motion_w = self.motion_weight_at(it);
        loop {
            let frame = &self.frames[fi];
            let mut rec = if timed {
                Recorder::timed(self.gpu)?
            } else {
                Recorder::new(self.gpu)?
            };
            if motion_w > 0.0 {
                self.record_dispflow_step(&mut rec, fi, t, &opts, sh_degree, motion_w);
            } else {
                rec.set_zone("deform");
                self.record_deform(&mut rec, t, active);
                rec.set_zone("raster");
                let g = splat_inputs(&self.layout, &self.params, &self.drawn, self.n, sh_degree);
                self.raster
                    .forward(&mut rec, &self.raster_bufs, &frame.camera, &g, &opts);
                rec.set_zone("loss");
                let (out, tgt) = (self.raster_bufs.out_rgba.all(), frame.target.all());
                self.loss.record(
                    &mut rec,
                    &mut self.loss_bufs,
                    out,
                    tgt,
                    self.d_render.all(),
                    self.cfg.lambda_ssim,
                );
                rec.set_zone("raster bwd");
                let d = OutputGrads {
                    rgba: self.d_render.all(),
                    depth: self.zero_depth.all(),
                    features: None,
                };
                self.raster
                    .backward(&mut rec, &self.raster_bufs, &frame.camera, &g, &opts, &d);
                rec.set_zone("deform bwd");
                self.record_backward_to_params(&mut rec, active);
            }
            rec.set_zone("densify stats");
            if it <= self.cfg.densify.until {
                // (An overflowed, discarded step still adds its statistics once more; densification
                // reads averages, so one repeated view among hundreds is harmless.)
                self.densifier.record_stats(
                    &mut rec,
                    &self.densify_bufs,
                    &self.raster_bufs,
                    self.n,
                );
            }
            rec.set_zone("adam");
            self.record_adam(&mut rec, it, active);
            rec.copy(
                self.raster_bufs.overflow_flag(),
                self.step_flags.slice(0, 8),
            );
            if let Some(m) = self.motion.as_ref().filter(|_| motion_w > 0.0) {
                rec.copy(m.inter.overflow_flag(), self.step_flags.slice(8, 8));
            }
            let timings = rec.finish()?;
            let flags: Vec<u32> = self.step_flags.read_mapped();
            if let Some(m) = self
                .motion
                .as_mut()
                .filter(|_| motion_w > 0.0 && flags[2] != 0)
            {
                // A truncated intermediate render fed this step's flow (the optimiser step is
                // guarded by the main render only); later steps get room for it.
                let need = flags[3].saturating_add(flags[3] / 4);
                m.inter = self.raster.buffers(
                    self.gpu,
                    &RasterSize {
                        isect_capacity: need,
                        ..m.inter.size()
                    },
                )?;
            }
            if flags[0] != 0 {
                let grown = flags[1].saturating_add(flags[1] / 4).max(flags[1]);
                self.raster_bufs = self.raster.buffers(
                    self.gpu,
                    &RasterSize {
                        isect_capacity: grown,
                        ..self.raster_bufs.size()
                    },
                )?;
                continue;
            }
            self.iteration = it;
            self.densify_if_due(it)?;
            return Ok(if want_values {
                Some(StepLog {
                    iteration: it,
                    loss: self.loss_bufs.values(self.gpu)?,
                    num_gaussians: self.n,
                    timings,
                })
            } else {
                None
            });
        }
    }

    /// α_t of the motion term at 1-based `iteration`: 0 before `motion_start` (or without the
    /// deformation), then linear from 0.1·α to α over the remaining iterations.
    pub fn motion_weight_at(&self, iteration: u32) -> f32 {
        let (a, t0, end) = (
            self.cfg.motion_weight,
            self.cfg.motion_start,
            self.cfg.iterations,
        );
        if self.motion.is_none() || a <= 0.0 || iteration < t0 || !self.deform_active(iteration) {
            return 0.0;
        }
        let f = if end > t0 {
            (iteration - t0) as f32 / (end - t0) as f32
        } else {
            1.0
        };
        a * (0.1 + 0.9 * f.clamp(0.0, 1.0))
    }

    /// The temporal neighbour of training frame `fi`: `pair_gap` frames later in time (earlier
    /// at the end of the sequence).
    fn pair_frame(&self, fi: usize) -> usize {
        let m = self.motion.as_ref().expect("motion state");
        let (r, n, gap) = (
            m.rank[fi],
            m.by_time.len(),
            self.cfg.pair_gap.max(1) as usize,
        );
        let j = if r + gap < n {
            r + gap
        } else {
            r.saturating_sub(gap)
        };
        m.by_time[j]
    }

    /// The DispFlow-GS step (DESIGN §2): D at t1 and t2, δ = dx(t2) − dx(t1) splatted with the
    /// render of (v1, t1); intermediate render (v1, t2) without gradient; scene motion = flow
    /// from the frame's image to it; normalised magnitudes; α_t·L1 between them added to the
    /// photometric loss; gradients reach the MLP at both times and the Gaussians through the
    /// blend weights. A degenerate (flat) map skips the motion term for the step.
    fn record_dispflow_step(
        &mut self,
        rec: &mut Recorder<'_>,
        fi: usize,
        t1: f32,
        opts: &RenderOpts,
        sh_degree: u32,
        weight: f32,
    ) {
        let fj = self.pair_frame(fi);
        let t2 = self.frames[fj].time;
        let cam = self.frames[fi].camera;
        let m = self.motion.as_mut().expect("motion state");
        let means = self.layout.slice(&self.params, Section::Means, self.n);
        rec.set_zone("deform");
        self.mlp.forward(
            rec,
            &self.mlp_bufs,
            self.n,
            means,
            MlpTime::Batch(t1),
            self.mlp_params.all(),
            self.deform_out.all(),
        );
        self.mlp.forward(
            rec,
            &m.mlp_bufs2,
            self.n,
            means,
            MlpTime::Batch(t2),
            self.mlp_params.all(),
            m.deform_out2.all(),
        );
        m.dispflow.displacement(
            rec,
            self.n,
            self.deform_out.all(),
            m.deform_out2.all(),
            m.delta.all(),
        );
        let canon = canonical(&self.layout, &self.params, self.n);
        let drawn = drawn_of(&self.drawn);
        self.deform.forward(
            rec,
            self.n,
            &canon,
            Some(self.deform_out.all()),
            self.d_drawn_dummy.all(),
            &drawn,
        );
        if self.cfg.motion_order == MotionOrder::Direct {
            // Only the direct order draws the Gaussians at t2 (its intermediate render).
            let drawn2 = drawn_of(&m.drawn2);
            self.deform.forward(
                rec,
                self.n,
                &canon,
                Some(m.deform_out2.all()),
                self.d_drawn_dummy.all(),
                &drawn2,
            );
        }
        let reverse = self.cfg.motion_order == MotionOrder::Reverse;
        rec.set_zone("raster");
        let mut g = splat_inputs(&self.layout, &self.params, &self.drawn, self.n, sh_degree);
        if !reverse {
            g.features = Some((m.delta.all(), 3));
        }
        self.raster.forward(rec, &self.raster_bufs, &cam, &g, opts);
        rec.set_zone("loss");
        let target = self.frames[fi].target.all();
        self.loss.record(
            rec,
            &mut self.loss_bufs,
            self.raster_bufs.out_rgba.all(),
            target,
            self.d_render.all(),
            self.cfg.lambda_ssim,
        );
        rec.set_zone("intermediate");
        // Direct: (v1, t2) without gradient, scene motion = flow(I_a → it) under v1.
        // Reverse: (v2, t1) splatting δ, scene motion = flow(it → I_b) under v2.
        let (g_inter, cam_inter) = if reverse {
            let mut gi = splat_inputs(&self.layout, &self.params, &self.drawn, self.n, sh_degree);
            gi.features = Some((m.delta.all(), 3));
            (gi, self.frames[fj].camera)
        } else {
            let g2 = splat_inputs(&self.layout, &self.params, &m.drawn2, self.n, sh_degree);
            (g2, cam)
        };
        self.raster
            .forward(rec, &m.inter, &cam_inter, &g_inter, opts);
        rec.set_zone("flow");
        let (from, to) = if reverse {
            (m.inter.out_rgba.all(), self.frames[fj].target.all())
        } else {
            (target, m.inter.out_rgba.all())
        };
        match &self.frames[fi].gt_flow {
            Some(gt) => rec.copy(gt.all(), m.scene_flow.slice(0, gt.all().size)),
            None => m
                .flow
                .record(rec, &m.flow_scratch, from, to, m.scene_flow.all()),
        }
        rec.set_zone("motion");
        let disp_render = if reverse { &m.inter } else { &self.raster_bufs };
        m.norm.record(
            rec,
            &mut m.norm_disp,
            disp_render.out_features.all(),
            m.norm_cfg,
        );
        m.norm
            .record(rec, &mut m.norm_scene, m.scene_flow.all(), m.norm_cfg);
        rec.copy(
            m.norm_disp.stats().buf.slice(m.norm_disp.stats().offset, 4),
            m.flags.slice(0, 4),
        );
        rec.copy(
            m.norm_scene
                .stats()
                .buf
                .slice(m.norm_scene.stats().offset, 4),
            m.flags.slice(4, 4),
        );
        let px = cam.width * cam.height;
        m.dispflow.motion_l1(
            rec,
            px,
            weight,
            m.norm_disp.m_hat(),
            m.norm_scene.m_hat(),
            m.flags.all(),
            m.d_mhat.all(),
            m.sums.all(),
        );
        m.norm.record_backward(
            rec,
            &m.norm_disp,
            disp_render.out_features.all(),
            m.d_mhat.all(),
            m.d_feat.all(),
        );
        rec.set_zone("raster bwd");
        let d = OutputGrads {
            rgba: self.d_render.all(),
            depth: self.zero_depth.all(),
            features: (!reverse).then(|| m.d_feat.all()),
        };
        self.raster
            .backward(rec, &self.raster_bufs, &cam, &g, opts, &d);
        if let Some(zero) = &m.zero_rgba {
            // Reverse order: the motion loss reaches the MLP through δ only; the blend-weight
            // gradients of the intermediate render are not added to the Gaussians.
            let d = OutputGrads {
                rgba: zero.all(),
                depth: self.zero_depth.all(),
                features: Some(m.d_feat.all()),
            };
            self.raster
                .backward(rec, &m.inter, &cam_inter, &g_inter, opts, &d);
        }
        rec.set_zone("deform bwd");
        self.record_grads_to_params(rec, true);
        let m = self.motion.as_ref().expect("motion state");
        let d_delta = if reverse {
            m.inter.d_features.all()
        } else {
            self.raster_bufs.d_features.all()
        };
        m.dispflow
            .displacement_bwd(rec, self.n, d_delta, self.d_deform.all(), m.d_deform2.all());
        rec.set_zone("mlp bwd");
        self.mlp.backward(
            rec,
            &self.mlp_bufs,
            self.n,
            self.mlp_params.all(),
            self.d_deform.all(),
            self.mlp_grads.all(),
            false,
        );
        self.mlp.backward(
            rec,
            &m.mlp_bufs2,
            self.n,
            self.mlp_params.all(),
            m.d_deform2.all(),
            self.mlp_grads.all(),
            true,
        );
    }

    /// Rasteriser gradients → canonical parameter gradients (and MLP output gradients, then
    /// the MLP's weight gradients when the deformation is active).
    fn record_backward_to_params(&self, rec: &mut Recorder<'_>, active: bool) {
        self.record_grads_to_params(rec, active);
        if active {
            rec.set_zone("mlp bwd");
            let (p, d, g) = (
                self.mlp_params.all(),
                self.d_deform.all(),
                self.mlp_grads.all(),
            );
            self.mlp
                .backward(rec, &self.mlp_bufs, self.n, p, d, g, false);
        }
    }

    /// Deform backward into the canonical gradient sections (and ∂L/∂(dx, dr, ds) into
    /// `d_deform` when the deformation is active) plus the opacity/SH gradient copies.
    fn record_grads_to_params(&self, rec: &mut Recorder<'_>, active: bool) {
        let rb = &self.raster_bufs;
        let d_drawn = Drawn {
            means: rb.d_means.all(),
            scales: rb.d_scales.all(),
            quats: rb.d_quats.all(),
        };
        let grads = canonical(&self.layout, &self.grads, self.n);
        let params = canonical(&self.layout, &self.params, self.n);
        let dd = active.then(|| self.d_deform.all());
        self.deform.backward(
            rec,
            self.n,
            &params,
            &d_drawn,
            &grads,
            dd,
            self.d_drawn_dummy.all(),
        );
        copy_raster_grads(rec, &self.layout, rb, &self.grads, self.n);
    }

    fn record_adam(&self, rec: &mut Recorder<'_>, it: u32, active: bool) {
        let lr = &self.cfg.lr;
        let l = &self.layout;
        let pos = ExpLr {
            lr_init: lr.position_init * self.extent as f64,
            lr_final: lr.position_final * self.extent as f64,
            lr_delay_steps: 0,
            lr_delay_mult: lr.position_delay_mult,
            max_steps: self.cfg.iterations,
        };
        let group = |s: Section, lr: f64| AdamGroup {
            first: l.offset(s) as u32,
            count: self.n * l.row_len(s),
            lr: lr as f32,
            mask: None,
        };
        let mut groups = vec![
            group(Section::Means, pos.at(it as i64)),
            group(Section::LogScales, lr.scaling),
            group(Section::Quats, lr.rotation),
            group(Section::Opacity, lr.opacity),
            group(Section::ShDc, lr.feature),
        ];
        if l.sh_coeffs > 1 {
            groups.push(group(Section::ShRest, lr.feature / lr.feature_rest_div));
        }
        groups.retain(|g| g.count > 0);
        let flag = self.raster_bufs.overflow_flag();
        let skip = flag.buf.slice(flag.offset, 4);
        let bufs = AdamBuffers {
            params: self.params.all(),
            grads: self.grads.all(),
            m: self.m.all(),
            v: self.v.all(),
        };
        let h = AdamHyper::default();
        self.adam.record_guarded(rec, bufs, &groups, &h, it, skip);
        if active {
            let dl = ExpLr {
                lr_init: lr.deform_init,
                lr_final: lr.deform_final,
                lr_delay_steps: 0,
                lr_delay_mult: lr.position_delay_mult,
                max_steps: self.cfg.iterations,
            };
            let total = self.mlp.layout.total as u32;
            let g = [AdamGroup {
                first: 0,
                count: total,
                lr: dl.at(it as i64) as f32,
                mask: None,
            }];
            let b = AdamBuffers {
                params: self.mlp_params.all(),
                grads: self.mlp_grads.all(),
                m: self.mlp_m.all(),
                v: self.mlp_v.all(),
            };
            // The MLP's own step count starts after the warm-up (its bias correction too).
            self.adam
                .record_guarded(rec, b, &g, &h, it - self.cfg.warm_up, skip);
        }
    }
}

impl Trainer<'_> {
    /// 3DGS density control at its cadence: densify every `interval` iterations after `from`
    /// up to `until`, opacity reset every `opacity_reset_interval`. Reads the new count back:
    /// this runs every hundred steps, outside a step.
    fn densify_if_due(&mut self, it: u32) -> Result<()> {
        let d = self.cfg.densify;
        if it > d.until {
            return Ok(());
        }
        if it > d.from && it % d.interval == 0 {
            let mut s = DensifySettings::new(self.extent, d.budget);
            s.grad_threshold = d.grad_threshold;
            s.percent_dense = d.percent_dense;
            s.min_opacity = d.min_opacity;
            s.max_screen_size = if it > d.opacity_reset_interval {
                d.max_screen_size
            } else {
                0.0
            };
            s.seed = self.cfg.seed as u32;
            s.iteration = it;
            let mut rec = Recorder::new(self.gpu)?;
            let src = GaussianBuffers {
                layout: &self.layout,
                params: &self.params,
                m: &self.m,
                v: &self.v,
            };
            let dst = GaussianBuffers {
                layout: &self.layout,
                params: &self.next[0],
                m: &self.next[1],
                v: &self.next[2],
            };
            self.densifier
                .record_densify(&mut rec, &self.densify_bufs, src, dst, self.n, &s)?;
            rec.finish()?;
            self.n = self.densify_bufs.read_count(self.gpu)?;
            std::mem::swap(&mut self.params, &mut self.next[0]);
            std::mem::swap(&mut self.m, &mut self.next[1]);
            std::mem::swap(&mut self.v, &mut self.next[2]);
        }
        if it % d.opacity_reset_interval == 0 {
            let mut rec = Recorder::new(self.gpu)?;
            let g = GaussianBuffers {
                layout: &self.layout,
                params: &self.params,
                m: &self.m,
                v: &self.v,
            };
            self.densifier.record_opacity_reset(&mut rec, g, self.n);
            rec.finish()?;
        }
        Ok(())
    }

    /// Renders `frame`'s view at `time` with the current model into `self.raster_bufs.out_rgba`
    /// (growing the intersection buffers if needed).
    pub fn render(&mut self, camera: &Camera, time: f32, background: [f32; 3]) -> Result<()> {
        let active = self.deform_active(self.iteration.max(1));
        let mut rec = Recorder::new(self.gpu)?;
        self.record_deform(&mut rec, time, active);
        rec.finish()?;
        let deg = self.sh_degree_at(self.iteration.max(1));
        let g = splat_inputs(&self.layout, &self.params, &self.drawn, self.n, deg);
        let opts = RenderOpts {
            background,
            alpha_max: 0.99,
        };
        self.raster
            .render_checked(self.gpu, &mut self.raster_bufs, camera, &g, &opts)
    }

    /// Evaluates every validation frame at its view and time (black background): PSNR, SSIM
    /// and L1 of the render; with a predecessor time `t−1` in the dataset, the displacement
    /// flow δ = dx(t) − dx(t−1) splatted with the weights of the render at `(v, t)`, min-max
    /// normalised, scored against the frame's motion mask (AP, for MMAP) and DRC against the
    /// frozen render `(v, D(t−1))`. `want_images` also reads the pictures back.
    pub fn evaluate(&mut self, want_images: bool) -> Result<Vec<FrameEval>> {
        let mut out = Vec::with_capacity(self.val.len());
        for i in 0..self.val.len() {
            out.push(self.evaluate_one(i, want_images)?);
        }
        Ok(out)
    }

    fn eval_state(&mut self) -> Result<&mut EvalState> {
        if self.eval.is_none() {
            let gpu = self.gpu;
            let cap = self.layout.capacity as u64;
            let size = RasterSize {
                feature_dims: 3,
                ..self.raster_bufs.size()
            };
            let (w, h) = (size.width, size.height);
            let norm = MotionNorm::new(gpu)?;
            let metrics = MotionMetrics::new(gpu)?;
            let flow = TvL1Flow::new(gpu, FlowConfig::preset(&self.cfg.flow_preset)?)?;
            self.eval = Some(EvalState {
                bufs: self.raster.buffers(gpu, &size)?,
                deform_prev: gpu.buffer("eval deformation t-1", cap * 40)?,
                delta: gpu.buffer("eval displacement", cap * 12)?,
                drawn_prev: [
                    gpu.buffer("eval drawn means t-1", cap * 12)?,
                    gpu.buffer("eval drawn scales t-1", cap * 12)?,
                    gpu.buffer("eval drawn quats t-1", cap * 16)?,
                ],
                full: gpu.buffer("eval full render", (w * h) as u64 * 16)?,
                dispflow: DispFlow::new(gpu)?,
                metric_bufs: metrics.buffers(gpu, w, h)?,
                flow_scratch: flow.scratch(gpu, w, h)?,
                flow,
                scene_flow: gpu.buffer("eval scene flow", (w * h) as u64 * 8)?,
                scene_norm: norm.buffers(gpu, w, h, 2)?,
                scene_metric_bufs: metrics.buffers(gpu, w, h)?,
                norm_bufs: norm.buffers(gpu, w, h, 3)?,
                norm,
                metrics,
                flags: gpu.host_buffer("eval overflow flags", 16)?,
            });
        }
        Ok(self.eval.as_mut().expect("just allocated"))
    }

    /// The last motion step's normalised magnitude maps `(m̂_disp, m̂_scene)` ([H·W] each) and
    /// the training frame it used; `None` before any motion step. For diagnostics (reads the
    /// GPU; call between steps).
    pub fn last_motion_maps(&self) -> Result<Option<(Vec<f32>, Vec<f32>)>> {
        let Some(m) = &self.motion else {
            return Ok(None);
        };
        Ok(Some((
            self.gpu.read(m.norm_disp.m_hat())?,
            self.gpu.read(m.norm_scene.m_hat())?,
        )))
    }

    /// Evaluates validation frame `i` (see [`Trainer::evaluate`]).
    pub fn evaluate_one(&mut self, i: usize, want_images: bool) -> Result<FrameEval> {
        let f = &self.val[i];
        let (cam, t, prev) = (f.camera, f.time, f.prev_time);
        self.render_motion(&cam, t, prev, Some(i), want_images)
    }

    /// Renders `(camera, t)` (black background) and, with `prev`, the displacement flow
    /// δ = dx(t) − dx(prev) splatted with the same weights (min-max normalised magnitude). With
    /// a validation frame `val` it also scores the render (photometric values, AP against its
    /// mask, DRC against the frozen render `(camera, D(prev))`).
    pub fn render_motion(
        &mut self,
        camera: &Camera,
        t: f32,
        prev: Option<f32>,
        val: Option<usize>,
        want_images: bool,
    ) -> Result<FrameEval> {
        let active = self.deform_active(self.iteration.max(1));
        let deg = self.sh_degree_at(self.iteration.max(1));
        let opts = RenderOpts {
            background: [0.0; 3],
            alpha_max: 0.99,
        };
        self.eval_state()?;
        let cam = *camera;
        let px = (cam.width * cam.height) as u64;
        loop {
            let e = self.eval.as_mut().expect("eval state");
            let mut rec = Recorder::new(self.gpu)?;
            let means = self.layout.slice(&self.params, Section::Means, self.n);
            let canon = canonical(&self.layout, &self.params, self.n);
            if active {
                let mut fwd = |time: f32, dst: &Buffer| {
                    let (b, p) = (&self.mlp_bufs, self.mlp_params.all());
                    let tm = MlpTime::Batch(time);
                    self.mlp
                        .forward(&mut rec, b, self.n, means, tm, p, dst.all());
                };
                fwd(t, &self.deform_out);
                if let Some(tp) = prev {
                    fwd(tp, &e.deform_prev);
                }
            }
            let dummy = self.d_drawn_dummy.all();
            let d = active.then(|| self.deform_out.all());
            let drawn = drawn_of(&self.drawn);
            self.deform
                .forward(&mut rec, self.n, &canon, d, dummy, &drawn);
            let mut g = splat_inputs(&self.layout, &self.params, &self.drawn, self.n, deg);
            if prev.is_some() {
                if active {
                    let (a, b) = (e.deform_prev.all(), self.deform_out.all());
                    e.dispflow
                        .displacement(&mut rec, self.n, a, b, e.delta.all());
                } else {
                    // No deformation yet: D ≡ 0 at every time, δ = 0.
                    rec.fill(e.delta.all(), 0);
                }
                let d = active.then(|| e.deform_prev.all());
                let drawn_prev = drawn_of(&e.drawn_prev);
                self.deform
                    .forward(&mut rec, self.n, &canon, d, dummy, &drawn_prev);
                g.features = Some((e.delta.all(), 3));
            }
            self.raster.forward(&mut rec, &e.bufs, &cam, &g, &opts);
            rec.copy(e.bufs.overflow_flag(), e.flags.slice(0, 8));
            let frame = val.map(|i| &self.val[i]);
            if let Some(f) = frame {
                self.loss.record(
                    &mut rec,
                    &mut self.loss_bufs,
                    e.bufs.out_rgba.all(),
                    f.target.all(),
                    self.d_render.all(),
                    self.cfg.lambda_ssim,
                );
            }
            rec.copy(e.bufs.out_rgba.slice(0, px * 16), e.full.slice(0, px * 16));
            if prev.is_some() {
                let feat = e.bufs.out_features.all();
                e.norm
                    .record(&mut rec, &mut e.norm_bufs, feat, NormConfig::default());
                if let Some((mask, _)) = frame.and_then(|f| f.mask.as_ref()) {
                    let m_hat = e.norm_bufs.m_hat();
                    e.metrics
                        .record_ap(&mut rec, &e.metric_bufs, m_hat, mask.all());
                }
            }
            if let (Some(f), Some(_)) = (frame, prev) {
                // The frozen render: the same view with the deformation of t−1.
                let g_prev = splat_inputs(&self.layout, &self.params, &e.drawn_prev, self.n, deg);
                self.raster.forward(&mut rec, &e.bufs, &cam, &g_prev, &opts);
                rec.copy(e.bufs.overflow_flag(), e.flags.slice(8, 8));
                e.metrics.record_drc(
                    &mut rec,
                    &e.metric_bufs,
                    e.norm_bufs.m_hat(),
                    e.bufs.out_rgba.all(),
                    e.full.all(),
                    f.target.all(),
                );
                let (frozen, sf) = (e.bufs.out_rgba.all(), e.scene_flow.all());
                e.flow
                    .record(&mut rec, &e.flow_scratch, frozen, f.target.all(), sf);
                e.norm
                    .record(&mut rec, &mut e.scene_norm, sf, NormConfig::default());
                if let Some((mask, _)) = &f.mask {
                    let m_hat = e.scene_norm.m_hat();
                    e.metrics
                        .record_ap(&mut rec, &e.scene_metric_bufs, m_hat, mask.all());
                }
            }
            rec.finish()?;
            let flags: Vec<u32> = e.flags.read_mapped();
            let frozen = prev.is_some() && val.is_some();
            if flags[0] != 0 || (frozen && flags[2] != 0) {
                let need = flags[1].max(if frozen { flags[3] } else { 0 });
                let grown = need.saturating_add(need / 4).max(need);
                e.bufs = self.raster.buffers(
                    self.gpu,
                    &RasterSize {
                        isect_capacity: grown,
                        ..e.bufs.size()
                    },
                )?;
                continue;
            }
            let frame = val.map(|i| &self.val[i]);
            let values = match frame {
                Some(_) => self.loss_bufs.values(self.gpu)?,
                None => LossValues::new(f64::NAN, f64::NAN, f64::NAN, self.cfg.lambda_ssim as f64),
            };
            let mask = frame.and_then(|f| f.mask.as_ref());
            let ap = match (mask, prev) {
                (Some(_), Some(_)) => e.metric_bufs.ap(self.gpu)?,
                _ => None,
            };
            let (drc, scene_ap) = match frame.zip(prev) {
                Some(_) => (
                    Some(e.metric_bufs.drc(self.gpu)?),
                    match mask {
                        Some(_) => e.scene_metric_bufs.ap(self.gpu)?,
                        None => None,
                    },
                ),
                None => (None, None),
            };
            let images = if want_images {
                let render: Vec<[f32; 4]> = self.gpu.read(e.full.elems::<[f32; 4]>(0, px))?;
                let gt: Vec<[f32; 4]> = match frame {
                    Some(f) => self.gpu.read(f.target.elems::<[f32; 4]>(0, px))?,
                    None => Vec::new(),
                };
                let motion = match prev {
                    Some(_) => self.gpu.read(e.norm_bufs.m_hat())?,
                    None => vec![0.0; px as usize],
                };
                let scene_motion = match frame.zip(prev) {
                    Some(_) => {
                        let v: Vec<f32> = self.gpu.read(e.scene_norm.m_hat())?;
                        Some(v[..px as usize].to_vec())
                    }
                    None => None,
                };
                Some(FrameImages {
                    width: cam.width,
                    height: cam.height,
                    render,
                    gt,
                    motion: motion[..px as usize].to_vec(),
                    scene_motion,
                    mask: mask.map(|m| m.1.clone()),
                })
            } else {
                None
            };
            return Ok(FrameEval {
                id: frame.map_or_else(|| format!("t{t:.4}"), |f| f.id.clone()),
                time: t,
                values,
                has_mask: mask.is_some_and(|m| m.1.iter().any(|&v| v != 0)),
                ap,
                drc,
                scene_ap,
                images,
            });
        }
    }

    /// Replaces the model by trained Gaussians and MLP weights (a run's `point_cloud.ply` and
    /// `deform.bin`) as of `iteration` (which decides whether the deformation is active).
    pub fn load_model(&mut self, g: &HostGaussians, mlp: &[f32], iteration: u32) -> Result<()> {
        if mlp.len() != self.mlp.layout.total {
            return Err(Error::Invalid(format!(
                "deformation weights hold {} floats; this configuration's MLP ({}×{}) has {}",
                mlp.len(),
                self.cfg.mlp_depth,
                self.cfg.mlp_width,
                self.mlp.layout.total
            )));
        }
        if g.sh_coeffs != self.layout.sh_coeffs {
            return Err(Error::Invalid(format!(
                "the Gaussians carry {} SH coefficients; the configuration (sh_degree {}) expects {}",
                g.sh_coeffs, self.cfg.sh_degree, self.layout.sh_coeffs
            )));
        }
        if g.len() > self.layout.capacity as usize {
            return Err(Error::Capacity {
                what: "Gaussian budget (loaded model)",
                capacity: self.layout.capacity as u64,
                asked: g.len() as u64,
            });
        }
        if let Some(i) = (0..g.len()).find(|&i| {
            let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
            !(finite(&g.means[i])
                && finite(&g.log_scales[i])
                && finite(&g.quats[i])
                && g.opacity[i].is_finite()
                && finite(&g.sh_dc[i]))
        }) {
            return Err(Error::Invalid(format!(
                "Gaussian {i} has a non-finite parameter"
            )));
        }
        if mlp.iter().any(|v| !v.is_finite()) {
            return Err(Error::Invalid(
                "deformation weights contain a non-finite value".into(),
            ));
        }
        g.upload(self.gpu, &self.layout, &self.params)?;
        self.gpu.upload(self.mlp_params.all(), mlp)?;
        self.n = g.len() as u32;
        self.iteration = iteration;
        Ok(())
    }

    /// The Gaussians as drawn at time `t` (deformation applied) in the canonical layout: a
    /// standard 3DGS model of that instant (log of |scale|: the rasteriser squares it).
    pub fn deformed_gaussians(&mut self, t: f32) -> Result<HostGaussians> {
        let active = self.deform_active(self.iteration.max(1));
        let mut rec = Recorder::new(self.gpu)?;
        self.record_deform(&mut rec, t, active);
        rec.finish()?;
        let mut g = self.gaussians()?;
        let n = self.n as u64;
        let means: Vec<[f32; 3]> = self.gpu.read(self.drawn[0].elems::<[f32; 3]>(0, n))?;
        let scales: Vec<[f32; 3]> = self.gpu.read(self.drawn[1].elems::<[f32; 3]>(0, n))?;
        let quats: Vec<[f32; 4]> = self.gpu.read(self.drawn[2].elems::<[f32; 4]>(0, n))?;
        g.means = means[..n as usize].to_vec();
        g.log_scales = scales[..n as usize]
            .iter()
            .map(|s| s.map(|v| v.abs().max(1e-12).ln()))
            .collect();
        g.quats = quats[..n as usize]
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
        Ok(g)
    }

    /// Canonical Gaussians on the host (rows 0..n).
    pub fn gaussians(&self) -> Result<HostGaussians> {
        HostGaussians::download(self.gpu, &self.layout, &self.params, self.n)
    }

    pub fn checkpoint(&self) -> Result<Checkpoint> {
        let rd =
            |b: &Buffer| -> Result<Vec<f32>> { self.gpu.read(b.elems::<f32>(0, self.n as u64)) };
        let db = &self.densify_bufs;
        Ok(Checkpoint {
            iteration: self.iteration,
            gaussians: self.gaussians()?,
            gauss_m: HostGaussians::download(self.gpu, &self.layout, &self.m, self.n)?,
            gauss_v: HostGaussians::download(self.gpu, &self.layout, &self.v, self.n)?,
            densify_stats: [rd(&db.grad_accum)?, rd(&db.denom)?, rd(&db.max_radii)?],
            mlp_params: self.gpu.read(self.mlp_params.all())?,
            mlp_m: self.gpu.read(self.mlp_m.all())?,
            mlp_v: self.gpu.read(self.mlp_v.all())?,
        })
    }

    /// Restores a checkpoint written by a run with the same configuration.
    pub fn restore(&mut self, c: &Checkpoint) -> Result<()> {
        if c.mlp_params.len() != self.mlp.layout.total
            || c.gaussians.sh_coeffs != self.layout.sh_coeffs
        {
            return Err(Error::Invalid(
                "checkpoint does not match this configuration (MLP size or SH degree differ); use the run's config.toml".into(),
            ));
        }
        if c.gaussians.len() > self.layout.capacity as usize {
            return Err(Error::Capacity {
                what: "Gaussian budget (checkpoint)",
                capacity: self.layout.capacity as u64,
                asked: c.gaussians.len() as u64,
            });
        }
        c.gaussians.upload(self.gpu, &self.layout, &self.params)?;
        c.gauss_m.upload(self.gpu, &self.layout, &self.m)?;
        c.gauss_v.upload(self.gpu, &self.layout, &self.v)?;
        let db = &self.densify_bufs;
        for (b, v) in [&db.grad_accum, &db.denom, &db.max_radii]
            .iter()
            .zip(&c.densify_stats)
        {
            self.gpu.upload(b.all(), v)?;
        }
        self.gpu.upload(self.mlp_params.all(), &c.mlp_params)?;
        self.gpu.upload(self.mlp_m.all(), &c.mlp_m)?;
        self.gpu.upload(self.mlp_v.all(), &c.mlp_v)?;
        self.n = c.gaussians.len() as u32;
        self.iteration = c.iteration;
        Ok(())
    }
}

/// Means, log-scales and quaternions of rows 0..n of a Gaussian buffer (parameters or grads).
fn canonical<'a>(l: &GaussianLayout, buf: &'a Buffer, n: u32) -> Canonical<'a> {
    Canonical {
        means: l.slice(buf, Section::Means, n),
        log_scales: l.slice(buf, Section::LogScales, n),
        quats: l.slice(buf, Section::Quats, n),
    }
}

/// Drawn means, scales and rotations held in three buffers.
fn drawn_of(b: &[Buffer; 3]) -> Drawn<'_> {
    Drawn {
        means: b[0].all(),
        scales: b[1].all(),
        quats: b[2].all(),
    }
}

/// Opacity and SH gradients go from the rasteriser's buffers into their Adam sections.
fn copy_raster_grads(
    rec: &mut Recorder<'_>,
    l: &GaussianLayout,
    rb: &RasterBuffers,
    grads: &Buffer,
    n: u32,
) {
    if n == 0 {
        return;
    }
    let n64 = n as u64;
    rec.copy(
        rb.d_opacity_logits.slice(0, n64 * 4),
        l.slice(grads, Section::Opacity, n),
    );
    rec.copy(
        rb.d_sh_dc.slice(0, n64 * 12),
        l.slice(grads, Section::ShDc, n),
    );
    if l.sh_coeffs > 1 {
        let bytes = n64 * 4 * l.row_len(Section::ShRest) as u64;
        rec.copy(
            rb.d_sh_rest.slice(0, bytes),
            l.slice(grads, Section::ShRest, n),
        );
    }
}

/// What the rasteriser reads of the model: drawn (deformed) geometry, opacity and SH sections.
fn splat_inputs<'a>(
    l: &GaussianLayout,
    params: &'a Buffer,
    drawn: &'a [Buffer; 3],
    n: u32,
    sh_degree: u32,
) -> SplatInputs<'a> {
    SplatInputs {
        n,
        means: drawn[0].all(),
        scales: drawn[1].all(),
        quats: drawn[2].all(),
        opacity_logits: l.slice(params, Section::Opacity, n),
        sh_dc: l.slice(params, Section::ShDc, n),
        sh_rest: l.slice(params, Section::ShRest, n),
        sh_coeffs: l.sh_coeffs,
        sh_degree,
        features: None,
    }
}

pub(crate) fn sanitize(id: &str) -> String {
    id.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Writes images (RGBA f32, alpha ignored) side by side as one 8-bit PNG.
pub fn save_side_by_side(path: &Path, w: u32, h: u32, images: &[&[[f32; 4]]]) -> Result<()> {
    let k = images.len() as u32;
    let img = image::RgbImage::from_fn(w * k, h, |x, y| {
        let p = images[(x / w) as usize][(y * w + x % w) as usize];
        image::Rgb([0, 1, 2].map(|c| (p[c].clamp(0.0, 1.0) * 255.0).round() as u8))
    });
    if let Some(d) = path.parent() {
        std::fs::create_dir_all(d).map_err(|source| Error::Io {
            path: d.display().to_string(),
            source,
        })?;
    }
    img.save(path)
        .map_err(|e| Error::Invalid(format!("{}: {e}", path.display())))
}

fn subsample(h: &HostGaussians, keep: &[usize]) -> HostGaussians {
    let r = 3 * (h.sh_coeffs as usize - 1);
    HostGaussians {
        sh_coeffs: h.sh_coeffs,
        means: keep.iter().map(|&i| h.means[i]).collect(),
        log_scales: keep.iter().map(|&i| h.log_scales[i]).collect(),
        quats: keep.iter().map(|&i| h.quats[i]).collect(),
        opacity: keep.iter().map(|&i| h.opacity[i]).collect(),
        sh_dc: keep.iter().map(|&i| h.sh_dc[i]).collect(),
        sh_rest: keep
            .iter()
            .flat_map(|&i| h.sh_rest[i * r..(i + 1) * r].to_vec())
            .collect(),
    }
}
