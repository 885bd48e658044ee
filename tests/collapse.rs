//! A collapse is never silent: a run driven to collapse on purpose (a deformation rate 2500×
//! the fast preset's, so the deformation throws the Gaussians away as it starts) is reported
//! with its iteration and levels, by the trainer's guard and by `dispflow-vk train` in
//! `log.jsonl` and `metrics.json`; with rollback it returns to an earlier state with the
//! deformation rate halved and ends above the level it had collapsed to. A run that dies in
//! its first steps (before any sliding window could have filled) and a run that ends below
//! its initial test PSNR are caught too (issue 36): a warning, `status` in `metrics.json`, a
//! flag in the sweep's tables. A widening time curriculum is not a collapse.

mod train_common;

use dispflow_vk::testing;
use dispflow_vk::train::collapse::{CollapseEvent, OnCollapse, SAME_PLACE_ROLLBACKS};
use dispflow_vk::train::config::TrainConfig;
use dispflow_vk::train::guard::CollapseGuard;
use dispflow_vk::train::Trainer;
use std::path::PathBuf;
use train_common::{tiny_config, tiny_dataset, tiny_scene};

/// The tiny scene's configuration with the deformation starting at 100 of 240 iterations at
/// an absurd rate (2.0, decaying to 0.2).
fn absurd(action: OnCollapse) -> TrainConfig {
    let mut c = tiny_config(240);
    c.warm_up = 100;
    c.densify.until = 0;
    c.lr.deform_init = 2.0;
    c.lr.deform_final = 0.2;
    // A 1 dB fall is enough to report: these tests check the reporting and the rollback, not
    // the default threshold (whose depth varies run to run on threaded lavapipe).
    c.collapse.drop_db = 1.0;
    c.collapse.on_collapse = action;
    c
}

/// Trains `cfg` under the guard; returns the events and the mean training PSNR of the 10
/// steps after the first event (the first 10 steps of the restored state after a rollback).
fn run(cfg: &TrainConfig) -> (Vec<CollapseEvent>, f64) {
    // Single-threaded lavapipe adds its float atomics in a fixed order: the warned and the
    // rolled-back run are then the same run up to the collapse (threaded, the rollback run
    // once fell too little to report at all).
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    let mut tr = Trainer::new(&gpu, cfg, &ds).unwrap();
    let (mut guard, first) = CollapseGuard::new(&mut tr).unwrap();
    assert!(first.is_none(), "the initial renders are finite");
    let (mut events, mut after) = (Vec::new(), Vec::new());
    while tr.iteration < cfg.iterations {
        tr.step(false, false).unwrap();
        let done = tr.last_plan.unwrap();
        let (v, _) = tr.last_loss().unwrap();
        if !events.is_empty() && after.len() < 10 {
            after.push(v.psnr);
        }
        if let Some(e) = guard.after_step(&mut tr, &done, v.loss).unwrap() {
            let stop = e.kind == "non_finite_loss" && e.rolled_back_to.is_none();
            events.push(e);
            if stop {
                break;
            }
        }
    }
    (
        events,
        after.iter().sum::<f64>() / after.len().max(1) as f64,
    )
}

