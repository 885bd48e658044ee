//! Populations (DESIGN §3 "Populations"): sets of Gaussian rows with their own rules, which
//! the passes ask instead of testing whether the model has transients. The storage keeps the
//! canonical rows first and the transient rows last ([`crate::model::rows`]).
//!
//! This cut owns the optimiser's side (the sections only a population learns — its Adam
//! groups —, the budget rows it keeps in reserve, what densification prunes it by, whether
//! the opacity reset touches it) and what a population adds to the forward/backward
//! (`passes::deform`: an opacity factor per slot, δ by a learnt velocity). Spawning
//! (`train::transients`) and save/load still test the rows themselves.

use crate::kernels::adam::AdamGroup;
use crate::kernels::temporal::{Temporal, TemporalParams};
use crate::model::gaussians::{GaussianLayout, Section};
use crate::model::rows::Rows;
use crate::model::state::{GaussianState, TransientShape};
use crate::train::plan::StepLr;
use crate::vk::{BufSlice, Recorder};

/// One population of the model's rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Population {
    /// What the deformation moves: learns the shared sections only, pruned by its opacity,
    /// reset by 3DGS's periodic opacity reset.
    Canonical(Rows),
    /// Time-local Gaussians (`kernels::temporal`): learn their time centre, width and
    /// velocity too, are pruned by their largest opacity over the sequence, and are spared
    /// by the opacity reset (a young transient would not climb back before the next prune).
    Transient(Rows),
}

impl Population {
    /// The populations of `g` in row order: the canonical rows (even when empty), then the
    /// transient rows while there are any.
    pub fn of(g: &GaussianState) -> Vec<Population> {
        let p = g.populations();
        let mut all = vec![Population::Canonical(p.canonical)];
        if !p.transient.is_empty() {
            all.push(Population::Transient(p.transient));
        }
        all
    }

    pub fn rows(&self) -> Rows {
        match *self {
            Population::Canonical(r) | Population::Transient(r) => r,
        }
    }

    /// Adam groups of the sections only this population learns, over its rows (the shared
    /// sections — geometry, opacity, colour — are one group each over every row).
    pub fn own_groups(&self, l: &GaussianLayout, lr: &StepLr) -> Vec<AdamGroup<'static>> {
        let Population::Transient(r) = *self else {
            return Vec::new();
        };
        let rates = [lr.centre, lr.log_width, lr.velocity];
        (Section::TEMPORAL.iter().zip(rates))
            .map(|(&s, rate)| AdamGroup {
                first: (l.offset(s) + r.start as u64 * l.row_len(s) as u64) as u32,
                count: r.len() * l.row_len(s),
                lr: rate as f32,
                mask: None,
            })
            .collect()
    }

    /// Records the logits densification prunes this population's rows by into `out` (rows
    /// `0..g.n`), or `None` when the opacity itself is the criterion.
    pub fn record_prune_logits<'a>(
        &self,
        rec: &mut Recorder<'_>,
        g: &GaussianState,
        (temporal, shape): (&Temporal, TransientShape),
        out: BufSlice<'a>,
    ) -> Option<BufSlice<'a>> {
        let Population::Transient(r) = *self else {
            return None;
        };
        let p = TemporalParams {
            n: g.n,
            first: r.start,
            log_floor: shape.log_floor,
            cutoff: shape.cutoff,
            t_lo: shape.t_range[0],
            t_hi: shape.t_range[1],
            ..Default::default()
        };
        let (l, c, w) = (
            g.param(Section::Opacity),
            g.param(Section::TimeCentre),
            g.param(Section::TimeLogWidth),
        );
        temporal.peak(rec, &p, l, c, w, out);
        Some(out)
    }

    /// Whether the forward scales these rows' opacity by a per-slot factor (the transients'
    /// temporal weight at the slot's time), which the slot's splats then carry.
    pub fn scales_opacity(&self) -> bool {
        matches!(self, Population::Transient(_))
    }

    /// Whether any population of `g` scales its opacity per slot (the slot's splats then
    /// carry the factors, and a frozen model of one instant drops the rows they cull).
    pub fn any_scales_opacity(g: &GaussianState) -> bool {
        Population::of(g).iter().any(Population::scales_opacity)
    }

    /// The rows DispFlow's δ moves by a learnt velocity, v·(t2 − t1) (the transients'), or
    /// `None` when the deformation's output is their δ.
    pub fn velocity_rows(&self) -> Option<Rows> {
        match *self {
            Population::Transient(r) => Some(r),
            Population::Canonical(_) => None,
        }
    }

    /// Whether 3DGS's periodic opacity reset applies to these rows.
    pub fn resets_opacity(&self) -> bool {
        matches!(self, Population::Canonical(_))
    }
}

/// The budget rows densification leaves free for transients (`transient.max_share`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Reserve {
    /// The transients' share of the budget (0 without them).
    pub share: u32,
    /// Whether the share is kept before any transient exists (`--transients on`); `auto`
    /// keeps it only while transients are held, so a scene that never spawns loses no row.
    pub before_first: bool,
}

impl Reserve {
    pub fn of(cfg: &crate::train::config::TrainConfig) -> Reserve {
        Reserve {
            share: cfg.transient_share(),
            before_first: cfg.transient.mode == crate::train::config::TransientMode::On,
        }
    }

    /// The rows kept free now: the share less the rows the transients hold.
    pub fn rows(&self, g: &GaussianState) -> u32 {
        let held = g.transient_rows().len();
        if held == 0 && !self.before_first {
            return 0;
        }
        self.share.saturating_sub(held)
    }
}
