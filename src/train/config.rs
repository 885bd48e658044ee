//! Training configuration: everything a run needs to be reproduced, written as `config.toml`.
//! Defaults follow Deformable-3DGS (and 3DGS for the Gaussian recipe) at the paper's
//! 20 000-iteration setting; `fast` shrinks it to finish on a CPU (lavapipe) in minutes.
//! (Over ~600 lines with its unit tests: one struct family, its presets and validation.)

use serde::{Deserialize, Serialize};

pub use super::method::{MotionRepresentation, MotionSchedule, SceneMotionKind};
use crate::error::{Error, Result};

/// Most Gaussians a run may be configured for: 45 higher-band SH floats per Gaussian must stay
/// addressable with the kernels' 32-bit float indices.
pub const MAX_BUDGET: u32 = 1 << 26;

/// Learning rates (the official Deformable-3DGS code's, with DispFlow-GS's deformation rate;
/// docs/parity.md has each rule beside the official line).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LearningRates {
    pub position_init: f64,
    pub position_final: f64,
    pub position_delay_mult: f64,
    pub feature: f64,
    /// SH bands above 0 learn `feature / feature_rest_div`.
    pub feature_rest_div: f64,
    pub opacity: f64,
    pub scaling: f64,
    pub rotation: f64,
    /// Deformation MLP: `deform_init → deform_final`, exponential over `deform_max_steps`.
    pub deform_init: f64,
    pub deform_final: f64,
    /// Multiplier of the position and scaling rates. The official code hard-codes 5 for both,
    /// whatever the scene's size; 0 = this project's earlier rule: the position rate times the
    /// camera extent (3DGS's `spatial_lr_scale`), the scaling rate as it is.
    #[serde(default)]
    pub spatial_scale: f64,
    /// Steps the position rate decays over (official: 30 000, whatever the run's length);
    /// 0 = the run's iterations.
    #[serde(default)]
    pub position_max_steps: u32,
    /// Steps the deformation rate decays over (official: 40 000); 0 = the run's iterations.
    #[serde(default)]
    pub deform_max_steps: u32,
}

impl Default for LearningRates {
    fn default() -> Self {
        LearningRates {
            position_init: 0.00016,
            position_final: 0.0000016,
            position_delay_mult: 0.01,
            feature: 0.0025,
            feature_rest_div: 20.0,
            opacity: 0.05,
            scaling: 0.001,
            rotation: 0.001,
            // DispFlow-GS: "the spatial learning-rate scale for the deformation field is set
            // to 12" (the official Deformable-3DGS: 5); the final rate is not scaled.
            deform_init: 0.00016 * 12.0,
            deform_final: 0.0000016,
            spatial_scale: 5.0,
            position_max_steps: 30_000,
            deform_max_steps: 40_000,
        }
    }
}

impl LearningRates {
    /// Rates for runs of hundreds, not tens of thousands, of iterations. Adam moves a
    /// parameter by about its rate per step, so the paper's rates cannot carry a colour or a
    /// scale far in 600 steps: colour ×8, scale ×10, position ×4, and the deformation
    /// decaying 10× over the run instead of 500×. Measured at the fast preset, seed 0
    /// (issue 19's note): built-in 18.05 dB with the paper's rates, 19.80 with colour ×4 and
    /// scale ×5, 20.07 with these; movingnerf-capture1 18.45 → 20.20 dB (×4/×5). Positions
    /// scale with the camera extent and every rate decays over the run (the rule these were
    /// measured with).
    pub fn fast() -> Self {
        LearningRates {
            position_init: 0.00064,
            position_final: 0.0000064,
            feature: 0.02,
            scaling: 0.01,
            deform_init: 0.00016 * 5.0,
            deform_final: 0.00008,
            spatial_scale: 0.0,
            position_max_steps: 0,
            deform_max_steps: 0,
            ..LearningRates::default()
        }
    }

    /// The multipliers of the position and the scaling rates for a scene of camera extent
    /// `extent` (see [`LearningRates::spatial_scale`]).
    pub fn spatial(&self, extent: f32) -> (f64, f64) {
        if self.spatial_scale > 0.0 {
            (self.spatial_scale, self.spatial_scale)
        } else {
            (extent as f64, 1.0)
        }
    }
}

fn one_f32() -> f32 {
    1.0
}

/// Adaptive density control (3DGS, as the official Deformable-3DGS code runs it).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DensifyConfig {
    pub from: u32,
    /// Densification and its statistics stop before this iteration (exclusive, as the
    /// official `iteration < densify_until_iter`).
    pub until: u32,
    pub interval: u32,
    pub grad_threshold: f32,
    /// The statistic compared with `grad_threshold`: `abs` (the official rasteriser's: per
    /// pixel |∂L/∂mean2d| summed per component, then the norm; threshold 0.0007) or `norm`
    /// (3DGS's norm of the summed gradient; threshold 0.0002).
    #[serde(default)]
    pub grad_stat: GradStat,
    pub percent_dense: f32,
    pub min_opacity: f32,
    /// Screen-size prune (pixels) after the first opacity reset; 0 = off. The official code
    /// asks for 20 px, but `densification_postfix` zeroes the radii before the test, so it
    /// never removes anything there: the paper preset has 0 (issue 36: at 20 px our working
    /// test removed 96 % of the Gaussians at paper resolution).
    pub max_screen_size: f32,
    /// World-size prune after the first opacity reset: a Gaussian whose largest scale exceeds
    /// this fraction of the camera extent (official: 0.1); 0 = off. Independent of
    /// `max_screen_size`.
    #[serde(default = "tenth")]
    pub max_world_size: f32,
    pub opacity_reset_interval: u32,
    /// Most Gaussians the run may hold (buffers are allocated for this many).
    pub budget: u32,
}

fn tenth() -> f32 {
    0.1
}

/// The densification's gradient statistic (see [`DensifyConfig::grad_stat`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum GradStat {
    /// ‖Σ_pixels ∂L/∂mean_ndc‖ (3DGS).
    Norm,
    /// ‖Σ_pixels |∂L/∂mean_ndc|‖, componentwise absolute values (the official Deformable-3DGS
    /// rasteriser fork, as AbsGS).
    #[default]
    Abs,
}

impl Default for DensifyConfig {
    fn default() -> Self {
        DensifyConfig {
            from: 500,
            until: 15_000,
            interval: 100,
            grad_threshold: 0.0007,
            grad_stat: GradStat::Abs,
            percent_dense: 0.01,
            min_opacity: 0.005,
            max_screen_size: 0.0,
            max_world_size: 0.1,
            opacity_reset_interval: 3000,
            budget: 500_000,
        }
    }
}

