//! Training end to end on lavapipe (short), configuration, checkpoints and exports, bad input.

use dispflow_vk::model::gaussians::HostGaussians;
use dispflow_vk::testing;
use dispflow_vk::train::checkpoint::{read_ply, write_ply};
use dispflow_vk::train::cli::{default_preset, resolve_config, resolve_config_on, TrainArgs};
use dispflow_vk::train::config::{Preset, TrainConfig};
use dispflow_vk::train::Trainer;
use train_common::{tiny_config, tiny_dataset, tiny_scene};

mod train_common;

fn args() -> TrainArgs {
    TrainArgs::default()
}

#[test]
fn short_run_raises_test_psnr() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::gpu();
    let cfg = tiny_config(250);
    let mut tr = Trainer::new(&gpu, &cfg, &ds).unwrap();
    let n0 = tr.n();
    let before: f64 = tr
        .evaluate(false)
        .unwrap()
        .iter()
        .map(|v| v.psnr)
        .sum::<f64>()
        / ds.val.len() as f64;
    let mut last = None;
    while tr.iteration < cfg.iterations {
        if let Some(l) = tr.step(tr.iteration + 1 == cfg.iterations, false).unwrap() {
            last = Some(l);
        }
    }
    let after: f64 = tr
        .evaluate(false)
        .unwrap()
        .iter()
        .map(|v| v.psnr)
        .sum::<f64>()
        / ds.val.len() as f64;
    let l = last.unwrap();
    eprintln!(
        "PSNR {before:.2} -> {after:.2} dB; train loss {:.4}; Gaussians {n0} -> {}",
        l.loss.loss,
        tr.n()
    );
    assert!(l.loss.loss.is_finite());
    assert!(
        after > before + 1.5,
        "test PSNR only went from {before:.2} to {after:.2} dB"
    );
    assert_ne!(tr.n(), n0, "densification ran (the count changed)");
    let g = tr.gaussians().unwrap();
    assert!(g
        .means
        .iter()
        .flatten()
        .chain(g.log_scales.iter().flatten())
        .all(|v| v.is_finite()));
}

#[test]
fn ply_round_trip() {
    let tmp = tempfile::tempdir().unwrap();
    let mut g = HostGaussians::from_points(
        &[[0.1, 0.2, 0.3], [1.0, 2.0, 3.0]],
        Some(&[[0.2, 0.4, 0.6], [1.0, 0.0, 0.5]]),
        3,
    )
    .unwrap();
    for (i, v) in g.sh_rest.iter_mut().enumerate() {
        *v = i as f32 * 0.01;
    }
    g.quats[1] = [0.5, 0.5, -0.5, 0.5];
    let p = tmp.path().join("point_cloud.ply");
    write_ply(&p, &g).unwrap();
    assert_eq!(read_ply(&p).unwrap(), g);
    let text = std::fs::read(&p).unwrap();
    let header = String::from_utf8_lossy(
        &text[..text.windows(10).position(|w| w == b"end_header").unwrap()],
    )
    .to_string();
    assert!(
        header.contains("property float f_rest_44") && header.contains("property float rot_3"),
        "{header}"
    );
}

#[test]
fn config_rejects_unknown_fields_and_bad_values() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("c.toml");
    std::fs::write(&p, "iterations = 10\n[densify]\nbudgget = 3\n").unwrap();
    let e = TrainConfig::from_toml_over(&TrainConfig::fast(), &p)
        .unwrap_err()
        .to_string();
    assert!(e.contains("budgget") && e.contains("c.toml"), "{e}");
    std::fs::write(&p, "sh_degree = 7\n").unwrap();
    let e = TrainConfig::from_toml_over(&TrainConfig::fast(), &p)
        .unwrap_err()
        .to_string();
    assert!(e.contains("sh_degree"), "{e}");
    // The recipe knobs of issue 27, each refused by its field name.
    for (toml, field) in [
        ("[curriculum]\nstart = 1.5\n", "curriculum.start"),
        ("[curriculum]\nanchor = \"last\"\n", "anchor"),
        ("mlp_t_freqs = 40\n", "mlp_t_freqs"),
        ("mlp_init_gain = 0.0\n", "mlp_init_gain"),
        ("[collapse]\ndrop_db = -1.0\n", "collapse.drop_db"),
        ("[collapse]\non_collapse = \"ignore\"\n", "on_collapse"),
    ] {
        std::fs::write(&p, toml).unwrap();
        let e = TrainConfig::from_toml_over(&TrainConfig::fast(), &p)
            .and_then(|c| c.validate().map(|_| c))
            .unwrap_err()
            .to_string();
        assert!(e.contains(field), "{toml}: {e}");
    }
    std::fs::write(&p, "iterations = 'many'\n").unwrap();
    assert!(TrainConfig::from_toml_over(&TrainConfig::fast(), &p).is_err());
    // Every shipped recipe (tools/recipe/*.toml, which the README and recipe_rows.sh name)
    // reads as a valid configuration over the fast preset, and changes something.
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/recipe");
    let mut recipes = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let f = e.unwrap().path();
        if f.extension().is_some_and(|x| x == "toml") {
            let c = TrainConfig::from_toml_over(&TrainConfig::fast(), &f)
                .and_then(|c| c.validate().map(|_| c))
                .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
            assert_ne!(c, TrainConfig::fast(), "{} changes nothing", f.display());
            recipes += 1;
        }
    }
    assert!(recipes >= 2, "tools/recipe holds the shipped recipes");
    // The written config.toml reads back to the same configuration.
    let c = TrainConfig::paper();
    std::fs::write(&p, c.to_toml()).unwrap();
    assert_eq!(
        TrainConfig::from_toml_over(&TrainConfig::fast(), &p).unwrap(),
        c
    );
    // Flags override the preset.
    let mut a = args();
    a.iterations = Some(123);
    a.mlp_width = Some(16);
    let r = resolve_config(&a).unwrap();
    // --iterations scales the schedule: the fast preset densifies until 450 of 600.
    assert_eq!((r.iterations, r.mlp_width, r.densify.until), (123, 16, 92));
    // Without --preset: fast for the built-in scene or on a CPU device, paper for a dataset
    // on a GPU; --preset always wins.
    let mut d = args();
    d.data = Some("some/dataset".into());
    assert_eq!(resolve_config_on(&d, false).unwrap().iterations, 20_000);
    assert_eq!(resolve_config_on(&d, true).unwrap().iterations, 600);
    assert_eq!(default_preset(&args(), false).0, Preset::Fast);
    d.preset = Some(Preset::Paper);
    assert_eq!(resolve_config_on(&d, true).unwrap().iterations, 20_000);
}

