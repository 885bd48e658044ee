//! `dispflow-vk train`: flags, the run loop with progress and outputs.
//! (Over ~600 lines: most of it is the flag list clap documents, one doc comment a flag.)

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::checkpoint::{kept_checkpoint, last_checkpoint, write_atomic, write_ply, Checkpoint};
use super::config::{Background, Preset, TrainConfig};
use super::outputs::{last_wall_s, remove_stale_outputs, truncate_log};
pub use super::outputs::{save_side_by_side, write_dynamic_masks, LogLine};
use super::Trainer;
use crate::data::synthetic::{self, Preset as ScenePreset};
use crate::data::{self, LoadOptions};
use crate::error::{Error, Result};
use crate::eval::report::{mean, Report, ReportContext};
use crate::eval::run::frame_png;
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
    /// Training iterations [preset: paper 20000, fast 600]. The schedule (warm-up, motion
    /// start, SH growth, densification window, opacity resets, checkpoint and test intervals)
    /// scales with it in proportion.
    #[arg(long)]
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
    /// Background used in training [default: black].
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
    /// Gradient through the normalisation statistics: detached (min/max held constant) or full
    /// (autograd through them) [default: detached].
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
    /// What a collapse does (a non-finite loss, or the windowed training PSNR falling by
    /// `collapse.drop_db` (2 dB) below its best for three windows): warn (say so in the progress
    /// line, log.jsonl and metrics.json; a non-finite loss stops the run) or rollback
    /// (restore the last good in-memory checkpoint and go on with the deformation rate
    /// halved, at most 8 times) [default: warn].
    #[arg(long, value_enum)]
    pub on_collapse: Option<super::collapse::OnCollapse>,
    /// Keep every checkpoint as OUT/checkpoints/NNNNNN.ckpt (for `dispflow-vk signal`).
    #[arg(long)]
    pub keep_checkpoints: bool,
    /// Print a per-kernel GPU time breakdown at every log line.
    #[arg(short, long)]
    pub verbose: bool,
}

/// How a run loads its dataset (resolution, background of transparent images, seed).
pub fn load_options(cfg: &TrainConfig) -> LoadOptions {
    let bg = match cfg.background {
        Background::White => [1.0; 3],
        _ => [0.0; 3],
    };
    LoadOptions {
        max_size: (cfg.max_resolution > 0).then_some(cfg.max_resolution),
        background: bg,
        seed: cfg.seed,
        ..LoadOptions::default()
    }
}

/// Where the built-in scene is cached: `$XDG_CACHE_HOME` or `~/.cache`, else `./.cache`.
pub fn cache_dir() -> PathBuf {
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(|| PathBuf::from(".cache"));
    base.join("dispflow-vk")
}