/// How the image background is chosen for rendering and compositing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Background {
    /// Decided from the data before loading (`data::background`): the colour the views'
    /// transparent pixels agree on, black when they agree or carry no alpha. `train` resolves
    /// it and records the colour and the reason; what is saved in `config.toml` is the colour.
    Auto,
    Black,
    White,
    /// A random colour per step (training only; evaluation uses black).
    Random,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    pub iterations: u32,
    pub seed: u64,
    /// Highest SH degree (grown by one every `sh_interval` iterations).
    pub sh_degree: u32,
    pub sh_interval: u32,
    /// Largest image side after loading (box-downscaled); 0 = as stored.
    pub max_resolution: u32,
    pub mlp_width: u32,
    pub mlp_depth: u32,
    /// Iterations with D ≡ 0 before the deformation network is trained.
    pub warm_up: u32,
    /// Start the deformation head at zero (D = 0 exactly when the warm-up ends) instead of
    /// PyTorch's random init, which displaces and inflates every Gaussian at once.
    pub zero_deform_head: bool,
    /// Scale of the MLP's initial weight bounds: 1 = PyTorch's default `nn.Linear` init (the
    /// paper's), √6 ≈ 2.449 = He's uniform init for ReLU (the trunk's features keep their
    /// scale instead of shrinking ≈ 2.4× per layer, so a zero head learns fast).
    #[serde(default = "one_f32")]
    pub mlp_init_gain: f32,
    /// Frequencies of the MLP's positional encodings of x and of t; 0 = the paper's (x: 10;
    /// t: 10 on real captures, 6 through the time net on D-NeRF scenes). Fewer time
    /// frequencies make D smooth in t, so one frame's gradient teaches its neighbours.
    #[serde(default)]
    pub mlp_x_freqs: u32,
    #[serde(default)]
    pub mlp_t_freqs: u32,
    pub lambda_ssim: f32,
    pub background: Background,
    /// Time noise (AST) of Deformable-3DGS, as its `train.py` computes it: "auto" (on for real
    /// captures, off for D-NeRF scenes and the built-in scene, whose poses are exact), "on" or
    /// "off".
    pub time_noise: TimeNoise,
    pub lr: LearningRates,
    pub densify: DensifyConfig,
    pub log_interval: u32,
    pub checkpoint_interval: u32,
    /// Every this many iterations the run measures the mean test PSNR of a few test frames
    /// (render + loss only; not counted in the training time) for the PSNR-vs-time curve in
    /// `log.jsonl`; 0 = never.
    #[serde(default)]
    pub test_interval: u32,
    /// Motion loss weight α (displacement or Gaussian flow); 0 = the Deformable-3DGS baseline.
    pub motion_weight: f32,
    /// Iteration t0 from which the motion term is on (α_t ramps from 0.1·α to α after it).
    pub motion_start: u32,
    /// Normalisation of both magnitude maps.
    pub motion_normalize: crate::kernels::motion::NormMode,
    /// Temporal gap (in training frames sorted by time) between the frame and its pair.
    pub pair_gap: u32,
    /// Optical-flow preset: "fast", "default" or "accurate".
    pub flow_preset: String,
    /// Motion decomposition order: direct (intermediate (v1, t2), the paper's) or reverse
    /// (intermediate (v2, t1), the ablation).
    #[serde(default)]
    pub motion_order: MotionOrder,
    /// Gradient through the normalisation statistics: full (autograd through min/max, the
    /// default) or detached (constants). The loss is scale-free only with the full gradient;
    /// detached, every step also shrinks all displacements, and the deformation dies within
    /// ~450 iterations of the motion term's start (docs/motion_recipe.md).
    #[serde(default)]
    pub motion_norm_grad: NormGrad,
    /// Source of the scene motion: the TV-L1 estimator (the method) or, for synthetic scenes,
    /// their ground-truth scene flow (an oracle ablation that isolates the supervision from
    /// the estimator's quality).
    #[serde(default)]
    pub motion_flow: MotionFlow,
    /// The deformation network: on (Deformable-3DGS) or off (static 3D-GS, the paper's
    /// "3DGS" rows; no MLP is ever run).
    #[serde(default)]
    pub deform: DeformMode,
    /// Drop the dataset's initial points that no training camera sees or that sit within a
    /// camera's near range (see `train::init`); off in the paper preset (faithful), on in fast.
    #[serde(default)]
    pub init_filter: bool,
    /// Where the initial points come from: `official` (the paper preset: D-NeRF scenes read
    /// `points3d.ply` alone, else 100 000 random points in ±1.3) or `auto` (every point file
    /// the loader knows, `fused.ply` included, else random in a cube sized by the cameras).
    #[serde(default)]
    pub points: crate::data::points::PointsPreference,
    /// What `--iterations` does to the schedule: `proportional` (warm-up, motion start,
    /// densification window, resets, SH growth and intervals scale with it) or `absolute`
    /// (they stay at their iterations, as the official code's `--iterations`).
    #[serde(default)]
    pub schedule: ScheduleMode,
    /// Run the MLP over the dynamic Gaussians only (see [`SparsityConfig`]).
    #[serde(default)]
    pub sparsity: SparsityConfig,
    /// How the scene motion is measured and made robust (see [`SceneMotionConfig`]).
    #[serde(default)]
    pub scene_motion: SceneMotionConfig,
    /// What the motion term supervises: the displacement flow (DispFlow-GS) or the Gaussian
    /// flow (GaussianFlow / MotionGS); see `train::method`.
    #[serde(default)]
    pub motion_representation: MotionRepresentation,
    /// The motion weight's schedule (TS): ramp (on from `motion_start`, 0.1·α → α) or off
    /// (the full α from the end of the deformation warm-up).
    #[serde(default)]
    pub motion_schedule: MotionSchedule,
    /// Keep every checkpoint as `checkpoints/NNNNNN.ckpt` besides `last.ckpt` (for
    /// `dispflow-vk signal`, which scores the scene motion at several stages of one run).
    #[serde(default)]
    pub keep_checkpoints: bool,
    /// What a collapse (non-finite loss, or a lasting fall of the training PSNR) does.
    #[serde(default)]
    pub collapse: super::collapse::CollapseConfig,
    /// Time curriculum: train on a window of frames around the middle of the sequence that
    /// widens to all frames (see [`CurriculumConfig`]).
    #[serde(default)]
    pub curriculum: CurriculumConfig,
    /// The deformation field: the per-Gaussian MLP (Deformable-3DGS) or control nodes
    /// (SC-GS: the MLP at a few hundred nodes, blended into every Gaussian; docs/nodes.md).
    #[serde(default)]
    pub deform_field: crate::model::nodes::FieldConfig,
    /// Transient (time-local) Gaussians spawned from the residual (see [`TransientConfig`]).
    #[serde(default)]
    pub transient: TransientConfig,
}

