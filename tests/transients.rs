//! Transient Gaussians in training (issue 37): spawned from the residual, kept after the
//! canonical rows through densification, learning only their own temporal sections, spared by
//! the opacity reset, carried through checkpoints, written to `transients.ply`, reopened by
//! `eval` (the same scores) and exported per frame by `render --ply` (only what is alive);
//! the dynamic/static split over the canonical rows beside them; the motion term's gradient
//! with the temporal weights attached and detached (`[transient] motion_weights`).
//!
//! Over 600 lines on purpose: each test trains the tiny scene through the trainer's whole
//! transient path; one binary keeps one build and one device start for all of them. They run
//! on serial lavapipe (one core), so they split over two processes (`testing::in_other_half`).

mod train_common;

use dispflow_vk::bench::step::make_quarter_transient;
use dispflow_vk::model::gaussians::Section;
use dispflow_vk::model::state::GaussianState;
use dispflow_vk::testing;
use dispflow_vk::train::checkpoint::Checkpoint;
use dispflow_vk::train::config::{MotionWeights, SparsityMode, TrainConfig, TransientMode};
use dispflow_vk::train::population::Reserve;
use dispflow_vk::train::Trainer;
use train_common::{spawn_transients, tiny_config, tiny_dataset, tiny_scene};

/// The tiny scene with transients spawned every 30 steps from iteration 60, densification every
/// 50 from 40, an opacity reset at 150.
fn cfg() -> TrainConfig {
    let mut c = tiny_config(210);
    c.warm_up = 60;
    c.densify.opacity_reset_interval = 150;
    // Every spawn spawns (the persist gate's pairing has its unit tests in `transients`).
    spawn_transients(&mut c, 30, 0.25);
    c
}

#[test]
fn transients_spawn_stay_last_and_learn_only_their_own_sections() {
    if testing::in_other_half(1) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    let cfg = cfg();
    let mut tr = Trainer::new(&gpu, &cfg, &ds).unwrap();
    let mut spawned = 0;
    let mut born = None;
    while tr.iteration < cfg.iterations {
        tr.step(false, false).unwrap();
        let (v, _) = tr.last_loss().unwrap();
        assert!(v.loss.is_finite(), "iteration {}: {v:?}", tr.iteration);
        let g = &tr.model.gaussians;
        let host = g.download(&gpu).unwrap();
        let first = g.transient_rows().start as usize;
        assert_eq!(host.populations(), g.populations());
        // Canonical rows never learn a time (their temporal sections stay exactly 0); every
        // transient has a finite width of its own.
        if !g.transient_rows().is_empty() {
            for (i, t) in host.time.iter().enumerate() {
                if i < first {
                    assert_eq!(
                        *t,
                        [0.0, 0.0],
                        "iteration {}: canonical row {i}",
                        tr.iteration
                    );
                    assert_eq!(host.velocity[i], [0.0; 3]);
                } else {
                    assert!(t[1] < 0.0 && t[1].is_finite(), "transient {i}: {t:?}");
                }
            }
        }
        if tr.iteration == 150 {
            // The reset clamps the canonical opacities only.
            let reset = (0.01f32 / 0.99).ln() + 1e-4;
            assert!(host.opacity[..first].iter().all(|&l| l <= reset));
            assert!(
                host.opacity[first..].iter().any(|&l| l > reset),
                "transients spared by the reset"
            );
        }
        if let Some((it, s)) = &tr.last_spawn {
            if *it == tr.iteration {
                spawned += s.spawned;
                assert!(s.spawned > 0, "iteration {it}: {s}");
            }
        }
        // The transients learn their own sections: from the first spawn (iteration 60) to 85,
        // with no densification between to move rows, their c, σ and v leave what the spawn
        // gave on nearly every row. Fails with their Adam groups (`Population::own_groups`)
        // disabled.
        if tr.iteration == 60 {
            assert!(!g.transient_rows().is_empty(), "the first spawn is at 60");
            born = Some((g.transient_rows(), host.clone()));
        }
        if tr.iteration == 85 {
            let (rows, b) = born.take().expect("a snapshot at 60");
            assert_eq!(g.transient_rows(), rows, "rows moved before 85");
            let r = rows.start as usize..rows.end as usize;
            let share = |moved: usize| moved as f64 / r.len() as f64;
            let c = r
                .clone()
                .filter(|&i| host.time[i][0] != b.time[i][0])
                .count();
            let w = r
                .clone()
                .filter(|&i| host.time[i][1] != b.time[i][1])
                .count();
            let v = r
                .clone()
                .filter(|&i| host.velocity[i] != b.velocity[i])
                .count();
            for (name, m) in [("time centre", c), ("log-width", w), ("velocity", v)] {
                assert!(
                    share(m) > 0.9,
                    "{name}: {m} of {} transients moved",
                    r.len()
                );
            }
        }
    }
    assert!(spawned > 0 && !tr.model.gaussians.transient_rows().is_empty());
    // A checkpoint with transients restores into a fresh trainer exactly.
    let c = tr.checkpoint().unwrap();
    assert!(!c.model.gaussians.transient_rows().is_empty());
    let mut again = Trainer::new(&gpu, &cfg, &ds).unwrap();
    again.restore(&c).unwrap();
    assert_eq!(
        again.model.gaussians.populations(),
        tr.model.gaussians.populations()
    );
    assert_eq!(again.checkpoint().unwrap(), c);
    let centre: Vec<f32> = gpu
        .read(again.model.gaussians.param(Section::TimeCentre))
        .unwrap();
    assert!(centre.iter().all(|c| c.is_finite()));
}

