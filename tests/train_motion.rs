//! The DispFlow-GS motion step in training, both decomposition orders, against the same run
//! without it. lavapipe runs with LP_NUM_THREADS=1 here, so float-atomic sums are
//! reproducible and "the motion term changed the model" is measured against the run-to-run
//! noise of this very binary (two identical baseline runs), not guessed.

use dispflow_vk::testing;
use dispflow_vk::train::config::MotionOrder;
use dispflow_vk::train::Trainer;
use train_common::{tiny_config, tiny_dataset};

mod train_common;

#[test]
fn motion_step_changes_the_deformation_in_both_orders() {
    // Must happen before the device exists (the first testing::gpu() call).
    std::env::set_var("LP_NUM_THREADS", "1");
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::gpu();
    let mut cfg = tiny_config(40);
    cfg.warm_up = 10;
    cfg.densify.until = 0;
    cfg.flow_preset = "fast".into();
    cfg.motion_start = 20;
    let run = |w: f32, order: MotionOrder| {
        let mut c = cfg.clone();
        c.motion_weight = w;
        c.motion_order = order;
        let mut tr = Trainer::new(&gpu, &c, &ds).unwrap();
        assert_eq!(tr.motion_weight_at(19), 0.0);
        if w > 0.0 {
            assert!((tr.motion_weight_at(20) - 0.1 * w).abs() < 1e-6);
            assert!((tr.motion_weight_at(40) - w).abs() < 1e-6);
        }
        let mut last = None;
        while tr.iteration < c.iterations {
            last = tr.step(true, false).unwrap();
        }
        assert!(last.unwrap().loss.loss.is_finite());
        let p: Vec<f32> = gpu.read(tr.model.deform.params.all()).unwrap();
        assert!(p.iter().all(|v| v.is_finite()));
        p
    };
    let max_diff = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max)
    };
    let base = run(0.0, MotionOrder::Direct);
    let noise = max_diff(&base, &run(0.0, MotionOrder::Direct));
    let scale = base.iter().fold(0.0f32, |m, v| m.max(v.abs()));
    for order in [MotionOrder::Direct, MotionOrder::Reverse] {
        let motion = run(1.0, order);
        let diff = max_diff(&base, &motion);
        let changed = base.iter().zip(&motion).filter(|(a, b)| a != b).count();
        eprintln!(
            "{order:?}: max |Δ MLP| {diff:.3e} (noise {noise:.3e}, scale {scale:.3e}), {changed} of {} changed",
            base.len()
        );
        // A no-op motion term leaves the run at the baseline up to `noise` (0 with one
        // thread); 21 motion steps move the weights by many Adam steps' worth.
        assert!(
            diff > 100.0 * noise && diff > 1e-4 * scale,
            "{order:?}: the motion term moved the MLP by only {diff:.3e} (noise {noise:.3e})"
        );
        assert!(
            changed > base.len() / 10,
            "{order:?}: the motion term changed only {changed} of {} MLP parameters",
            base.len()
        );
    }
}
