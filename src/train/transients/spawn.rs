//! Spawning transient Gaussians from the residual (issue 37). Pure host code over images the
//! trainer hands in: which training frames to look at (`3 × frames` candidates spread over
//! time, rotating each spawn; the `frames` with the largest localized residual spawn), which
//! of their pixels are wrong enough (at least `min_error` and three times the frame's median
//! error, so a view the model gets wrong everywhere, such as a camera the static model fails,
//! spawns nothing; the largest errors, one per cell of a grid so they spread over the wrong
//! region), and the Gaussians that back-project them: at `depths` depths
//! along each pixel's ray inside the scene's bounds (the missing object's depth is unknown; a
//! wrong-depth transient fits one view, not the several cameras of its lifetime, and is
//! pruned), centred at the frame's time with σ = `init_frames` frame spacings, no velocity.

use super::ray::{pixel_ray, ray_box};
use super::residual::worst_pixels;
use super::track::{Track, Tracker};
use crate::data::Bounds;
use crate::kernels::raster::Camera;
use crate::model::gaussians::{inverse_sigmoid, rgb_to_sh_dc, HostGaussians};
use crate::train::config::{TransientConfig, TransientMode};

/// What one spawn did (logged).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SpawnReport {
    /// Frames spawned from: (id, localized residual, pixels taken), of `looked_at` rendered.
    pub frames: Vec<(String, f64, usize)>,
    pub looked_at: usize,
    /// Transients added.
    pub spawned: usize,
    /// Pixels tracked (each one transient with a velocity; [`super::track`]).
    pub tracked: usize,
    /// Pixels over the error threshold that the budget left out.
    pub over_budget: usize,
    /// Still depth hypotheses no neighbour confirmed, not spawned.
    pub rejected: usize,
    /// Wall-clock milliseconds the spawn took (renders, read-backs, tracking, upload).
    pub ms: f64,
    /// The Gaussian budget was full: nothing was rendered.
    pub full: bool,
    /// Frames left to training because their residual shrank since their last look, and
    /// frames looked at for the first time (`transient.persist`).
    pub improving: usize,
    pub first_looks: usize,
    /// Frames whose residual held, short of `auto`'s gate (`transient.gate`), and frames
    /// through it but covered by the model (`transient.uncovered`).
    pub held: usize,
    pub covered: usize,
    /// Frames through `auto`'s gate whose localized residual is too small to open it
    /// (`transient.min_residual`).
    pub small: usize,
    /// Frames looked at (under `auto`) whose residual matters and whose truth the render
    /// draws nowhere near (`transient.unexplained`), whether or not the round lets them spawn.
    pub lacking: usize,
}

impl std::fmt::Display for SpawnReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.full {
            return write!(f, "none: the Gaussian budget is full; {:.0} ms", self.ms);
        }
        let frames: Vec<String> = self
            .frames
            .iter()
            .map(|(id, r, k)| format!("{id} (residual {r:.1}, {k} px)"))
            .collect();
        write!(
            f,
            "{} transients from {} of {} frames looked at",
            self.spawned,
            if frames.is_empty() {
                "none".to_string()
            } else {
                frames.join(", ")
            },
            self.looked_at
        )?;
        if self.tracked > 0 {
            write!(f, "; {} pixels tracked", self.tracked)?;
        }
        if self.rejected > 0 {
            write!(
                f,
                "; {} depth hypotheses no neighbour confirmed",
                self.rejected
            )?;
        }
        if self.improving > 0 {
            write!(f, "; {} improving frames left to training", self.improving)?;
        }
        if self.first_looks > 0 {
            write!(f, "; {} frames looked at first", self.first_looks)?;
        }
        if self.held > 0 {
            write!(f, "; {} held frames short of the gate", self.held)?;
        }
        if self.covered > 0 {
            write!(f, "; {} held frames drawn where wrong", self.covered)?;
        }
        if self.small > 0 {
            write!(f, "; {} held frames wrong over too little", self.small)?;
        }
        if self.lacking > 0 {
            write!(f, "; {} frames draw their truth nowhere near", self.lacking)?;
        }
        if self.over_budget > 0 {
            write!(f, "; {} pixels left out by the budget", self.over_budget)?;
        }
        write!(f, "; {:.0} ms", self.ms)
    }
}

