//! The collapse guard of a training run: the [`CollapseWatch`] over a fixed set of probe views
//! (training frames spread over the sequence's time, each rendered before the first step and
//! then one every `probe_every` steps in turn) and over every step's loss, and, with
//! `on_collapse = rollback`, the in-memory checkpoints it returns to. A checkpoint is taken
//! every round over the views while the watch reads the run as healthy; a rollback restores the
//! newest one taken at least `CONFIRM_ROUNDS + 1` rounds before the collapse was confirmed (the
//! fall began at least that early), so it never returns to a model that had already started
//! to fall.

use std::collections::VecDeque;

use super::checkpoint::Checkpoint;
use super::collapse::{
    CollapseEvent, CollapseWatch, OnCollapse, CONFIRM_ROUNDS, MAX_ROLLBACKS, PROBE_VIEWS,
    SAME_DEPTH, SAME_PLACE_ROLLBACKS,
};
use super::params_check::ParamCheck;
use super::plan::StepPlan;
use super::Trainer;
use crate::error::{Error, Result};

/// In-memory checkpoints kept (the oldest but the first go when more are taken): enough to
/// reach back `CONFIRM_ROUNDS + 1` rounds.
const KEPT: usize = 5;

/// Training frames the guard probes: [`PROBE_VIEWS`] spread evenly over the frames sorted by
/// time (all of them when there are fewer).
pub fn probe_views(times: &[f32]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..times.len()).collect();
    order.sort_by(|&a, &b| times[a].total_cmp(&times[b]).then(a.cmp(&b)));
    let n = order.len();
    if n <= PROBE_VIEWS {
        return order;
    }
    (0..PROBE_VIEWS)
        .map(|i| order[i * (n - 1) / (PROBE_VIEWS - 1)])
        .collect()
}

pub struct CollapseGuard {
    watch: CollapseWatch,
    /// Training frames probed, and the steps between two probe renders.
    views: Vec<usize>,
    every: u32,
    action: OnCollapse,
    kept: VecDeque<Checkpoint>,
    rollbacks: u32,
    /// Where the last rollback's fall was confirmed and how deep it was (dB), and how many
    /// rollbacks in a row met an unchanged fall there.
    last_fall: Option<(u32, f64)>,
    same_place: u32,
    /// The parameters' finiteness, checked with every probe render and after the last step.
    params: ParamCheck,
}

impl CollapseGuard {
    /// Renders every probe view now (the references a fall is measured from: before the first
    /// step, the initial model) and, with `rollback`, keeps the trainer's state now (the
    /// launch's first state: the rollback of last resort). A non-finite initial render is
    /// returned as an event.
    pub fn new(tr: &mut Trainer<'_>) -> Result<(Self, Option<CollapseEvent>)> {
        let cfg = tr.cfg.collapse;
        let times: Vec<f32> = tr.frames.iter().map(|f| f.time).collect();
        let views = probe_views(&times);
        let mut watch = CollapseWatch::new(cfg.drop_db as f64, views.len().max(1));
        let mut first = None;
        for (k, &i) in views.iter().enumerate() {
            let psnr = tr.train_view_psnr(i)?;
            first = first.or(watch.see(tr.iteration, k, psnr));
        }
        let mut kept = VecDeque::new();
        if cfg.on_collapse == OnCollapse::Rollback {
            kept.push_back(tr.checkpoint()?);
        }
        let guard = CollapseGuard {
            watch,
            views,
            every: cfg.probe_every_for(tr.cfg.iterations),
            action: cfg.on_collapse,
            kept,
            rollbacks: 0,
            last_fall: None,
            same_place: 0,
            params: ParamCheck::new(tr.gpu)?,
        };
        Ok((guard, first))
    }

    /// The probe views' mean latest PSNR and their mean fall below their references (dB).
    pub fn probe_level(&self) -> Option<(f64, f64)> {
        Some((self.watch.level()?, self.watch.fall()?))
    }

    /// Steps of one round over the probe views.
    fn round(&self) -> u32 {
        self.every * self.views.len().max(1) as u32
    }