/// The built-in scene (generated on first use; a complete generation is marked by
/// `synthetic.json`, so an interrupted one is redone).
pub fn builtin_scene(preset: ScenePreset, seed: u64) -> Result<PathBuf> {
    let dir = cache_dir().join(format!("synthetic-{}-seed{seed}", preset.name()));
    if !dir.join("synthetic.json").is_file() {
        let tmp = dir.with_extension("partial");
        let _ = std::fs::remove_dir_all(&tmp);
        eprintln!(
            "generating the built-in synthetic scene ({}) into {}",
            preset.name(),
            dir.display()
        );
        synthetic::generate(preset, seed, &tmp)?;
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::rename(&tmp, &dir).map_err(|source| Error::Io {
            path: dir.display().to_string(),
            source,
        })?;
    }
    Ok(dir)
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
    c.keep_checkpoints |= a.keep_checkpoints;
    c.collapse.on_collapse = a.on_collapse.unwrap_or(c.collapse.on_collapse);
    c.validate()?;
    Ok(c)
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |source| Error::Io {
        path: path.display().to_string(),
        source,
    }
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
    let dataset = data::load(&data_dir, &load_options(&cfg))?;
    eprintln!("device: {}", gpu.info);
    let mut tr = Trainer::new(&gpu, &cfg, &dataset).map_err(|e| match e {
        Error::Alloc { .. }
        | Error::Vulkan(
            ash::vk::Result::ERROR_OUT_OF_DEVICE_MEMORY | ash::vk::Result::ERROR_OUT_OF_HOST_MEMORY,
        ) => Error::Invalid(format!(
            "allocating the training buffers on {} failed ({e}): config field densify.budget \
             = {} Gaussians at SH degree {} does not fit; lower --budget (or --sh-degree, \
             --max-resolution)",
            gpu.info.name, cfg.densify.budget, cfg.sh_degree
        )),
        e => e,
    })?;
    eprintln!("{}", tr.init_report);
    let ckpt = last_checkpoint(&out);
    let resume = a.resume && ckpt.is_file();
    if resume {
        // Everything is checked before the run directory changes.
        check_same_config(&out.join("config.toml"), &cfg)?;
        let c = Checkpoint::load(&ckpt)?;
        if c.iteration > cfg.iterations {
            return Err(Error::Invalid(format!(
                "{}: the checkpoint is at iteration {}, past this configuration's iterations = {}",
                ckpt.display(),
                c.iteration,
                cfg.iterations
            )));
        }
        tr.restore(&c).map_err(|e| {
            Error::Invalid(format!(
                "{}: cannot resume from this checkpoint: {}",
                ckpt.display(),
                message(&e)
            ))
        })?;
    }
    std::fs::create_dir_all(out.join("checkpoints")).map_err(io(&out))?;
    remove_stale_outputs(&out, !resume)?;
    let log_path = out.join("log.jsonl");
    if resume {
        // Lines logged after the checkpoint are logged again by the resumed run.
        truncate_log(&log_path, tr.iteration)?;
        eprintln!(
            "resumed from {} at iteration {}",
            ckpt.display(),
            tr.iteration
        );
    } else {
        write_atomic(&out.join("config.toml"), cfg.to_toml().as_bytes())?;
        write_atomic(&log_path, b"")?;
    }
    eprintln!(
        "training {} frames ({} val) at {}×{}, {} Gaussians, MLP {}×{}{}, {} iterations",
        tr.frames.len(),
        tr.val.len(),
        dataset.train[0].camera.width,
        dataset.train[0].camera.height,
        tr.n(),
        cfg.mlp_depth,
        cfg.mlp_width,
        match tr.model.nodes.as_ref() {
            Some(n) => format!(" at {} control nodes (K = {})", n.cfg.nodes, n.cfg.knn),
            None => String::new(),
        },
        cfg.iterations
    );
    let initial_psnr = if tr.iteration == 0 {
        Some(mean(tr.evaluate(false)?.iter().map(|v| v.psnr)))
    } else {
        None
    };
    let pb = indicatif::ProgressBar::new(cfg.iterations as u64);
    pb.set_style(
        indicatif::ProgressStyle::with_template(
            "{bar:30} {pos}/{len} [{elapsed_precise}<{eta_precise}, {per_sec}] {msg}",
        )
        .expect("progress template"),
    );
    pb.set_position(tr.iteration as u64);
    let tty = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let mut step_ms = Vec::new();
    // Wall ms per step by what the step ran (in first-seen order).
    let mut phase_ms: Vec<(String, Vec<f64>)> = Vec::new();
    let mut dyn_sum = (0.0, 0u32); // mean dynamic fraction over the steps the MLP ran in
    let wall_before = if resume { last_wall_s(&log_path) } else { 0.0 };
    let mut split_seen = None;
    let probes = super::curve::probe_frames(tr.val.len());
    let mut worst = super::curve::WorstView::default();
    let mut guard = super::guard::CollapseGuard::new(&tr)?;
    let mut collapse = None;
    let mut dead_warned = false;
    let mut log_file = std::fs::OpenOptions::new()
        .append(true)
        .open(&log_path)
        .map_err(io(&log_path))?;
    while tr.iteration < cfg.iterations {
        let next = tr.iteration + 1;
        let test = cfg.test_interval > 0
            && !probes.is_empty()
            && (next % cfg.test_interval == 0 || next == cfg.iterations);
        let log = next % cfg.log_interval == 0 || next == cfg.iterations || test;
        let t0 = Instant::now();
        let info = tr.step(log, log && a.verbose)?;
        step_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        let done = tr.last_plan.expect("a step ran");
        if let Some((v, id)) = tr.last_loss() {
            worst.see(v.psnr, id);
            if let Some(ev) = guard.after_step(&mut tr, &done, v.loss, v.psnr)? {
                let what = match ev.rolled_back_to {
                    Some(r) => {
                        // The abandoned iterations' lines go; the next line carries the event.
                        truncate_log(&log_path, r)?;
                        format!(
                            "; rolled back to iteration {r}, deformation rate ×{}",
                            tr.deform_lr_scale
                        )
                    }
                    None => " (--on-collapse rollback would restore an earlier state)".into(),
                };
                pb.suspend(|| {
                    eprintln!(
                        "collapse at iteration {}: {}, windowed training PSNR {:.2} → {:.2} dB{what}",
                        ev.iteration,
                        ev.kind.replace('_', " "),
                        ev.before_db,
                        ev.after_db
                    )
                });
                if ev.rolled_back_to.is_none() && ev.kind == "non_finite_loss" {
                    let line = LogLine {
                        iteration: ev.iteration,
                        loss: v.loss,
                        psnr: v.psnr,
                        num_gaussians: tr.n(),
                        collapse: Some(ev.clone()),
                        ..LogLine::default()
                    };
                    let text = serde_json::to_string(&line).expect("log line serialises");
                    std::io::Write::write_all(&mut log_file, format!("{text}\n").as_bytes())
                        .map_err(io(&log_path))?;
                    return Err(Error::Invalid(format!(
                        "iteration {}: the loss is not finite ({:?}); rerun with --on-collapse \
                         rollback to restore an earlier state with a lower deformation rate",
                        ev.iteration, v
                    )));
                }
                let rolled_back = ev.rolled_back_to.is_some();
                collapse = Some(ev);
                if rolled_back {
                    // A resumed run must not return to the abandoned branch.
                    tr.checkpoint()?.save(&ckpt)?;
                    pb.set_position(tr.iteration as u64);
                    continue;
                }
            }
        }
        let phase = match (done.deform_active, done.sparse) {
            (false, _) => "no MLP",
            (true, false) => "MLP over all",
            (true, true) => "MLP over dynamic",
        };
        let phase = format!(
            "{phase}{}",
            if done.motion.is_some() {
                " + motion"
            } else {
                ""
            }
        );
        let ms = *step_ms.last().expect("timed");
        match phase_ms.iter_mut().find(|p| p.0 == phase) {
            Some(p) => p.1.push(ms),
            None => phase_ms.push((phase, vec![ms])),
        }
        if done.deform_active {
            dyn_sum = (dyn_sum.0 + tr.dynamic_fraction(), dyn_sum.1 + 1);
        }
        pb.set_position(tr.iteration as u64);
        if tr.last_split.map(|s| s.0) != split_seen {
            split_seen = tr.last_split.map(|s| s.0);
            if let Some((it, s)) = tr.last_split {
                pb.suspend(|| eprintln!("split after iteration {it}: {s}"));
            }
        }
        if let Some(l) = info {
            if !l.loss.loss.is_finite() {
                return Err(Error::Invalid(format!(
                    "iteration {}: the loss is not finite ({:?})",
                    l.iteration, l.loss
                )));
            }
            let dynamic = tr.dynamic_fraction();
            // Not counted in the training time: the probe is a measurement, not training.
            let probe = if test {
                Some(tr.probe(&probes, true)?)
            } else {
                None
            };
            let test_psnr = probe.map(|p| p.psnr);
            let frozen = probe.is_some_and(|p| p.p99_px == Some(0.0));
            if frozen && tr.view().deform_active && !dead_warned {
                // Measured at 10× the fast rate: every ReLU of the trunk died and D(x, t)
                // turned constant in t, silently a static model.
                dead_warned = true;
                pb.suspend(|| {
                    eprintln!(
                        "warning: iteration {}: the deformation moves no Gaussian between the \
                         probe frames' times (projected motion p99 = 0 px): the MLP's output is \
                         constant in time (dead ReLUs; a lower lr.deform_init avoids it)",
                        l.iteration
                    )
                });
            }
            let worst = worst.take();
            let msg = format!(
                "loss {:.4} psnr {:.2} (worst view {}){} gaussians {} dynamic {:.0}%",
                l.loss.loss,
                l.loss.psnr,
                worst
                    .as_ref()
                    .map_or("n/a".into(), |(p, id)| format!("{p:.2} {id}")),
                probe.map_or(String::new(), |p| p.summary()),
                l.num_gaussians,
                100.0 * dynamic
            );
            pb.set_message(msg.clone());
            let line = LogLine {
                iteration: l.iteration,
                loss: l.loss.loss,
                psnr: l.loss.psnr,
                num_gaussians: l.num_gaussians,
                motion_weight: tr.motion_weight_at(l.iteration),
                ms: if a.verbose {
                    l.timings.total_ms()
                } else {
                    *step_ms.last().expect("timed")
                },
                dynamic_fraction: dynamic,
                wall_s: wall_before + step_ms.iter().sum::<f64>() / 1e3,
                test_psnr,
                test_dynamic_psnr: probe.and_then(|p| p.dynamic_psnr),
                test_static_psnr: probe.and_then(|p| p.static_psnr),
                motion_epe: probe.and_then(|p| p.epe),
                motion_gt_px: probe.and_then(|p| p.gt_px),
                motion_p50_px: probe.and_then(|p| p.p50_px),
                motion_p99_px: probe.and_then(|p| p.p99_px),
                worst_psnr: worst.as_ref().map(|w| w.0),
                worst_view: worst.map(|w| w.1),
                collapse: collapse.take(),
            };
            let text = serde_json::to_string(&line).expect("log line serialises");
            std::io::Write::write_all(&mut log_file, format!("{text}\n").as_bytes())
                .map_err(io(&log_path))?;
            if !tty {
                eprintln!("[{}/{}] {msg}", l.iteration, cfg.iterations);
            }
            if a.verbose {
                let total = l.timings.total_ms();
                let rows: Vec<String> = l
                    .timings
                    .by_label()
                    .iter()
                    .map(|(k, ms)| {
                        format!(
                            "  {k:<28} {ms:8.3} ms {:5.1}%",
                            100.0 * ms / total.max(1e-9)
                        )
                    })
                    .collect();
                pb.suspend(|| {
                    eprintln!(
                        "GPU time of iteration {} ({total:.2} ms):\n{}",
                        l.iteration,
                        rows.join("\n")
                    )
                });
            }
        }
        if tr.iteration % cfg.checkpoint_interval == 0 || tr.iteration == cfg.iterations {
            let c = tr.checkpoint()?;
            c.save(&ckpt)?;
            if cfg.keep_checkpoints {
                c.save(&kept_checkpoint(&out, tr.iteration))?;
            }
        }
    }
    pb.finish_and_clear();

    let renders = out.join("renders");
    let mut per = tr.evaluate(true)?;
    for (i, e) in per.iter_mut().enumerate() {
        if let Some(im) = e.images.take() {
            let path = renders.join(frame_png(i, &e.id));
            save_side_by_side(&path, im.width, im.height, &[&im.render, &im.gt])?;
        }
    }
    write_dynamic_masks(&mut tr, &renders.join("dynamic"))?;
    write_ply(&out.join("point_cloud.ply"), &tr.gaussians()?)?;
    let mlp = tr.model.deform.download(&gpu)?;
    write_atomic(&out.join("deform.bin"), bytemuck::cast_slice(&mlp))?;
    if let Some(ns) = tr.model.nodes.as_ref().filter(|n| n.placed()) {
        let p = ns.download(&gpu, tr.n())?.params;
        write_atomic(&out.join("nodes.bin"), bytemuck::cast_slice(&p))?;
    }
    let dynamic_bin = out.join("dynamic.bin");
    match tr.model.dynamic.download(&gpu, tr.n())? {
        Some(d) => write_atomic(&dynamic_bin, &crate::eval::run::dynamic_bin(&d))?,
        None if dynamic_bin.is_file() => {
            std::fs::remove_file(&dynamic_bin).map_err(io(&dynamic_bin))?
        }
        None => {}
    }
    let ctx = ReportContext {
        run: out.display().to_string(),
        scene: name,
        dataset: data_dir.display().to_string(),
        device: gpu.info.to_string(),
        iterations: tr.iteration,
        num_gaussians: tr.n(),
    };
    let mut metrics = Report::new(&cfg, ctx, per);
    metrics.initial_psnr = initial_psnr;
    // None when no step ran (a resumed run that had already finished).
    metrics.ms_per_step = (!step_ms.is_empty()).then(|| crate::bench::median(step_ms.clone()));
    metrics.dynamic_fraction = Some(tr.dynamic_fraction());
    metrics.train_seconds = Some(wall_before + step_ms.iter().sum::<f64>() / 1e3);
    metrics.ms_per_step_by_phase = phase_ms
        .into_iter()
        .map(|(phase, v)| crate::eval::report::PhaseMs {
            phase,
            steps: v.len() as u32,
            median_ms: crate::bench::median(v),
        })
        .collect();
    metrics.mean_dynamic_fraction = (dyn_sum.1 > 0).then(|| dyn_sum.0 / dyn_sum.1 as f64);
    let log = crate::eval::run::read_log(&log_path)?;
    metrics.time_to_psnr = super::curve::time_to_psnr(&log);
    metrics.collapses = log.iter().filter_map(|l| l.collapse.clone()).collect();
    crate::report::save_png(
        &crate::eval::run::training_plot(&log)?,
        &out.join("training.png"),
    )?;
    write_atomic(&out.join("metrics.json"), metrics.to_json().as_bytes())?;
    let fmt = |v: Option<f64>| v.map_or("n/a".into(), |x| format!("{x:.4}"));
    let fmt2 = |v: Option<f64>| v.map_or("n/a".into(), |x| format!("{x:.2}"));
    println!(
        "test PSNR {:.2} dB (initial {}; dynamic {}, static {}), SSIM {:.4}, MMAP {}, DRC {}, {} Gaussians, {} ms/step; outputs in {}",
        metrics.psnr,
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
        out.display()
    );
    // A validation error anywhere in the run (device creation included) fails the command.
    gpu.check_validation("train")?;
    Ok(metrics)
}

