//! `dispflow-vk train`: its flags and how they resolve over a preset and a config file. The
//! run itself is the library's [`super::session::train_run`].

use std::path::PathBuf;

use super::config::{Background, Preset, TrainConfig};
use super::session::{train_run, Bar, RunSpec};
use crate::data::builtin::builtin_scene;
use crate::data::synthetic::Preset as ScenePreset;
use crate::error::Result;
use crate::train::metrics::Report;
use crate::vk::Gpu;

#[derive(clap::Args, Debug, Clone, Default)]
pub struct TrainArgs {
    /// Dataset directory (nerfies or D-NeRF/blender format). Default: the built-in synthetic
    /// scene (small preset), generated once into the cache directory.
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Output directory. Default: runs/<dataset name>.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Starting configuration. Default: `fast` for the built-in scene or on a CPU device
    /// (lavapipe), `paper` with --data on a GPU; the run prints which and why.
    #[arg(long, value_enum)]
    pub preset: Option<Preset>,
    /// TOML file overriding fields of the preset (same names as the run's config.toml).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Training iterations, at least 1 [preset: paper 20000 (40000 on a D-NeRF/blender scene, as
    /// the official command), fast 600]. With the fast preset
    /// the schedule (warm-up, motion start, SH growth, densification window, opacity resets,
    /// checkpoint and test intervals) scales with it in proportion, the test interval no
    /// shorter than the log interval (a short run probes at its log lines and its end, not
    /// every few iterations); the paper preset keeps
    /// every schedule point where it is, as the official code's --iterations (config field
    /// `schedule`).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub iterations: Option<u32>,
    /// Continue from OUT/checkpoints/last.ckpt when it exists (same configuration).
    #[arg(long)]
    pub resume: bool,
    /// Largest image side after loading, in pixels; 0 = as stored [preset: paper 0, fast 160].
    #[arg(long)]
    pub max_resolution: Option<u32>,
    /// Highest SH degree, 0-3 [preset: paper 3, fast 1].
    #[arg(long)]
    pub sh_degree: Option<u32>,
    /// Deformation MLP width [preset: paper 256, fast 64].
    #[arg(long)]
    pub mlp_width: Option<u32>,
    /// Deformation MLP depth [preset: paper 8, fast 4].
    #[arg(long)]
    pub mlp_depth: Option<u32>,
    /// Deformation field: mlp (Deformable-3DGS: the MLP at every Gaussian) or nodes (SC-GS:
    /// the MLP at --nodes control nodes placed by farthest-point sampling when the deformation
    /// starts, each Gaussian blending its --knn nearest nodes' rigid transforms; the MLP's
    /// cost then follows the node count, not the Gaussian count) [preset: paper mlp, fast
    /// nodes].
    #[arg(long, value_enum)]
    pub deform_field: Option<crate::model::nodes::FieldKind>,
    /// Control nodes of the nodes field [default: 512].
    #[arg(long)]
    pub nodes: Option<u32>,
    /// Nearest nodes each Gaussian blends, 1-8 [default: 4].
    #[arg(long)]
    pub knn: Option<u32>,
    /// Most Gaussians the run may hold [preset: paper 500000, fast 20000].
    #[arg(long)]
    pub budget: Option<u32>,
    /// Background of transparent images and of the render [preset: fast auto, paper black].
    /// auto: decided from the images' alpha before loading (white when views disagree about
    /// what is transparent and the surface they see through is light, as a white floor; black
    /// otherwise, as on D-NeRF), printed with its reason and recorded in metrics.json;
    /// black / white: the images are composited on it and training, evaluation, probes and
    /// spawns render on it; random: a random colour per training step, black in evaluation.
    #[arg(long, value_enum)]
    pub background: Option<Background>,
    /// Seed of everything random (initial points, frame order, MLP init) [default: 0].
    #[arg(long)]
    pub seed: Option<u64>,
    /// Weight α of the motion loss (displacement or Gaussian flow); 0 = the Deformable-3DGS
    /// baseline [default: 0.1].
    #[arg(long)]
    pub motion_weight: Option<f32>,
    /// Iteration t0 from which the motion loss is on [preset: paper 10000, fast 400].
    #[arg(long)]
    pub motion_start: Option<u32>,
    /// Normalisation of the motion magnitudes: min-max, max-abs, z-score or iqr [default: min-max].
    #[arg(long)]
    pub motion_normalize: Option<crate::kernels::motion::NormMode>,
    /// Temporal gap, in training frames sorted by time, between a frame and its pair [default: 1].
    #[arg(long)]
    pub pair_gap: Option<u32>,
    /// Optical-flow preset: fast, default or accurate (pyramid levels, warps, iterations)
    /// [preset: paper default, fast fast].
    #[arg(long)]
    pub flow_preset: Option<String>,
    /// Motion decomposition: direct = intermediate render (v1, t2), the paper's; reverse =
    /// intermediate (v2, t1), the ablation [default: direct].
    #[arg(long, value_enum)]
    pub motion_order: Option<super::config::MotionOrder>,
    /// Gradient through the normalisation statistics: full (autograd through min/max; the loss
    /// stays scale-free) or detached (held constant: an ablation whose extra shrinking
    /// direction kills the deformation in long runs) [default: full].
    #[arg(long, value_enum)]
    pub motion_norm_grad: Option<super::config::NormGrad>,
    /// Scene-motion source: tvl1 (the GPU optical flow, the method) or oracle (the synthetic
    /// scene's ground-truth flow; an ablation isolating the estimator) [default: tvl1].
    #[arg(long, value_enum)]
    pub motion_flow: Option<super::config::MotionFlow>,
    /// A compared method as a preset of the switches below (applied before them): 3dgs
    /// (static), deformable-3dgs (no motion term), motiongs (Gaussian flow + indirect scene
    /// motion) or dispflow (displacement flow + direct scene motion, the method) [default:
    /// dispflow].
    #[arg(long, value_enum)]
    pub method: Option<super::method::Method>,
    /// What the motion term supervises: displacement (DispFlow-GS: α-blended 3D displacement,
    /// normalised magnitudes) or gaussian-flow (GaussianFlow/MotionGS: α-blended 2D motion of
    /// the projected Gaussians, L1 on the vectors) [default: displacement].
    #[arg(long, value_enum)]
    pub motion_representation: Option<super::method::MotionRepresentation>,
    /// Scene motion: direct (flow photo → render at the same view, the method), indirect
    /// (MotionGS: flow photo a → photo b minus the camera flow of the rendered depth) or none
    /// (the raw pair flow, camera motion included: the paper's "DF without MD") [default:
    /// direct].
    #[arg(long, value_enum)]
    pub scene_motion: Option<super::method::SceneMotionKind>,
    /// Motion weight schedule (TS): ramp (on from --motion-start, 0.1·α → α) or off (the full
    /// α from the end of the deformation warm-up) [default: ramp].
    #[arg(long, value_enum)]
    pub motion_schedule: Option<super::method::MotionSchedule>,
    /// Motion-mask filtering: scene motion shorter than this many pixels is set to 0 (the
    /// paper's ablation; it found no consistent gain) [default: 0 = off].
    #[arg(long, value_name = "PX")]
    pub motion_mask: Option<f32>,
    /// Deformation network: on (Deformable-3DGS) or off (static 3D-GS, the paper's "3DGS"
    /// rows; needs --motion-weight 0) [default: on].
    #[arg(long, value_enum)]
    pub deform: Option<super::config::DeformMode>,
    /// Split the Gaussians into dynamic and static ones and run the MLP over the dynamic ones
    /// only (auto: 1.4–1.9× faster runs, 0–0.3 dB lower PSNR measured), or run it over every
    /// Gaussian (off) [default: off].
    #[arg(long, value_enum)]
    pub sparsity: Option<super::config::SparsityMode>,
    /// Largest motion, in pixels of the training view where it looks largest, that the
    /// deformation may give a Gaussian treated as static [default: 0.5].
    #[arg(long)]
    pub sparsity_threshold: Option<f32>,
    /// A Gaussian must also move more than this multiple of the median Gaussian's motion to
    /// be dynamic (the MLP's noise floor); 0 = the pixel threshold alone [default: 3].
    #[arg(long)]
    pub sparsity_noise_k: Option<f32>,
    /// Re-split (after a dense window) every this fraction of the deformation's iterations
    /// [default: 0.25].
    #[arg(long)]
    pub probe_every: Option<f32>,
    /// Drop initial points no training camera sees or within a camera's near range: on or off
    /// [preset: paper off, fast on].
    #[arg(long, value_parser = clap::builder::BoolishValueParser::new())]
    pub init_filter: Option<bool>,
    /// Residual-flow correction of the scene motion: subtract the flow photo → render(v1, t1)
    /// (reconstruction error) from the flow photo → render(v1, t2); on or off [default: off].
    #[arg(long, value_parser = clap::builder::BoolishValueParser::new())]
    pub motion_residual: Option<bool>,
    /// Confidence σ of the scene motion: each pixel weighs exp(−mean|photo − render(v1, t1)|
    /// / σ) in the motion loss (colours in [0, 1]); 0 = off [default: 0].
    #[arg(long)]
    pub motion_confidence: Option<f32>,
    /// Run the motion term on every k-th step after its start only (a speed knob) [default: 1].
    #[arg(long)]
    pub motion_every: Option<u32>,
    /// Blur the photo's grey image by k binomial passes (σ = √k px) before the optical flow,
    /// to match a blurry render [default: 0].
    #[arg(long)]
    pub flow_blur_photo: Option<u32>,
    /// Structure–texture factor β in [0, 1): the flow sees I − β·blur(I), not the shading
    /// [default: 0 = off].
    #[arg(long)]
    pub flow_texture: Option<f32>,
    /// Finest pyramid level the optical flow is solved at (0 = full resolution; 1 = half,
    /// about 4× cheaper), upsampled afterwards [preset: paper 0, fast 1].
    #[arg(long)]
    pub flow_level: Option<u32>,
    /// What a collapse does (a non-finite loss, render or parameter, or the mean PSNR of four
    /// probe training views, spread over time, falling `collapse.drop_db` (2 dB) below its best
    /// for two rounds over them): warn (say so in the progress line, log.jsonl and
    /// metrics.json, whose `status` reads collapsed unless the run climbs back; a non-finite
    /// loss stops the run) or rollback
    /// (restore the last good in-memory checkpoint and go on with the deformation rate
    /// halved, at most 8 times; after two rollbacks that meet the same fall as deep, the rate
    /// is not its cause and the run goes on without rolling back) [default: warn].
    #[arg(long, value_enum)]
    pub on_collapse: Option<super::collapse::OnCollapse>,
    /// Transient Gaussians, a second population local in time for what moves most of its
    /// size per frame, appears, vanishes or splits (config [transient]): auto (spawned only
    /// once a frame's localized residual has held through transient.gate looks
    /// transient.every steps apart where the model draws nothing, or in colours it draws
    /// nowhere near in many frames of a round, i.e. the canonical model cannot draw it; no
    /// budget is reserved before; the fast preset's default), on (spawned every transient.every steps
    /// from the frames with the largest held residual, a quarter of the budget reserved from
    /// the start) or off (the paper preset's default).
    #[arg(long, value_enum)]
    pub transients: Option<super::config::TransientMode>,
    /// Keep every checkpoint as OUT/checkpoints/NNNNNN.ckpt (for `dispflow-vk signal`).
    #[arg(long)]
    pub keep_checkpoints: bool,
    /// Print a per-kernel GPU time breakdown at every log line.
    #[arg(short, long)]
    pub verbose: bool,
}