/// Whether the model grows transient Gaussians.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum TransientMode {
    /// The canonical population alone (Deformable-3DGS).
    #[default]
    Off,
    /// Transients spawn where the frames with the largest residual are wrong.
    On,
    /// Transients only where the scene calls for them: nothing spawns (and no budget is
    /// reserved) until a frame's localized residual has persisted through `transient.gate`
    /// comparisons with at least `transient.uncovered` of its wrong pixels drawn by nothing
    /// (the canonical population has shown it cannot draw what is missing there), or with
    /// `transient.unexplained` of them in a colour drawn nowhere near, in a round where many
    /// frames read so (content that appears and vanishes); the same rules judge every round
    /// after. A scene that never opens the gate holds no transient row and trains exactly as
    /// `off`.
    Auto,
}

impl TransientMode {
    /// Whether the run may spawn transients (spawn rounds, their knobs checked).
    pub fn spawns(self) -> bool {
        self != TransientMode::Off
    }
}

/// Transient Gaussians (issue 37, `kernels::temporal`): a second population, local in time,
/// for what one canonical space plus a deformation cannot draw (an object that moves most of
/// its size per frame under a new camera each frame, appears, vanishes or splits). Every
/// `every` steps in [`from`, `until`] × iterations, `3 × frames` training frames spread over
/// time are rendered; of the `frames` with the largest localized residual, the `pixels` worst
/// pixels above `min_error` (and three times the frame's median error) are back-projected at
/// `depths` depths along the ray inside the scene's bounds into transients centred at that
/// frame's time (`train::transients`). Times are in frame spacings (the median gap
/// between consecutive training times), so no transient lives in one camera's view only.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TransientConfig {
    pub mode: TransientMode,
    /// σ's floor, in frame spacings.
    pub floor_frames: f32,
    /// A new transient's σ, in frame spacings (at least the floor).
    pub init_frames: f32,
    /// Opacity factors below this are culled before projection.
    pub cutoff: f32,
    pub every: u32,
    pub from: f32,
    pub until: f32,
    pub frames: u32,
    pub pixels: u32,
    /// Depths along the ray at which a pixel that is not tracked spawns still transients
    /// (0: an untracked pixel spawns nothing; needs `track` > 0). A wrong-depth transient is
    /// a floater in every other view.
    pub depths: u32,
    /// Temporal neighbours each side (0: off) whose residuals a wrong pixel is tracked through
    /// (`train::transients::track`): a pixel whose residual a point moving at a constant velocity explains
    /// in them spawns one transient there, with that velocity, instead of `depths` still ones.
    pub track: u32,
    /// Mean absolute RGB error (colours in [0, 1]) a pixel needs to spawn transients.
    pub min_error: f32,
    /// Opacity of a new transient.
    pub init_opacity: f32,
    /// Spawn only from a frame whose localized residual is at least this fraction of what it
    /// was when the frame was last looked at (0: off, spawn on the first look). A residual that
    /// training is still shrinking (the deformation learning the motion) is left to training;
    /// one that persists (an object the canonical model cannot draw) spawns. A frame's first
    /// look only records its residual; with `persist` on, each set of candidate frames is
    /// looked at by two successive spawns, `every` steps apart (three under `auto`'s closed
    /// gate, `gate`). 0.8 by default: the best rows
    /// of `--transients on` on an H100 at two seeds (docs/usage.md).
    pub persist: f32,
    /// Under `auto`, the successive persisting comparisons (each `every` steps apart, each
    /// kept `persist` of the last) a frame's residual needs before the run's first spawn; `on`
    /// needs one. More is a stricter test of "the canonical population cannot draw it".
    pub gate: u32,
    /// Under `auto`, the share of a held frame's wrong pixels where the model draws nothing
    /// (coverage 1 − T under ½) it needs to spawn (to open the gate, and at every round after):
    /// an object missing from the model,
    /// where densification has no Gaussian to clone or split, and not one drawn wrong, which
    /// the canonical population can still fix. Measured before any spawn (docs/usage.md):
    /// 1.0 on mujoco-scene5 (white), at most 0.32 on D-NeRF bouncingballs, 0.13 on scene7.
    pub uncovered: f32,
    /// Under `auto`, the localized residual (mean absolute RGB error summed over the wrong
    /// pixels) per pixel of the frame that a held frame needs to spawn (the opening and every
    /// round after): the missing region must matter. 0.01 by default: at the gate's opening on mujoco-scene5 the frames
    /// read 0.019–0.031, on D-NeRF hellwarrior (a dark figure on black, whose thin parts are
    /// bare) 0.002–0.004, where opening cost 0.30 dB.
    pub min_residual: f32,
    /// Under `auto`, a second way through the coverage rule (`uncovered`): a frame whose wrong
    /// pixels hold at least this share whose true colour the render draws nowhere within 6
    /// pixels (`train::transients::residual::explained`: an object the model lacks at this
    /// time, drawn in front of a surface it does hold, as the built-in `events` scene's
    /// spheres that appear and vanish before textured walls) spawns in a round where at least
    /// `unexplained_frames` of the frames looked at read so with a residual that matters
    /// (`min_residual`), once the deformation trains (before, every render is still and a
    /// moving object is drawn nowhere near in any scene). 0: off. Measured per round
    /// (docs/measurements.md, "The `events` gate"): `events` reads so in 7 of 12 frames from
    /// round 800 of 1 800, D-NeRF's closed scenes in at most 3.
    pub unexplained: f32,
    /// The share of a round's looked-at frames that must read `unexplained` for any to spawn
    /// through it: one frame that lacks an object is a pose the deformation has not learnt,
    /// many at once are a scene whose content changes.
    pub unexplained_frames: f32,
    /// Under `auto`, whether a still depth hypothesis (a wrong pixel no track explains,
    /// spawned at `depths` depths) must be confirmed by a temporal neighbour (`track` > 0)
    /// that sees it: wrong there, with the pixel's ground-truth patch, as a track's evidence
    /// (`Tracker::confirms_still`; one no neighbour sees is kept). A hypothesis at the wrong
    /// depth is a floater in the other views (D-NeRF trex, seed 0: +0.68 dB with the check);
    /// but a still hypothesis on a moving figure is rejected too (standup, seed 2: −1.94 dB).
    /// Off by default: over 10 runs it is a wash (docs/measurements.md, "Confirming depth
    /// hypotheses").
    pub confirm: bool,
    /// Whether a pixel's still depth hypotheses are alternatives: at the first densification
    /// or spawn after they were spawned (at most `every` steps later), each pixel keeps its
    /// most opaque hypothesis and the others are dropped (opacity logit −30, moments zeroed,
    /// so densification prunes them). Training in between has seen them from the other views
    /// of their lifetime, where a wrong depth is a floater that densification would grow.
    /// On by default: D-NeRF trex +0.40 dB, standup seed 1 +0.55, mujoco-scene5 in the masks
    /// +0.01 / +0.26 over `auto` without it (docs/measurements.md, "Depth hypotheses as
    /// alternatives"). Checkpoints carry the pending ones.
    pub resolve: bool,
    /// The share of the Gaussian budget kept for transients: the canonical population starts
    /// and densifies within the rest (so a scene whose initial points fill the budget still
    /// has room to spawn). A reservation, not a ceiling: transients spawn, clone and split
    /// into any free row, those the canonical population leaves unused included.
    pub max_share: f32,
    /// Learning rates of the time centre (time units), of the log-width, and of the velocity
    /// as a multiple of the position rate per σ floor (a transient then moves about as far
    /// within its life per step as a canonical Gaussian does).
    pub lr_centre: f64,
    pub lr_width: f64,
    pub lr_velocity_mult: f64,
    /// Whether the motion term's gradient reaches a transient's time centre and width through
    /// its temporal weight in the blend of the displacement (or Gaussian-flow) channels:
    /// `attached` (the default: the photometric render blends those channels with the same
    /// weights as its colour and one backward carries both) or `detached` (the weight is a
    /// constant there; c and σ learn from the photometric outputs alone). Either way v gets
    /// the term's gradient through v·(t2 − t1), and the base opacity through every output.
    pub motion_weights: MotionWeights,
}