/// The split (`sparsity.mode = auto`) is over the canonical rows only: transients never go
/// through D, so none is ever in the dynamic list, the flags a checkpoint carries are one per
/// canonical row (a spawn after a split leaves rows beyond them whose flags mean nothing), and a
/// restored split trainer steps exactly as the one it was taken from.
#[test]
fn the_split_covers_the_canonical_rows_and_composes_with_transients() {
    if testing::in_other_half(1) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    let mut cfg = cfg();
    cfg.sparsity.mode = SparsityMode::Auto;
    cfg.sparsity.start = 0.0;
    cfg.sparsity.every = 0.2;
    cfg.sparsity.threshold_px = 0.0; // every canonical row that moves at all is dynamic
    cfg.sparsity.noise_k = 0.0;
    let mut tr = Trainer::new(&gpu, &cfg, &ds).unwrap();
    // A checkpoint taken with both, and the losses of the three steps after it.
    let mut both: Option<(_, Vec<u64>)> = None;
    while tr.iteration < cfg.iterations {
        let log = tr.step(true, false).unwrap().expect("values asked");
        assert!(log.loss.loss.is_finite(), "iteration {}", log.iteration);
        if let Some((_, after)) = both.as_mut().filter(|(_, a)| a.len() < 3) {
            after.push(log.loss.loss.to_bits());
        }
        let g = &tr.model.gaussians;
        let Some(count) = tr.model.dynamic.split() else {
            continue;
        };
        assert!(
            count <= g.canonical_rows().len(),
            "{count} dynamic of {}",
            g.canonical_rows().len()
        );
        if count > 0 {
            let idx: Vec<u32> = gpu
                .read(tr.model.dynamic.idx.elems::<u32>(0, count as u64))
                .unwrap();
            let first = g.canonical_rows().len();
            assert!(idx.iter().all(|&i| i < first), "a transient in {idx:?}");
        }
        let f = tr.dynamic_fraction();
        assert!((0.0..=1.0).contains(&f), "{f}");
        if count > 0 && !g.transient_rows().is_empty() && both.is_none() {
            both = Some((tr.checkpoint().unwrap(), Vec::new()));
        }
    }
    let (c, after) = both.expect("a step with both a split with dynamic rows and transients");
    assert_eq!(after.len(), 3, "three steps after the checkpoint");
    let g = &c.model.gaussians;
    let flags = &c.model.dynamic.as_ref().expect("split").flags;
    assert_eq!(
        flags.len(),
        g.canonical_rows().len() as usize,
        "one flag per canonical row"
    );
    // Restored, it steps exactly as the trainer it was taken from (same plan, same split).
    let mut a = Trainer::new(&gpu, &cfg, &ds).unwrap();
    a.restore(&c).unwrap();
    assert_eq!(a.checkpoint().unwrap(), c);
    let resumed: Vec<u64> = (0..3)
        .map(|_| a.step(true, false).unwrap().unwrap().loss.loss.to_bits())
        .collect();
    assert_eq!(
        resumed, after,
        "losses (bits) of the three steps after the checkpoint"
    );
}

