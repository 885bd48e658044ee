//! Training: the [`Trainer`] loop around a step that reads as a list of pass calls
//! ([`step::record_step`]): a pure per-iteration [`plan::StepPlan`], passes that own their
//! pipelines and scratch ([`passes`]), the model state in [`crate::model::state`], density
//! control at its cadence, checkpoints. Scoring a frame lives in [`score`] with its own
//! scratch, and what the trainer renders outside a step in `looking`; the run loop is
//! [`session`]; the commands that reopen a run (`crate::eval`) sit above this module.

pub mod checkpoint;
pub mod cli;
pub mod collapse;
pub mod config;
pub mod cost;
pub mod curve;
pub mod frames;
pub mod guard;
pub mod init;
mod looking;
pub mod method;
pub mod metrics;
pub mod outputs;
pub mod params_check;
pub mod passes;
pub mod plan;
pub mod population;
pub mod run;
mod run_loop;
pub mod score;
pub mod session;
pub mod step;
pub mod transients;

use std::rc::Rc;

use crate::data::Dataset;
use crate::error::{Error, Result};
use crate::kernels::loss::LossValues;
use crate::kernels::motion::NormConfig;
use crate::kernels::raster::{Camera, Rasterizer};
use crate::model::dynamic::DynamicSet;
use crate::model::gaussians::HostGaussians;
use crate::model::nodes::{FieldKind, NodeState};
use crate::model::state::{mlp_config_of, DeformState, GaussianState, Model, TransientShape};
use crate::train::score::Evaluator;
use crate::vk::{Gpu, Recorder, Timings};
use checkpoint::Checkpoint;
use config::{
    DeformMode, MotionFlow, MotionOrder, NormGrad, SceneMotionKind, SparsityMode, TrainConfig,
};
use frames::GpuFrame;
use passes::motion::{IndirectFlow, MotionVariant, OpticalFlow, OracleFlow};
use passes::sparsity::{Classifier, ProbeConfig, SplitStats};
use passes::{
    AdamPass, DeformPass, DensifyPass, MotionTerm, OverflowWatch, PhotoLoss, RenderPass,
    SceneMotion, StepSizes,
};
use passes::{SceneSignal, Slot};
use plan::{Decomposition, FrameTimes, StepPlan};
use population::Population;
use step::StepPasses;

/// A training frame's render and its ground truth, [H·W] RGBA each.
pub(crate) type Shot = (Vec<[f32; 4]>, Vec<[f32; 4]>);

/// Numbers reported per logged step.
#[derive(Clone, Debug, Default)]
pub struct StepLog {
    pub iteration: u32,
    pub loss: LossValues,
    pub num_gaussians: u32,
    pub timings: Timings,
    /// The rows the step drew, by population (timed steps only).
    pub rows: Option<cost::Rows>,
}

impl Default for LossValues {
    fn default() -> Self {
        LossValues::new(0.0, 0.0, 0.0, 0.2)
    }
}

/// The training loop's state: model, frames, the step's passes, the iteration count.
pub struct Trainer<'g> {
    pub gpu: &'g Gpu,
    pub cfg: TrainConfig,
    pub model: Model,
    pub frames: Vec<GpuFrame>,
    pub val: Vec<GpuFrame>,
    pub times: FrameTimes,
    pub sizes: StepSizes,
    raster: Rc<Rasterizer>,
    /// Built on the first step (or restore): evaluation-only uses never allocate them.
    passes: Option<StepPasses>,
    /// Built on the first evaluation; owns its scratch (evaluating never touches training's).
    eval: Option<Evaluator>,
    /// Iterations completed.
    pub iteration: u32,
    /// The last classification: after which iteration, what it found.
    pub last_split: Option<(u32, SplitStats)>,
    /// What the last step ran (its plan, less a motion term skipped because nothing moved).
    pub last_plan: Option<StepPlan>,
    /// Which of the dataset's points became the initial Gaussians.
    pub init_report: init::InitReport,
    /// Multiplier of the deformation's learning rate (halved by each collapse rollback).
    pub deform_lr_scale: f64,
    /// The scene's bounds and the near distance (where spawned transients may lie).
    bounds: crate::data::Bounds,
    /// The colour the dataset's images were composited on: evaluation, probes, spawns' shots
    /// and the signal render on it (training's own background is the plan's).
    pub background: [f32; 3],
    /// The last spawn of transients and its iteration.
    pub last_spawn: Option<(u32, transients::spawn::SpawnReport)>,
    /// Which frames spawns looked at and what they saw.
    looks: transients::spawn::Looks,
    /// The last spawn's depth hypotheses, until resolved (`transient.resolve`).
    hypotheses: Option<transients::resolve::Hypotheses>,
    /// The last resolution of depth hypotheses and its iteration.
    pub last_resolved: Option<(u32, transients::resolve::Resolved)>,
}

