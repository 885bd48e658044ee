//! Training as a library call: a resolved configuration, a dataset directory, an output
//! directory and a progress sink in; the run's outputs written and its [`Report`] out. The
//! `train` command only parses flags around it; `sweep` runs it as `train` processes.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::checkpoint::{kept_checkpoint, last_checkpoint, write_atomic, write_ply, Checkpoint};
use super::collapse::PruneEvent;
use super::config::TrainConfig;
use super::outputs::frame_png;
use super::outputs::{last_wall_s, remove_stale_outputs, truncate_log};
use super::outputs::{save_side_by_side, write_dynamic_masks, LogLine};
use super::Trainer;
use crate::data;
use crate::error::{Error, Result};
use crate::train::metrics::{mean, Report, ReportContext};
use crate::vk::Gpu;

/// What one training run needs besides the device.
pub struct RunSpec<'a> {
    pub cfg: &'a TrainConfig,
    pub data_dir: PathBuf,
    /// The scene's name in the report (by default the dataset directory's name).
    pub scene: String,
    pub out: PathBuf,
    /// Continue from `out/checkpoints/last.ckpt` when it exists.
    pub resume: bool,
    /// A per-kernel GPU time breakdown at every log line.
    pub verbose: bool,
}

/// Where a run reports its progress.
pub trait Progress {
    fn start(&mut self, total: u32, at: u32);
    fn position(&mut self, iteration: u32);
    /// The status line of a logged iteration.
    fn message(&mut self, iteration: u32, total: u32, msg: &str);
    /// An event worth a line of its own (device, resume, splits, collapses, warnings).
    fn note(&mut self, text: &str);
    fn finish(&mut self);
}

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

fn io(path: &Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |source| Error::Io {
        path: path.display().to_string(),
        source,
    }
}

