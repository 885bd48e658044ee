//! The collapse guard of a training run: the [`CollapseWatch`] over every step and, with
//! `on_collapse = rollback`, the in-memory checkpoints it returns to. A checkpoint is taken
//! every window of steps while the watch reads the run as healthy; a rollback restores the
//! newest one taken at least `CONFIRM_WINDOWS + 1` windows before the collapse was confirmed
//! (the fall began at least that many windows earlier, less the sliding mean's lag of up to
//! one), so it never returns to a model that had already started to fall.

use std::collections::VecDeque;

use super::checkpoint::Checkpoint;
use super::collapse::{
    CollapseEvent, CollapseWatch, OnCollapse, CONFIRM_WINDOWS, MAX_ROLLBACKS, SAME_DEPTH,
    SAME_PLACE_ROLLBACKS,
};
use super::plan::StepPlan;
use super::Trainer;
use crate::error::{Error, Result};

/// In-memory checkpoints kept (the oldest but the first go when more are taken): enough to
/// reach back `CONFIRM_WINDOWS + 1` windows.
const KEPT: usize = 6;

pub struct CollapseGuard {
    watch: CollapseWatch,
    window: u32,
    action: OnCollapse,
    kept: VecDeque<Checkpoint>,
    rollbacks: u32,
    /// Where the last rollback's fall was confirmed and how deep it was (dB), and how many
    /// rollbacks in a row met an unchanged fall there.
    last_fall: Option<(u32, f64)>,
    same_place: u32,
}

impl CollapseGuard {
    /// With `rollback`, keeps the trainer's state now (the launch's first state: the rollback
    /// of last resort).
    pub fn new(tr: &Trainer<'_>) -> Result<Self> {
        let cfg = &tr.cfg.collapse;
        let mut kept = VecDeque::new();
        if cfg.on_collapse == OnCollapse::Rollback {
            kept.push_back(tr.checkpoint()?);
        }
        Ok(CollapseGuard {
            watch: CollapseWatch::new(cfg, tr.cfg.iterations),
            window: cfg.window_for(tr.cfg.iterations) as u32,
            action: cfg.on_collapse,
            kept,
            rollbacks: 0,
            last_fall: None,
            same_place: 0,
        })
    }

    /// Reads step `done`'s loss values (`loss`, `psnr`) after it ran. Returns the collapse it
    /// confirmed, after acting on it: with `rollback`, the trainer is back at an earlier
    /// iteration with its deformation rate halved; with `warn` nothing else changes (the
    /// caller stops on a non-finite loss).
    pub fn after_step(
        &mut self,
        tr: &mut Trainer<'_>,
        done: &StepPlan,
        loss: f64,
        psnr: f64,
    ) -> Result<Option<CollapseEvent>> {
        let Some(mut ev) = self.watch.see(tr.iteration, loss, psnr) else {
            if done.opacity_reset {
                // The PSNR drops on purpose; the next full window is the new reference.
                self.watch.restart();
            }
            self.keep(tr)?;
            return Ok(None);
        };
        if self.action == OnCollapse::Warn {
            return Ok(Some(ev));
        }
        let reach = (CONFIRM_WINDOWS as u32 + 1) * self.window;
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
            return Ok(Some(ev));
        }
        if self.rollbacks >= MAX_ROLLBACKS {
            return Err(Error::Invalid(format!(
                "iteration {}: the run collapsed again ({}: training PSNR {:.2} → {:.2} dB) after \
                 {MAX_ROLLBACKS} rollbacks that each halved the deformation rate (now ×{}); \
                 lower lr.deform_init/deform_final or check the data",
                ev.iteration, ev.kind, ev.before_db, ev.after_db, tr.deform_lr_scale
            )));
        }
        let limit = ev
            .iteration
            .saturating_sub((CONFIRM_WINDOWS as u32 + 1) * self.window);
        let target = self
            .kept
            .iter()
            .rev()
            .find(|c| c.iteration <= limit)
            .or(self.kept.front())
            .expect("the launch's first state is kept")
            .clone();
        let scale = tr.deform_lr_scale * 0.5;
        tr.restore(&target)?;
        tr.deform_lr_scale = scale;
        self.rollbacks += 1;
        // Checkpoints after the one restored belong to the abandoned branch.
        self.kept.retain(|c| c.iteration <= target.iteration);
        // The restored state is measured against the best level before the fall.
        self.watch.resume_at(ev.before_db);
        ev.rolled_back_to = Some(target.iteration);
        ev.deform_lr_scale = Some(tr.deform_lr_scale);
        Ok(Some(ev))
    }

    /// Takes a rollback checkpoint every window of steps while the run is healthy.
    fn keep(&mut self, tr: &Trainer<'_>) -> Result<()> {
        if self.action != OnCollapse::Rollback
            || tr.iteration % self.window != 0
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