#[test]
fn a_collapse_is_reported_and_rollback_recovers_from_it() {
    let (warned, after_warn) = run(&absurd(OnCollapse::Warn));
    eprintln!("warn: {warned:?}, 10 steps after: {after_warn:.2}");
    let first = warned.first().expect("the absurd rate collapses the run");
    assert!(
        first.iteration > 100,
        "not before the deformation starts: {first:?}"
    );
    if first.kind == "psnr_drop" {
        assert!(first.after_db < first.before_db - 1.0, "{first:?}");
    }
    assert!(warned.iter().all(|e| e.rolled_back_to.is_none()));

    let (rolled, after) = run(&absurd(OnCollapse::Rollback));
    eprintln!("rollback: {rolled:?}, 10 steps after the first: {after:.2}");
    let r = rolled.first().expect("the same collapse");
    let to = r.rolled_back_to.expect("rolled back");
    assert!(to < r.iteration, "{r:?}");
    assert_eq!(r.deform_lr_scale, Some(0.5));
    // Each further rollback halves again. A stop (the fall came back where it was after the
    // halvings: `rollback_stops_when_halving_the_rate_leaves_the_fall_as_it_was`) is the last
    // event and keeps the rate it found.
    for (k, e) in rolled.iter().enumerate() {
        if e.rollback_stopped {
            assert_eq!(k + 1, rolled.len(), "a stop ends the rollbacks: {rolled:?}");
            assert!(k > 0 && e.rolled_back_to.is_none(), "{e:?}");
            assert_eq!(e.deform_lr_scale, rolled[k - 1].deform_lr_scale, "{e:?}");
        } else {
            assert_eq!(e.deform_lr_scale, Some(0.5f64.powi(k as i32 + 1)), "{e:?}");
        }
    }
    // The restored state trains at the level before the fall, above the collapsed one.
    assert!(
        after.is_finite() && after > r.after_db + 0.5,
        "back above the collapse level {:.2} dB: {after:.2} over the next 10 steps",
        r.after_db
    );
}

/// A fall the deformation rate does not cause: the spherical harmonics' higher band starts at
/// iteration 150 with an absurd rate (the base colour's ×10 000), whatever the deformation does.
fn sh_blowup() -> TrainConfig {
    let mut c = tiny_config(300);
    c.warm_up = 100;
    c.densify.until = 0;
    c.sh_degree = 1;
    c.sh_interval = 150;
    c.lr.feature_rest_div = 1e-4;
    c.collapse.drop_db = 1.0;
    c.collapse.on_collapse = OnCollapse::Rollback;
    c
}

#[test]
fn rollback_stops_when_halving_the_rate_leaves_the_fall_as_it_was() {
    let cfg = sh_blowup();
    let (events, _) = run(&cfg);
    eprintln!("{events:#?}");
    // Two rollbacks meet the same fall; the third time the run goes on (it used to roll back
    // 8 times and stop with an error).
    let stop = events
        .iter()
        .position(|e| e.rollback_stopped)
        .expect("the rollbacks stop");
    assert_eq!(stop, SAME_PLACE_ROLLBACKS as usize, "{events:#?}");
    for e in &events[..stop] {
        assert!(e.rolled_back_to.is_some_and(|r| r < 150), "{e:?}");
    }
    let s = &events[stop];
    assert!(s.rolled_back_to.is_none(), "{s:?}");
    assert_eq!(s.deform_lr_scale, Some(0.25));
    assert!(events[..=stop]
        .windows(2)
        .all(|w| w[0].iteration.abs_diff(w[1].iteration) < 60));
    // No rollback after it: the run is in warn mode to its end.
    assert!(events[stop..].iter().all(|e| e.rolled_back_to.is_none()));
}

#[test]
fn train_writes_the_collapse_to_its_log_and_metrics() {
    let tmp = tempfile::tempdir().unwrap();
    let (ok, stderr, out) = train_cli(tmp.path(), "absurd", &absurd(OnCollapse::Warn));
    assert!(stderr.contains("collapse at iteration"), "{stderr}");
    let log = std::fs::read_to_string(out.join("log.jsonl")).unwrap();
    assert!(log.contains("\"collapse\""), "log.jsonl names the collapse");
    if ok {
        let m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap())
                .unwrap();
        let c = m["collapses"]
            .as_array()
            .expect("metrics.json lists collapses");
        assert!(!c.is_empty());
        assert!(c[0]["iteration"].as_u64().unwrap() > 100);
        assert!(c[0]["before_db"].as_f64().unwrap() > c[0]["after_db"].as_f64().unwrap());
    } else {
        // Only a non-finite loss stops a `warn` run, and it says so.
        assert!(stderr.contains("not finite"), "{stderr}");
    }
}