/// How a transient's temporal weight enters the motion term's backward ([`TransientConfig`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MotionWeights {
    #[default]
    Attached,
    Detached,
}

impl Default for TransientConfig {
    fn default() -> Self {
        TransientConfig {
            mode: TransientMode::Off,
            floor_frames: 3.0,
            init_frames: 5.0,
            cutoff: 0.01,
            every: 100,
            from: 0.2,
            until: 0.8,
            frames: 4,
            pixels: 64,
            depths: 4,
            track: 2,
            confirm: false,
            resolve: true,
            min_error: 0.12,
            init_opacity: 0.7,
            persist: 0.8,
            gate: 2,
            uncovered: 0.5,
            min_residual: 0.01,
            unexplained: 0.1,
            unexplained_frames: 0.4,
            max_share: 0.25,
            lr_centre: 0.002,
            lr_width: 0.01,
            lr_velocity_mult: 1.0,
            motion_weights: MotionWeights::Attached,
        }
    }
}

/// A time curriculum: the training frames are drawn from the frames whose time ranks lie in a
/// window (centred on the sequence's middle, or from its first frame: `anchor`), covering
/// `start` of the frames through the deformation's warm-up and widening linearly to all of
/// them at `until` × iterations. The canonical
/// Gaussians then fit one instant sharply instead of averaging a moving object along its path
/// (a smear the photometric gradient cannot pull back), and the deformation learns the motion
/// outwards from that instant a little at a time, where each new time needs a displacement
/// of a fraction of the object's size. `start = 1`: off (every frame from the start).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CurriculumConfig {
    pub start: f32,
    pub until: f32,
    /// Where the window starts: `middle` (centred on the sequence's middle, widening both
    /// ways) or `first` (the earliest frames, widening forwards: sequential training).
    pub anchor: CurriculumAnchor,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CurriculumAnchor {
    #[default]
    Middle,
    First,
}

impl Default for CurriculumConfig {
    fn default() -> Self {
        CurriculumConfig {
            start: 1.0,
            until: 0.0,
            anchor: CurriculumAnchor::Middle,
        }
    }
}

/// The scene-motion signal's knobs (issue 16; each measured in its closing note). The flow
/// fields override the `flow_preset`'s.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SceneMotionConfig {
    /// Subtract the flow photo → render (v1, t1) from the flow photo → render (v1, t2): what
    /// reconstruction error alone reads as motion (direct order, optical flow only).
    pub residual: bool,
    /// Confidence σ: pixels weigh exp(−mean|photo − render(v1, t1)| / σ) in the motion L1
    /// (normalised by the pixel count); 0 = off (direct order only).
    pub confidence: f32,
    /// The motion term runs on every this-many-th step after its start (1 = every step).
    pub every: u32,
    /// Binomial blur passes on the photo's grey image before the flow (σ = √k px).
    pub blur_photo: u32,
    /// Structure–texture factor β: both images become I − β·blur(I) before the flow; 0 = off.
    pub texture: f32,
    /// Finest pyramid level the flow is solved at (0 = full resolution), upsampled after.
    pub level: u32,
    /// Which scene motion (see [`SceneMotionKind`]): direct (the method), indirect (MotionGS)
    /// or none (the raw pair flow).
    pub kind: SceneMotionKind,
    /// Motion-mask filtering: scene motion shorter than this many pixels is set to 0 (the
    /// paper's "motion mask filtering" ablation); 0 = off.
    pub mask_px: f32,
}

impl Default for SceneMotionConfig {
    fn default() -> Self {
        SceneMotionConfig {
            residual: false,
            confidence: 0.0,
            every: 1,
            blur_photo: 0,
            texture: 0.0,
            level: 0,
            kind: SceneMotionKind::Direct,
            mask_px: 0.0,
        }
    }
}

impl SceneMotionConfig {
    /// The flow preset with this configuration's overrides (validated).
    pub fn flow_config(
        &self,
        preset: &str,
    ) -> crate::error::Result<crate::kernels::flow::FlowConfig> {
        let c = crate::kernels::flow::FlowConfig {
            blur_a: self.blur_photo,
            texture: self.texture,
            finest: self.level,
            ..crate::kernels::flow::FlowConfig::preset(preset)?
        };
        c.validate()?;
        Ok(c)
    }

    /// The residual correction and confidence of the scene signal.
    pub fn signal(&self) -> crate::train::passes::SignalConfig {
        crate::train::passes::SignalConfig {
            residual: self.residual,
            sigma: self.confidence,
            mask_px: self.mask_px,
        }
    }
}

/// How `--iterations` changes the schedule (see [`TrainConfig::schedule`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum ScheduleMode {
    #[default]
    Proportional,
    Absolute,
}