/// The message of `e` without the variant's prefix (for errors wrapped in more context).
fn message(e: &Error) -> String {
    match e {
        Error::Invalid(m) => m.clone(),
        e => e.to_string(),
    }
}

/// A resumed run must continue the configuration it started with (its `config.toml`):
/// another one would silently train something else from the checkpoint on. Names every
/// field that differs.
fn check_same_config(path: &Path, cfg: &TrainConfig) -> Result<()> {
    if !path.is_file() {
        return Err(Error::Invalid(format!(
            "{}: missing; --resume needs the run's configuration beside its checkpoint",
            path.display()
        )));
    }
    let run = TrainConfig::from_toml_over(cfg, path)?;
    if run == *cfg {
        return Ok(());
    }
    let flat = |c: &TrainConfig| {
        let mut out = Vec::new();
        flatten(
            "",
            &toml::Value::try_from(c).expect("config serialises"),
            &mut out,
        );
        out
    };
    let (was, now) = (flat(&run), flat(cfg));
    let diff: Vec<String> = was
        .iter()
        .zip(&now)
        .filter(|(a, b)| a != b)
        .map(|((k, a), (_, b))| format!("{k} = {b} (the run has {a})"))
        .collect();
    Err(Error::Invalid(format!(
        "{}: --resume with another configuration: {}; resume with the run's settings \
         (e.g. --config {}) or train into a new --out",
        path.display(),
        diff.join(", "),
        path.display()
    )))
}

fn flatten(prefix: &str, v: &toml::Value, out: &mut Vec<(String, String)>) {
    match v {
        toml::Value::Table(t) => {
            for (k, v) in t {
                let key = if prefix.is_empty() {
                    k.clone()
                } else {
                    format!("{prefix}.{k}")
                };
                flatten(&key, v, out);
            }
        }
        v => out.push((prefix.to_string(), v.to_string())),
    }
}