#[test]
fn a_rolled_back_run_logs_to_its_end() {
    let tmp = tempfile::tempdir().unwrap();
    let cfg = absurd(OnCollapse::Rollback);
    let (ok, stderr, out) = train_cli(tmp.path(), "rollback", &cfg);
    assert!(ok, "{stderr}");
    assert!(stderr.contains("rolled back to iteration"), "{stderr}");
    let lines: Vec<serde_json::Value> = std::fs::read_to_string(out.join("log.jsonl"))
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let rolled = lines
        .iter()
        .position(|l| l["collapse"]["rolled_back_to"].is_u64())
        .expect("log.jsonl names the rollback");
    // The lines after the rollback are there (the cut once replaced the file under the open
    // handle, and every later line went to the deleted one), in order, to the last iteration.
    let its: Vec<u64> = lines[rolled..]
        .iter()
        .map(|l| l["iteration"].as_u64().unwrap())
        .collect();
    assert!(its.windows(2).all(|w| w[0] < w[1]), "{its:?}");
    assert_eq!(its.last(), Some(&(cfg.iterations as u64)), "{its:?}");
}

/// A run that dies at once: a colour rate of 1000 throws every base colour far out of [0, 1]
/// at the first Adam step, and the training PSNR sits at 7.6 dB from iteration 1 on (the
/// start: 11.3), long before a sliding window of training steps could have measured a level
/// to fall from. Measured on the code before issue 36: no collapse reported, exit 0.
fn early_death() -> TrainConfig {
    let mut c = tiny_config(200);
    c.warm_up = 200;
    c.densify.until = 0;
    c.lr.feature = 1000.0;
    c
}

#[test]
fn an_early_death_and_an_end_below_the_start_are_reported() {
    let tmp = tempfile::tempdir().unwrap();
    let (ok, stderr, out) = train_cli(tmp.path(), "dead", &early_death());
    assert!(ok, "{stderr}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    let (initial, last) = (
        m["initial_psnr"].as_f64().unwrap(),
        m["psnr"].as_f64().unwrap(),
    );
    eprintln!("initial {initial:.2} dB, final {last:.2} dB\n{stderr}");
    // The probe views were measured before the first step: the death is a fall from there.
    let c = m["collapses"]
        .as_array()
        .expect("metrics.json lists the collapse");
    assert!(
        c[0]["iteration"].as_u64().unwrap() <= 100,
        "caught early: {c:?}"
    );
    assert!(c[0]["before_db"].as_f64().unwrap() > c[0]["after_db"].as_f64().unwrap() + 2.0);
    assert!(
        stderr.contains("warning: collapse at iteration"),
        "{stderr}"
    );
    // It ends below where it started, and says so.
    assert!(last < initial, "{last} vs {initial}");
    assert_eq!(m["status"], "collapsed", "{}", m["status_note"]);
    assert!(
        m["status_note"]
            .as_str()
            .unwrap()
            .contains("ended below its initial test PSNR"),
        "{}",
        m["status_note"]
    );
    assert!(stderr.contains("warning: the run ended below its initial test PSNR"));
    // The sweep's cell result carries the status; its tables flag it.
    let r = dispflow_vk::sweep::exec::cell_status(&out).unwrap();
    assert_eq!(r.as_deref(), Some("collapsed"));
}

#[test]
fn a_healthy_run_is_ok_and_a_widening_curriculum_is_no_collapse() {
    // The seq9full recipe's curriculum (the first 2 % of the frames, widening to all by 80 %
    // of the run) with its deformation rate, on the tiny scene: the training views change
    // under it, the probe views do not.
    let tmp = tempfile::tempdir().unwrap();
    let mut cfg = TrainConfig::from_toml_over(
        &tiny_config(400),
        std::path::Path::new(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tools/recipe/seq9full.toml"
        )),
    )
    .unwrap();
    cfg.warm_up = 0;
    let (ok, stderr, out) = train_cli(tmp.path(), "curriculum", &cfg);
    assert!(ok, "{stderr}");
    assert!(!stderr.contains("collapse at iteration"), "{stderr}");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    assert_eq!(m["status"], "ok", "{m}");
    assert!(m.get("collapses").is_none());
    // Its log carries the probe views' level.
    let log = std::fs::read_to_string(out.join("log.jsonl")).unwrap();
    assert!(log.contains("\"probe_psnr\""), "{log}");
}

