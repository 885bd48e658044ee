//! The middle phase of a training run ([`super::session::train_run`]): the steps from where
//! the run stands to its last iteration, with what watches them (the collapse guard, mass
//! prunes, a frozen deformation), the `log.jsonl` lines, the progress messages and the
//! checkpoints. Set-up and the final evaluation live in `session`.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::collapse::{CollapseEvent, PruneEvent, SAME_PLACE_ROLLBACKS};
use super::guard::CollapseGuard;
use super::outputs::{truncate_log, LogLine};
use super::run::{Progress, RunSpec};
use super::Trainer;
use crate::error::{Error, Result};

/// `log.jsonl`, open for appending.
pub(super) struct RunLog {
    path: PathBuf,
    file: std::fs::File,
}

impl RunLog {
    pub fn open(path: &Path) -> Result<Self> {
        let file = std::fs::OpenOptions::new()
            .append(true)
            .open(path)
            .map_err(Error::io(path))?;
        Ok(RunLog {
            path: path.to_path_buf(),
            file,
        })
    }

    pub fn write(&mut self, line: &LogLine) -> Result<()> {
        let text = serde_json::to_string(line).expect("log line serialises");
        std::io::Write::write_all(&mut self.file, format!("{text}\n").as_bytes())
            .map_err(Error::io(&self.path))
    }

    /// Drops the lines after `iteration` (a rollback's abandoned branch). The cut replaces
    /// the file, so the handle is reopened: appending to the old inode would lose every later
    /// line.
    pub fn cut_to(&mut self, iteration: u32) -> Result<()> {
        truncate_log(&self.path, iteration)?;
        *self = RunLog::open(&self.path)?;
        Ok(())
    }
}

/// What the loop measured, for the run's report.
#[derive(Default)]
pub(super) struct LoopStats {
    /// Wall ms of every step (training only: probes and logging excluded).
    pub step_ms: Vec<f64>,
    /// Wall ms per step by what the step ran, in first-seen order.
    pub phase_ms: Vec<(String, Vec<f64>)>,
    /// Sum and count of the dynamic fraction over the steps the MLP ran in.
    pub dyn_sum: (f64, u32),
    /// Training seconds of earlier launches (a resumed run continues the count).
    pub wall_before: f64,
    /// GPU time by population at the log lines (this launch's steps).
    pub cost: super::cost::CostSampler,
}

impl LoopStats {
    pub fn train_seconds(&self) -> f64 {
        self.wall_before + self.step_ms.iter().sum::<f64>() / 1e3
    }

    fn add_phase(&mut self, phase: String, ms: f64) {
        match self.phase_ms.iter_mut().find(|p| p.0 == phase) {
            Some(p) => p.1.push(ms),
            None => self.phase_ms.push((phase, vec![ms])),
        }
    }
}

/// What a step's plan ran, as the report groups step times.
fn phase_of(done: &super::plan::StepPlan) -> String {
    let base = match (done.deform_active, done.sparse) {
        (false, _) => "no MLP",
        (true, false) => "MLP over all",
        (true, true) => "MLP over dynamic",
    };
    let motion = if done.motion.is_some() {
        " + motion"
    } else {
        ""
    };
    format!("{base}{motion}")
}

/// The progress note of a collapse event.
fn collapse_note(ev: &CollapseEvent, deform_lr_scale: f64) -> String {
    let what = match ev.rolled_back_to {
        Some(r) => format!("; rolled back to iteration {r}, deformation rate ×{deform_lr_scale}"),
        None if ev.rollback_stopped => format!(
            "; it came back as deep at the place of the last {SAME_PLACE_ROLLBACKS} rollbacks, \
             which halved the deformation rate (now ×{deform_lr_scale}): the rate is not its \
             cause, so the run goes on without rolling back"
        ),
        None => " (--on-collapse rollback would restore an earlier state)".into(),
    };
    if ev.kind == "non_finite_gaussians" {
        return format!(
            "warning: iteration {}: {}",
            ev.iteration,
            ev.detail
                .as_deref()
                .unwrap_or("non-finite Gaussians retired")
        );
    }
    let detail = ev
        .detail
        .as_ref()
        .map_or(String::new(), |d| format!(" ({d})"));
    format!(
        "warning: collapse at iteration {}: {}{detail}, probe views' PSNR {:.2} → {:.2} dB{what}",
        ev.iteration,
        ev.kind.replace('_', " "),
        ev.before_db,
        ev.after_db
    )
}