/// Whether the scene is modelled with a deformation at all.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DeformMode {
    #[default]
    On,
    /// Static 3D-GS: D ≡ 0 for the whole run.
    Off,
}

/// Whether the Gaussians are split into dynamic and static ones.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SparsityMode {
    /// Every Gaussian through the MLP at every step (Deformable-3DGS). The default: `auto`
    /// measured 0.15–0.3 dB lower test PSNR on mujoco-scene7 and movingnerf-capture1 at the
    /// fast preset (issue 15's note), so it stays a speed knob.
    #[default]
    Off,
    /// Probe the deformation and run the MLP over the dynamic Gaussians only.
    Auto,
}

/// The dynamic/static split's schedule and threshold. Times are fractions of the
/// deformation's iterations (`iterations − warm_up`), so `--iterations` alone keeps the
/// schedule coherent. The first split comes at `start`; then every `every` the model is dense
/// again for the last `dense_window` (a fraction of `every`) iterations before it is split
/// anew (a static Gaussian whose region started to move gets MLP gradients there and is
/// found again), and right after each densification (children are probed, never guessed).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SparsityConfig {
    pub mode: SparsityMode,
    /// Largest motion D may give a static Gaussian, in pixels of the training view where it
    /// looks largest, at any probed time ...
    pub threshold_px: f32,
    /// ... or this multiple of the median Gaussian's, when larger (the MLP moves every
    /// Gaussian a little; real motion stands out from that floor). 0 = the absolute
    /// threshold alone.
    pub noise_k: f32,
    /// Times D is probed at (evenly over the training frames' time range).
    pub probe_times: u32,
    pub start: f32,
    pub every: f32,
    pub dense_window: f32,
}

impl Default for SparsityConfig {
    fn default() -> Self {
        SparsityConfig {
            mode: SparsityMode::Off,
            threshold_px: 0.5,
            noise_k: 3.0,
            probe_times: 8,
            start: 0.25,
            every: 0.25,
            dense_window: 0.2,
        }
    }
}

/// Where the motion step's scene motion comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MotionFlow {
    /// flow(frame, intermediate render) from the GPU TV-L1 estimator.
    #[default]
    Tvl1,
    /// The dataset's ground-truth 2D scene flow of the frame (synthetic scenes; direct order).
    Oracle,
}

/// How the motion loss differentiates the magnitude normalisation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum NormGrad {
    /// Statistics (min, max, …) are constants of the backward pass (an ablation: it adds a
    /// shrinking direction that a scale-free loss does not have).
    Detached,
    /// Autograd semantics: gradients also flow through the statistics.
    #[default]
    Full,
}

/// Which intermediate image separates scene motion from camera motion (DESIGN §2).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MotionOrder {
    /// (v1,t1) → (v1,t2) → (v2,t2): scene motion under the photometrically supervised view.
    #[default]
    Direct,
    /// (v1,t1) → (v2,t1) → (v2,t2): scene motion under the pair's view (ablation).
    Reverse,
}

impl Default for TrainConfig {
    fn default() -> Self {
        TrainConfig::paper()
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TimeNoise {
    Auto,
    On,
    Off,
}

/// Named starting points for the configuration.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// The paper's setting: 20 000 iterations, 8×256 MLP, warm-up 3000, densify 500–15 000.
    Paper,
    /// Minutes on a CPU: 600 iterations, 4×64 MLP, warm-up 200, densify 100–450 (no opacity
    /// reset), SH degree 1, short-run learning rates, initial points filtered.
    Fast,
}

impl TrainConfig {
    pub fn paper() -> Self {
        TrainConfig {
            iterations: 20_000,
            seed: 0,
            sh_degree: 3,
            sh_interval: 1000,
            max_resolution: 0,
            mlp_width: 256,
            mlp_depth: 8,
            warm_up: 3000,
            // PyTorch's default init of the heads, as the official code (docs/parity.md).
            zero_deform_head: false,
            mlp_init_gain: 1.0,
            mlp_x_freqs: 0,
            mlp_t_freqs: 0,
            lambda_ssim: 0.2,
            background: Background::Black,
            time_noise: TimeNoise::Auto,
            lr: LearningRates::default(),
            densify: DensifyConfig::default(),
            log_interval: 100,
            checkpoint_interval: 2000,
            test_interval: 1000,
            motion_weight: 0.1,
            motion_start: 10_000,
            motion_normalize: crate::kernels::motion::NormMode::MinMax,
            pair_gap: 1,
            flow_preset: "default".into(),
            motion_order: MotionOrder::Direct,
            motion_norm_grad: NormGrad::Full,
            motion_flow: MotionFlow::Tvl1,
            deform: DeformMode::On,
            init_filter: false,
            points: crate::data::points::PointsPreference::Official,
            schedule: ScheduleMode::Absolute,
            sparsity: SparsityConfig::default(),
            scene_motion: SceneMotionConfig::default(),
            motion_representation: MotionRepresentation::Displacement,
            motion_schedule: MotionSchedule::Ramp,
            keep_checkpoints: false,
            collapse: super::collapse::CollapseConfig::default(),
            curriculum: CurriculumConfig::default(),
            deform_field: Default::default(),
            transient: TransientConfig::default(),
        }
    }

    pub fn fast() -> Self {
        TrainConfig {
            iterations: 600,
            sh_degree: 1,
            sh_interval: 500,
            max_resolution: 160,
            mlp_width: 64,
            mlp_depth: 4,
            warm_up: 200,
            // 3DGS's statistic and threshold, measured with the rates below; the size prunes
            // never come (the first opacity reset would be at 1000 of 600).
            densify: DensifyConfig {
                from: 100,
                until: 450,
                interval: 100,
                grad_threshold: 0.0002,
                grad_stat: GradStat::Norm,
                max_screen_size: 20.0,
                opacity_reset_interval: 1000,
                budget: 20_000,
                ..DensifyConfig::default()
            },
            log_interval: 50,
            checkpoint_interval: 200,
            test_interval: 50,
            init_filter: true,
            points: crate::data::points::PointsPreference::Auto,
            schedule: ScheduleMode::Proportional,
            zero_deform_head: true,
            lr: LearningRates::fast(),
            motion_start: 400,
            // Issue 57: the colour the views' transparent pixels agree on (white for a white
            // floor seen through from some views; black on D-NeRF and the built-in scene).
            background: Background::Auto,
            // The scene motion that scored and trained best here (issue 16's note): the fast
            // TV-L1 (4 levels, 2 warps, 10 iterations) solved down to half resolution only.
            flow_preset: "fast".into(),
            scene_motion: SceneMotionConfig {
                level: 1,
                ..SceneMotionConfig::default()
            },
            // Issue 28's note: the step 2.8× (built-in) to 3.5× (mujoco-scene7) faster at the
            // same test PSNR at equal iterations, +1.6 dB at equal training time.
            deform_field: crate::model::nodes::FieldConfig {
                kind: crate::model::nodes::FieldKind::Nodes,
                ..Default::default()
            },
            // Issue 57: transients only where a residual persists (the paper preset: none).
            transient: TransientConfig {
                mode: TransientMode::Auto,
                ..TransientConfig::default()
            },
            ..TrainConfig::paper()
        }
    }