/// The temporal stage's constants for training frames `train`: σ's floor in time units
/// (`transient.floor_frames` × the median gap between consecutive training times) and the
/// sequence's time range.
pub fn transient_shape(cfg: &TrainConfig, train: &[GpuFrame]) -> TransientShape {
    let times: Vec<f32> = train.iter().map(|f| f.time).collect();
    let spacing = plan::median_gap(&times);
    let lo = times.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = times.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    TransientShape {
        log_floor: (cfg.transient.floor_frames * spacing).max(1e-6).ln(),
        cutoff: cfg.transient.cutoff,
        t_range: if lo <= hi { [lo, hi] } else { [0.0, 1.0] },
    }
}

impl<'g> Trainer<'g> {
    /// Allocates everything for `cfg.densify.budget` Gaussians and initialises them from the
    /// dataset's points. Fails with a clear error before any training on a bad dataset.
    pub fn new(gpu: &'g Gpu, cfg: &TrainConfig, data: &Dataset) -> Result<Self> {
        cfg.validate()?;
        let (width, height) = frames::check_dataset(data)?;
        let synthetic = matches!(data.format, crate::data::Format::Blender);
        let (mut train, val) = frames::upload_splits(gpu, data)?;
        let motion_on = cfg.motion_weight > 0.0;
        if motion_on && cfg.motion_flow == MotionFlow::Oracle {
            if cfg.motion_order == MotionOrder::Reverse {
                return Err(Error::Invalid(
                    "config field motion_flow: oracle gives the flow under the frame's own view (direct order); use motion_order = direct".into(),
                ));
            }
            frames::attach_gt_flow(gpu, &mut train, data)?;
        }
        let (init, init_report) = init::initial_gaussians(data, cfg)?;
        let budget = cfg.densify.budget;
        let model = Model {
            gaussians: GaussianState::new(gpu, budget, cfg.sh_degree, &init)?,
            deform: DeformState::with_gain(
                gpu,
                mlp_config_of(synthetic, cfg.mlp_shape()),
                cfg.seed,
                cfg.zero_deform_head,
                cfg.mlp_init_gain,
            )?,
            dynamic: DynamicSet::new(gpu, budget)?,
            nodes: (cfg.deform_field.kind == FieldKind::Nodes && cfg.deform == DeformMode::On)
                .then(|| NodeState::new(gpu, cfg.deform_field, budget))
                .transpose()?,
            transient: transient_shape(cfg, &train),
        };
        let sizes = StepSizes {
            capacity: budget,
            width,
            height,
            sh_coeffs: model.gaussians.layout.sh_coeffs,
            isect_guess: (4 * init.len() as u32).max(1 << 16),
        };
        // Deformable-3DGS turns its time noise off for synthetic scenes, whose poses are
        // exact; so is the built-in scene (`synthetic.json` marks it), although it is written
        // in the nerfies format. Measured on the tiny scene (single-threaded): with the
        // official noise on, DispFlow's MMAP gain over the baseline vanished (0.110 vs 0.112).
        let exact_poses = synthetic || data.root.join("synthetic.json").is_file();
        let times = FrameTimes::new(
            train.iter().map(|f| f.time).collect(),
            cfg.time_noise,
            exact_poses,
            frames::camera_extent(&data.train),
        );
        let raster = Rc::new(Rasterizer::new(gpu)?);
        // Settings the passes read, checked now (the passes themselves are built on the first
        // step: `eval` and `render` open a run without allocating training scratch).
        cfg.scene_motion.flow_config(&cfg.flow_preset)?;
        NormConfig::new(cfg.motion_normalize, 1e-6)?;
        Ok(Trainer {
            gpu,
            cfg: cfg.clone(),
            model,
            frames: train,
            val,
            times,
            sizes,
            raster,
            passes: None,
            eval: None,
            iteration: 0,
            last_split: None,
            last_plan: None,
            init_report,
            deform_lr_scale: 1.0,
            bounds: data.bounds,
            background: data.background,
            last_spawn: None,
            looks: Default::default(),
            hypotheses: None,
            last_resolved: None,
        })
    }

    /// The step's passes, allocated on first use for the Gaussian budget and the image size.
    fn passes(&mut self) -> Result<&mut StepPasses> {
        if self.passes.is_none() {
            self.passes = Some(build_passes(
                self.gpu,
                &self.cfg,
                &self.model,
                &self.sizes,
                &self.times,
                &self.raster,
                &self.frames,
            )?);
        }
        Ok(self.passes.as_mut().expect("just built"))
    }