/// Trains `tr` from its iteration to the configured end. `ckpt` is `last.ckpt`.
pub(super) fn train_loop(
    tr: &mut Trainer<'_>,
    spec: &RunSpec<'_>,
    ckpt: &Path,
    log: &mut RunLog,
    mut stats: LoopStats,
    progress: &mut dyn Progress,
) -> Result<LoopStats> {
    let cfg = spec.cfg;
    let out = &spec.out;
    let test_frames = super::curve::probe_frames(tr.val.len());
    let mut worst = super::curve::WorstView::default();
    let (mut guard, first) = CollapseGuard::new(tr)?;
    let mut collapse = first;
    if let Some(ev) = &collapse {
        progress.note(&collapse_note(ev, tr.deform_lr_scale));
    }
    let mut dead_warned = false;
    let mut prune = None;
    let mut spawn_seen = None;
    let mut resolved_seen = None;
    let mut split_seen = None;
    let transients_on = cfg.transient.mode.spawns();
    progress.start(cfg.iterations, tr.iteration);
    while tr.iteration < cfg.iterations {
        let next = tr.iteration + 1;
        let last = next == cfg.iterations;
        let test = cfg.test_interval > 0
            && !test_frames.is_empty()
            && (next % cfg.test_interval == 0 || last);
        // A progress message at log intervals only; a test probe off them still gets its
        // log.jsonl line (the two intervals need not divide each other).
        let message = next % cfg.log_interval == 0 || last;
        let line = message || test;
        let t0 = Instant::now();
        let n_before = tr.n();
        // Log lines are timed: what each population costs is sampled there.
        let info = tr.step(line, line)?;
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        stats.step_ms.push(ms);
        let done = tr.last_plan.expect("a step ran");
        if let Some(cut) = done.densify {
            prune = prune.or(check_prune(
                tr,
                cfg,
                n_before,
                done.iteration,
                cut,
                progress,
            )?);
        }
        if let Some((v, id)) = tr.last_loss() {
            worst.see(v.psnr, id);
            let (loss, psnr) = (v.loss, v.psnr);
            if let Some(ev) = guard.after_step(tr, &done, loss)? {
                progress.note(&collapse_note(&ev, tr.deform_lr_scale));
                if let Some(r) = ev.rolled_back_to {
                    // The abandoned iterations' lines go; the next line carries the event.
                    log.cut_to(r)?;
                } else if ev.stops_run() {
                    log.write(&LogLine {
                        iteration: ev.iteration,
                        loss,
                        psnr,
                        num_gaussians: tr.n(),
                        collapse: Some(ev.clone()),
                        ..LogLine::default()
                    })?;
                    let detail = ev
                        .detail
                        .as_ref()
                        .map_or(String::new(), |d| format!(": {d}"));
                    return Err(Error::Invalid(format!(
                        "iteration {}: {}{detail} (loss {loss}); rerun with --on-collapse \
                         rollback to restore an earlier state with a lower deformation rate",
                        ev.iteration,
                        ev.kind.replace('_', " "),
                    )));
                }
                let rolled_back = ev.rolled_back_to.is_some();
                if let Some(old) = collapse.replace(ev).filter(|_| !rolled_back) {
                    // Two events before one log line: the first gets a line of its own.
                    log.write(&LogLine {
                        iteration: old.iteration,
                        loss,
                        psnr,
                        num_gaussians: tr.n(),
                        wall_s: stats.train_seconds(),
                        collapse: Some(old),
                        ..LogLine::default()
                    })?;
                }
                if rolled_back {
                    // A resumed run must not return to the abandoned branch.
                    tr.checkpoint()?.save(ckpt)?;
                    progress.position(tr.iteration);
                    continue;
                }
            }
        }
        stats.add_phase(phase_of(&done), ms);
        if done.deform_active {
            stats.dyn_sum = (stats.dyn_sum.0 + tr.dynamic_fraction(), stats.dyn_sum.1 + 1);
        }
        progress.position(tr.iteration);
        if tr.last_split.map(|s| s.0) != split_seen {
            split_seen = tr.last_split.map(|s| s.0);
            if let Some((it, s)) = tr.last_split {
                progress.note(&format!("split after iteration {it}: {s}"));
            }
        }
        if tr.last_resolved.map(|s| s.0) != resolved_seen {
            resolved_seen = tr.last_resolved.map(|s| s.0);
            if let Some((it, r)) = tr.last_resolved {
                progress.note(&format!(
                    "depth hypotheses resolved after iteration {it}: {} pixels kept their most \
                     opaque, {} dropped",
                    r.pixels, r.dropped
                ));
            }
        }
        if tr.last_spawn.as_ref().map(|s| s.0) != spawn_seen {
            spawn_seen = tr.last_spawn.as_ref().map(|s| s.0);
            if let Some((it, s)) = &tr.last_spawn {
                progress.note(&format!("spawned after iteration {it}: {s}"));
            }
        }
        if let Some(l) = info {
            // A queue without timestamps times nothing: no sample rather than a zero one.
            if let Some(rows) = l.rows.filter(|_| !l.timings.entries.is_empty()) {
                stats.cost.add(rows, &l.timings);
            }
            let dynamic = tr.dynamic_fraction();
            // Not counted in the training time: the probe is a measurement, not training.
            let probe = if test {
                Some(tr.probe(&test_frames, true)?)
            } else {
                None
            };
            // A split that froze every Gaussian also reads p99 = 0, but its MLP is alive (the
            // split line says why).
            let frozen =
                probe.is_some_and(|p| p.p99_px == Some(0.0)) && tr.model.dynamic.split() != Some(0);
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
            let level = guard.probe_level();
            let worst = worst.take();
            if message {
                let transients = if transients_on {
                    let alive = l.rows.map_or(0, |r| r.alive);
                    let held = tr.model.gaussians.transient_rows().len();
                    format!(" ({held} transient, {alive} alive at this step)")
                } else {
                    String::new()
                };
                let msg = format!(
                    "loss {:.4} psnr {:.2} (worst view {}){}{} gaussians {}{transients} dynamic {:.0}%",
                    l.loss.loss,
                    l.loss.psnr,
                    worst
                        .as_ref()
                        .map_or("n/a".into(), |(p, id)| format!("{p:.2} {id}")),
                    probe.map_or(String::new(), |p| p.summary(test_frames.len())),
                    level.map_or(String::new(), |(p, _)| format!(" probe views {p:.2}")),
                    l.num_gaussians,
                    100.0 * dynamic
                );
                progress.message(l.iteration, cfg.iterations, &msg);
            }
            log.write(&LogLine {
                iteration: l.iteration,
                loss: l.loss.loss,
                psnr: l.loss.psnr,
                num_gaussians: l.num_gaussians,
                motion_weight: tr.motion_weight_at(l.iteration),
                ms: if spec.verbose {
                    l.timings.total_ms()
                } else {
                    ms
                },
                dynamic_fraction: dynamic,
                wall_s: stats.train_seconds(),
                test_psnr: probe.map(|p| p.psnr),
                test_dynamic_psnr: probe.and_then(|p| p.dynamic_psnr),
                test_static_psnr: probe.and_then(|p| p.static_psnr),
                motion_epe: probe.and_then(|p| p.epe),
                motion_gt_px: probe.and_then(|p| p.gt_px),
                motion_p50_px: probe.and_then(|p| p.p50_px),
                motion_p99_px: probe.and_then(|p| p.p99_px),
                transients: transients_on.then_some(tr.model.gaussians.transient_rows().len()),
                probe_psnr: level.map(|l| l.0),
                probe_fall_db: level.map(|l| l.1),
                worst_psnr: worst.as_ref().map(|w| w.0),
                worst_view: worst.map(|w| w.1),
                collapse: collapse.take(),
                prune: prune.take(),
            })?;
            if spec.verbose {
                progress.note(&timing_table(l.iteration, &l.timings));
            }
        }
        if tr.iteration % cfg.checkpoint_interval == 0 || tr.iteration == cfg.iterations {
            let c = tr.checkpoint()?;
            c.save(ckpt)?;
            if cfg.keep_checkpoints {
                c.save(&super::checkpoint::kept_checkpoint(out, tr.iteration))?;
            }
        }
    }
    progress.finish();
    Ok(stats)
}