/// Trains `spec` on `gpu` to its configured iterations (resuming when asked), writes every
/// output of a run into `spec.out` and returns the metrics it wrote to `metrics.json`.
pub fn train_run(gpu: &Gpu, spec: &RunSpec<'_>, progress: &mut dyn Progress) -> Result<Report> {
    let (cfg, out) = (spec.cfg, &spec.out);
    let dataset = data::load(&spec.data_dir, &cfg.load_options())?;
    progress.note(&format!("device: {}", gpu.info));
    let mut tr = Trainer::new(gpu, cfg, &dataset).map_err(|e| match e {
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
    progress.note(&tr.init_report.to_string());
    let ckpt = last_checkpoint(out);
    let resume = spec.resume && ckpt.is_file();
    if resume {
        // Everything is checked before the run directory changes.
        check_same_config(&out.join("config.toml"), cfg)?;
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
    std::fs::create_dir_all(out.join("checkpoints")).map_err(io(out))?;
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
    progress.note(&format!(
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
    ));
    let initial_psnr = if tr.iteration == 0 {
        Some(mean(tr.evaluate(false)?.iter().map(|v| v.psnr)))
    } else {
        None
    };
    progress.start(cfg.iterations, tr.iteration);
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
    let mut prune = None;
    let open_log = || {
        std::fs::OpenOptions::new()
            .append(true)
            .open(&log_path)
            .map_err(io(&log_path))
    };
    let mut log_file = open_log()?;
    while tr.iteration < cfg.iterations {
        let next = tr.iteration + 1;
        let test = cfg.test_interval > 0
            && !probes.is_empty()
            && (next % cfg.test_interval == 0 || next == cfg.iterations);
        let log = next % cfg.log_interval == 0 || next == cfg.iterations || test;
        let t0 = Instant::now();
        let n_before = tr.n();
        let info = tr.step(log, log && spec.verbose)?;
        step_ms.push(t0.elapsed().as_secs_f64() * 1e3);
        let done = tr.last_plan.expect("a step ran");
        if let Some(cut) = done.densify {
            let n = tr.n();
            if n == 0 {
                // Nothing is left to draw, to densify from, or to place nodes on.
                let ev = PruneEvent {
                    iteration: done.iteration,
                    before: n_before,
                    after: 0,
                    screen_cut: cut,
                };
                return Err(Error::Invalid(format!(
                    "nothing left to train: {}",
                    ev.describe(cfg.densify.max_screen_size)
                )));
            }
            if let Some(ev) = PruneEvent::of(done.iteration, n_before, n, cut) {
                progress.note(&format!(
                    "warning: {}",
                    ev.describe(cfg.densify.max_screen_size)
                ));
                prune = Some(ev);
            }
        }
        if let Some((v, id)) = tr.last_loss() {
            worst.see(v.psnr, id);
            if let Some(ev) = guard.after_step(&mut tr, &done, v.loss, v.psnr)? {
                let what = match ev.rolled_back_to {
                    Some(r) => {
                        // The abandoned iterations' lines go; the next line carries the event.
                        // The cut replaces the file: append to the new one, not the old inode.
                        truncate_log(&log_path, r)?;
                        log_file = open_log()?;
                        format!(
                            "; rolled back to iteration {r}, deformation rate ×{}",
                            tr.deform_lr_scale
                        )
                    }
                    None if ev.rollback_stopped => format!(
                        "; it came back as deep at the place of the last {} rollbacks, which \
                         halved the deformation rate (now ×{}): the rate is not its cause, so \
                         the run goes on without rolling back",
                        super::collapse::SAME_PLACE_ROLLBACKS,
                        tr.deform_lr_scale
                    ),
                    None => " (--on-collapse rollback would restore an earlier state)".into(),
                };
                progress.note(&format!(
                    "collapse at iteration {}: {}, windowed training PSNR {:.2} → {:.2} dB{what}",
                    ev.iteration,
                    ev.kind.replace('_', " "),
                    ev.before_db,
                    ev.after_db
                ));
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
                    progress.position(tr.iteration);
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
        progress.position(tr.iteration);
        if tr.last_split.map(|s| s.0) != split_seen {
            split_seen = tr.last_split.map(|s| s.0);
            if let Some((it, s)) = tr.last_split {
                progress.note(&format!("split after iteration {it}: {s}"));
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
                progress.note(&format!(
                    "warning: iteration {}: the deformation moves no Gaussian between the \
                     probe frames' times (projected motion p99 = 0 px): the MLP's output is \
                     constant in time (dead ReLUs; a lower lr.deform_init avoids it)",
                    l.iteration
                ));
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
            let line = LogLine {
                iteration: l.iteration,
                loss: l.loss.loss,
                psnr: l.loss.psnr,
                num_gaussians: l.num_gaussians,
                motion_weight: tr.motion_weight_at(l.iteration),
                ms: if spec.verbose {
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
                prune: prune.take(),
            };
            let text = serde_json::to_string(&line).expect("log line serialises");
            std::io::Write::write_all(&mut log_file, format!("{text}\n").as_bytes())
                .map_err(io(&log_path))?;
            progress.message(l.iteration, cfg.iterations, &msg);
            if spec.verbose {
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
                progress.note(&format!(
                    "GPU time of iteration {} ({total:.2} ms):\n{}",
                    l.iteration,
                    rows.join("\n")
                ));
            }
        }
        if tr.iteration % cfg.checkpoint_interval == 0 || tr.iteration == cfg.iterations {
            let c = tr.checkpoint()?;
            c.save(&ckpt)?;
            if cfg.keep_checkpoints {
                c.save(&kept_checkpoint(out, tr.iteration))?;
            }
        }
    }
    progress.finish();

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
    let mlp = tr.model.deform.download(gpu)?;
    write_atomic(&out.join("deform.bin"), bytemuck::cast_slice(&mlp))?;
    if let Some(ns) = tr.model.nodes.as_ref().filter(|n| n.placed()) {
        let p = ns.download(gpu, tr.n())?.params;
        write_atomic(&out.join("nodes.bin"), bytemuck::cast_slice(&p))?;
    }
    let dynamic_bin = out.join("dynamic.bin");
    match tr.model.dynamic.download(gpu, tr.n())? {
        Some(d) => write_atomic(&dynamic_bin, &super::outputs::dynamic_bin(&d))?,
        None if dynamic_bin.is_file() => {
            std::fs::remove_file(&dynamic_bin).map_err(io(&dynamic_bin))?
        }
        None => {}
    }
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
    // None when no step ran (a resumed run that had already finished).
    metrics.ms_per_step = (!step_ms.is_empty()).then(|| crate::bench::median(step_ms.clone()));
    metrics.dynamic_fraction = Some(tr.dynamic_fraction());
    metrics.train_seconds = Some(wall_before + step_ms.iter().sum::<f64>() / 1e3);
    metrics.ms_per_step_by_phase = phase_ms
        .into_iter()
        .map(|(phase, v)| crate::train::metrics::PhaseMs {
            phase,
            steps: v.len() as u32,
            median_ms: crate::bench::median(v),
        })
        .collect();
    metrics.mean_dynamic_fraction = (dyn_sum.1 > 0).then(|| dyn_sum.0 / dyn_sum.1 as f64);
    let log = super::outputs::read_log(&log_path)?;
    metrics.time_to_psnr = super::curve::time_to_psnr(&log);
    metrics.collapses = log.iter().filter_map(|l| l.collapse.clone()).collect();
    metrics.mass_prunes = log.iter().filter_map(|l| l.prune.clone()).collect();
    crate::report::save_png(
        &super::outputs::training_plot(&log)?,
        &out.join("training.png"),
    )?;
    write_atomic(&out.join("metrics.json"), metrics.to_json().as_bytes())?;
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