#[test]
fn transients_spawn_into_free_rows_beyond_their_share_until_the_budget_is_full() {
    if testing::in_other_half(1) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    // No reserved share at all: the canonical population leaves rows free, so spawns use them.
    let mut c = cfg();
    c.transient.max_share = 0.0;
    c.densify.until = 0; // keep the canonical count where initialisation put it
    let first_spawn = |cfg: &TrainConfig| {
        let mut tr = Trainer::new(&gpu, cfg, &ds).unwrap();
        while tr.last_spawn.is_none() {
            assert!(tr.iteration < cfg.iterations, "no spawn in the whole run");
            tr.step(false, false).unwrap();
        }
        let (_, s) = tr.last_spawn.clone().unwrap();
        (
            s,
            tr.model.gaussians.n,
            tr.model.gaussians.transient_rows().len(),
        )
    };
    let (s, n, transients) = first_spawn(&c);
    assert!(n < c.densify.budget, "{n} of {}", c.densify.budget);
    assert!(
        !s.full && s.spawned > 0 && transients as usize == s.spawned,
        "{s}"
    );
    // A budget the initial points fill: nothing to spawn into, and the spawn says so.
    c.densify.budget = n - transients;
    let (s, n, transients) = first_spawn(&c);
    assert!(s.full && s.spawned == 0 && transients == 0, "{s}");
    assert_eq!(n, c.densify.budget);
}

#[test]
fn a_transient_run_writes_reopens_and_exports_its_transients() {
    if testing::in_other_half(0) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let scene = tiny_scene(tmp.path());
    let toml = tmp.path().join("t.toml");
    // Split, so dynamic.bin is written beside transients.ply and eval reads both.
    let mut c = cfg();
    c.sparsity.mode = SparsityMode::Auto;
    // Transients come from the flag, which wins over the config's `off`.
    c.transient.mode = TransientMode::Off;
    std::fs::write(&toml, c.to_toml()).unwrap();
    let out = tmp.path().join("run");
    let bin = env!("CARGO_BIN_EXE_dispflow-vk");
    let o = std::process::Command::new(bin)
        .env("LP_NUM_THREADS", testing::LP_SERIAL)
        .args([
            "train",
            "--preset",
            "fast",
            "--transients",
            "on",
            "--config",
        ])
        .arg(&toml)
        .arg("--data")
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains("spawned after iteration"), "{stderr}");
    let saved = std::fs::read_to_string(out.join("config.toml")).unwrap();
    assert!(saved.contains("[transient]\nmode = \"on\""), "{saved}");
    assert!(stderr.contains("split after iteration"), "{stderr}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    let nt = m["gaussians_transient"].as_u64().unwrap();
    assert!(nt > 0, "{m}");
    assert_eq!(
        m["gaussians_canonical"].as_u64().unwrap() + nt,
        m["num_gaussians"].as_u64().unwrap()
    );
    assert!(out.join("transients.ply").is_file());
    // One dynamic.bin row (flag + 10 floats) per canonical Gaussian.
    let canonical = m["gaussians_canonical"].as_u64().unwrap();
    let dynamic_bin = std::fs::metadata(out.join("dynamic.bin")).unwrap().len();
    let row = dispflow_vk::train::outputs::DYN_ROW as u64;
    assert_eq!(dynamic_bin, canonical * row * 4);
    // What each population costs: the timed log steps' GPU time, attributed without a gap.
    let c = &m["cost_per_step"];
    assert!(c["sampled_steps"].as_u64().unwrap() > 0, "{c}");
    let pops = c["populations"].as_array().unwrap();
    let names: Vec<&str> = pops
        .iter()
        .map(|p| p["population"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["static", "deforming", "transient"]);
    let ms: f64 = pops.iter().map(|p| p["ms"].as_f64().unwrap()).sum();
    let all = c["gpu_ms"].as_f64().unwrap();
    assert!(pops.iter().all(|p| p["ms"].as_f64().unwrap() >= 0.0), "{c}");
    assert!((ms + c["per_pixel_ms"].as_f64().unwrap() - all).abs() < 1e-6 * all.max(1.0));
    // Some transient was alive at a timed step after the first spawn, never more than held.
    let alive = pops[2]["rows"].as_f64().unwrap();
    assert!(
        alive > 0.0 && alive <= c["transient_rows"].as_f64().unwrap(),
        "{c}"
    );
    assert!(
        pops[0]["rows"].as_f64().unwrap() > 0.0,
        "the split drew static rows: {c}"
    );
    assert!(stderr.contains("GPU ms per step by population"), "{stderr}");
    // eval reopens point_cloud.ply + transients.ply and scores the same model.
    let o = std::process::Command::new(bin)
        .env("LP_NUM_THREADS", testing::LP_SERIAL)
        .args(["eval", "--no-pictures", "--run"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let e: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("eval/metrics.json")).unwrap())
            .unwrap();
    let (a, b) = (m["psnr"].as_f64().unwrap(), e["psnr"].as_f64().unwrap());
    assert!((a - b).abs() < 0.05, "train {a} dB, eval {b} dB");
    assert_eq!(e["num_gaussians"], m["num_gaussians"]);
    // Per-frame PLYs hold the canonical Gaussians and only the transients alive then.
    let o = std::process::Command::new(bin)
        .env("LP_NUM_THREADS", testing::LP_SERIAL)
        .args(["render", "--path", "test", "--ply", "--run"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let plys = walk(&out.join("render"), "ply");
    let counts: Vec<u64> = plys
        .iter()
        .filter(|p| {
            p.file_name()
                .unwrap()
                .to_string_lossy()
                .starts_with("frame_")
        })
        .map(|p| dispflow_vk::eval::reference::ply_vertex_count(p).unwrap() as u64)
        .collect();
    assert!(!counts.is_empty(), "{plys:?}");
    assert!(
        counts.iter().all(|&c| c >= canonical && c < canonical + nt),
        "{counts:?}"
    );
}

fn walk(d: &std::path::Path, ext: &str) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    if let Ok(rd) = std::fs::read_dir(d) {
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                out.extend(walk(&p, ext));
            } else if p.extension().is_some_and(|x| x == ext) {
                out.push(p);
            }
        }
    }
    out
}