    /// The rasteriser the passes share (for probes that draw with the trainer's model).
    pub fn raster(&self) -> Rc<Rasterizer> {
        self.raster.clone()
    }

    /// The plan of 1-based `iteration`.
    pub fn plan(&self, iteration: u32) -> StepPlan {
        let mut p = StepPlan::at(&self.cfg, &self.times, iteration);
        if let Some((lr, k)) = p.lr.deform {
            p.lr.deform = Some((lr * self.deform_lr_scale, k));
        }
        p
    }

    /// α_t at 1-based `iteration` (0 without the motion term).
    pub fn motion_weight_at(&self, iteration: u32) -> f32 {
        plan::motion_weight_at(&self.cfg, iteration)
    }

    /// Live Gaussians.
    pub fn n(&self) -> u32 {
        self.model.gaussians.n
    }

    /// One training iteration. Returns the loss values when `want_values` (read after the
    /// submit, never mid-step). An iteration whose tile intersections overflowed is discarded
    /// on the GPU (the optimiser skips it) and re-run with grown buffers.
    pub fn step(&mut self, want_values: bool, timed: bool) -> Result<Option<StepLog>> {
        let mut p = self.plan(self.iteration + 1);
        if p.sparse && self.model.dynamic.split() == Some(0) {
            // Nothing moves: δ ≡ 0, the displacement flow is zero and the motion term has no
            // gradient for anything (the GPU would skip it as degenerate); skip its work too.
            p.motion = None;
        }
        loop {
            let mut rec = if timed {
                Recorder::timed(self.gpu)?
            } else {
                Recorder::new(self.gpu)?
            };
            self.passes()?;
            if !p.sparse {
                self.model.dynamic.set_dense();
            }
            self.update_nodes(&p, &mut rec)?;
            let (m, s) = (&self.model, self.passes.as_mut().expect("built"));
            step::record_step(&mut rec, &p, m, s, &self.frames, self.cfg.lambda_ssim);
            let timings = rec.finish()?;
            // An overflowed render discarded the step on the GPU (no update, no statistics):
            // grow what overflowed and run the step again, so no step ever learns from a
            // truncated render and the result does not depend on the buffers' history.
            let s = self.passes.as_mut().expect("built");
            let mut again = false;
            let o = s.watch.read(0, "training render")?;
            if o.overflowed {
                s.render.grow(self.gpu, o.needed)?;
                again = true;
            }
            let m = s.motion.as_mut().filter(|_| p.motion.is_some());
            if let Some(m) = m.filter(|m| m.rendered_intermediate().is_some()) {
                let o = s.watch.read(1, "intermediate render")?;
                if o.overflowed {
                    m.grow_intermediate(self.gpu, o.needed)?;
                    again = true;
                }
            }
            if again {
                continue;
            }
            // Before densification and spawning change the rows.
            let rows = if timed {
                Some(self.rows_drawn(&p)?)
            } else {
                None
            };
            self.iteration = p.iteration;
            self.last_plan = Some(p);
            self.resolve_if_due(&p)?;
            self.densify_if_due(&p)?;
            if p.classify {
                self.classify()?;
            }
            if p.spawn {
                self.spawn_transients()?;
            }
            return Ok(if want_values {
                Some(StepLog {
                    iteration: p.iteration,
                    loss: self.passes.as_ref().expect("built").loss.values(),
                    num_gaussians: self.n(),
                    timings,
                    rows,
                })
            } else {
                None
            });
        }
    }

    /// The control nodes before step `p`: placed when the deformation starts (farthest-point
    /// sampling of the canonical means, read back here, between steps), their KNN refreshed
    /// every `knn_every` steps.
    fn update_nodes(&mut self, p: &StepPlan, rec: &mut Recorder<'_>) -> Result<()> {
        let Some(ns) = self.model.nodes.as_mut() else {
            return Ok(());
        };
        if p.deform_active && !ns.placed() {
            // On the canonical rows, which the field deforms: transients spawned before the
            // deformation starts (the first spawn can come at its first step) are not its.
            let g = &self.model.gaussians;
            let mut means = g.download(self.gpu)?.means;
            means.truncate(g.canonical_rows().len() as usize);
            ns.place(self.gpu, &means)?;
        }
        let every = ns.cfg.knn_every;
        if every > 0 && p.iteration % every == 0 {
            ns.invalidate_knn();
        }
        let s = self.passes.as_ref().expect("built");
        s.deform.ensure_knn(rec, &self.model);
        Ok(())
    }

