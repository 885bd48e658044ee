//! The DispFlow-GS motion step in training, both decomposition orders, against the same run
//! without it. lavapipe runs serially here (`testing::serial_gpu`), so float-atomic sums are
//! reproducible and "the motion term changed the model" is measured against the run-to-run
//! noise of this very binary (two identical baseline runs), not guessed. The two tests run in
//! two processes (`testing::in_other_half`), one core each.

use dispflow_vk::testing;
use dispflow_vk::train::config::MotionOrder;
use dispflow_vk::train::Trainer;
use train_common::{tiny_config, tiny_dataset};

mod train_common;

#[test]
fn motion_step_changes_the_deformation_in_both_orders() {
    if testing::in_other_half(0) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
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

/// Every kernel of a timed step carries the zone of the pass that recorded it (`--verbose`'s
/// table, `cost_per_step`): a kernel family that names its own zone (MLP, control nodes, the
/// motion term's normalisation) hands the caller's zone back, so the kernels the caller records
/// after it are not left unlabelled (the motion term's L1 was, and its per-pixel cost was
/// counted as the Gaussians').
#[test]
fn every_kernel_of_a_timed_step_names_its_zone() {
    if testing::in_other_half(1) {
        return;
    }
    use dispflow_vk::model::nodes::FieldKind;
    use dispflow_vk::train::config::MotionRepresentation;
    use dispflow_vk::train::cost::{kind_of, KernelKind};
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    for (field, repr, l1) in [
        (
            FieldKind::Nodes,
            MotionRepresentation::Displacement,
            "motion/motion_l1",
        ),
        (
            FieldKind::Mlp,
            MotionRepresentation::Displacement,
            "motion/motion_l1",
        ),
        (
            FieldKind::Mlp,
            MotionRepresentation::GaussianFlow,
            "motion/gflow_l1",
        ),
    ] {
        let mut c = tiny_config(3);
        c.warm_up = 0;
        c.motion_start = 0;
        c.densify.until = 0;
        c.flow_preset = "fast".into();
        c.deform_field.kind = field;
        c.motion_representation = repr;
        let mut tr = Trainer::new(&gpu, &c, &ds).unwrap();
        let mut labels = Vec::new();
        while tr.iteration < c.iterations {
            let log = tr
                .step(true, true)
                .unwrap()
                .expect("a step asked for its values logs");
            labels.extend(log.timings.entries.into_iter().map(|(l, _)| l));
        }
        let unzoned: Vec<&String> = labels.iter().filter(|l| !l.contains('/')).collect();
        assert!(unzoned.is_empty(), "{field:?} {repr:?}: {unzoned:?}");
        for want in [l1, "deform/deform_apply"] {
            assert!(labels.iter().any(|l| l == want), "{want} in {labels:?}");
        }
        assert_eq!(kind_of(l1), KernelKind::Image, "{l1}");
    }
}