    pub fn preset(p: Preset) -> Self {
        match p {
            Preset::Paper => TrainConfig::paper(),
            Preset::Fast => TrainConfig::fast(),
        }
    }

    /// Gaussians the canonical population may start with: the budget less the transients'
    /// share when they are on (`auto` reserves nothing before its first spawn).
    pub fn canonical_budget(&self) -> u32 {
        match self.transient.mode {
            TransientMode::On => self.densify.budget - self.transient_share(),
            TransientMode::Off | TransientMode::Auto => self.densify.budget,
        }
    }

    /// The budget rows densification keeps free for transients once they are spawned (`on`:
    /// from the start), 0 without them.
    pub fn transient_share(&self) -> u32 {
        if !self.transient.mode.spawns() {
            return 0;
        }
        let b = self.densify.budget as f64 * (1.0 - self.transient.max_share as f64);
        self.densify.budget - (b as u32).max(1)
    }

    /// The same run in proportion over `n` iterations: every schedule point counted in
    /// iterations (warm-up, motion start, SH growth, densification window, opacity resets,
    /// checkpoint and test-PSNR intervals) scales by `n / iterations`, so `--iterations` alone
    /// gives a coherent run; the test-PSNR interval does not fall below the log interval.
    /// Kept as they are: the densification interval (3DGS accumulates its gradient statistics
    /// over 100 steps whatever the length) and the log interval. The
    /// learning-rate decays and the sparsity schedule already span the run. With
    /// `schedule = absolute` (the paper preset, as the official `--iterations`) only the
    /// iteration count changes.
    pub fn with_iterations(&self, n: u32) -> TrainConfig {
        let mut c = self.clone();
        if n == self.iterations {
            return c;
        }
        if self.schedule == ScheduleMode::Absolute {
            c.iterations = n;
            return c;
        }
        let r = n as f64 / self.iterations.max(1) as f64;
        let scale = |v: u32| (v as f64 * r).round() as u32;
        let scale1 = |v: u32| scale(v).max(1);
        c.iterations = n;
        c.warm_up = scale(self.warm_up);
        c.motion_start = scale(self.motion_start);
        c.sh_interval = scale1(self.sh_interval);
        c.checkpoint_interval = scale1(self.checkpoint_interval);
        // A probe renders every probe frame: no more often than the log lines (unless the
        // preset probes more often), or a 30-iteration run spends a third of its time probing.
        c.test_interval = if self.test_interval == 0 {
            0
        } else {
            scale1(self.test_interval).max(self.test_interval.min(self.log_interval))
        };
        let d = &mut c.densify;
        d.from = scale(self.densify.from);
        d.until = scale(self.densify.until).min(n);
        d.opacity_reset_interval = scale1(self.densify.opacity_reset_interval);
        c
    }

    /// Reads a TOML file (every field optional over `base`).
    pub fn from_toml_over(base: &TrainConfig, path: &std::path::Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_toml_str_over(base, &text, &path.display().to_string())
    }

    /// Like [`TrainConfig::from_toml_over`] for TOML text; errors name `origin`.
    pub fn from_toml_str_over(base: &TrainConfig, text: &str, origin: &str) -> Result<Self> {
        let mut merged = toml::Value::try_from(base).expect("config serialises");
        let user: toml::Value =
            toml::from_str(text).map_err(|e| Error::Invalid(format!("{origin}: {e}")))?;
        merge(&mut merged, user);
        let cfg: TrainConfig = merged
            .try_into()
            .map_err(|e| Error::Invalid(format!("{origin}: {e}")))?;
        cfg.problem()
            .map_err(|m| Error::Invalid(format!("{origin}: {m}")))?;
        Ok(cfg)
    }

    /// The deformation MLP's shape as configured (the model builds its layout from it).
    pub fn mlp_shape(&self) -> crate::model::state::MlpShape {
        crate::model::state::MlpShape {
            depth: self.mlp_depth,
            width: self.mlp_width,
            x_freqs: self.mlp_x_freqs,
            t_freqs: self.mlp_t_freqs,
        }
    }

    /// How a run loads its dataset (resolution, background of transparent images, seed).
    /// `auto` loads on black here: `train` resolves it first ([`Self::with_background_from`]).
    pub fn load_options(&self) -> crate::data::LoadOptions {
        let bg = match self.background {
            Background::White => [1.0; 3],
            _ => [0.0; 3],
        };
        crate::data::LoadOptions {
            max_size: (self.max_resolution > 0).then_some(self.max_resolution),
            background: bg,
            points: self.points,
            seed: self.seed,
            ..crate::data::LoadOptions::default()
        }
    }

