//! A spawn round of the trainer: render candidate frames, keep those whose localized residual
//! persists, track their wrong pixels through the temporal neighbours and append the
//! transients they back-project into free rows of the budget.

use super::residual::frame_residual;
use super::resolve::Hypotheses;
use super::rules::{Admit, RoundRules};
use super::spawn::{transients_of, SpawnFrame, SpawnReport, Verdict};
use super::track::{Residual, Tracker};
use crate::error::Result;
use crate::model::gaussians::HostGaussians;
use crate::train::config::TransientMode;
use crate::train::Trainer;

impl Trainer<'_> {
    /// The iteration after which this launch first spawned transients.
    pub fn transients_first_spawn(&self) -> Option<u32> {
        self.looks.opened
    }

    /// Whether transients have been spawned this run (`auto`'s gate is open): a spawn added
    /// rows, or the model holds some (a resumed run).
    fn transients_opened(&self) -> bool {
        self.looks.opened.is_some() || !self.model.gaussians.transient_rows().is_empty()
    }
}

/// The farthest a tracked transient may move per frame spacing, as a share of the scene
/// bounds' diagonal (a hypothesis faster than that is a false match across the scene).
const MAX_STEP_OF_BOUNDS: f32 = 0.25;

impl Trainer<'_> {
    /// Spawns transients from the frames with the lowest PSNR at their last step (see
    /// `transients`), into any free row of the budget.
    pub fn spawn_transients(&mut self) -> Result<()> {
        let started = std::time::Instant::now();
        let tc = self.cfg.transient;
        let g = &self.model.gaussians;
        let cap = g.layout.capacity as usize;
        // The share is the transients' reservation, not their ceiling: the canonical
        // population never grows into it, and rows it leaves free are the transients' too
        // (densification already grows them into those).
        let room = cap - g.n as usize;
        let mut report = SpawnReport::default();
        if room == 0 {
            // Nothing could be added: skip the renders and the tracking.
            self.looks.skip();
            report.full = true;
            report.ms = started.elapsed().as_secs_f64() * 1e3;
            self.last_spawn = Some((self.iteration, report));
            return Ok(());
        }
        let mut all = HostGaussians {
            sh_coeffs: g.layout.sh_coeffs,
            ..Default::default()
        };
        let view = self.view();
        let spacing = self.times.spacing;
        // Candidates spread over the frames the time curriculum trains now (one it has not
        // reached yet is wrong because it is untrained, not because the canonical model cannot
        // draw it), rotating each spawn, rendered; those with the largest localized residual
        // spawn.
        let window = self.times.window(&self.cfg, self.iteration.max(1));
        // `auto` asks a closed gate for a residual held through `gate` comparisons.
        let closed = tc.mode == TransientMode::Auto && !self.transients_opened();
        let need = if closed { tc.gate } else { 1 };
        // `auto` spawns only where the canonical population draws nothing over a region that
        // matters, at the opening and at every round after it: judging only the opening let
        // later rounds spawn from frames drawn wrong (D-NeRF standup, jumpingjacks) and from
        // small residuals; judging every round gained 0.3-0.8 dB there and on mujoco-scene5
        // (docs/measurements.md, "Judging every spawn").
        let judged = tc.mode == TransientMode::Auto;
        // Three times as many candidates as spawn, a closed gate too: looking at `frames`
        // alone took mujoco-scene5 from 15.55 / 14.92 to 14.64 / 14.63 dB inside the motion
        // masks (seeds 0 / 1; its first spawn came from weaker frames).
        let k = 3 * tc.frames as usize;
        let cands = self.looks.candidates(window, k, tc.persist, need);
        let mut shots = Vec::new();
        for &i in &cands {
            let Some((render, gt)) = self.shot(i, view)? else {
                continue;
            };
            let width = self.frames[i].camera.width;
            let r = frame_residual(&render, &gt, width, tc.min_error);
            shots.push((r, i, render, gt));
        }
        report.looked_at = shots.len();
        let rules = RoundRules::of(
            &tc,
            &shots.iter().map(|s| s.0).collect::<Vec<_>>(),
            view.deform_active,
        );
        if judged {
            report.lacking = rules.lacking;
        }
        shots.retain(|s| match self.looks.judge(s.1, s.0.sum, tc.persist, need) {
            // `auto` judges every held frame, at the opening and at every round after it.
            Verdict::Spawn if judged => match rules.admit(&tc, &s.0) {
                Admit::Spawn => true,
                Admit::Small => {
                    report.small += 1;
                    false
                }
                Admit::Covered => {
                    report.covered += 1;
                    false
                }
            },
            Verdict::Spawn => true,
            Verdict::FirstLook => {
                report.first_looks += 1;
                false
            }
            Verdict::Improving => {
                report.improving += 1;
                false
            }
            Verdict::Held => {
                report.held += 1;
                false
            }
        });
        shots.sort_by(|a, b| b.0.sum.total_cmp(&a.0.sum).then(a.1.cmp(&b.1)));
        shots.truncate(tc.frames as usize);
        shots.retain(|s| s.0.sum > 0.0);
        // Tracking reads the spawning frames' temporal neighbours too.
        let mut near = std::collections::BTreeMap::new();
        for s in &shots {
            for j in self.times.neighbours(s.1, tc.track as usize) {
                if let std::collections::btree_map::Entry::Vacant(e) = near.entry(j) {
                    if let Some(shot) = self.shot(j, view)? {
                        e.insert(shot);
                    }
                }
            }
        }
        let first = self.model.gaussians.n;
        let mut groups = Vec::new();
        let diag = (self.bounds.max - self.bounds.min).length();
        let v_max = MAX_STEP_OF_BOUNDS * diag / spacing.max(1e-9);
        for (r, i, render, gt) in &shots {
            let f = &self.frames[*i];
            let tracker = (tc.track > 0).then(|| {
                let nb = self
                    .times
                    .neighbours(*i, tc.track as usize)
                    .into_iter()
                    .filter_map(|j| {
                        let (rj, gj) = near.get(&j)?;
                        let fj = &self.frames[j];
                        Some(Residual::new(&fj.camera, fj.time, rj, gj, tc.min_error))
                    })
                    .collect();
                let me = Residual::new(&f.camera, f.time, render, gt, tc.min_error);
                Tracker::new(me, nb, v_max, &self.bounds)
            });
            let sf = SpawnFrame {
                camera: &f.camera,
                time: f.time,
                render,
                gt,
            };
            let left = room - all.len();
            let sh = self.model.gaussians.layout.sh_coeffs;
            let (t, fs) =
                transients_of(&sf, &tc, &self.bounds, spacing, sh, left, tracker.as_ref());
            report.frames.push((f.id.clone(), r.sum, fs.picked));
            report.tracked += fs.tracked;
            report.rejected += fs.rejected;
            report.over_budget += fs.over;
            let at = first + all.len() as u32;
            groups.extend(fs.groups.iter().map(|g| g.start + at..g.end + at));
            all.append(&t);
        }
        report.spawned = all.len();
        if !all.is_empty() && self.looks.opened.is_none() {
            self.looks.opened = Some(self.iteration);
        }
        self.model.gaussians.append_transients(self.gpu, &all)?;
        if tc.resolve && !groups.is_empty() {
            self.hypotheses = Some(Hypotheses {
                iteration: self.iteration,
                groups,
            });
        }
        if let Some(s) = self.passes.as_ref() {
            s.densify.clear_stats(self.gpu, first, all.len() as u32)?;
        }
        report.ms = started.elapsed().as_secs_f64() * 1e3;
        self.last_spawn = Some((self.iteration, report));
        Ok(())
    }
}