/// Which training frames the spawns look at, and each frame's localized residual at its last
/// look (`transient.persist`) with how many successive looks it has persisted through.
/// Saved in checkpoints ([`super::SpawnState`]).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Looks {
    /// Candidate sets drawn (rotates them).
    rounds: usize,
    /// The candidates the next spawns look at again, and how many more times.
    recheck: Option<(Vec<usize>, u32)>,
    last: std::collections::BTreeMap<usize, (f64, u32)>,
    /// The iteration after which a spawn first added rows (`auto`'s gate opened).
    pub opened: Option<u32>,
}

/// What a look at a frame's residual decides (`transient.persist`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Verdict {
    Spawn,
    /// Not looked at before: the residual is recorded only.
    FirstLook,
    /// Shrank since the last look: left to training.
    Improving,
    /// Held since the last look, but not through as many looks as the gate asks.
    Held,
}

impl Looks {
    /// What is wrong with these looks for data of `frames` training frames, if anything: a
    /// frame index past the data or a residual that is not a finite non-negative number.
    pub fn problem(&self, frames: Option<usize>) -> Option<String> {
        if let Some(n) = frames {
            let recheck = self.recheck.iter().flat_map(|r| r.0.iter());
            if let Some(f) = self.last.keys().chain(recheck).find(|&&f| f >= n) {
                return Some(format!(
                    "spawn state: frame {f}; the data has {n} training frames"
                ));
            }
        }
        let bad = self
            .last
            .iter()
            .find(|(_, r)| !(r.0.is_finite() && r.0 >= 0.0));
        bad.map(|(f, r)| {
            format!(
                "spawn state: frame {f}'s residual is {}; expected a finite non-negative number",
                r.0
            )
        })
    }

    /// The next spawn's `k` candidates from `window` (training frames in time order), rotating;
    /// with `persist` on, every set is looked at by `1 + need` successive spawns, so each
    /// residual is compared with itself `every` steps apart `need` times (a whole rotation can
    /// be longer than the run). Only a frame looked at before can spawn then, so the first
    /// spawn of each set spawns from none of a set new to the run.
    pub fn candidates(
        &mut self,
        window: &[usize],
        k: usize,
        persist: f32,
        need: u32,
    ) -> Vec<usize> {
        if let Some((c, left)) = self.recheck.take() {
            if left > 1 {
                self.recheck = Some((c.clone(), left - 1));
            }
            return c;
        }
        let c = candidate_frames(window, k, self.rounds);
        self.rounds += 1;
        self.recheck = (persist > 0.0 && need > 0).then(|| (c.clone(), need));
        c
    }

    /// A spawn that looks at nothing (the budget is full) still takes its turn: the
    /// pending look, else a new set, so the rotation goes on as if it had looked.
    pub fn skip(&mut self) {
        match self.recheck.take() {
            Some((c, left)) if left > 1 => self.recheck = Some((c, left - 1)),
            Some(_) => {}
            None => self.rounds += 1,
        }
    }

    /// Records `frame`'s residual `now` and judges it ([`persists`]): it spawns once it has
    /// persisted through `need` successive comparisons.
    pub fn judge(&mut self, frame: usize, now: f64, persist: f32, need: u32) -> Verdict {
        let last = self.last.get(&frame).copied();
        let held = persists(now, last.map(|l| l.0), persist);
        let streak = if held { last.map_or(0, |l| l.1) + 1 } else { 0 };
        self.last.insert(frame, (now, streak));
        match (held, last) {
            (true, _) if persist <= 0.0 || streak >= need => Verdict::Spawn,
            (true, _) => Verdict::Held,
            (false, None) => Verdict::FirstLook,
            (false, Some(_)) => Verdict::Improving,
        }
    }
}