/// `[transient] motion_weights` through a whole step: the first step (a motion step) of three
/// trainers on the same model, a quarter of it transient, that differ only in the choice or in
/// having no motion term. Detached, the widths' gradient is the photometric render's alone
/// (that of the step without the term: σ enters only the temporal weight); attached, the term
/// adds its share through the weights in the blend of δ. The centres' gradient differs between
/// the two by that share (c also moves the drawn mean, a path both keep); the velocities' is
/// the same either way (the term reaches v through the drawn mean and v·(t2 − t1)).
#[test]
fn detached_motion_weights_leave_the_time_gradients_to_the_photometric_render() {
    if testing::in_other_half(1) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    let sections = [
        Section::TimeCentre,
        Section::TimeLogWidth,
        Section::Velocity,
    ];
    let step = |weights: MotionWeights, motion_weight: f32| -> Vec<Vec<f32>> {
        let mut c = tiny_config(100);
        c.warm_up = 0;
        c.motion_start = 0;
        c.motion_weight = motion_weight;
        c.transient.motion_weights = weights;
        let mut tr = Trainer::new(&gpu, &c, &ds).unwrap();
        make_quarter_transient(&mut tr).unwrap();
        assert_eq!(tr.plan(1).motion.is_some(), motion_weight > 0.0);
        tr.step(false, false).unwrap();
        let g = &tr.model.gaussians;
        let first = g.canonical_rows().len() as usize;
        sections
            .iter()
            .map(|&s| {
                let per = g.layout.row_len(s) as usize;
                let v: Vec<f32> = gpu.read(g.grad(s)).unwrap();
                v[first * per..g.n as usize * per].to_vec()
            })
            .collect()
    };
    let attached = step(MotionWeights::Attached, 0.5);
    let detached = step(MotionWeights::Detached, 0.5);
    let photo = step(MotionWeights::Attached, 0.0);
    let max = |v: &[f32]| v.iter().fold(0.0f32, |m, x| m.max(x.abs()));
    let dist = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .fold(0.0f32, |m, (x, y)| m.max((x - y).abs()))
    };
    for (k, name) in ["centre", "log-width", "velocity"].iter().enumerate() {
        let (a, d, p) = (&attached[k], &detached[k], &photo[k]);
        assert!(a.iter().chain(d).chain(p).all(|x| x.is_finite()), "{name}");
        let scale = max(a).max(max(p));
        assert!(scale > 0.0, "{name}: no gradient reached the transients");
        eprintln!(
            "{name}: max |attached| {:.3e}, |attached − photometric| {:.3e}, \
             |detached − photometric| {:.3e}, |detached − attached| {:.3e}",
            max(a),
            dist(a, p),
            dist(d, p),
            dist(d, a)
        );
        match k {
            // σ enters only the temporal weight: detached, the photometric gradient alone.
            1 => {
                assert!(
                    dist(d, p) <= 1e-3 * scale,
                    "{name}: detached is not photometric"
                );
                assert!(dist(a, p) > 2e-2 * scale, "{name}: the term added nothing");
            }
            // c also moves the drawn mean (μ + v(t − c)), whose blend-weight gradient the term
            // keeps: detached differs from attached by the weight's share only.
            0 => assert!(
                dist(d, a) > 2e-2 * scale,
                "{name}: the choice changed nothing"
            ),
            _ => assert!(
                dist(d, a) <= 1e-3 * scale,
                "{name}: the choice moved v's gradient"
            ),
        }
    }
}