    /// This configuration with `background = auto` resolved from the dataset at `dir`, and
    /// what was picked and why (`None` when the background was given).
    pub fn with_background_from(
        &self,
        dir: &std::path::Path,
    ) -> Result<(TrainConfig, Option<crate::data::background::BackgroundPick>)> {
        if self.background != Background::Auto {
            return Ok((self.clone(), None));
        }
        let pick = crate::data::background::pick_background(dir)?;
        let mut c = self.clone();
        c.background = if pick.white {
            Background::White
        } else {
            Background::Black
        };
        Ok((c, Some(pick)))
    }

    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).expect("config serialises")
    }

    /// Rejects every setting that would crash (a zero divisor, an out-of-range degree) or
    /// poison training (a non-finite or negative weight or learning rate), naming the field,
    /// the value found and what was expected. Runs before any file is loaded or written.
    pub fn validate(&self) -> Result<()> {
        self.problem().map_err(Error::Invalid)
    }

    /// What [`TrainConfig::validate`] rejects, as a message.
    fn problem(&self) -> std::result::Result<(), String> {
        fn bad(
            field: &str,
            found: impl std::fmt::Display,
            want: &str,
        ) -> std::result::Result<(), String> {
            Err(format!("config field {field} = {found}: expected {want}"))
        }
        let at_least_1 = |field: &str, v: u32| {
            if v == 0 {
                bad(field, v, "at least 1")
            } else {
                Ok(())
            }
        };
        let non_negative = |field: &str, v: f64| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                bad(field, v, "a finite value >= 0")
            }
        };
        let unit = |field: &str, v: f64| {
            if v.is_finite() && (0.0..=1.0).contains(&v) {
                Ok(())
            } else {
                bad(field, v, "a value in [0, 1]")
            }
        };
        at_least_1("iterations", self.iterations)?;
        if self.sh_degree > 3 {
            bad("sh_degree", self.sh_degree, "0, 1, 2 or 3")?;
        }
        // Divisors of the schedules (`iteration % interval`).
        at_least_1("sh_interval", self.sh_interval)?;
        at_least_1("log_interval", self.log_interval)?;
        at_least_1("checkpoint_interval", self.checkpoint_interval)?;
        at_least_1("densify.interval", self.densify.interval)?;
        at_least_1(
            "densify.opacity_reset_interval",
            self.densify.opacity_reset_interval,
        )?;
        at_least_1("pair_gap", self.pair_gap)?;
        at_least_1("densify.budget", self.densify.budget)?;
        if self.densify.budget > MAX_BUDGET {
            bad(
                "densify.budget",
                self.densify.budget,
                &format!("at most {MAX_BUDGET} (the kernels index floats with 32 bits)"),
            )?;
        }
        // The MLP kernels' limits (MlpConfig::validate), checked here to name the field.
        if !(1..=64).contains(&self.mlp_depth) {
            bad("mlp_depth", self.mlp_depth, "1..=64")?;
        }
        if !(1..=4096).contains(&self.mlp_width) {
            bad("mlp_width", self.mlp_width, "1..=4096")?;
        }
        if self.mlp_x_freqs > 24 {
            bad("mlp_x_freqs", self.mlp_x_freqs, "0 (the paper's 10) ..= 24")?;
        }
        if self.mlp_t_freqs > 24 {
            bad("mlp_t_freqs", self.mlp_t_freqs, "0 (the paper's) ..= 24")?;
        }
        if !(self.mlp_init_gain.is_finite() && self.mlp_init_gain > 0.0) {
            bad("mlp_init_gain", self.mlp_init_gain, "a finite value > 0")?;
        }
        self.deform_field.validate().map_err(|e| e.to_string())?;
        unit("curriculum.start", self.curriculum.start as f64)?;
        unit("curriculum.until", self.curriculum.until as f64)?;
        if !(self.collapse.drop_db.is_finite() && self.collapse.drop_db > 0.0) {
            bad(
                "collapse.drop_db",
                self.collapse.drop_db,
                "a finite value > 0 (dB)",
            )?;
        }
        unit("lambda_ssim", self.lambda_ssim as f64)?;
        non_negative("motion_weight", self.motion_weight as f64)?;
        let lr = &self.lr;
        for (field, v) in [
            ("lr.position_init", lr.position_init),
            ("lr.position_final", lr.position_final),
            ("lr.feature", lr.feature),
            ("lr.opacity", lr.opacity),
            ("lr.scaling", lr.scaling),
            ("lr.rotation", lr.rotation),
            ("lr.deform_init", lr.deform_init),
            ("lr.deform_final", lr.deform_final),
        ] {
            non_negative(field, v)?;
        }
        unit("lr.position_delay_mult", lr.position_delay_mult)?;
        if !(lr.feature_rest_div.is_finite() && lr.feature_rest_div > 0.0) {
            bad(
                "lr.feature_rest_div",
                lr.feature_rest_div,
                "a finite value > 0 (a divisor)",
            )?;
        }
        // Exponential schedules interpolate ln(rate): a single zero end gives ln(0)·0 = NaN.
        for (name, a, b) in [
            (
                "lr.position_init/lr.position_final",
                lr.position_init,
                lr.position_final,
            ),
            (
                "lr.deform_init/lr.deform_final",
                lr.deform_init,
                lr.deform_final,
            ),
        ] {
            if (a == 0.0) != (b == 0.0) {
                bad(
                    name,
                    format!("{a}/{b}"),
                    "both > 0 (an exponential schedule), or both 0 (frozen)",
                )?;
            }
        }
        let d = &self.densify;
        non_negative("densify.grad_threshold", d.grad_threshold as f64)?;
        non_negative("densify.percent_dense", d.percent_dense as f64)?;
        unit("densify.min_opacity", d.min_opacity as f64)?;
        non_negative("densify.max_screen_size", d.max_screen_size as f64)?;
        if crate::kernels::flow::FlowConfig::preset(&self.flow_preset).is_err() {
            bad(
                "flow_preset",
                format!("{:?}", self.flow_preset),
                "one of \"fast\", \"default\", \"accurate\"",
            )?;
        }
        if self.motion_weight > 0.0
            && self.motion_flow == MotionFlow::Oracle
            && self.motion_order == MotionOrder::Reverse
        {
            bad(
                "motion_flow",
                "\"oracle\" with motion_order = \"reverse\"",
                "motion_order = \"direct\" (the oracle gives the flow under the frame's own view)",
            )?;
        }
        if self.deform == DeformMode::Off && self.motion_weight > 0.0 {
            bad(
                "motion_weight",
                self.motion_weight,
                "0 with deform = \"off\" (a static scene has no displacement flow)",
            )?;
        }
        let sm = &self.scene_motion;
        at_least_1("scene_motion.every", sm.every)?;
        non_negative("scene_motion.confidence", sm.confidence as f64)?;
        if !(0.0..1.0).contains(&sm.texture) {
            bad("scene_motion.texture", sm.texture, "a factor β in [0, 1)")?;
        }
        if let Err(e) = sm.flow_config(&self.flow_preset) {
            bad("scene_motion", e, "flow settings the estimator accepts")?;
        }
        let corrected = sm.residual || sm.confidence > 0.0;
        if self.motion_weight > 0.0 && corrected && self.motion_order == MotionOrder::Reverse {
            bad(
                "scene_motion.residual/confidence",
                "on with motion_order = \"reverse\"",
                "motion_order = \"direct\" (they compare the photo with the render at (v1, t1))",
            )?;
        }
        if self.motion_weight > 0.0 && sm.residual && self.motion_flow == MotionFlow::Oracle {
            bad(
                "scene_motion.residual",
                "true with motion_flow = \"oracle\"",
                "false (the oracle has no reconstruction error to remove)",
            )?;
        }
        non_negative("scene_motion.mask_px", sm.mask_px as f64)?;
        if self.motion_weight > 0.0 {
            super::method::validate(self)?;
        }
        let tc = &self.transient;
        if tc.mode.spawns() {
            at_least_1("transient.every", tc.every)?;
            at_least_1("transient.frames", tc.frames)?;
            at_least_1("transient.pixels", tc.pixels)?;
            if tc.depths == 0 && tc.track == 0 {
                bad(
                    "transient.depths",
                    tc.depths,
                    "at least 1 when transient.track = 0 (else nothing spawns)",
                )?;
            }
        }
        for (field, v) in [
            ("transient.floor_frames", tc.floor_frames),
            ("transient.init_frames", tc.init_frames),
        ] {
            if !(v.is_finite() && v > 0.0) {
                bad(field, v, "a finite value > 0 (frame spacings)")?;
            }
        }
        unit("transient.cutoff", tc.cutoff as f64)?;
        unit("transient.from", tc.from as f64)?;
        unit("transient.until", tc.until as f64)?;
        unit("transient.max_share", tc.max_share as f64)?;
        unit("transient.persist", tc.persist as f64)?;
        unit("transient.uncovered", tc.uncovered as f64)?;
        unit("transient.min_residual", tc.min_residual as f64)?;
        unit("transient.unexplained", tc.unexplained as f64)?;
        unit("transient.unexplained_frames", tc.unexplained_frames as f64)?;
        unit("transient.init_opacity", tc.init_opacity as f64)?;
        if !(tc.init_opacity > 0.0 && tc.init_opacity < 1.0) {
            bad(
                "transient.init_opacity",
                tc.init_opacity,
                "a value in (0, 1)",
            )?;
        }
        non_negative("transient.min_error", tc.min_error as f64)?;
        non_negative("transient.lr_centre", tc.lr_centre)?;
        non_negative("transient.lr_width", tc.lr_width)?;
        non_negative("transient.lr_velocity_mult", tc.lr_velocity_mult)?;
        let sp = &self.sparsity;
        non_negative("sparsity.threshold_px", sp.threshold_px as f64)?;
        non_negative("sparsity.noise_k", sp.noise_k as f64)?;
        at_least_1("sparsity.probe_times", sp.probe_times)?;
        unit("sparsity.start", sp.start as f64)?;
        unit("sparsity.dense_window", sp.dense_window as f64)?;
        if !(sp.every.is_finite() && sp.every > 0.0 && sp.every <= 1.0) {
            bad("sparsity.every", sp.every, "a value in (0, 1]")?;
        }
        Ok(())
    }
}

