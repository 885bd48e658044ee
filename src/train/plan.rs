//! What one training iteration does, decided on the CPU before anything is recorded: the
//! frame and its pair, the times (with time noise), background, SH degree, motion weight α_t,
//! the learning rates and whether densification is due. Pure: no GPU, unit-tested.
//!
//! Every choice is hashed from (seed, iteration), never drawn from a running generator, so a
//! resumed run makes exactly the choices of an uninterrupted one.
//! (Over ~600 lines with its unit tests: one schedule, a test for each of its parts.)

use super::config::{
    Background, CurriculumAnchor, DeformMode, GradStat, MotionOrder, MotionSchedule, MotionWeights,
    SparsityMode, TimeNoise, TrainConfig,
};
use crate::model::optim::ExpLr;

/// Facts about the training frames the schedule needs: their times, time order, camera extent.
#[derive(Clone, Debug)]
pub struct FrameTimes {
    pub times: Vec<f32>,
    /// Frame indices sorted by time (ties by index) and each frame's rank in that order.
    by_time: Vec<usize>,
    rank: Vec<usize>,
    time_noise: bool,
    /// 3DGS's camera extent (scales the position learning rate).
    pub extent: f32,
    /// The median gap between consecutive distinct training times (transients' time unit).
    pub spacing: f32,
}

impl FrameTimes {
    /// `synthetic`: a D-NeRF/blender scene (time noise `auto` is off there).
    pub fn new(times: Vec<f32>, noise: TimeNoise, synthetic: bool, extent: f32) -> Self {
        let mut by_time: Vec<usize> = (0..times.len()).collect();
        by_time.sort_by(|&a, &b| times[a].total_cmp(&times[b]).then(a.cmp(&b)));
        let mut rank = vec![0; times.len()];
        for (r, &i) in by_time.iter().enumerate() {
            rank[i] = r;
        }
        let spacing = median_gap(&times);
        FrameTimes {
            spacing,
            time_noise: match noise {
                TimeNoise::Auto => !synthetic,
                TimeNoise::On => true,
                TimeNoise::Off => false,
            },
            times,
            by_time,
            rank,
            extent,
        }
    }

    /// The training frame of 1-based iteration `it`: an epoch-wise shuffle of every frame,
    /// or, while the time curriculum's window is narrower than the sequence, of the frames
    /// whose time ranks lie in the window (centred on the middle rank).
    pub fn pick(&self, cfg: &TrainConfig, it: u32) -> usize {
        let n = self.times.len();
        let window = self.window(cfg, it);
        if window.len() >= n {
            return frame_for_iteration(cfg.seed, it, n);
        }
        window[frame_for_iteration(cfg.seed, it, window.len())]
    }

    /// The frames (in time order) the time curriculum trains at 1-based iteration `it`: all of
    /// them once it is over or when it is off.
    pub fn window(&self, cfg: &TrainConfig, it: u32) -> &[usize] {
        let n = self.times.len();
        let span = curriculum_span(cfg, it, n).min(n);
        let lo = match cfg.curriculum.anchor {
            CurriculumAnchor::Middle => (n - span) / 2,
            CurriculumAnchor::First => 0,
        };
        &self.by_time[lo..lo + span]
    }

    /// Frame indices in time order (ties by index).
    pub fn by_time(&self) -> &[usize] {
        &self.by_time
    }

    /// Frame `fi`'s temporal neighbours: up to `k` before and `k` after it in time order.
    pub fn neighbours(&self, fi: usize, k: usize) -> Vec<usize> {
        let (r, n) = (self.rank[fi], self.by_time.len());
        (r.saturating_sub(k)..(r + k + 1).min(n))
            .filter(|&j| j != r)
            .map(|j| self.by_time[j])
            .collect()
    }

    /// The temporal neighbour of frame `fi`: `gap` frames later in time (earlier at the end).
    pub fn pair(&self, fi: usize, gap: u32) -> usize {
        let (r, n, gap) = (self.rank[fi], self.by_time.len(), gap.max(1) as usize);
        let j = if r + gap < n {
            r + gap
        } else {
            r.saturating_sub(gap)
        };
        self.by_time[j]
    }
}