/// Candidate frames of spawn number `round`: `k` of the `n` training frames, evenly spread over
/// the time order `by_time`, the offset rotating with `round` so that successive spawns look at
/// every frame in turn.
pub fn candidate_frames(by_time: &[usize], k: usize, round: usize) -> Vec<usize> {
    let n = by_time.len();
    if n == 0 || k == 0 {
        return Vec::new();
    }
    let k = k.min(n);
    let stride = n / k;
    let offset = round % stride.max(1);
    (0..k).map(|j| by_time[(j * stride + offset) % n]).collect()
}

/// Whether a frame whose localized residual is `now` (and was `last` when a spawn last looked
/// at it) may spawn under `transient.persist` = `persist`: always when 0; otherwise only when it
/// was looked at before and kept at least `persist` of that residual (training is not fixing it).
pub fn persists(now: f64, last: Option<f64>, persist: f32) -> bool {
    if persist <= 0.0 {
        return true;
    }
    last.is_some_and(|l| now >= persist as f64 * l)
}

/// Everything a spawn needs about one frame.
pub struct SpawnFrame<'a> {
    pub camera: &'a Camera,
    pub time: f32,
    pub render: &'a [[f32; 4]],
    pub gt: &'a [[f32; 4]],
}

/// What [`transients_of`] did with one frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameSpawn {
    /// Pixels picked.
    pub picked: usize,
    /// Of those, pixels tracked (one transient with a velocity each).
    pub tracked: usize,
    /// Transients the budget left out.
    pub over: usize,
    /// Still depth hypotheses no neighbour confirmed (`Tracker::confirms_still`).
    pub rejected: usize,
    /// The rows (of the returned Gaussians) of each pixel's still depth hypotheses, where a
    /// pixel spawned more than one (`transient.resolve` keeps one of each).
    pub groups: Vec<std::ops::Range<u32>>,
}