fn merge(base: &mut toml::Value, over: toml::Value) {
    match (base, over) {
        (toml::Value::Table(b), toml::Value::Table(o)) => {
            for (k, v) in o {
                match b.get_mut(&k) {
                    Some(bv) => merge(bv, v),
                    None => {
                        b.insert(k, v);
                    }
                }
            }
        }
        (b, o) => *b = o,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every iteration-counted schedule point as a fraction of the run.
    fn fractions(c: &TrainConfig) -> Vec<f64> {
        let n = c.iterations as f64;
        [
            c.warm_up,
            c.motion_start,
            c.sh_interval,
            c.densify.from,
            c.densify.until,
            c.densify.opacity_reset_interval,
            c.checkpoint_interval,
        ]
        .iter()
        .map(|&v| v as f64 / n)
        .collect()
    }

    #[test]
    fn iterations_scale_the_schedule_in_proportion() {
        let proportional_paper = TrainConfig {
            schedule: ScheduleMode::Proportional,
            ..TrainConfig::paper()
        };
        for base in [TrainConfig::fast(), proportional_paper.clone()] {
            assert_eq!(base.with_iterations(base.iterations), base);
            for n in [base.iterations * 5, base.iterations / 2, 3000] {
                let c = base.with_iterations(n);
                c.validate().unwrap();
                assert_eq!(c.iterations, n);
                for (f, f0) in fractions(&c).iter().zip(fractions(&base)) {
                    // Rounding to whole iterations is the only difference.
                    assert!(
                        (f - f0).abs() <= 0.5 / n as f64 + 1e-12,
                        "{f} vs {f0} at {n}"
                    );
                }
                assert_eq!(c.densify.interval, base.densify.interval);
                assert_eq!(c.log_interval, base.log_interval);
                // Test probes scale too, but never more often than the log lines.
                let probes =
                    (base.test_interval as f64 * n as f64 / base.iterations as f64).round() as u32;
                let floor = base.test_interval.min(base.log_interval);
                assert_eq!(c.test_interval, probes.max(floor), "at {n}");
                assert_eq!(c.lr, base.lr);
            }
        }
        // The fast preset over 3000 iterations: warm-up and densification in proportion.
        let c = TrainConfig::fast().with_iterations(3000);
        assert_eq!((c.warm_up, c.motion_start), (1000, 2000));
        assert_eq!((c.densify.from, c.densify.until), (500, 2250));
        // Tiny runs keep every divisor at least 1 and the window inside the run.
        let c = proportional_paper.with_iterations(3);
        c.validate().unwrap();
        assert!(c.densify.until <= 3 && c.sh_interval >= 1 && c.checkpoint_interval >= 1);
        // A short fast run probes at its log lines (and the end), not every 3 iterations.
        let c = TrainConfig::fast().with_iterations(30);
        assert_eq!((c.test_interval, c.log_interval), (50, 50));
        assert_eq!(TrainConfig::fast().with_iterations(6000).test_interval, 500);
    }

    #[test]
    fn the_paper_preset_keeps_its_schedule_points_as_the_official_iterations_flag() {
        let p = TrainConfig::paper();
        for n in [300, 40_000] {
            let c = p.with_iterations(n);
            c.validate().unwrap();
            assert_eq!(c.iterations, n);
            assert_eq!(
                TrainConfig {
                    iterations: p.iterations,
                    ..c
                },
                p
            );
        }
    }

    #[test]
    fn transient_knobs_are_checked() {
        let mut c = TrainConfig::fast();
        c.transient.mode = TransientMode::On;
        c.transient.depths = 0;
        c.validate()
            .expect("depths 0 with tracking: untracked pixels spawn nothing");
        c.transient.track = 0;
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("transient.depths = 0"), "{e}");
        c.transient.track = 2;
        for bad in [-0.1f32, 1.5, f32::NAN] {
            c.transient.persist = bad;
            let e = c.validate().unwrap_err().to_string();
            assert!(e.contains("transient.persist"), "{bad}: {e}");
        }
        c.transient.persist = 0.8;
        c.validate().unwrap();
    }
}