/// The preset a run without `--preset` starts from, and why: `fast` for the built-in scene or
/// on a CPU device (the paper's 20 000 iterations take hours there), `paper` otherwise.
pub fn default_preset(a: &TrainArgs, cpu_device: bool) -> (Preset, &'static str) {
    match (&a.data, cpu_device) {
        (None, _) => (Preset::Fast, "the built-in scene"),
        (Some(_), true) => (
            Preset::Fast,
            "a CPU device: the paper's 20 000 iterations would take hours; --preset paper to \
             insist",
        ),
        (Some(_), false) => (Preset::Paper, "a dataset on a GPU"),
    }
}

/// `--iterations` of the official Deformable-3DGS command for D-NeRF / blender scenes.
pub const OFFICIAL_BLENDER_ITERATIONS: u32 = 40_000;

fn is_blender(dir: &std::path::Path) -> bool {
    crate::data::detect_format(dir).is_ok_and(|f| f == crate::data::Format::Blender)
}

/// Resolves flags over the preset and the optional TOML file (as on a GPU device).
pub fn resolve_config(a: &TrainArgs) -> Result<TrainConfig> {
    resolve_config_on(a, false)
}

/// Resolves flags over the preset (`--preset`, else [`default_preset`] for the device) and
/// the optional TOML file.
pub fn resolve_config_on(a: &TrainArgs, cpu_device: bool) -> Result<TrainConfig> {
    resolve_config_with(a, cpu_device, None)
}

