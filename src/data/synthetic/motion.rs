//! How the built-in scene's objects move over the sequence: a time warp from frame time `t`
//! (frame `k` at `t_k = k/(N−1)`) to the scene time at which the rigid sphere and the blob are
//! posed. The camera arc follows frame time in every kind; only the objects are warped. The
//! `events` kind adds objects that appear, vanish and split (`synthetic/events.rs`).

/// Motion kind of the built-in scene.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum SceneMotion {
    /// The sphere and the blob move over the whole sequence (scene time = frame time).
    #[default]
    Moving,
    /// Nothing moves: every frame shows the objects at their t = 0 pose; masks and flow are all
    /// zero.
    Static,
    /// The objects rest at their t = 0 pose for the first half (t ≤ 0.5), then run their
    /// whole [0, 1] trajectory at double speed in the second half.
    Late,
    /// As `moving`, plus three small spheres: one appears at t = 0.35, one vanishes at t = 0.65,
    /// one splits in two at t = 0.5 (pieces moving apart).
    Events,
}

impl SceneMotion {
    /// Scene time of frame time `t`: Moving and Events `t`; Static `0`; Late `0` for `t ≤ 0.5`,
    /// else `(t − 0.5)·2`. `warp(0) = 0` in every kind, so `t = 0` is the common rest pose.
    pub fn warp(self, t: f64) -> f64 {
        match self {
            SceneMotion::Moving | SceneMotion::Events => t,
            SceneMotion::Static => 0.0,
            SceneMotion::Late if t <= 0.5 => 0.0,
            SceneMotion::Late => (t - 0.5) * 2.0,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            SceneMotion::Moving => "moving",
            SceneMotion::Static => "static",
            SceneMotion::Late => "late",
            SceneMotion::Events => "events",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::SceneMotion::*;

    #[test]
    fn warp_matches_each_kind() {
        for t in [0.0, 0.2, 0.5, 0.75, 1.0] {
            assert_eq!(Moving.warp(t), t);
            assert_eq!(Events.warp(t), t);
            assert_eq!(Static.warp(t), 0.0);
        }
        assert_eq!(Late.warp(0.3), 0.0);
        assert_eq!(Late.warp(0.5), 0.0);
        assert_eq!(Late.warp(0.75), 0.5);
        assert_eq!(Late.warp(1.0), 1.0);
    }
}