    /// 3DGS density control after step `p`, as its plan says.
    fn densify_if_due(&mut self, p: &StepPlan) -> Result<()> {
        let d = &self.passes.as_ref().expect("a step ran").densify;
        if let Some(screen_cut) = p.densify {
            let tr = self.model.transient;
            d.densify(
                self.gpu,
                &mut self.model.gaussians,
                tr,
                p.iteration,
                screen_cut,
            )?;
            if let Some(ns) = self.model.nodes.as_mut() {
                ns.invalidate_knn(); // new rows, and survivors moved to other rows
            }
        }
        if p.opacity_reset {
            d.reset_opacity(self.gpu, &self.model.gaussians)?;
        }
        Ok(())
    }

    /// Splits the model into dynamic and static Gaussians now (the motion probe). `None`
    /// without a probe (sparsity off or the deformation off).
    pub fn classify(&mut self) -> Result<Option<SplitStats>> {
        self.passes()?;
        let s = self.passes.as_ref().expect("built");
        let Some(c) = &s.classifier else {
            return Ok(None);
        };
        let stats = c.classify(self.gpu, &mut self.model, &s.deform)?;
        self.last_split = Some((self.iteration, stats));
        Ok(Some(stats))
    }

    /// The rows step `p` drew, by population, read after its submit (the transients' opacity
    /// factors at its time: the culled ones cost nothing after the temporal stage).
    fn rows_drawn(&self, p: &StepPlan) -> Result<cost::Rows> {
        let g = &self.model.gaussians;
        let rows = g.populations();
        let canonical = rows.canonical.len();
        let deforming = match p.deform_active {
            true => self
                .model
                .dynamic
                .split()
                .unwrap_or(canonical)
                .min(canonical),
            false => 0,
        };
        let mut alive = 0;
        if let Some(s) = self.passes.as_ref() {
            // The rows with an opacity factor (every other row's is 1) whose factor is not 0.
            let scaled = Population::of(g)
                .into_iter()
                .filter(Population::scales_opacity);
            for r in scaled.map(|p| p.rows()) {
                let w: Vec<f32> = self.gpu.read(s.deform.opacity_scale(Slot::T1, r))?;
                alive += w.iter().filter(|&&w| w > 0.0).count() as u32;
            }
        }
        Ok(cost::Rows {
            still: canonical - deforming,
            deforming,
            alive,
            transients: rows.transient.len(),
        })
    }

    /// Fraction of the canonical Gaussians the deformation runs over (1 while dense;
    /// transients never go through it).
    pub fn dynamic_fraction(&self) -> f64 {
        self.model
            .dynamic
            .fraction(self.model.gaussians.canonical_rows().len())
    }

    /// Replaces the model by trained Gaussians and MLP weights as of `iteration`.
    pub fn load_model(&mut self, g: &HostGaussians, mlp: &[f32], iteration: u32) -> Result<()> {
        self.model.load(self.gpu, g, mlp)?;
        self.iteration = iteration;
        Ok(())
    }

    /// Canonical Gaussians on the host.
    pub fn gaussians(&self) -> Result<HostGaussians> {
        self.model.gaussians.download(self.gpu)
    }

    pub fn checkpoint(&self) -> Result<Checkpoint> {
        Ok(Checkpoint {
            iteration: self.iteration,
            deform_lr_scale: (self.deform_lr_scale != 1.0).then_some(self.deform_lr_scale),
            spawns: Some(transients::SpawnState {
                looks: self.looks.clone(),
                hypotheses: self.hypotheses.clone(),
            })
            .filter(|s| *s != transients::SpawnState::default()),
            model: self.model.checkpoint(self.gpu)?,
            densify_stats: match &self.passes {
                Some(s) => s.densify.stats(self.gpu, self.n())?,
                // No step yet: the statistics are still the zeros they start as.
                None => std::array::from_fn(|_| vec![0.0; self.n() as usize]),
            },
        })
    }