/// [`resolve_config_on`] with TOML text `(text, origin)` merged after `--config` and before
/// the flags (how `sweep` checks a cell's config table before anything runs).
pub fn resolve_config_with(
    a: &TrainArgs,
    cpu_device: bool,
    extra: Option<(&str, &str)>,
) -> Result<TrainConfig> {
    let preset = a.preset.unwrap_or(default_preset(a, cpu_device).0);
    let mut c = TrainConfig::preset(preset);
    if preset == Preset::Paper && a.data.as_deref().is_some_and(is_blender) {
        // The official command for a blender scene (`train.py --eval --is_blender`) keeps its
        // default 40 000 iterations; the 20 000 are its NeRF-DS/HyperNeRF command's.
        c = c.with_iterations(OFFICIAL_BLENDER_ITERATIONS);
    }
    if let Some(p) = &a.config {
        c = TrainConfig::from_toml_over(&c, p)?;
    }
    if let Some((text, origin)) = extra {
        c = TrainConfig::from_toml_str_over(&c, text, origin)?;
    }
    if let Some(v) = a.iterations {
        c = c.with_iterations(v);
    }
    if let Some(m) = a.method {
        m.apply(&mut c);
    }
    c.max_resolution = a.max_resolution.unwrap_or(c.max_resolution);
    c.sh_degree = a.sh_degree.unwrap_or(c.sh_degree);
    c.mlp_width = a.mlp_width.unwrap_or(c.mlp_width);
    c.mlp_depth = a.mlp_depth.unwrap_or(c.mlp_depth);
    let f = &mut c.deform_field;
    f.kind = a.deform_field.unwrap_or(f.kind);
    f.nodes = a.nodes.unwrap_or(f.nodes);
    f.knn = a.knn.unwrap_or(f.knn);
    c.densify.budget = a.budget.unwrap_or(c.densify.budget);
    c.background = a.background.unwrap_or(c.background);
    c.seed = a.seed.unwrap_or(c.seed);
    c.motion_weight = a.motion_weight.unwrap_or(c.motion_weight);
    c.motion_start = a.motion_start.unwrap_or(c.motion_start);
    c.motion_normalize = a.motion_normalize.unwrap_or(c.motion_normalize);
    c.pair_gap = a.pair_gap.unwrap_or(c.pair_gap);
    c.flow_preset = a.flow_preset.clone().unwrap_or(c.flow_preset);
    c.motion_order = a.motion_order.unwrap_or(c.motion_order);
    c.motion_norm_grad = a.motion_norm_grad.unwrap_or(c.motion_norm_grad);
    c.motion_flow = a.motion_flow.unwrap_or(c.motion_flow);
    c.motion_representation = a.motion_representation.unwrap_or(c.motion_representation);
    c.motion_schedule = a.motion_schedule.unwrap_or(c.motion_schedule);
    c.deform = a.deform.unwrap_or(c.deform);
    if c.deform == super::config::DeformMode::Off && a.motion_weight.is_none() {
        c.motion_weight = 0.0; // a static model has no motion term; --deform off says so
    }
    c.init_filter = a.init_filter.unwrap_or(c.init_filter);
    c.sparsity.mode = a.sparsity.unwrap_or(c.sparsity.mode);
    c.sparsity.threshold_px = a.sparsity_threshold.unwrap_or(c.sparsity.threshold_px);
    c.sparsity.every = a.probe_every.unwrap_or(c.sparsity.every);
    c.sparsity.noise_k = a.sparsity_noise_k.unwrap_or(c.sparsity.noise_k);
    let sm = &mut c.scene_motion;
    sm.residual = a.motion_residual.unwrap_or(sm.residual);
    sm.confidence = a.motion_confidence.unwrap_or(sm.confidence);
    sm.every = a.motion_every.unwrap_or(sm.every);
    sm.blur_photo = a.flow_blur_photo.unwrap_or(sm.blur_photo);
    sm.texture = a.flow_texture.unwrap_or(sm.texture);
    sm.level = a.flow_level.unwrap_or(sm.level);
    sm.kind = a.scene_motion.unwrap_or(sm.kind);
    sm.mask_px = a.motion_mask.unwrap_or(sm.mask_px);
    c.transient.mode = a.transients.unwrap_or(c.transient.mode);
    c.keep_checkpoints |= a.keep_checkpoints;
    c.collapse.on_collapse = a.on_collapse.unwrap_or(c.collapse.on_collapse);
    c.validate()?;
    Ok(c)
}