#[test]
fn bad_data_paths_give_clear_errors() {
    testing::validate_command_devices();
    // The command makes its own (validated) device: not while another test submits.
    let _serial = testing::gpu();
    let tmp = tempfile::tempdir().unwrap();
    let mut a = args();
    a.data = Some(tmp.path().join("no-such-dataset"));
    a.out = Some(tmp.path().join("out"));
    let e = dispflow_vk::train::cli::run(&a).unwrap_err().to_string();
    assert!(e.contains("no-such-dataset"), "{e}");
    // A dataset with no training frames.
    let dir = tiny_scene(tmp.path());
    let ds = dir.join("dataset.json");
    let mut j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&ds).unwrap()).unwrap();
    j["train_ids"] = serde_json::json!([]);
    std::fs::write(&ds, j.to_string()).unwrap();
    a.data = Some(dir);
    let e = dispflow_vk::train::cli::run(&a).unwrap_err().to_string();
    assert!(e.contains("train"), "{e}");
    assert!(
        !tmp.path().join("out/metrics.json").exists(),
        "no training on half-loaded data"
    );
}

/// Time to quality at a small budget: the fast preset scaled to 200 iterations by
/// `with_iterations` alone (the recipe a user gets from `--iterations`) must lift the tiny
/// scene's test PSNR above a fixed bar, measured by the run's own PSNR-vs-time probe.
#[test]
fn fast_recipe_reaches_the_bar_at_a_small_budget() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::gpu();
    let mut cfg = TrainConfig::fast().with_iterations(200);
    // The MLP's size does not change the recipe; a small one keeps the test quick.
    (cfg.mlp_width, cfg.mlp_depth, cfg.densify.budget) = (16, 2, 8000);
    cfg.validate().unwrap();
    let curve = |cfg: &TrainConfig| {
        let mut tr = Trainer::new(&gpu, cfg, &ds).unwrap();
        let probes = dispflow_vk::train::curve::probe_frames(ds.val.len());
        let mut curve = vec![(0, tr.test_psnr(&probes).unwrap())];
        while tr.iteration < cfg.iterations {
            tr.step(false, false).unwrap();
            if tr.iteration % cfg.test_interval == 0 || tr.iteration == cfg.iterations {
                curve.push((tr.iteration, tr.test_psnr(&probes).unwrap()));
            }
        }
        eprintln!("test PSNR over iterations: {curve:.2?}");
        assert!(curve.iter().all(|c| c.1.is_finite()));
        curve.last().unwrap().1
    };
    let after = curve(&cfg);
    assert!(
        after >= BAR_DB,
        "test PSNR {after:.2} dB after 200 iterations, below the bar {BAR_DB} dB"
    );
    // The same run with the paper's learning rates (made for 20 000 iterations), decayed over
    // the run and scaled by the extent as the fast ones are, stays below the bar: what the bar
    // measures is how fast the recipe learns. (Under the official rules instead, ×5 and decay
    // over 30 000 steps, those rates reach 15.14 dB here, see BAR_DB.)
    let paper_rates = TrainConfig {
        lr: dispflow_vk::train::config::LearningRates {
            spatial_scale: 0.0,
            position_max_steps: 0,
            deform_max_steps: 0,
            ..Default::default()
        },
        ..cfg.clone()
    };
    let slow = curve(&paper_rates);
    assert!(
        after > slow + 1.0,
        "the fast rates ({after:.2} dB) should beat the paper's ({slow:.2} dB) at 200 iterations"
    );
}

/// Measured 2026-11-23 (lavapipe, 2 vCPU): 11.32 dB → 14.71 dB after 200 iterations with the
/// fast preset's learning rates (14.69 on a second run), the paper's rates 13.18 dB; the bar
/// sits 0.7 dB under the fast recipe's measurement. 2026-11-26: fast 14.72 dB; the paper's
/// rates under the official rules (issue 36: position and scaling rates ×5 whatever the extent,
/// the position rate decayed over 30 000 steps, so barely at all in 200) 15.14 dB.
const BAR_DB: f64 = 14.0;
