//! Training as a library call: a resolved configuration, a dataset directory, an output
//! directory and a progress sink in; the run's outputs written and its [`Report`] out. The
//! `train` command only parses flags around it; `sweep` runs it as `train` processes.

use std::path::Path;

use super::checkpoint::{last_checkpoint, write_atomic, write_ply, Checkpoint};
use super::collapse::RunStatus;
use super::config::TrainConfig;
use super::outputs::frame_png;
use super::outputs::{last_wall_s, remove_stale_outputs, truncate_log};
use super::outputs::{save_side_by_side, write_dynamic_masks};
pub use super::run::{Progress, RunSpec};
use super::run_loop::{train_loop, LoopStats, RunLog};
use super::Trainer;
use crate::data;
use crate::error::{Error, Result};
use crate::train::metrics::{mean, Report, ReportContext};
use crate::vk::Gpu;

/// The CLI's progress: a bar with ETA on a terminal, one line per logged iteration otherwise.
pub struct Bar {
    pb: Option<indicatif::ProgressBar>,
    tty: bool,
}

impl Default for Bar {
    fn default() -> Self {
        Bar {
            pb: None,
            tty: std::io::IsTerminal::is_terminal(&std::io::stderr()),
        }
    }
}

impl Progress for Bar {
    fn start(&mut self, total: u32, at: u32) {
        let pb = indicatif::ProgressBar::new(total as u64);
        pb.set_style(
            indicatif::ProgressStyle::with_template(
                "{bar:30} {pos}/{len} [{elapsed_precise}<{eta_precise}, {per_sec}] {msg}",
            )
            .expect("progress template"),
        );
        pb.set_position(at as u64);
        self.pb = Some(pb);
    }
    fn position(&mut self, iteration: u32) {
        if let Some(pb) = &self.pb {
            pb.set_position(iteration as u64);
        }
    }
    fn message(&mut self, iteration: u32, total: u32, msg: &str) {
        if let Some(pb) = &self.pb {
            pb.set_message(msg.to_string());
        }
        if !self.tty {
            eprintln!("[{iteration}/{total}] {msg}");
        }
    }
    fn note(&mut self, text: &str) {
        match &self.pb {
            Some(pb) => pb.suspend(|| eprintln!("{text}")),
            None => eprintln!("{text}"),
        }
    }
    fn finish(&mut self) {
        if let Some(pb) = self.pb.take() {
            pb.finish_and_clear();
        }
    }
}

/// No output (benches, library callers that report on their own).
pub struct Quiet;

impl Progress for Quiet {
    fn start(&mut self, _: u32, _: u32) {}
    fn position(&mut self, _: u32) {}
    fn message(&mut self, _: u32, _: u32, _: &str) {}
    fn note(&mut self, _: &str) {}
    fn finish(&mut self) {}
}

/// Trains `spec` on `gpu` to its configured iterations (resuming when asked), writes every
/// output of a run into `spec.out` and returns the metrics it wrote to `metrics.json`. Three
/// phases: set-up (trainer, resume, run directory, the initial test PSNR), the loop
/// (`run_loop`), and the finish (final evaluation, outputs, the run's status).
pub fn train_run(gpu: &Gpu, spec: &RunSpec<'_>, progress: &mut dyn Progress) -> Result<Report> {
    // `--background auto` is decided from the images before they are composited; from here
    // on the run (and its config.toml) knows only the colour.
    let (cfg, pick) = spec.cfg.with_background_from(&spec.data_dir)?;
    if let Some(p) = &pick {
        progress.note(&format!("background: {} (auto: {})", p.name(), p.reason));
    }
    let spec = &RunSpec {
        cfg: &cfg,
        ..spec.clone()
    };
    let mut opts = cfg.load_options();
    opts.background_from_data = pick.is_some();
    let dataset = data::load(&spec.data_dir, &opts)?;
    progress.note(&format!("device: {}", gpu.info));
    // The loader's warnings were only in `data check`; a run that trains on them says so.
    for w in &dataset.warnings {
        progress.note(&format!("warning: {w}"));
    }
    let mut tr = open_trainer(gpu, spec, &dataset)?;
    progress.note(&tr.init_report.to_string());
    let ckpt = last_checkpoint(&spec.out);
    let stats = prepare_run_dir(&mut tr, spec, &ckpt, progress)?;
    progress.note(&run_summary(&tr, spec.cfg, &dataset));
    let initial_psnr = if tr.iteration == 0 {
        Some(mean(tr.evaluate(false)?.iter().map(|v| v.psnr)))
    } else {
        None
    };
    let mut log = RunLog::open(&spec.out.join("log.jsonl"))?;
    let stats = train_loop(&mut tr, spec, &ckpt, &mut log, stats, progress)?;
    let ended = Ended {
        stats,
        initial_psnr,
        background_reason: pick.map(|p| p.reason),
    };
    finish(gpu, spec, &mut tr, ended, progress)
}