/// `auto`, the fast preset's default: a round spawns nothing until a frame's residual has held
/// through `gate` comparisons (the canonical model has shown it cannot draw it), and no budget
/// row is kept for transients before the first spawn.
#[test]
fn auto_spawns_once_a_residual_has_held_through_the_gate() {
    if testing::in_other_half(0) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    let mut c = cfg();
    c.transient.mode = TransientMode::Auto;
    c.transient.persist = 1e-6; // every residual holds: the gate alone decides when
    c.transient.gate = 2;
    c.transient.uncovered = 0.0; // the coverage, size and lacking rules: below
    c.transient.min_residual = 0.0;
    c.transient.unexplained = 0.0;
    assert_eq!(
        c.canonical_budget(),
        c.densify.budget,
        "no share kept at the start"
    );
    let reserve = Reserve::of(&c);
    let mut on = c.clone();
    on.transient.mode = TransientMode::On;
    assert_eq!(on.canonical_budget(), on.densify.budget - reserve.share);
    let mut tr = Trainer::new(&gpu, &c, &ds).unwrap();
    let mut rounds = Vec::new();
    while tr.iteration < 125 {
        tr.step(false, false).unwrap();
        let g = &tr.model.gaussians;
        let held = g.transient_rows().len();
        let want = if held == 0 {
            0
        } else {
            reserve.share.saturating_sub(held)
        };
        assert_eq!(reserve.rows(g), want, "iteration {}", tr.iteration);
        match &tr.last_spawn {
            Some((it, s)) if *it == tr.iteration => rounds.push((*it, s.clone(), held)),
            _ => {}
        }
    }
    let its: Vec<u32> = rounds.iter().map(|r| r.0).collect();
    assert_eq!(its, [60, 90, 120]);
    assert_eq!(
        tr.transients_first_spawn(),
        Some(120),
        "metrics.json's record"
    );
    let (_, first, held) = &rounds[0];
    assert!(
        first.looked_at > 0 && first.first_looks == first.looked_at,
        "{first}"
    );
    assert_eq!((first.spawned, *held), (0, 0));
    let (_, second, held) = &rounds[1];
    assert!(
        second.held == second.looked_at && second.looked_at > 0,
        "{second}"
    );
    assert_eq!((second.spawned, *held), (0, 0));
    let (_, third, held) = &rounds[2];
    assert!(
        third.spawned > 0 && *held as usize == third.spawned,
        "{third}"
    );
    // Open, the rules still judge every round: where the model draws every wrong pixel
    // nothing more spawns (`on` would). Round 150 looks at new frames, 180 at them again.
    tr.cfg.transient.uncovered = 1.0;
    train_common::run_to(&mut tr, 180);
    let (it, s) = tr.last_spawn.clone().unwrap();
    assert!(
        it == 180 && s.spawned == 0 && s.covered > 0 && s.covered == s.looked_at,
        "an open gate spawned from frames it draws: {s}"
    );
    // Where the model draws the wrong pixels (it covers the whole tiny scene), a frame held
    // through the gate is left to densification: not all of its wrong pixels are bare.
    c.transient.uncovered = 1.0;
    let mut tr = Trainer::new(&gpu, &c, &ds).unwrap();
    train_common::run_to(&mut tr, 120);
    let (it, s) = tr.last_spawn.clone().unwrap();
    assert!(
        it == 120 && s.spawned == 0 && s.covered == s.looked_at,
        "{s}"
    );
    assert!(tr.model.gaussians.transient_rows().is_empty());
    // Nor where the wrong region is too small to matter (a residual per pixel of 1 is a frame
    // wrong by the whole colour range everywhere).
    c.transient.uncovered = 0.0;
    c.transient.min_residual = 1.0;
    let mut tr = Trainer::new(&gpu, &c, &ds).unwrap();
    train_common::run_to(&mut tr, 120);
    let (it, s) = tr.last_spawn.clone().unwrap();
    assert!(it == 120 && s.spawned == 0 && s.small == s.looked_at, "{s}");
    // A lacking round opens what coverage keeps closed: frames whose true colour the render
    // draws nowhere near (here: any such pixel) in enough of the round's frames (here: any),
    // once the deformation trains (after iteration 60).
    c.transient.min_residual = 0.0;
    c.transient.uncovered = 1.0;
    c.transient.unexplained = 1e-6;
    c.transient.unexplained_frames = 1e-6;
    let mut tr = Trainer::new(&gpu, &c, &ds).unwrap();
    train_common::run_to(&mut tr, 120);
    let (it, s) = tr.last_spawn.clone().unwrap();
    assert!(
        it == 120 && s.spawned > 0 && s.lacking > 0 && s.covered < s.looked_at,
        "lacking frames did not open the gate: {s}"
    );
    // Not while the deformation is still: then every moving object is drawn nowhere near.
    c.warm_up = 150;
    let mut tr = Trainer::new(&gpu, &c, &ds).unwrap();
    train_common::run_to(&mut tr, 120);
    let (it, s) = tr.last_spawn.clone().unwrap();
    assert!(
        it == 120 && s.spawned == 0 && s.lacking > 0 && s.covered == s.looked_at,
        "a still model's round opened the gate: {s}"
    );
}

