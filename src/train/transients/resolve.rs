//! Depth hypotheses as alternatives (`transient.resolve`): a pixel no track explains spawns
//! still transients at several depths along its ray, of which at most one is right. The
//! spawn remembers each pixel's rows; at the first densification or spawn after it (nothing
//! moves rows before), each pixel keeps its most opaque hypothesis and the others are
//! dropped. Training in between has seen them from the other views of their lifetime, where
//! a wrong depth draws in the wrong place and loses opacity; left alone, densification grows
//! those floaters (D-NeRF trex, docs/measurements.md, "Where transients cost trex").

use crate::error::Result;
use crate::train::plan::StepPlan;
use crate::train::Trainer;
use std::ops::Range;

/// The still depth hypotheses of the last spawn, by pixel, in absolute rows.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Hypotheses {
    /// The spawn's iteration.
    pub iteration: u32,
    pub groups: Vec<Range<u32>>,
}

impl Hypotheses {
    /// The rows every group covers (the span to read).
    pub fn span(&self) -> Range<u32> {
        let lo = self.groups.iter().map(|g| g.start).min().unwrap_or(0);
        let hi = self.groups.iter().map(|g| g.end).max().unwrap_or(lo);
        lo..hi
    }
}

/// The rows to drop: in each group all but the one with the largest logit (the first of
/// equals). `logits[i]` is row `first + i`.
pub fn losers(groups: &[Range<u32>], first: u32, logits: &[f32]) -> Vec<u32> {
    let mut out = Vec::new();
    for g in groups {
        let at = |r: u32| logits[(r - first) as usize];
        let Some(best) = g.clone().reduce(|a, b| if at(b) > at(a) { b } else { a }) else {
            continue;
        };
        out.extend(g.clone().filter(|&r| r != best));
    }
    out
}

/// A dropped hypothesis' opacity logit: σ(−30) ≈ 1e-13, far under any prune threshold.
const DROPPED: f32 = -30.0;

/// What a resolution did (logged with the next spawn).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Resolved {
    pub pixels: usize,
    pub dropped: usize,
}

impl Trainer<'_> {
    /// The last spawn's depth hypotheses while they wait to be resolved.
    pub fn pending_hypotheses(&self) -> Option<&Hypotheses> {
        self.hypotheses.as_ref()
    }

    /// After step `p`: resolves the last spawn's depth hypotheses (see the module) when rows
    /// are about to move (a densification or a spawn) or `transient.every` steps after the
    /// spawn (the last spawns come after densification's window).
    pub(crate) fn resolve_if_due(&mut self, p: &StepPlan) -> Result<()> {
        let due = self.hypotheses.as_ref().is_some_and(|h| {
            p.densify.is_some() || p.spawn || p.iteration >= h.iteration + self.cfg.transient.every
        });
        if due {
            if let Some(r) = self.resolve_hypotheses()? {
                self.last_resolved = Some((p.iteration, r));
            }
        }
        Ok(())
    }

    /// Resolves the last spawn's depth hypotheses now, once.
    fn resolve_hypotheses(&mut self) -> Result<Option<Resolved>> {
        let Some(h) = self.hypotheses.take() else {
            return Ok(None);
        };
        let g = &self.model.gaussians;
        let span = h.span();
        let logits = g.read_opacity(self.gpu, span.clone())?;
        if logits.len() != span.len() {
            // The rows moved (a restore): nothing to resolve.
            return Ok(None);
        }
        let drop = losers(&h.groups, span.start, &logits);
        g.set_opacity(self.gpu, span, &drop, DROPPED)?;
        Ok(Some(Resolved {
            pixels: h.groups.len(),
            dropped: drop.len(),
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_pixel_keeps_its_most_opaque_hypothesis() {
        // Rows 10..14 one pixel, 14..16 another; row 16 untouched (a tracked transient).
        let logits = [0.1, 0.9, -1.0, 0.3, 2.0, 2.0, 5.0];
        let groups = [10..14, 14..16];
        assert_eq!(losers(&groups, 10, &logits), vec![10, 12, 13, 15]);
        let h = Hypotheses {
            iteration: 600,
            groups: groups.to_vec(),
        };
        assert_eq!(h.span(), 10..16);
        assert!(losers(&[], 0, &[]).is_empty());
    }
}