/// The median gap between consecutive distinct values of `times` (1 with fewer than two).
pub fn median_gap(times: &[f32]) -> f32 {
    let mut t: Vec<f32> = times.iter().copied().filter(|v| v.is_finite()).collect();
    t.sort_by(f32::total_cmp);
    t.dedup();
    let gaps: Vec<f64> = t.windows(2).map(|w| (w[1] - w[0]) as f64).collect();
    if gaps.is_empty() {
        return 1.0;
    }
    crate::stats::median(gaps) as f32
}

/// Which render of a DispFlow step plays which part. Decided once from the order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Decomposition {
    /// The photometric render (v1, t1) splats δ (direct); else the intermediate does.
    pub photo_splats: bool,
    /// The intermediate render's view is the pair's (v2, reverse) instead of the frame's (v1).
    pub inter_at_pair_view: bool,
    /// The intermediate render draws the Gaussians at t2 (direct) instead of t1.
    pub inter_at_t2: bool,
    /// Scene motion = flow(photo a → intermediate) (direct) or flow(intermediate → photo b).
    pub flow_from_photo: bool,
}

impl Decomposition {
    pub fn of(order: MotionOrder) -> Self {
        let direct = order == MotionOrder::Direct;
        // Direct: (v1,t1) → (v1,t2) → (v2,t2): the intermediate (v1, t2) differs from the
        // photo of a by scene motion only. Reverse: (v1,t1) → (v2,t1) → (v2,t2).
        Decomposition {
            photo_splats: direct,
            inter_at_pair_view: !direct,
            inter_at_t2: direct,
            flow_from_photo: direct,
        }
    }
}

/// The motion term of one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotionPlan {
    /// The pair frame b = (v2, t2).
    pub pair: usize,
    pub t2: f32,
    /// α_t.
    pub weight: f32,
    pub roles: Decomposition,
}

/// Learning rates of one step (f64 as computed; the optimiser takes f32).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepLr {
    pub means: f64,
    pub log_scales: f64,
    pub quats: f64,
    pub opacity: f64,
    pub sh_dc: f64,
    pub sh_rest: f64,
    /// The MLP's rate and its own Adam step (counted from the end of the warm-up); `None`
    /// while the deformation is off.
    pub deform: Option<(f64, u32)>,
    /// Transients' time centre, log-width and velocity (0 without transients).
    pub centre: f64,
    pub log_width: f64,
    pub velocity: f64,
}

/// Everything iteration `iteration` (1-based) does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepPlan {
    pub iteration: u32,
    pub frame: usize,
    /// The frame's time plus time noise (when on and the deformation is active).
    pub t1: f32,
    /// The deformation network runs (after the warm-up); else D ≡ 0.
    pub deform_active: bool,
    pub background: [f32; 3],
    pub sh_degree: u32,
    pub motion: Option<MotionPlan>,
    pub lr: StepLr,
    /// The step accumulates densification statistics.
    pub densify_stats: bool,
    /// Its backward also sums |∂L/∂mean2d| per pixel (the `abs` statistic).
    pub abs_grad: bool,
    /// Densification (clone/split/prune) runs after the step; with the screen-size cut-off
    /// when the second member is set.
    pub densify: Option<bool>,
    /// Opacity reset after the step.
    pub opacity_reset: bool,
    /// The step runs the MLP over the dynamic Gaussians of the model's split (else over all).
    pub sparse: bool,
    /// The model is split anew after the step (and after its densification).
    pub classify: bool,
    /// Transients are spawned after the step (and after its densification).
    pub spawn: bool,
    /// The transients' temporal weights are constants in the blend of the motion channels
    /// (`[transient] motion_weights = "detached"` on a motion step; the step asks the blend for
    /// the features' share only when the model holds transients).
    pub detach_motion_weights: bool,
}

