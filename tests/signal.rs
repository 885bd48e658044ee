//! `dispflow-vk signal` on a tiny run with kept checkpoints: every checkpoint scored, every
//! variant's flow_mmap a probability, the ground-truth flow scoring near 1 against the masks
//! (the probe pairs each frame with its own mask and flow), the outputs written; and the
//! scene-motion knobs the configuration refuses.

mod train_common;

use dispflow_vk::eval::signal::{run_signal, variants, SignalArgs};
use dispflow_vk::train::cli::{resolve_config, TrainArgs};
use train_common::{tiny_scene, tiny_toml};

#[test]
fn signal_scores_every_kept_checkpoint() {
    let tmp = tempfile::tempdir().unwrap();
    let data = tiny_scene(tmp.path());
    let out = tmp.path().join("run");
    let cfg = tmp.path().join("run.toml");
    std::fs::write(&cfg, tiny_toml(30)).unwrap();
    let a = TrainArgs {
        data: Some(data),
        out: Some(out.clone()),
        config: Some(cfg),
        motion_weight: Some(0.0),
        keep_checkpoints: true,
        ..TrainArgs::default()
    };
    dispflow_vk::train::cli::run(&a).unwrap();
    for it in [30, 60] {
        assert!(out.join(format!("checkpoints/{it:06}.ckpt")).is_file());
    }
    let s = run_signal(&SignalArgs {
        run: out.clone(),
        checkpoint: vec![],
        data: None,
        // Three of the 21 frames: each costs 12 variants' flows a checkpoint (~0.2 s each on
        // lavapipe); spread, capped and scored as six are.
        frames: 3,
        sigma: 0.1,
        json: None,
        table: None,
    })
    .unwrap();
    assert_eq!(s.iter().map(|c| c.iteration).collect::<Vec<_>>(), [30, 60]);
    let names: Vec<String> = variants().into_iter().map(|v| v.name).collect();
    for c in &s {
        assert_eq!(c.frames, 3);
        assert_eq!(
            c.flow_mmap.iter().map(|v| v.0.clone()).collect::<Vec<_>>(),
            names
        );
        for (name, v) in &c.flow_mmap {
            assert!((0.0..=1.0).contains(v), "{name}: {v}");
        }
        let oracle = c.oracle.expect("the synthetic scene has ground-truth flow");
        assert!(
            oracle > 0.9,
            "ground-truth flow vs its own masks: AP {oracle}"
        );
        assert!((0.0..=1.0).contains(&c.model_delta));
        assert!((0.0..=1.0).contains(&c.confidence_in) && (0.0..=1.0).contains(&c.confidence_out));
    }
    let md = std::fs::read_to_string(out.join("signal.md")).unwrap();
    assert_eq!(md.lines().count(), 2 + names.len() + 3, "{md}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("signal.json")).unwrap()).unwrap();
    assert_eq!(json.as_array().unwrap().len(), 2);
}

/// A change to the flags.
type Edit<'a> = &'a dyn Fn(&mut TrainArgs);

#[test]
fn scene_motion_knobs_are_checked_by_name() {
    let with = |f: &dyn Fn(&mut TrainArgs)| {
        let mut a = TrainArgs {
            preset: Some(dispflow_vk::train::config::Preset::Fast),
            ..TrainArgs::default()
        };
        f(&mut a);
        resolve_config(&a).map(|_| ()).map_err(|e| e.to_string())
    };
    assert!(with(&|a| a.motion_residual = Some(true)).is_ok());
    let cases: [(Edit, &str); 5] = [
        (&|a| a.motion_every = Some(0), "scene_motion.every"),
        (
            &|a| a.motion_confidence = Some(-1.0),
            "scene_motion.confidence",
        ),
        (&|a| a.flow_texture = Some(1.0), "scene_motion.texture"),
        (
            &|a| {
                a.motion_residual = Some(true);
                a.motion_order = Some(dispflow_vk::train::config::MotionOrder::Reverse)
            },
            "scene_motion.residual",
        ),
        (
            &|a| {
                a.motion_residual = Some(true);
                a.motion_flow = Some(dispflow_vk::train::config::MotionFlow::Oracle)
            },
            "scene_motion.residual",
        ),
    ];
    for (f, field) in cases {
        let e = with(f).expect_err(field);
        assert!(e.contains(field), "{e}");
    }
}