/// Trains the tiny scene with `cfg` through the CLI (single-threaded lavapipe); returns the
/// exit status, stderr and the run directory.
fn train_cli(tmp: &std::path::Path, name: &str, cfg: &TrainConfig) -> (bool, String, PathBuf) {
    let scene = tiny_scene(tmp);
    let toml = tmp.join(format!("{name}.toml"));
    std::fs::write(&toml, cfg.to_toml()).unwrap();
    let out = tmp.join(name);
    let mut cmd = std::process::Command::new(env!("CARGO_BIN_EXE_dispflow-vk"));
    let o = dispflow_vk::testing::isolated_home(&mut cmd, tmp)
        .env("LP_NUM_THREADS", testing::LP_SERIAL)
        .args(["train", "--preset", "fast", "--config"])
        .arg(&toml)
        .arg("--data")
        .arg(&scene)
        .arg("--out")
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    (o.status.success(), stderr, out)
}

/// The tiny scene at 32 px with an opacity reset at 20, so the densification at 30 prunes by
/// screen size at `max_px`, the last densification at `until`.
fn size_pruned(max_px: f32, until: u32) -> TrainConfig {
    let mut c = tiny_config(60);
    c.max_resolution = 32;
    c.densify.from = 10;
    c.densify.interval = 10;
    c.densify.until = until;
    c.densify.opacity_reset_interval = 20;
    c.densify.max_screen_size = max_px;
    c
}

/// A densification step that removes most of the Gaussians is reported, not silent (what the
/// 20 px screen-size prune did to mujoco-scene5 at 200 px, issue 27); one that removes all of
/// them stops the run with an error naming the setting, instead of training nothing.
#[test]
fn train_reports_a_mass_prune_and_stops_when_none_is_left() {
    let tmp = tempfile::tempdir().unwrap();
    // 2 px keeps a handful of the tiny scene's ~3000 Gaussians at iteration 30 (measured: 8).
    let (ok, stderr, out) = train_cli(tmp.path(), "pruned", &size_pruned(2.0, 35));
    assert!(ok, "{stderr}");
    assert!(
        stderr.contains("iteration 30: densification kept")
            && stderr.contains("max_screen_size = 2 px"),
        "{stderr}"
    );
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("metrics.json")).unwrap()).unwrap();
    let p = m["mass_prunes"].as_array().expect("metrics.json lists it");
    assert_eq!(p.len(), 1, "{p:?}");
    assert_eq!(p[0]["iteration"].as_u64(), Some(30));
    assert_eq!(p[0]["screen_cut"].as_bool(), Some(true));
    let (before, after) = (
        p[0]["before"].as_u64().unwrap(),
        p[0]["after"].as_u64().unwrap(),
    );
    assert!(after > 0 && 4 * after < before, "{before} → {after}");
    let log = std::fs::read_to_string(out.join("log.jsonl")).unwrap();
    assert!(log.contains("\"prune\""), "log.jsonl names it");

    // Half a pixel removes every Gaussian: an error, not a run that trains nothing.
    let (ok, stderr, _) = train_cli(tmp.path(), "emptied", &size_pruned(0.5, 60));
    assert!(!ok, "{stderr}");
    assert!(
        stderr.contains("nothing left to train") && stderr.contains("max_screen_size = 0.5"),
        "{stderr}"
    );

    // The tiny scene's ordinary schedule reports none.
    let (ok, stderr, out) = train_cli(tmp.path(), "plain", &tiny_config(60));
    assert!(ok, "{stderr}");
    assert!(!stderr.contains("densification kept"), "{stderr}");
    let m = std::fs::read_to_string(out.join("metrics.json")).unwrap();
    assert!(!m.contains("mass_prunes"));
}