impl StepPlan {
    pub fn at(cfg: &TrainConfig, frames: &FrameTimes, iteration: u32) -> StepPlan {
        let it = iteration.max(1);
        let frame = frames.pick(cfg, it);
        let deform_active = deform_on(cfg, it);
        let mut t1 = frames.times[frame];
        if frames.time_noise && deform_active {
            let (u1, u2) = (
                hash_uniform(cfg.seed, it as u64, 1),
                hash_uniform(cfg.seed, it as u64, 2),
            );
            let z = (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos();
            t1 += (z * ast_scale(it, frames.times.len())) as f32;
        }
        let background = match cfg.background {
            // `train` resolves auto before it builds a plan; black is what it loads on.
            Background::Auto | Background::Black => [0.0; 3],
            Background::White => [1.0; 3],
            Background::Random => {
                [1, 2, 3].map(|k| hash_uniform(cfg.seed ^ 0xb9, it as u64, k) as f32)
            }
        };
        let weight = motion_weight_at(cfg, it);
        // `scene_motion.every`: the term runs on every k-th step from its start (a speed knob).
        let every = cfg.scene_motion.every.max(1);
        let due = it.saturating_sub(motion_start(cfg)) % every == 0;
        let motion = (weight > 0.0 && due).then(|| {
            let pair = frames.pair(frame, cfg.pair_gap);
            MotionPlan {
                pair,
                t2: frames.times[pair],
                weight,
                roles: Decomposition::of(cfg.motion_order),
            }
        });
        // The official loop: statistics and densification while `it < until`, densification
        // after `from` every `interval`, with the size prunes once past the first opacity
        // reset; resets every `opacity_reset_interval`, and once more at `from` on a white
        // background.
        let d = &cfg.densify;
        let window = it < d.until;
        let densify = (window && it > d.from && it % d.interval == 0)
            .then_some(it > d.opacity_reset_interval);
        let white_reset = cfg.background == Background::White && it == d.from;
        let (sparse, split_due) = sparsity_at(cfg, it);
        StepPlan {
            iteration: it,
            frame,
            t1,
            deform_active,
            background,
            sh_degree: cfg.sh_degree.min((it - 1) / cfg.sh_interval),
            motion,
            lr: learning_rates(cfg, frames, it),
            densify_stats: window,
            abs_grad: window && d.grad_stat == GradStat::Abs,
            densify,
            opacity_reset: window && (it % d.opacity_reset_interval == 0 || white_reset),
            sparse,
            // Densification renumbers the Gaussians: a split model is probed again at once.
            classify: split_due || (sparse && densify.is_some()),
            spawn: spawn_due(cfg, it),
            detach_motion_weights: motion.is_some()
                && cfg.transient.motion_weights == MotionWeights::Detached,
        }
    }
}

/// The standard deviation of Deformable-3DGS's annealed time noise (AST) at 1-based
/// iteration `it` with `frames` training frames, as its `train.py` computes it:
/// `(1 / R) · β(it)`, where `R` is the number of the epoch's cameras not yet picked, counted
/// before this pick (`len(viewpoint_stack)` before the pop: `frames` at an epoch's first
/// pick, 1 at its last, so the noise grows through each epoch), and `β` is
/// `get_linear_noise_func(0.1, 1e-15, max_steps = 20 000)`: a *linear* decay from 0.1 to
/// 1e-15, clamped after 20 000 iterations. Epochs here are `frames` iterations long, as the
/// frame order ([`frame_for_iteration`]) draws every frame once per epoch.
pub fn ast_scale(it: u32, frames: usize) -> f64 {
    let n = frames.max(1);
    let picked = (it.max(1) as usize - 1) % n;
    let remaining = (n - picked) as f64;
    let f = (it as f64 / 20_000.0).clamp(0.0, 1.0);
    let beta = 0.1 * (1.0 - f) + 1e-15 * f;
    beta / remaining
}

/// Frames the time curriculum allows at 1-based iteration `it` (of `n`; `n` when off or
/// done): `start · n` through the deformation's warm-up (the canonical Gaussians fit those
/// instants sharply while nothing can move), then growing linearly to `n` at
/// `until · iterations`; at least 2 (a single instant has no motion to learn).
pub fn curriculum_span(cfg: &TrainConfig, it: u32, n: usize) -> usize {
    let c = &cfg.curriculum;
    if c.start >= 1.0 || n <= 2 {
        return n;
    }
    let open = cfg.warm_up as f64;
    let end = (c.until.max(0.0) as f64 * cfg.iterations as f64).max(open + 1.0);
    let f = ((it.max(1) as f64 - 1.0 - open).max(0.0) / (end - open)).min(1.0);
    let frac = c.start.max(0.0) as f64 + (1.0 - c.start.max(0.0) as f64) * f;
    ((frac * n as f64).ceil() as usize).clamp(2, n)
}

/// The first iteration the motion term may run: `motion_start` with the schedule (TS), the
/// first step after the deformation warm-up without it.
pub fn motion_start(cfg: &TrainConfig) -> u32 {
    match cfg.motion_schedule {
        MotionSchedule::Ramp => cfg.motion_start,
        MotionSchedule::Off => cfg.warm_up + 1,
    }
}

/// The deformation network runs at 1-based iteration `it` (after the warm-up, unless off).
fn deform_on(cfg: &TrainConfig, it: u32) -> bool {
    cfg.deform == DeformMode::On && it > cfg.warm_up
}

/// The split's schedule at 1-based `it`: (the step uses the split, a split is due after it).
/// Dense until the first split after step `s0`; then period `P`: steps `s0 + kP − W + 1 ..=
/// s0 + kP` are dense (the window a static Gaussian can start moving in) and the model is
/// split again after step `s0 + kP`.
pub fn sparsity_at(cfg: &TrainConfig, it: u32) -> (bool, bool) {
    let sp = &cfg.sparsity;
    if sp.mode == SparsityMode::Off || !deform_on(cfg, it) {
        return (false, false);
    }
    let span = cfg.iterations.saturating_sub(cfg.warm_up).max(1) as f32;
    let s0 = cfg.warm_up + ((sp.start * span).round() as u32).max(1);
    let period = ((sp.every * span).round() as u32).max(1);
    let window = ((sp.dense_window * period as f32).round() as u32).min(period);
    if it < s0 {
        return (false, false);
    }
    let phase = (it - s0) % period;
    // A window that would not end (with its re-split) by the last iteration is skipped, so a
    // run never ends dense after its first split.
    let window_end = it + (period - phase) % period;
    let in_window = window > 0 && (phase == 0 || phase > period - window);
    let dense = it == s0 || (in_window && window_end <= cfg.iterations);
    (
        !dense,
        phase == 0 && (it == s0 || window_end <= cfg.iterations),
    )
}

/// α_t of the motion term at 1-based `iteration`: 0 before `motion_start` (or during the
/// warm-up), then linear from 0.1·α to α over the remaining iterations.
pub fn motion_weight_at(cfg: &TrainConfig, iteration: u32) -> f32 {
    let (a, t0, end) = (cfg.motion_weight, motion_start(cfg), cfg.iterations);
    if a <= 0.0 || iteration < t0 || iteration <= cfg.warm_up {
        return 0.0;
    }
    if cfg.motion_schedule == MotionSchedule::Off {
        return a;
    }
    let f = if end > t0 {
        (iteration - t0) as f32 / (end - t0) as f32
    } else {
        1.0
    };
    a * (0.1 + 0.9 * f.clamp(0.0, 1.0))
}

/// Transients are spawned after 1-based step `it` (every `transient.every` steps inside its
/// window, counted in fractions of the run).
pub fn spawn_due(cfg: &TrainConfig, it: u32) -> bool {
    let t = &cfg.transient;
    if !t.mode.spawns() {
        return false;
    }
    let n = cfg.iterations as f64;
    let (lo, hi) = (t.from as f64 * n, t.until as f64 * n);
    it % t.every.max(1) == 0 && (it as f64) >= lo && (it as f64) <= hi
}

fn learning_rates(cfg: &TrainConfig, frames: &FrameTimes, it: u32) -> StepLr {
    let extent = frames.extent;
    let lr = &cfg.lr;
    let (pos_scale, scaling_scale) = lr.spatial(extent);
    let steps = |s: u32| if s > 0 { s } else { cfg.iterations };
    let pos = ExpLr {
        lr_init: lr.position_init * pos_scale,
        lr_final: lr.position_final * pos_scale,
        lr_delay_steps: 0,
        lr_delay_mult: lr.position_delay_mult,
        max_steps: steps(lr.position_max_steps),
    };
    let deform = ExpLr {
        lr_init: lr.deform_init,
        lr_final: lr.deform_final,
        lr_delay_steps: 0,
        lr_delay_mult: lr.position_delay_mult,
        max_steps: steps(lr.deform_max_steps),
    };
    let means = pos.at(it as i64);
    let tc = &cfg.transient;
    let floor = (tc.floor_frames * frames.spacing).max(1e-6) as f64;
    StepLr {
        means,
        centre: tc.lr_centre,
        log_width: tc.lr_width,
        velocity: tc.lr_velocity_mult * means / floor,
        log_scales: lr.scaling * scaling_scale,
        quats: lr.rotation,
        opacity: lr.opacity,
        sh_dc: lr.feature,
        sh_rest: lr.feature / lr.feature_rest_div,
        deform: deform_on(cfg, it).then(|| (deform.at(it as i64), it - cfg.warm_up)),
    }
}

/// SplitMix-style hash → uniform in (0, 1), for per-iteration choices that must not depend on
/// how many random numbers were drawn before (so a resumed run makes the same choices).
pub fn hash_uniform(seed: u64, a: u64, b: u64) -> f64 {
    let mut z =
        seed ^ a.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ b.wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    ((z >> 11) as f64 + 0.5) / (1u64 << 53) as f64
}

/// Training frame of 1-based `iteration`: a fresh shuffle of all frames every epoch, as 3DGS
/// draws cameras, but seeded by (seed, epoch) so it depends on the iteration alone.
pub fn frame_for_iteration(seed: u64, iteration: u32, frames: usize) -> usize {
    let i = (iteration as usize).saturating_sub(1);
    let (epoch, k) = (i / frames, i % frames);
    let mut perm: Vec<usize> = (0..frames).collect();
    for j in (1..frames).rev() {
        let r = (hash_uniform(seed, epoch as u64, j as u64) * (j + 1) as f64) as usize;
        perm.swap(j, r.min(j));
    }
    perm[k]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::config::CurriculumConfig;

    fn cfg() -> TrainConfig {
        let mut c = TrainConfig::fast();
        c.iterations = 100;
        c.warm_up = 20;
        c.motion_weight = 0.5;
        c.motion_start = 40;
        c.sh_degree = 2;
        c.sh_interval = 30;
        c.densify.from = 10;
        c.densify.until = 60;
        c.densify.interval = 25;
        c.densify.opacity_reset_interval = 50;
        c
    }

    fn frames() -> FrameTimes {
        // Deliberately not in time order; two frames share t = 0.5.
        FrameTimes::new(vec![0.5, 0.0, 1.0, 0.25, 0.5], TimeNoise::Off, true, 2.0)
    }

    #[test]
    fn motion_weights_are_detached_only_on_motion_steps_when_asked_to() {
        let f = frames();
        let detached = |w| -> Vec<u32> {
            let mut c = cfg();
            c.transient.motion_weights = w;
            (1..=c.iterations)
                .filter(|&it| StepPlan::at(&c, &f, it).detach_motion_weights)
                .collect()
        };
        let c = cfg();
        let motion: Vec<u32> = (1..=c.iterations)
            .filter(|&it| StepPlan::at(&c, &f, it).motion.is_some())
            .collect();
        assert!(!motion.is_empty());
        assert_eq!(detached(MotionWeights::Detached), motion);
        assert!(detached(MotionWeights::Attached).is_empty());
    }

    #[test]
    fn motion_every_k_runs_the_term_on_every_kth_step_from_its_start() {
        let mut c = cfg();
        let f = frames();
        let on = |c: &TrainConfig| -> Vec<u32> {
            (1..=c.iterations)
                .filter(|&it| StepPlan::at(c, &f, it).motion.is_some())
                .collect()
        };
        assert_eq!(on(&c), (40..=100).collect::<Vec<_>>());
        c.scene_motion.every = 3;
        assert_eq!(on(&c), (40..=100).step_by(3).collect::<Vec<_>>());
        // Steps between keep their weight schedule (α_t is not rescaled).
        assert_eq!(
            StepPlan::at(&c, &f, 43).motion.unwrap().weight,
            motion_weight_at(&c, 43)
        );
    }

    #[test]
    fn every_epoch_visits_every_frame_once() {
        for epoch in 0..4u32 {
            let mut seen: Vec<usize> = (1..=7)
                .map(|k| frame_for_iteration(9, epoch * 7 + k, 7))
                .collect();
            seen.sort_unstable();
            assert_eq!(seen, (0..7).collect::<Vec<_>>(), "epoch {epoch}");
        }
        let a: Vec<usize> = (1..=7).map(|k| frame_for_iteration(9, k, 7)).collect();
        let b: Vec<usize> = (8..=14).map(|k| frame_for_iteration(9, k, 7)).collect();
        assert_ne!(a, b, "each epoch reshuffles");
    }

    #[test]
    fn pairs_follow_time_order_with_a_gap() {
        let f = frames();
        // Time order: 1 (0.0), 3 (0.25), 0 (0.5), 4 (0.5), 2 (1.0).
        assert_eq!(f.pair(1, 1), 3);
        assert_eq!(f.pair(3, 2), 4);
        assert_eq!(f.pair(2, 1), 4, "the last frame pairs backwards");
        assert_eq!(f.pair(4, 3), 1, "past the end: gap frames earlier");
        assert_eq!(f.pair(1, 0), 3, "a zero gap is read as 1");
    }

    #[test]
    fn schedule_switches_at_the_configured_iterations() {
        let (c, f) = (cfg(), frames());
        let p = |it| StepPlan::at(&c, &f, it);
        assert!(!p(20).deform_active && p(21).deform_active);
        assert_eq!(p(20).lr.deform, None);
        assert_eq!(
            p(21).lr.deform.map(|d| d.1),
            Some(1),
            "MLP Adam counts from 1"
        );
        assert_eq!(
            [p(1), p(30), p(31), p(61), p(100)].map(|s| s.sh_degree),
            [0, 0, 1, 2, 2]
        );
        assert!(p(39).motion.is_none());
        let m = p(40).motion.expect("motion from motion_start");
        assert!((m.weight - 0.05).abs() < 1e-7, "ramp starts at 0.1·α");
        assert!((p(100).motion.unwrap().weight - 0.5).abs() < 1e-7);
        assert_eq!(m.t2, f.times[m.pair]);
        assert_ne!(m.pair, p(40).frame);
        // `until` is exclusive, as the official `iteration < densify_until_iter`.
        assert!(p(59).densify_stats && !p(60).densify_stats);
        assert!(!p(59).abs_grad, "the fast preset's statistic is the norm");
        assert_eq!(
            (p(10).densify, p(25).densify, p(50).densify),
            (None, Some(false), Some(false))
        );
        assert_eq!(p(75).densify, None, "no densification after `until`");
        assert!(p(50).opacity_reset && !p(100).opacity_reset);
        assert!(!p(10).opacity_reset, "no extra reset on a black background");
        let mut w = c.clone();
        w.background = Background::White;
        w.densify.grad_stat = GradStat::Abs;
        let pw = |it| StepPlan::at(&w, &f, it);
        assert!(
            pw(10).opacity_reset,
            "the official extra reset at `from` on white"
        );
        assert!(pw(59).abs_grad && !pw(60).abs_grad);
        let mut c2 = c.clone();
        c2.densify.opacity_reset_interval = 20;
        assert_eq!(
            StepPlan::at(&c2, &f, 25).densify,
            Some(true),
            "screen-size cut after a reset"
        );
    }

    #[test]
    fn no_motion_without_weight_or_deformation() {
        let (mut c, f) = (cfg(), frames());
        c.motion_weight = 0.0;
        assert!((1..=100).all(|it| StepPlan::at(&c, &f, it).motion.is_none()));
        let mut c = cfg();
        c.motion_start = 5; // before the warm-up ends: still nothing until the MLP runs
        assert_eq!(motion_weight_at(&c, 20), 0.0);
        assert!(motion_weight_at(&c, 21) > 0.0);
    }

    #[test]
    fn time_noise_only_when_asked_and_deterministic() {
        let c = cfg();
        let on = FrameTimes::new(vec![0.0, 0.5, 1.0], TimeNoise::Auto, false, 1.0);
        let off = FrameTimes::new(vec![0.0, 0.5, 1.0], TimeNoise::Auto, true, 1.0);
        let a = StepPlan::at(&c, &on, 30);
        assert_ne!(a.t1, on.times[a.frame], "real captures get time noise");
        assert_eq!(
            a,
            StepPlan::at(&c, &on, 30),
            "a plan depends on the iteration alone"
        );
        let w = StepPlan::at(&c, &on, 10);
        assert_eq!(w.t1, on.times[w.frame], "no noise during the warm-up");
        let b = StepPlan::at(&c, &off, 30);
        assert_eq!(b.t1, off.times[b.frame], "synthetic scenes: auto = off");
    }

    #[test]
    fn ast_follows_the_official_formula() {
        // train.py: total_frame = len(viewpoint_stack) before the pop; time_interval =
        // 1 / total_frame; smooth_term = get_linear_noise_func(0.1, 1e-15, 0, 0.01, 20000).
        let official = |it: u32, remaining: usize| {
            let t = (it as f64 / 20000.0).clamp(0.0, 1.0);
            (0.1 * (1.0 - t) + 1e-15 * t) * (1.0 / remaining as f64)
        };
        let n = 50;
        for (it, remaining) in [(1, 50), (2, 49), (50, 1), (51, 50), (600, 1), (3000, 1)] {
            let (a, b) = (ast_scale(it, n), official(it, remaining));
            assert!((a - b).abs() <= 1e-15 * b.max(1e-15), "it {it}: {a} vs {b}");
        }
        assert!(
            (ast_scale(600, 50) - 0.097).abs() < 1e-12,
            "linear, not exponential"
        );
        assert!(
            (ast_scale(10_000, 1) - 0.05).abs() < 1e-12,
            "half way: half of 0.1"
        );
        assert!(ast_scale(25_000, 1) < 1e-14, "clamped at 20 000");
        // The noise grows through an epoch: 1/N at its first pick, 1 at its last.
        assert!(ast_scale(1, n) * 49.0 < ast_scale(50, n));
        // The plan adds N(0,1)·ast_scale to the frame's time on real captures.
        let mut c = cfg();
        c.warm_up = 0;
        let f = FrameTimes::new(
            (0..n).map(|k| k as f32 / 49.0).collect(),
            TimeNoise::On,
            false,
            1.0,
        );
        let z: Vec<f64> = (1..=4000)
            .map(|it| {
                let p = StepPlan::at(&c, &f, it);
                (p.t1 - f.times[p.frame]) as f64 / ast_scale(it, n)
            })
            .collect();
        let mean = z.iter().sum::<f64>() / z.len() as f64;
        let var = z.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / z.len() as f64;
        assert!(
            mean.abs() < 0.1 && (var - 1.0).abs() < 0.1,
            "N(0,1): {mean} {var}"
        );
    }

    #[test]
    fn curriculum_widens_from_the_middle_to_every_frame() {
        let mut c = cfg();
        let n = 21;
        let f = FrameTimes::new(
            (0..n).map(|k| (n - 1 - k) as f32 / 20.0).collect(),
            TimeNoise::Off,
            true,
            1.0,
        );
        assert!(
            (1..=100)
                .all(|it| StepPlan::at(&c, &f, it).frame == frame_for_iteration(c.seed, it, n)),
            "off by default"
        );
        c.curriculum = CurriculumConfig {
            start: 0.2,
            until: 0.5,
            anchor: CurriculumAnchor::Middle,
        };
        c.warm_up = 0;
        assert_eq!(curriculum_span(&c, 1, n), 5);
        assert_eq!(curriculum_span(&c, 26, n), 13, "half way to iteration 50");
        assert_eq!(curriculum_span(&c, 51, n), n);
        c.warm_up = 20;
        assert_eq!(curriculum_span(&c, 21, n), 5, "held through the warm-up");
        assert_eq!(curriculum_span(&c, 36, n), 13, "half way from 20 to 50");
        assert_eq!(curriculum_span(&c, 51, n), n);
        assert_eq!(curriculum_span(&c, 100, n), n);
        let spread = |c: &TrainConfig, its: std::ops::RangeInclusive<u32>| {
            let ts: Vec<f32> = its
                .map(|it| f.times[StepPlan::at(c, &f, it).frame])
                .collect();
            let lo = ts.iter().copied().fold(f32::MAX, f32::min);
            let hi = ts.iter().copied().fold(f32::MIN, f32::max);
            (lo, hi)
        };
        // The first iterations see the 5 middle times only (ranks 8..=12: t 0.4..0.6).
        let (lo, hi) = spread(&c, 1..=3);
        assert!(lo >= 0.4 - 1e-6 && hi <= 0.6 + 1e-6, "{lo} {hi}");
        let (lo, hi) = spread(&c, 51..=100);
        assert!(
            lo == 0.0 && hi == 1.0,
            "all frames once the window is full: {lo} {hi}"
        );
        // The window the spawn of transients reads is the one `pick` draws from.
        let times_of = |w: &[usize]| -> Vec<f32> { w.iter().map(|&i| f.times[i]).collect() };
        assert_eq!(times_of(f.window(&c, 1)), [0.4, 0.45, 0.5, 0.55, 0.6]);
        assert_eq!(f.window(&c, 51).len(), n);
        c.curriculum.anchor = CurriculumAnchor::First;
        let (lo, hi) = spread(&c, 1..=3);
        assert!(
            lo == 0.0 && hi <= 0.2 + 1e-6,
            "the 5 earliest times: {lo} {hi}"
        );
        assert_eq!(times_of(f.window(&c, 1)), [0.0, 0.05, 0.1, 0.15, 0.2]);
        c.curriculum.start = 0.0;
        assert_eq!(curriculum_span(&c, 1, n), 2, "at least two instants");
    }

    #[test]
    fn decomposition_of_each_order() {
        let d = Decomposition::of(MotionOrder::Direct);
        assert!(d.photo_splats && d.inter_at_t2 && !d.inter_at_pair_view && d.flow_from_photo);
        let r = Decomposition::of(MotionOrder::Reverse);
        assert!(!r.photo_splats && !r.inter_at_t2 && r.inter_at_pair_view && !r.flow_from_photo);
    }

    #[test]
    fn sparsity_schedule_is_fractions_of_the_deformation_run() {
        let (mut c, f) = (cfg(), frames());
        // warm-up 20 of 100: span 80, first split after 20 + 20 = 40, period 20, window 4.
        c.densify.until = 0;
        assert_eq!(c.sparsity.mode, SparsityMode::Off, "off unless asked");
        assert!((1..=100).all(|it| sparsity_at(&c, it) == (false, false)));
        c.sparsity.mode = SparsityMode::Auto;
        let at = |c: &TrainConfig, it| sparsity_at(c, it);
        assert_eq!(at(&c, 20), (false, false), "warm-up: no MLP, no split");
        assert_eq!(at(&c, 39), (false, false));
        assert_eq!(at(&c, 40), (false, true), "first split after step 40");
        assert_eq!(at(&c, 41), (true, false));
        assert_eq!(at(&c, 56), (true, false));
        for it in 57..=60 {
            assert!(!at(&c, it).0, "dense window before the re-split: {it}");
        }
        assert_eq!(at(&c, 60), (false, true));
        assert_eq!(at(&c, 61), (true, false));
        // The window of 100 (97..=100) ends with the run: dense, split after the last step;
        // a run of 98 iterations skips it and ends on the split.
        assert_eq!(at(&c, 100), (false, true));
        let mut short = c.clone();
        short.iterations = 98;
        assert!(sparsity_at(&short, 97).0);
        c.sparsity.mode = SparsityMode::Off;
        assert!((1..=100).all(|it| at(&c, it) == (false, false)));
        let mut d = cfg();
        d.sparsity.mode = SparsityMode::Auto;
        d.deform = DeformMode::Off;
        d.motion_weight = 0.0;
        assert!((1..=100).all(|it| at(&d, it) == (false, false)));
        assert!((1..=100).all(|it| !StepPlan::at(&d, &f, it).deform_active));
        assert!((1..=100).all(|it| StepPlan::at(&d, &f, it).lr.deform.is_none()));
        // A densification inside a sparse stretch re-splits at once.
        let mut e = cfg();
        e.sparsity.mode = SparsityMode::Auto;
        e.densify.from = 0;
        e.densify.until = 100;
        e.densify.interval = 50;
        let p = StepPlan::at(&e, &f, 50);
        assert!(p.sparse && p.densify.is_some() && p.classify);
        // Twice the iterations: the same schedule in proportion.
        let mut g = c.clone();
        g.sparsity.mode = SparsityMode::Auto;
        g.iterations = 180;
        assert_eq!(at(&g, 60), (false, true), "20 + 0.25 · 160");
    }

    #[test]
    fn random_background_is_per_iteration() {
        let (mut c, f) = (cfg(), frames());
        c.background = Background::Random;
        let (a, b) = (StepPlan::at(&c, &f, 3), StepPlan::at(&c, &f, 4));
        assert_ne!(a.background, b.background);
        assert!(a.background.iter().all(|v| (0.0..=1.0).contains(v)));
    }
}