/// The transients of one frame: up to `room` of them (the rest counted as over budget).
/// `spacing`: the training frames' time spacing. With a `tracker` over the frame's temporal
/// neighbours ([`super::track`]), a pixel it tracks spawns one transient on its track, with its
/// velocity; the others spawn at `depths` depths, still.
pub fn transients_of(
    f: &SpawnFrame<'_>,
    cfg: &TransientConfig,
    bounds: &Bounds,
    spacing: f32,
    sh_coeffs: u32,
    room: usize,
    tracker: Option<&Tracker<'_>>,
) -> (HostGaussians, FrameSpawn) {
    let cam = f.camera;
    let (px, cell) = worst_pixels(
        f.render,
        f.gt,
        cam.width,
        cam.height,
        cfg.min_error,
        cfg.pixels as usize,
    );
    let mut g = HostGaussians {
        sh_coeffs,
        ..Default::default()
    };
    let k = cfg.depths as usize;
    // `auto`'s rule: a still hypothesis must be confirmed by a neighbour that sees it.
    let confirm = cfg.confirm && cfg.mode == TransientMode::Auto;
    let tau = (cfg.init_frames.max(cfg.floor_frames) * spacing)
        .max(1e-6)
        .ln();
    let logit = inverse_sigmoid(cfg.init_opacity);
    let mut out = FrameSpawn {
        picked: px.len(),
        ..Default::default()
    };
    let push = |g: &mut HostGaussians, p: [f32; 3], z: f32, v: [f32; 3], c: [f32; 4]| {
        // About a cell's footprint at that depth: neighbouring picks overlap.
        let s = (0.5 * cell as f32 * z / cam.fx).max(1e-6).ln();
        g.means.push(p);
        g.log_scales.push([s; 3]);
        g.quats.push([1.0, 0.0, 0.0, 0.0]);
        g.opacity.push(logit);
        g.sh_dc.push([c[0], c[1], c[2]].map(rgb_to_sh_dc));
        g.sh_rest.extend(vec![0.0; 3 * (sh_coeffs as usize - 1)]);
        g.time.push([f.time, tau]);
        g.velocity.push(v);
    };
    // Tracking is the spawn's cost (a grid of hypotheses per pixel): the pixels in parallel.
    let tracks: Vec<Option<Track>> = match tracker {
        Some(tr) => {
            use rayon::prelude::*;
            px.par_iter().map(|&(x, y, _)| tr.track(x, y)).collect()
        }
        None => vec![None; px.len()],
    };
    for (&(x, y, _), track) in px.iter().zip(tracks) {
        let c = f.gt[(y * cam.width + x) as usize];
        if let Some(t) = track {
            if g.len() >= room {
                out.over += 1;
                continue;
            }
            push(&mut g, t.mean, t.depth, t.velocity, c);
            out.tracked += 1;
            continue;
        }
        let (o, d) = pixel_ray(cam, x, y);
        let Some((z0, z1)) = ray_box(o, d, bounds, cam.near.max(1e-3)) else {
            continue;
        };
        let group = g.len() as u32;
        for j in 0..k {
            if g.len() >= room {
                out.over += 1;
                continue;
            }
            let z = z0 + (z1 - z0) * (j as f32 + 0.5) / k as f32;
            let p = std::array::from_fn(|a| o[a] + d[a] * z);
            if confirm && tracker.is_some_and(|t| !t.confirms_still(x, y, p)) {
                out.rejected += 1;
                continue;
            }
            push(&mut g, p, z, [0.0; 3], c);
        }
        if g.len() as u32 > group + 1 {
            out.groups.push(group..g.len() as u32);
        }
    }
    g.transients = g.len();
    (g, out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidates_spread_over_time_and_rotate() {
        let by_time: Vec<usize> = (0..12).rev().collect(); // frame 11 first in time
        assert_eq!(candidate_frames(&by_time, 4, 0), vec![11, 8, 5, 2]);
        assert_eq!(candidate_frames(&by_time, 4, 1), vec![10, 7, 4, 1]);
        assert_eq!(
            candidate_frames(&by_time, 4, 3),
            vec![11, 8, 5, 2],
            "every frame in turn"
        );
        assert_eq!(candidate_frames(&by_time, 20, 0).len(), 12);
        assert!(candidate_frames(&[], 4, 0).is_empty());
    }

    #[test]
    fn only_a_residual_that_training_does_not_shrink_spawns() {
        assert!(persists(5.0, None, 0.0), "off: the first look spawns");
        assert!(
            persists(1.0, Some(9.0), 0.0),
            "off: a shrinking residual spawns"
        );
        assert!(!persists(5.0, None, 0.8), "on: the first look only records");
        assert!(
            persists(8.5, Some(10.0), 0.8),
            "shrank by less than a fifth"
        );
        assert!(persists(12.0, Some(10.0), 0.8), "a growing residual spawns");
        assert!(
            !persists(7.9, Some(10.0), 0.8),
            "shrank by more than a fifth"
        );
    }

    #[test]
    fn with_persist_each_candidate_set_is_looked_at_twice() {
        let by_time: Vec<usize> = (0..12).collect();
        let mut off = Looks::default();
        assert_eq!(off.candidates(&by_time, 4, 0.0, 1), vec![0, 3, 6, 9]);
        assert_eq!(off.candidates(&by_time, 4, 0.0, 1), vec![1, 4, 7, 10]);
        let mut on = Looks::default();
        assert_eq!(on.candidates(&by_time, 4, 0.8, 1), vec![0, 3, 6, 9]);
        assert_eq!(on.candidates(&by_time, 4, 0.8, 1), vec![0, 3, 6, 9]);
        assert_eq!(on.candidates(&by_time, 4, 0.8, 1), vec![1, 4, 7, 10]);
        assert_eq!(on.candidates(&by_time, 4, 0.8, 1), vec![1, 4, 7, 10]);
        assert_eq!(on.candidates(&by_time, 4, 0.8, 1), vec![2, 5, 8, 11]);
        // Frame 3: the first look records, a held residual spawns, a shrunk one does not.
        assert_eq!(on.judge(3, 10.0, 0.8, 1), Verdict::FirstLook);
        assert_eq!(on.judge(3, 9.0, 0.8, 1), Verdict::Spawn);
        assert_eq!(on.judge(3, 5.0, 0.8, 1), Verdict::Improving);
        assert_eq!(
            on.judge(3, 4.5, 0.8, 1),
            Verdict::Spawn,
            "compared with the last look, not the first"
        );
        assert_eq!(off.judge(3, 1.0, 0.0, 1), Verdict::Spawn);
    }

    #[test]
    fn the_gate_asks_for_a_residual_held_through_more_looks() {
        let by_time: Vec<usize> = (0..12).collect();
        let mut l = Looks::default();
        for _ in 0..3 {
            assert_eq!(l.candidates(&by_time, 4, 0.8, 2), vec![0, 3, 6, 9]);
        }
        assert_eq!(l.candidates(&by_time, 4, 0.8, 2), vec![1, 4, 7, 10]);
        assert_eq!(l.judge(3, 10.0, 0.8, 2), Verdict::FirstLook);
        assert_eq!(l.judge(3, 9.0, 0.8, 2), Verdict::Held);
        assert_eq!(l.judge(3, 8.0, 0.8, 2), Verdict::Spawn);
        // A shrink starts the count again.
        assert_eq!(l.judge(3, 4.0, 0.8, 2), Verdict::Improving);
        assert_eq!(l.judge(3, 4.0, 0.8, 2), Verdict::Held);
        assert_eq!(l.judge(3, 4.0, 0.8, 2), Verdict::Spawn);
        // Once open (need 1), a held residual spawns at once.
        assert_eq!(l.judge(3, 4.0, 0.8, 1), Verdict::Spawn);
        // Skips count the pending looks down.
        let mut s = Looks::default();
        s.candidates(&by_time, 4, 0.8, 2);
        s.skip();
        s.skip();
        assert_eq!(s.candidates(&by_time, 4, 0.8, 2), vec![1, 4, 7, 10]);
    }

    #[test]
    fn a_skipped_spawn_takes_its_turn() {
        let by_time: Vec<usize> = (0..12).collect();
        let mut on = Looks::default();
        assert_eq!(on.candidates(&by_time, 4, 0.8, 1), vec![0, 3, 6, 9]);
        on.skip(); // the second look at {0, 3, 6, 9}
        assert_eq!(on.candidates(&by_time, 4, 0.8, 1), vec![1, 4, 7, 10]);
        on.skip(); // ditto
        on.skip(); // a new set: {2, 5, 8, 11}
        assert_eq!(on.candidates(&by_time, 4, 0.8, 1), vec![0, 3, 6, 9]);
        let mut off = Looks::default();
        off.skip();
        assert_eq!(off.candidates(&by_time, 4, 0.0, 1), vec![1, 4, 7, 10]);
    }

    #[test]
    fn a_full_budget_says_so() {
        let full = SpawnReport {
            full: true,
            ms: 0.2,
            ..Default::default()
        };
        assert_eq!(full.to_string(), "none: the Gaussian budget is full; 0 ms");
        let some = SpawnReport {
            frames: vec![("r_003".into(), 12.5, 64)],
            looked_at: 12,
            spawned: 64,
            improving: 5,
            ms: 41.0,
            ..Default::default()
        };
        assert_eq!(
            some.to_string(),
            "64 transients from r_003 (residual 12.5, 64 px) of 12 frames looked at; \
             5 improving frames left to training; 41 ms"
        );
    }
}