/// The whole `train` command. Returns the metrics it wrote.
pub fn run(a: &TrainArgs) -> Result<Report> {
    // Flags and configuration files are checked before the device is opened.
    resolve_config(a)?;
    let gpu = Gpu::new_default()?;
    let cpu = gpu.info.kind == "CPU";
    let cfg = resolve_config_on(a, cpu)?;
    if a.preset.is_none() {
        let (p, why) = default_preset(a, cpu);
        eprintln!("preset: {} ({why})", format!("{p:?}").to_lowercase());
    }
    let data_dir = match &a.data {
        Some(d) => d.clone(),
        None => builtin_scene(ScenePreset::Small, 0)?,
    };
    let name = data_dir
        .file_name()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "run".into());
    let out = a
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join(&name));
    let spec = RunSpec {
        cfg: &cfg,
        data_dir,
        scene: name,
        out,
        resume: a.resume,
        verbose: a.verbose,
    };
    let metrics = train_run(&gpu, &spec, &mut Bar::default())?;
    let fmt = |v: Option<f64>| v.map_or("n/a".into(), |x| format!("{x:.4}"));
    let fmt2 = |v: Option<f64>| v.map_or("n/a".into(), |x| format!("{x:.2}"));
    println!(
        "test PSNR {:.2} dB over all {} test frames (initial {}; dynamic {}, static {}), SSIM {:.4}, MMAP {}, DRC {}, {} Gaussians, {} ms/step; outputs in {}",
        metrics.psnr,
        metrics.per_frame.len(),
        metrics
            .initial_psnr
            .map_or("not measured: resumed".into(), |p| format!("{p:.2}")),
        fmt2(metrics.dynamic_psnr),
        fmt2(metrics.static_psnr),
        metrics.ssim,
        fmt(metrics.mmap),
        fmt(metrics.drc),
        metrics.num_gaussians,
        metrics
            .ms_per_step
            .map_or("n/a".into(), |v| format!("{v:.1}")),
        spec.out.display()
    );
    if let (Some(st), Some(why)) = (metrics.status, &metrics.status_note) {
        println!("status: {} ({why})", st.label());
    }
    // A validation error anywhere in the run (device creation included) fails the command.
    gpu.check_validation("train")?;
    Ok(metrics)
}
