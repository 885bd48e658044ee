//! The transient population's room (issue 37): which pixels are wrong ([`residual`]), the ray
//! maths both spawning and tracking stand on ([`ray`]), the tracker that explains a wrong pixel
//! by a point moving at constant velocity through the temporal neighbours ([`track`]), the
//! spawn rules and what one frame spawns ([`spawn`]), `auto`'s rules for a held frame
//! ([`rules`]), and the trainer's spawn round
//! (`round`: `Trainer::spawn_transients`), and the resolution of a spawn's depth hypotheses
//! ([`resolve`]). Dependencies point down: round → rules, spawn → track → ray, residual.

pub mod ray;
pub mod residual;
pub mod resolve;
mod round;
pub mod rules;
pub mod spawn;
pub mod track;

use crate::model::rows::Populations;

/// What the spawns carry from one round to the next: which frames they looked at and what
/// they saw, and the depth hypotheses waiting to be resolved. Checkpoints hold it, so a
/// resumed run spawns as the uninterrupted one would.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpawnState {
    pub looks: spawn::Looks,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hypotheses: Option<resolve::Hypotheses>,
}

impl SpawnState {
    /// What is wrong with this state for a model of `rows` trained on `frames` frames, if
    /// anything: a frame index past the data, a residual that is not a finite non-negative
    /// number, or a hypothesis outside the transient rows.
    pub fn problem(&self, rows: Populations, frames: Option<usize>) -> Option<String> {
        if let Some(p) = self.looks.problem(frames) {
            return Some(p);
        }
        let t = rows.transient;
        let h = self.hypotheses.iter().flat_map(|h| h.groups.iter());
        if let Some(g) = h
            .clone()
            .find(|g| g.start >= g.end || g.start < t.start || g.end > t.end)
        {
            return Some(format!(
                "spawn state: depth hypotheses at rows {g:?}; the transient rows are {}..{}",
                t.start, t.end
            ));
        }
        None
    }
}