/// A scene that never opens `auto`'s gate pays nothing in quality: the run is bit for bit the
/// run without transients (the rounds only look; no row, no reserve, no state changes).
#[test]
fn auto_with_a_closed_gate_trains_exactly_as_off() {
    if testing::in_other_half(1) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    let run = |mode: TransientMode| {
        let mut c = cfg();
        c.iterations = 120;
        c.transient.mode = mode;
        c.transient.persist = 1e-6;
        c.transient.gate = 1000;
        let mut tr = Trainer::new(&gpu, &c, &ds).unwrap();
        train_common::run_to(&mut tr, c.iterations);
        let looked = tr.last_spawn.as_ref().map(|s| s.1.looked_at);
        (tr.checkpoint().unwrap(), looked)
    };
    let (auto, looked) = run(TransientMode::Auto);
    let (off, none) = run(TransientMode::Off);
    assert!(
        looked.is_some_and(|n| n > 0) && none.is_none(),
        "auto looked, off did not"
    );
    assert!(auto.model.gaussians.transient_rows().is_empty());
    // The rounds' looks are auto's own state (a resumed run needs them); the rest is off's.
    let mut auto = auto;
    assert!(
        auto.spawns.take().is_some(),
        "auto's looks are checkpointed"
    );
    assert!(auto == off, "auto with a closed gate differs from off");
}

