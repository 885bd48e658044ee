//! Every compared method and ablation switch (issue 17) trains a few steps on the tiny scene:
//! finite losses and parameters, and a motion gradient that reaches the deformation network's
//! second pass exactly where the variant has a motion term (non-zero, finite), none where it
//! has not. The configurations the trainer refuses are refused by field name.

use dispflow_vk::testing;
use dispflow_vk::train::config::{MotionFlow, MotionOrder, TrainConfig};
use dispflow_vk::train::method::{
    row_name, Method, MotionRepresentation as Rep, MotionSchedule, SceneMotionKind as Kind,
};
use dispflow_vk::train::Trainer;
use train_common::{tiny_config, tiny_dataset};

mod train_common;

fn base() -> TrainConfig {
    let mut c = tiny_config(24);
    c.warm_up = 8;
    c.motion_start = 14;
    c.densify.until = 0;
    c.flow_preset = "fast".into();
    c
}

fn with(m: Method) -> TrainConfig {
    let mut c = base();
    m.apply(&mut c);
    c
}

fn variant(rep: Rep, kind: Kind) -> TrainConfig {
    let mut c = with(Method::Dispflow);
    c.motion_representation = rep;
    c.scene_motion.kind = kind;
    c
}

/// Case: name, configuration, whether it has a motion term.
type Case = (&'static str, TrainConfig, bool);

/// Every method, and the reverse order (the paper's other decomposition).
fn methods() -> Vec<Case> {
    let mut c = with(Method::Dispflow);
    c.motion_order = MotionOrder::Reverse;
    vec![
        ("3dgs", with(Method::Gs3d), false),
        ("deformable-3dgs", with(Method::Deformable3dgs), false),
        ("motiongs", with(Method::Motiongs), true),
        ("dispflow", with(Method::Dispflow), true),
        ("reverse order", c, true),
    ]
}

/// Every ablation switch of DispFlow-GS.
fn switches() -> Vec<Case> {
    let mut off = with(Method::Dispflow);
    off.motion_schedule = MotionSchedule::Off;
    let mut mask = with(Method::Dispflow);
    mask.scene_motion.mask_px = 0.05;
    vec![
        (
            "gaussian flow + direct",
            variant(Rep::GaussianFlow, Kind::Direct),
            true,
        ),
        (
            "gaussian flow + none",
            variant(Rep::GaussianFlow, Kind::None),
            true,
        ),
        (
            "displacement + indirect",
            variant(Rep::Displacement, Kind::Indirect),
            true,
        ),
        (
            "displacement + none",
            variant(Rep::Displacement, Kind::None),
            true,
        ),
        ("schedule off", off, true),
        ("motion mask", mask, true),
    ]
}

/// The binary's tests train one after another on one device; they split over two processes
/// (`testing::in_other_half`), each on one core (serial lavapipe, the quicker for the tiny
/// scene's small dispatches).
const METHODS: u8 = 0;
const SWITCHES: u8 = 1;

#[test]
fn every_method_trains_with_a_motion_gradient_where_it_has_one() {
    if testing::in_other_half(METHODS) {
        return;
    }
    train_cases(&methods());
}

#[test]
fn every_switch_trains_with_a_motion_gradient() {
    if testing::in_other_half(SWITCHES) {
        return;
    }
    train_cases(&switches());
}

/// A few steps of each case: finite loss and MLP parameters, and a motion gradient into the
/// MLP (finite, non-zero) exactly where the case has a motion term.
fn train_cases(cases: &[Case]) {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    for (name, cfg, motion) in cases {
        let (name, motion) = (*name, *motion);
        cfg.validate().unwrap();
        let mut tr = Trainer::new(&gpu, cfg, &ds).unwrap();
        let mut last = None;
        while tr.iteration < cfg.iterations {
            last = tr.step(true, false).unwrap();
        }
        let loss = last.unwrap().loss.loss;
        assert!(loss.is_finite(), "{name}: loss {loss}");
        let p: Vec<f32> = gpu.read(tr.model.deform.params.all()).unwrap();
        assert!(p.iter().all(|v| v.is_finite()), "{name}: MLP parameters");
        let g = tr.motion_output_grad().unwrap();
        assert_eq!(
            g.is_some(),
            motion,
            "{name}: a motion term ran in the last step"
        );
        if let Some(g) = g {
            assert!(
                g.iter().all(|v| v.is_finite()),
                "{name}: motion gradient finite"
            );
            let nonzero = g.iter().filter(|v| **v != 0.0).count();
            let max = g.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            eprintln!(
                "{name}: loss {loss:.4}, motion gradient max {max:.3e}, {nonzero} non-zero of {}",
                g.len()
            );
            assert!(
                nonzero > 0 && max > 0.0,
                "{name}: the motion gradient reaches the MLP"
            );
        }
        eprintln!("{name}: {}", row_name(cfg));
    }
}

#[test]
fn schedule_off_gives_the_full_weight_from_the_warm_up() {
    if testing::in_other_half(METHODS) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    let mut c = with(Method::Dispflow);
    c.motion_weight = 0.5;
    let tr = Trainer::new(&gpu, &c, &ds).unwrap();
    assert_eq!(tr.motion_weight_at(8), 0.0, "warm-up");
    assert_eq!(tr.motion_weight_at(13), 0.0, "before motion_start");
    assert!(
        (tr.motion_weight_at(14) - 0.05).abs() < 1e-6,
        "ramp starts at 0.1·α"
    );
    c.motion_schedule = MotionSchedule::Off;
    let tr = Trainer::new(&gpu, &c, &ds).unwrap();
    assert_eq!(tr.motion_weight_at(8), 0.0, "warm-up");
    assert_eq!(
        tr.motion_weight_at(9),
        0.5,
        "full α right after the warm-up"
    );
    assert_eq!(tr.motion_weight_at(24), 0.5);
}

#[test]
fn refused_combinations_name_their_field() {
    if testing::in_other_half(SWITCHES) {
        return;
    }
    let mut cases = Vec::new();
    let mut c = variant(Rep::GaussianFlow, Kind::Direct);
    c.motion_order = MotionOrder::Reverse;
    cases.push((c, "motion_representation"));
    let mut c = variant(Rep::Displacement, Kind::Indirect);
    c.motion_order = MotionOrder::Reverse;
    cases.push((c, "scene_motion.kind"));
    let mut c = variant(Rep::Displacement, Kind::None);
    c.motion_flow = MotionFlow::Oracle;
    cases.push((c, "scene_motion.kind"));
    let mut c = variant(Rep::Displacement, Kind::Indirect);
    c.scene_motion.residual = true;
    cases.push((c, "scene_motion.residual"));
    let mut c = base();
    c.scene_motion.mask_px = -1.0;
    cases.push((c, "scene_motion.mask_px"));
    for (c, field) in cases {
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains(field), "{field}: {e}");
    }
}

#[test]
fn methods_have_the_papers_row_names() {
    if testing::in_other_half(SWITCHES) {
        return;
    }
    assert_eq!(row_name(&with(Method::Gs3d)), "3DGS");
    assert_eq!(row_name(&with(Method::Deformable3dgs)), "Deformable 3DGS");
    assert_eq!(
        row_name(&with(Method::Motiongs)),
        "Gaussian Flow + Indirect Scene Motion (MotionGS)"
    );
    assert_eq!(
        row_name(&with(Method::Dispflow)),
        "Displacement Flow + Direct Scene Motion (DispFlow-GS)"
    );
    assert_eq!(
        row_name(&variant(Rep::GaussianFlow, Kind::Direct)),
        "Gaussian Flow + Direct Scene Motion"
    );
    assert_eq!(
        row_name(&variant(Rep::Displacement, Kind::Indirect)),
        "Displacement Flow + Indirect Scene Motion"
    );
}