/// A densification at `iteration` left `tr.n()` of `before` Gaussians: an error when none is
/// left, a warning (returned for the log) when most went.
fn check_prune(
    tr: &Trainer<'_>,
    cfg: &super::config::TrainConfig,
    before: u32,
    iteration: u32,
    cut: bool,
    progress: &mut dyn Progress,
) -> Result<Option<PruneEvent>> {
    let n = tr.n();
    let d = &cfg.densify;
    if n == 0 {
        // Nothing is left to draw, to densify from, or to place nodes on.
        let ev = PruneEvent {
            iteration,
            before,
            after: 0,
            screen_cut: cut,
        };
        return Err(Error::Invalid(format!(
            "nothing left to train: {}",
            ev.describe(d)
        )));
    }
    let ev = PruneEvent::of(iteration, before, n, cut);
    if let Some(ev) = &ev {
        progress.note(&format!("warning: {}", ev.describe(d)));
    }
    Ok(ev)
}

/// The per-kernel GPU time breakdown of a step (`--verbose`).
fn timing_table(iteration: u32, t: &crate::vk::Timings) -> String {
    let total = t.total_ms();
    let rows: Vec<String> = t
        .by_label()
        .iter()
        .map(|(k, ms)| {
            let count = t.entries.iter().filter(|e| &e.0 == k).count();
            format!(
                "  {k:<28} {ms:8.3} ms {:5.1}% {count:>4}×",
                100.0 * ms / total.max(1e-9)
            )
        })
        .collect();
    format!(
        "GPU time of iteration {iteration} ({total:.2} ms, {} dispatches and copies):\n{}",
        t.entries.len(),
        rows.join("\n")
    )
}