/// `transient.resolve`: a pixel's still depth hypotheses are alternatives. At the next spawn
/// (rows have not moved since theirs) each pixel keeps one and the others are dropped: their
/// opacity logit at −30 with zero moments, so nothing carries them back before the prune.
/// Which one is kept (the most opaque) is `resolve`'s unit test; here the trainer's wiring.
#[test]
fn resolve_keeps_one_depth_hypothesis_per_pixel() {
    if testing::in_other_half(1) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    let mut c = cfg();
    c.transient.track = 0; // every picked pixel spawns `depths` (2) hypotheses
    c.densify.until = 60; // no densification moves the rows after the first spawn
    assert!(c.transient.resolve, "on by default");
    c.transient.resolve = false;
    let mut off = Trainer::new(&gpu, &c, &ds).unwrap();
    train_common::run_to(&mut off, 60);
    assert!(off.last_spawn.as_ref().is_some_and(|s| s.1.spawned > 0));
    assert!(
        off.pending_hypotheses().is_none(),
        "resolve = false keeps them all"
    );
    drop(off);
    c.transient.resolve = true;
    let mut tr = Trainer::new(&gpu, &c, &ds).unwrap();
    train_common::run_to(&mut tr, 60);
    let (it, s) = tr.last_spawn.clone().unwrap();
    let h = tr.pending_hypotheses().cloned().expect("the spawn at 60");
    assert_eq!((it, h.iteration), (60, 60));
    assert_eq!(h.groups.len() * 2, s.spawned, "{s}");
    assert!(h.groups.iter().all(|g| g.len() == 2));
    let span = h.span();
    let t = tr.model.gaussians.transient_rows();
    assert_eq!(span, t.start..t.end);
    let k = span.end - span.start;
    let read = |tr: &Trainer, b: fn(&GaussianState) -> &dispflow_vk::vk::Buffer| -> Vec<f32> {
        let g = &tr.model.gaussians;
        gpu.read(g.layout.rows(b(g), Section::Opacity, span.start, k))
            .unwrap()
    };
    train_common::run_to(&mut tr, 89);
    let before = read(&tr, |g| &g.params);
    assert!(before.iter().all(|&l| l > -20.0), "nothing dropped yet");
    train_common::run_to(&mut tr, 90);
    let (rit, r) = tr.last_resolved.expect("resolved at the next spawn");
    assert_eq!(rit, 90);
    assert_eq!((r.pixels, r.dropped), (h.groups.len(), h.groups.len()));
    let after = read(&tr, |g| &g.params);
    let (m, v) = (read(&tr, |g| &g.m), read(&tr, |g| &g.v));
    for grp in &h.groups {
        let at = |r: u32| (r - span.start) as usize;
        let kept: Vec<u32> = grp.clone().filter(|&r| after[at(r)] != -30.0).collect();
        assert_eq!(kept.len(), 1, "pixel rows {grp:?}: {after:?}");
        let best = grp.clone().map(|r| before[at(r)]).fold(f32::MIN, f32::max);
        // One Adam step (opacity rate 0.05) lies between the read and the resolution.
        assert!(
            before[at(kept[0])] >= best - 0.1,
            "kept {kept:?} of {grp:?}"
        );
        for r in grp.clone().filter(|&r| r != kept[0]) {
            assert_eq!((m[at(r)], v[at(r)]), (0.0, 0.0), "row {r}'s moments");
        }
    }
}

/// A transient run resumed from its checkpoint trains as the uninterrupted run, bit for bit:
/// the spawns' looks (which candidate set comes next, each frame's last residual) and the
/// depth hypotheses waiting to be resolved travel in the checkpoint, and so does the control
/// nodes' KNN (over the canonical rows: with transients after them it used to be dropped and
/// recomputed, which moved every parameter from the first step on). Taken at 75, after the
/// spawn at 60 and before its resolution at 90.
#[test]
fn a_transient_run_resumed_between_spawns_trains_as_the_uninterrupted_one() {
    if testing::in_other_half(0) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    let mut c = cfg();
    c.transient.track = 0;
    let mut a = Trainer::new(&gpu, &c, &ds).unwrap();
    train_common::run_to(&mut a, 75);
    assert!(a.pending_hypotheses().is_some(), "the spawn at 60 waits");
    let path = tmp.path().join("75.ckpt");
    a.checkpoint().unwrap().save(&path).unwrap();
    let mut b = Trainer::new(&gpu, &c, &ds).unwrap();
    b.restore(&Checkpoint::load(&path).unwrap()).unwrap();
    assert_eq!(b.pending_hypotheses(), a.pending_hypotheses());
    train_common::run_to(&mut a, 150);
    train_common::run_to(&mut b, 150);
    assert_eq!(a.last_resolved, b.last_resolved);
    assert_eq!(
        a.last_spawn.as_ref().map(|s| (s.0, s.1.frames.clone())),
        b.last_spawn.as_ref().map(|s| (s.0, s.1.frames.clone()))
    );
    assert!(
        a.checkpoint().unwrap() == b.checkpoint().unwrap(),
        "the resumed run left the uninterrupted one"
    );
}