/// A Gaussian whose mean turns NaN draws nothing (the projection culls it), so no loss or
/// render shows it, only the saved model (issue 36: an H100 paper-preset run saved one and
/// reported ok). The parameter check finds it on the GPU, names its row and section, and
/// retires it: every parameter finite, the render unchanged, training goes on. A non-finite
/// deformation weight is found too and left for the caller (it cannot be repaired).
#[test]
fn a_non_finite_gaussian_is_found_and_retired() {
    use dispflow_vk::model::gaussians::Section;
    use dispflow_vk::train::params_check::{bad_rows, ParamCheck};
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    let cfg = tiny_config(40);
    let mut tr = Trainer::new(&gpu, &cfg, &ds).unwrap();
    train_common::run_to(&mut tr, 10);
    let check = ParamCheck::new(&gpu).unwrap();
    assert_eq!(check.run(&mut tr).unwrap(), None, "a healthy model");
    let before = tr.train_view_psnr(0).unwrap();

    let means = tr.model.gaussians.param(Section::Means);
    let mut m: Vec<f32> = gpu.read(means).unwrap();
    let row = 7;
    m[3 * row + 1] = f32::NAN;
    gpu.upload(means, &m).unwrap();
    let planted = tr.train_view_psnr(0).unwrap();
    assert!(
        (planted - before).abs() < 1e-3,
        "the NaN Gaussian is culled, not drawn: {before:.3} → {planted:.3} dB"
    );

    let fault = check.run(&mut tr).unwrap().expect("the NaN mean is found");
    assert_eq!((fault.gaussians, fault.first_row), (1, Some(row)));
    assert_eq!((fault.sections.clone(), fault.weights), (vec!["means"], 0));
    assert!(fault
        .describe()
        .contains("1 Gaussian(s) with non-finite means (first: row 7)"));
    let g = tr.gaussians().unwrap();
    assert!(
        bad_rows(&g).is_empty(),
        "every parameter finite after retiring"
    );
    assert!(g.opacity[row] < -10.0, "retired: {}", g.opacity[row]);
    let after = tr.train_view_psnr(0).unwrap();
    assert!(
        (after - planted).abs() < 1e-3,
        "retiring a culled Gaussian changes no pixel: {planted:.4} → {after:.4} dB"
    );
    assert_eq!(check.run(&mut tr).unwrap(), None, "nothing left to find");
    train_common::run_to(&mut tr, 20);
    assert!(tr.last_loss().unwrap().0.loss.is_finite());

    // Through the guard: found at its next probe, reported as repaired, the run goes on.
    let (mut guard, _) = CollapseGuard::new(&mut tr).unwrap();
    let means = tr.model.gaussians.param(Section::Means);
    let mut m: Vec<f32> = gpu.read(means).unwrap();
    m[3 * 3] = f32::NEG_INFINITY;
    gpu.upload(means, &m).unwrap();
    let mut ev = None;
    while ev.is_none() && tr.iteration < cfg.iterations {
        tr.step(false, false).unwrap();
        let done = tr.last_plan.unwrap();
        let loss = tr.last_loss().unwrap().0.loss;
        ev = guard.after_step(&mut tr, &done, loss).unwrap();
    }
    let ev = ev.expect("the guard finds the planted value");
    assert_eq!(ev.kind, "non_finite_gaussians");
    assert!(!ev.stops_run());
    assert!(ev.detail.unwrap().contains("(first: row 3)"));
    assert!(bad_rows(&tr.gaussians().unwrap()).is_empty());

    // A non-finite deformation weight: reported, not repaired.
    let w = tr.model.deform.params.all();
    let mut v: Vec<f32> = gpu.read(w).unwrap();
    v[3] = f32::INFINITY;
    gpu.upload(w, &v).unwrap();
    let fault = check.run(&mut tr).unwrap().expect("the weight is found");
    assert_eq!((fault.weights, fault.gaussians), (1, 0));
}