/// What the run knows at its end besides the trainer.
struct Ended {
    stats: LoopStats,
    initial_psnr: Option<f64>,
    background_reason: Option<String>,
}

/// The trainer for `spec`, with an allocation failure explained in terms of the settings.
fn open_trainer<'g>(
    gpu: &'g Gpu,
    spec: &RunSpec<'_>,
    dataset: &data::Dataset,
) -> Result<Trainer<'g>> {
    let cfg = spec.cfg;
    Trainer::new(gpu, cfg, dataset).map_err(|e| match e {
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
    })
}

/// Resumes from `ckpt` when asked (after checking it belongs to this configuration) and makes
/// the run directory consistent: stale outputs removed, `config.toml` and an empty
/// `log.jsonl` for a fresh run, the log cut back to the checkpoint for a resumed one.
fn prepare_run_dir(
    tr: &mut Trainer<'_>,
    spec: &RunSpec<'_>,
    ckpt: &Path,
    progress: &mut dyn Progress,
) -> Result<LoopStats> {
    let (cfg, out) = (spec.cfg, &spec.out);
    let resume = spec.resume && ckpt.is_file();
    if resume {
        // Everything is checked before the run directory changes.
        check_same_config(&out.join("config.toml"), cfg)?;
        let c = Checkpoint::load(ckpt)?;
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
    std::fs::create_dir_all(out.join("checkpoints")).map_err(Error::io(out))?;
    remove_stale_outputs(out, !resume)?;
    let log_path = out.join("log.jsonl");
    if resume {
        // Lines logged after the checkpoint are logged again by the resumed run.
        truncate_log(&log_path, tr.iteration)?;
        progress.note(&format!(
            "resumed from {} at iteration {}",
            ckpt.display(),
            tr.iteration
        ));
    } else {
        write_atomic(&out.join("config.toml"), cfg.to_toml().as_bytes())?;
        write_atomic(&log_path, b"")?;
    }
    Ok(LoopStats {
        wall_before: if resume { last_wall_s(&log_path) } else { 0.0 },
        ..LoopStats::default()
    })
}

/// The "training N frames at W×H ..." line.
fn run_summary(tr: &Trainer<'_>, cfg: &TrainConfig, dataset: &data::Dataset) -> String {
    format!(
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
    )
}

/// The final phase: every test frame evaluated (pictures written), the model's files, the
/// report with the run's status (a run that collapsed or ended below its initial test PSNR
/// says so here, in `metrics.json` and in a warning), `training.png` and `metrics.json`.
fn finish(
    gpu: &Gpu,
    spec: &RunSpec<'_>,
    tr: &mut Trainer<'_>,
    ended: Ended,
    progress: &mut dyn Progress,
) -> Result<Report> {
    let (cfg, out) = (spec.cfg, &spec.out);
    let Ended {
        stats,
        initial_psnr,
        background_reason,
    } = ended;
    let renders = out.join("renders");
    let mut per = tr.evaluate(true)?;
    for (i, e) in per.iter_mut().enumerate() {
        if let Some(im) = e.images.take() {
            let path = renders.join(frame_png(i, &e.id));
            save_side_by_side(&path, im.width, im.height, &[&im.render, &im.gt])?;
        }
    }
    write_dynamic_masks(tr, &renders.join("dynamic"))?;
    write_model_files(gpu, tr, out)?;
    let ctx = ReportContext {
        run: out.display().to_string(),
        scene: spec.scene.clone(),
        dataset: spec.data_dir.display().to_string(),
        device: gpu.info.to_string(),
        iterations: tr.iteration,
        num_gaussians: tr.n(),
    };
    let mut metrics = Report::new(cfg, ctx, per);
    metrics.initial_psnr = initial_psnr;
    metrics.background_reason = background_reason;
    if cfg.transient.mode.spawns() {
        let g = &tr.model.gaussians;
        metrics.gaussians_canonical = Some(g.canonical_rows().len());
        metrics.gaussians_transient = Some(g.transient_rows().len());
        metrics.transients_first_spawn = tr.transients_first_spawn();
    }
    // None when no step ran (a resumed run that had already finished).
    metrics.ms_per_step =
        (!stats.step_ms.is_empty()).then(|| crate::stats::median(stats.step_ms.clone()));
    metrics.dynamic_fraction = Some(tr.dynamic_fraction());
    metrics.train_seconds = Some(stats.train_seconds());
    metrics.ms_per_step_by_phase = stats
        .phase_ms
        .into_iter()
        .map(|(phase, v)| crate::train::metrics::PhaseMs {
            phase,
            steps: v.len() as u32,
            median_ms: crate::stats::median(v),
        })
        .collect();
    metrics.cost_per_step = stats.cost.report();
    if let Some(c) = &metrics.cost_per_step {
        progress.note(&c.summary());
    }
    metrics.mean_dynamic_fraction =
        (stats.dyn_sum.1 > 0).then(|| stats.dyn_sum.0 / stats.dyn_sum.1 as f64);
    let log = super::outputs::read_log(&out.join("log.jsonl"))?;
    metrics.time_to_psnr = super::curve::time_to_psnr(&log);
    metrics.collapses = log.iter().filter_map(|l| l.collapse.clone()).collect();
    metrics.mass_prunes = log.iter().filter_map(|l| l.prune.clone()).collect();
    let end = log.iter().rev().find_map(|l| l.probe_psnr);
    let end = end.map(|probe| (probe, cfg.collapse.drop_db as f64));
    let (status, why) = RunStatus::judge(&metrics.collapses, initial_psnr, metrics.psnr, end);
    metrics.status = Some(status);
    metrics.status_note = why.clone();
    metrics.rollbacks = metrics
        .collapses
        .iter()
        .filter(|e| e.rolled_back_to.is_some())
        .count() as u32;
    match (&why, status) {
        (Some(why), RunStatus::Collapsed) => progress.note(&format!("warning: the run {why}")),
        (Some(why), RunStatus::Ok) => progress.note(&format!("note: {why}")),
        _ => {}
    }
    crate::report::save_png(
        &super::outputs::training_plot(&log)?,
        &out.join("training.png"),
    )?;
    write_atomic(&out.join("metrics.json"), metrics.to_json().as_bytes())?;
    Ok(metrics)
}

/// `point_cloud.ply`, `transients.ply` (when the model has transients), `deform.bin`,
/// `nodes.bin` and `dynamic.bin` (removed when the model has no split).
fn write_model_files(gpu: &Gpu, tr: &mut Trainer<'_>, out: &Path) -> Result<()> {
    // Canonical Gaussians in the standard layout (what viewers read); transients apart.
    let (canonical, transients) = tr.gaussians()?.split_transients();
    write_ply(&out.join("point_cloud.ply"), &canonical)?;
    let tpath = out.join("transients.ply");
    if !transients.is_empty() {
        write_ply(&tpath, &transients)?;
    } else if tpath.is_file() {
        std::fs::remove_file(&tpath).map_err(Error::io(&tpath))?;
    }
    let mlp = tr.model.deform.download(gpu)?;
    write_atomic(&out.join("deform.bin"), bytemuck::cast_slice(&mlp))?;
    if let Some(ns) = tr.model.nodes.as_ref().filter(|n| n.placed()) {
        let p = ns.download(gpu, 0, 0)?.params; // the parameters only
        write_atomic(&out.join("nodes.bin"), bytemuck::cast_slice(&p))?;
    }
    let dynamic_bin = out.join("dynamic.bin");
    match tr
        .model
        .dynamic
        .download(gpu, tr.model.gaussians.canonical_rows().len())?
    {
        Some(d) => write_atomic(&dynamic_bin, &super::outputs::dynamic_bin(&d))?,
        None if dynamic_bin.is_file() => {
            std::fs::remove_file(&dynamic_bin).map_err(Error::io(&dynamic_bin))?
        }
        None => {}
    }
    Ok(())
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