    /// Reads step `done`'s loss after it ran and, when due, renders the next probe view.
    /// Returns the collapse it confirmed, after acting on it: with `rollback`, the trainer is
    /// back at an earlier iteration with its deformation rate halved; with `warn` nothing else
    /// changes (the caller stops on a non-finite loss).
    pub fn after_step(
        &mut self,
        tr: &mut Trainer<'_>,
        done: &StepPlan,
        loss: f64,
    ) -> Result<Option<CollapseEvent>> {
        let mut ev = self.watch.see_loss(tr.iteration, loss);
        if ev.is_none() && done.opacity_reset {
            // The PSNR drops on purpose; each view's next render is its new reference.
            self.watch.restart();
        }
        if ev.is_none() && !self.views.is_empty() && tr.iteration % self.every == 0 {
            let k = (tr.iteration / self.every) as usize % self.views.len();
            let psnr = tr.train_view_psnr(self.views[k])?;
            ev = self.watch.see(tr.iteration, k, psnr);
        }
        if ev.is_none() && (tr.iteration % self.every == 0 || tr.iteration == tr.cfg.iterations) {
            ev = self.params.run(tr)?.map(|f| {
                let kind = if f.weights > 0 {
                    "non_finite_weights"
                } else {
                    "non_finite_gaussians"
                };
                let mut e = self.watch.event(tr.iteration, kind);
                e.detail = Some(f.describe());
                e
            });
            if ev
                .as_ref()
                .is_some_and(|e| e.kind == "non_finite_gaussians")
            {
                // Repaired in place: reported, nothing to roll back.
                return Ok(ev);
            }
        }
        let Some(ev) = ev else {
            self.keep(tr)?;
            return Ok(None);
        };
        if self.action == OnCollapse::Warn {
            return Ok(Some(ev));
        }
        self.roll_back(tr, ev).map(Some)
    }

    fn roll_back(&mut self, tr: &mut Trainer<'_>, mut ev: CollapseEvent) -> Result<CollapseEvent> {
        let reach = (CONFIRM_ROUNDS as u32 + 1) * self.round();
        let depth = ev.before_db - ev.after_db;
        self.same_place = match self.last_fall {
            Some((p, d)) if p.abs_diff(ev.iteration) <= reach && depth >= SAME_DEPTH * d => {
                self.same_place + 1
            }
            _ => 0,
        };
        self.last_fall = Some((ev.iteration, depth));
        if self.same_place >= SAME_PLACE_ROLLBACKS && ev.kind == "psnr_drop" {
            // Halving the rate did not move the fall: it is not the rate's doing, and more
            // rollbacks would only replay it. Go on from here, reporting what comes (a
            // non-finite loss cannot go on: it keeps rolling back up to MAX_ROLLBACKS).
            self.action = OnCollapse::Warn;
            ev.rollback_stopped = true;
            ev.deform_lr_scale = Some(tr.deform_lr_scale);
            return Ok(ev);
        }
        if self.rollbacks >= MAX_ROLLBACKS {
            return Err(Error::Invalid(format!(
                "iteration {}: the run collapsed again ({}: probe views {:.2} → {:.2} dB) after \
                 {MAX_ROLLBACKS} rollbacks that each halved the deformation rate (now ×{}); \
                 lower lr.deform_init/deform_final or check the data",
                ev.iteration, ev.kind, ev.before_db, ev.after_db, tr.deform_lr_scale
            )));
        }
        let limit = ev.iteration.saturating_sub(reach);
        let target = self
            .kept
            .iter()
            .rev()
            .find(|c| c.iteration <= limit)
            .or(self.kept.front())
            .expect("the launch's first state is kept")
            .clone();
        // The references before the fall (reporting it made the fallen levels the new ones);
        // a non-finite loss leaves them as they are.
        let references = if ev.kind == "psnr_drop" {
            self.watch.fallen_from()
        } else {
            self.watch.references()
        };
        let scale = tr.deform_lr_scale * 0.5;
        tr.restore(&target)?;
        tr.deform_lr_scale = scale;
        self.rollbacks += 1;
        // Checkpoints after the one restored belong to the abandoned branch.
        self.kept.retain(|c| c.iteration <= target.iteration);
        self.watch.resume_at(references);
        ev.rolled_back_to = Some(target.iteration);
        ev.deform_lr_scale = Some(tr.deform_lr_scale);
        Ok(ev)
    }

    /// Takes a rollback checkpoint every round while the run is healthy.
    fn keep(&mut self, tr: &Trainer<'_>) -> Result<()> {
        if self.action != OnCollapse::Rollback
            || tr.iteration % self.round() != 0
            || !self.watch.healthy()
        {
            return Ok(());
        }
        if self.kept.len() == KEPT {
            // Keep the launch's first state; drop the oldest of the rest.
            self.kept.remove(1);
        }
        self.kept.push_back(tr.checkpoint()?);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn probe_views_spread_over_time() {
        let times = [0.9, 0.1, 0.5, 0.3, 0.7, 0.0, 1.0];
        // Sorted by time: 5 (0.0), 1, 3, 2, 4, 0, 6 (1.0).
        assert_eq!(super::probe_views(&times), vec![5, 3, 4, 6]);
        assert_eq!(super::probe_views(&[0.2, 0.1]), vec![1, 0]);
        assert!(super::probe_views(&[]).is_empty());
    }
}
