//! `auto`'s rules for a frame held through the persist gate (`transient.persist`, `gate`):
//! what it is wrong over must matter (`min_residual`), and the model must draw nothing over
//! most of it (`uncovered`), or lack what it shows in a round that lacks it in many frames
//! (`unexplained`, `unexplained_frames`). Pure host code over the round's residuals.

use super::residual::FrameResidual;
use crate::train::config::TransientConfig;

/// What the rules say of one held frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Admit {
    Spawn,
    /// Wrong over too little of the frame to matter.
    Small,
    /// Drawn by the model where wrong, and not lacking in a lacking round.
    Covered,
}

/// The rules of one round: how many of its frames lack what they show, and whether that is
/// enough of them for any to spawn through it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RoundRules {
    pub lacking: usize,
    pub lacking_round: bool,
}

/// Whether a frame's residual per pixel is at least `min_residual`.
pub fn matters(tc: &TransientConfig, r: &FrameResidual) -> bool {
    r.per_pixel() >= tc.min_residual as f64
}

/// Whether a frame lacks an object of its time: at least `unexplained` of its wrong pixels
/// show a colour the render draws nowhere near, and the residual matters.
pub fn lacking(tc: &TransientConfig, r: &FrameResidual) -> bool {
    tc.unexplained > 0.0 && r.unexplained >= tc.unexplained as f64 && matters(tc, r)
}

impl RoundRules {
    /// The rules for a round that looked at `frames`. One frame that lacks an object is a pose
    /// the deformation has not learnt yet (D-NeRF's extreme frames); many at once are content
    /// that changes. Before the deformation trains every render is still, so any moving
    /// object is drawn nowhere near in many frames: the lacking route waits for it.
    pub fn of(tc: &TransientConfig, frames: &[FrameResidual], deform_active: bool) -> Self {
        let lacking = frames.iter().filter(|r| self::lacking(tc, r)).count();
        RoundRules {
            lacking,
            lacking_round: deform_active
                && lacking > 0
                && lacking as f64 >= tc.unexplained_frames as f64 * frames.len() as f64,
        }
    }

    /// What the rules say of a held frame `r` of this round.
    pub fn admit(&self, tc: &TransientConfig, r: &FrameResidual) -> Admit {
        if !matters(tc, r) {
            Admit::Small
        } else if r.uncovered >= tc.uncovered as f64 || (self.lacking_round && lacking(tc, r)) {
            Admit::Spawn
        } else {
            Admit::Covered
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(per_pixel: f64, uncovered: f64, unexplained: f64) -> FrameResidual {
        FrameResidual {
            sum: per_pixel * 100.0,
            pixels: 100,
            uncovered,
            unexplained,
        }
    }

    #[test]
    fn a_round_lacks_only_when_enough_of_its_frames_do_after_the_warm_up() {
        let tc = TransientConfig::default();
        assert_eq!((tc.unexplained, tc.unexplained_frames), (0.1, 0.4));
        let lost = frame(0.02, 0.0, 0.2);
        let drawn = frame(0.02, 0.0, 0.05);
        // 5 of 12 lacking: a lacking round; 4 of 12: not.
        let mut round: Vec<FrameResidual> = vec![lost; 5];
        round.extend(vec![drawn; 7]);
        let r = RoundRules::of(&tc, &round, true);
        assert_eq!((r.lacking, r.lacking_round), (5, true));
        assert_eq!(r.admit(&tc, &lost), Admit::Spawn);
        assert_eq!(
            r.admit(&tc, &drawn),
            Admit::Covered,
            "only the lacking frames"
        );
        round[0] = drawn;
        let r = RoundRules::of(&tc, &round, true);
        assert_eq!((r.lacking, r.lacking_round), (4, false));
        assert_eq!(r.admit(&tc, &lost), Admit::Covered);
        // Before the deformation trains, no round lacks.
        let r = RoundRules::of(&tc, &[lost; 12], false);
        assert_eq!((r.lacking, r.lacking_round), (12, false));
        assert_eq!(r.admit(&tc, &lost), Admit::Covered);
        // A lacking frame whose residual does not matter counts for nothing.
        let faint = frame(0.005, 0.0, 0.9);
        let r = RoundRules::of(&tc, &[faint; 12], true);
        assert_eq!((r.lacking, r.lacking_round), (0, false));
        assert_eq!(r.admit(&tc, &faint), Admit::Small);
        // Off.
        let off = TransientConfig {
            unexplained: 0.0,
            ..tc
        };
        let r = RoundRules::of(&off, &[frame(0.02, 0.0, 1.0); 12], true);
        assert!(!r.lacking_round);
    }

    #[test]
    fn coverage_admits_whatever_the_round() {
        let tc = TransientConfig::default();
        let bare = frame(0.02, 0.6, 0.0);
        let r = RoundRules::of(&tc, &[bare; 12], false);
        assert_eq!(r.admit(&tc, &bare), Admit::Spawn);
        assert_eq!(r.admit(&tc, &frame(0.02, 0.4, 0.0)), Admit::Covered);
        assert_eq!(r.admit(&tc, &frame(0.001, 1.0, 0.0)), Admit::Small);
    }
}