    /// Restores a checkpoint written by a run with the same configuration. Refuses, before
    /// changing anything, a checkpoint of another configuration (SH degree, MLP size,
    /// Gaussian budget: the message says which) or one holding a non-finite value (the
    /// message names the blob).
    pub fn restore(&mut self, c: &Checkpoint) -> Result<()> {
        self.model.check_snapshot(&c.model)?;
        let n = c.model.gaussians.len();
        for (name, v) in checkpoint::DENSIFY_STATS.iter().zip(&c.densify_stats) {
            if v.len() != n {
                return Err(Error::Invalid(format!(
                    "blob {name}: {} floats; {n} Gaussians need {n}",
                    v.len()
                )));
            }
            let blob = crate::model::state::Blob {
                name: name.to_string(),
                data: v,
                row: Some(1),
                non_negative: true,
            };
            blob.check_values()?;
        }
        let spawns = c.spawns.clone().unwrap_or_default();
        let rows = c.model.gaussians.populations();
        if let Some(p) = spawns.problem(rows, Some(self.frames.len())) {
            return Err(Error::Invalid(p));
        }
        self.passes()?;
        self.model.restore(self.gpu, &c.model)?;
        self.looks = spawns.looks;
        self.hypotheses = spawns.hypotheses;
        let gpu = self.gpu;
        self.passes()?
            .densify
            .restore_stats(gpu, &c.densify_stats)?;
        self.iteration = c.iteration;
        self.deform_lr_scale = c.deform_lr_scale.unwrap_or(1.0);
        Ok(())
    }
}

/// The passes of a training step for `cfg` (the motion term only when α > 0).
fn build_passes(
    gpu: &Gpu,
    cfg: &TrainConfig,
    model: &Model,
    sizes: &StepSizes,
    times: &FrameTimes,
    raster: &Rc<Rasterizer>,
    frames: &[GpuFrame],
) -> Result<StepPasses> {
    let motion_on = cfg.motion_weight > 0.0;
    let variant = MotionVariant {
        roles: Decomposition::of(cfg.motion_order),
        representation: cfg.motion_representation,
        scene: cfg.scene_motion.kind,
    };
    let motion = if motion_on {
        let flow = || cfg.scene_motion.flow_config(&cfg.flow_preset);
        let source: Box<dyn SceneMotion> = match (cfg.motion_flow, cfg.scene_motion.kind) {
            (MotionFlow::Oracle, _) => Box::new(OracleFlow),
            (MotionFlow::Tvl1, SceneMotionKind::Direct) => {
                Box::new(OpticalFlow::new(gpu, flow()?, sizes)?)
            }
            (MotionFlow::Tvl1, kind) => {
                let subtract = kind == SceneMotionKind::Indirect;
                Box::new(IndirectFlow::new(gpu, flow()?, sizes, subtract)?)
            }
        };
        let signal = SceneSignal::new(gpu, source, cfg.scene_motion.signal(), sizes.pixels())?;
        let norm = NormConfig {
            detach_stats: cfg.motion_norm_grad == NormGrad::Detached,
            ..NormConfig::new(cfg.motion_normalize, 1e-6)?
        };
        Some(MotionTerm::new(
            gpu,
            raster.clone(),
            sizes,
            variant,
            norm,
            signal,
        )?)
    } else {
        None
    };
    // The photometric render blends the motion channels when it is the one that splats them.
    let photo_feats = if motion_on {
        variant.photo_features()
    } else {
        0
    };
    let slots = 1 + motion_on as usize;
    Ok(StepPasses {
        deform: DeformPass::new(gpu, &model.deform.cfg, node_cfg(model), sizes, slots, true)?,
        render: RenderPass::new(raster.clone(), gpu, sizes, photo_feats)?,
        loss: PhotoLoss::new(gpu, sizes)?,
        motion,
        adam: AdamPass::new(gpu)?,
        densify: DensifyPass::new(
            gpu,
            cfg.densify,
            crate::train::population::Reserve::of(cfg),
            times.extent,
            cfg.seed,
        )?,
        watch: OverflowWatch::new(gpu, "step overflow flags", 2)?,
        classifier: classifier(gpu, cfg, sizes, times, frames)?,
    })
}

/// The control-node settings when the model has nodes.
pub fn node_cfg(model: &Model) -> Option<&crate::model::nodes::FieldConfig> {
    model.nodes.as_ref().map(|n| &n.cfg)
}

/// The motion probe when the configuration splits the model.
fn classifier(
    gpu: &Gpu,
    cfg: &TrainConfig,
    sizes: &StepSizes,
    times: &FrameTimes,
    frames: &[GpuFrame],
) -> Result<Option<Classifier>> {
    let sp = &cfg.sparsity;
    if sp.mode == SparsityMode::Off || cfg.deform == DeformMode::Off || frames.is_empty() {
        return Ok(None);
    }
    let lo = times.times.iter().copied().fold(f32::INFINITY, f32::min);
    let hi = times
        .times
        .iter()
        .copied()
        .fold(f32::NEG_INFINITY, f32::max);
    let probe = ProbeConfig::even(sp.threshold_px, sp.noise_k, sp.probe_times, lo, hi);
    let cams: Vec<Camera> = frames.iter().map(|f| f.camera).collect();
    Classifier::new(gpu, sizes.capacity, &cams, probe).map(Some)
}
