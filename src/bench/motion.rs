//! `dispflow-vk bench motion`: the DispFlow step with each scene-motion option (issue 16's
//! knobs: flow preset, finest level, photo blur, texture split, residual correction,
//! confidence) next to the baseline step without a motion term, same scenes and zones as
//! `bench step`, steps interleaved. `--motion-every k` costs (1 − 1/k)·baseline + (1/k)·row.
//! `dispflow-vk bench methods`: the step of every compared method and representation ×
//! scene-motion cell (issue 17), fast preset, the same way.

use super::median;
use super::step::{median_zones, scenes, time_interleaved, timed_config, StepRow};
use crate::data;
use crate::error::Result;
use crate::train::config::{SceneMotionConfig, TrainConfig};
use crate::train::method::{Method, MotionRepresentation, SceneMotionKind};
use crate::train::Trainer;
use crate::vk::{Gpu, Timings};

/// (label, motion weight, flow preset, scene-motion options).
fn options() -> Vec<(&'static str, f32, &'static str, SceneMotionConfig)> {
    let sm = |f: &dyn Fn(&mut SceneMotionConfig)| {
        let mut c = SceneMotionConfig::default();
        f(&mut c);
        c
    };
    vec![
        ("baseline (no motion term)", 0.0, "fast", sm(&|_| ())),
        (
            "DispFlow, default flow (before)",
            0.1,
            "default",
            sm(&|_| ()),
        ),
        ("DispFlow, fast flow", 0.1, "fast", sm(&|_| ())),
        (
            "DispFlow, fast flow, level 1",
            0.1,
            "fast",
            sm(&|c| c.level = 1),
        ),
        (
            "DispFlow, default flow, level 1",
            0.1,
            "default",
            sm(&|c| c.level = 1),
        ),
        (
            "DispFlow, default flow, blur photo 2",
            0.1,
            "default",
            sm(&|c| c.blur_photo = 2),
        ),
        (
            "DispFlow, default flow, texture 0.8",
            0.1,
            "default",
            sm(&|c| c.texture = 0.8),
        ),
        (
            "DispFlow, default flow, residual",
            0.1,
            "default",
            sm(&|c| c.residual = true),
        ),
        (
            "DispFlow, default flow, confidence 0.1",
            0.1,
            "default",
            sm(&|c| c.confidence = 0.1),
        ),
    ]
}

/// Times `steps` steps (after `warm`) of each scene × option.
pub fn run_motion_bench(gpu: &Gpu, warm: u32, steps: u32) -> Result<Vec<StepRow>> {
    let mut rows = Vec::new();
    let opts = options();
    for (scene, dir) in scenes()? {
        let base = timed_config(0.1);
        let data = data::load(&dir, &base.load_options())?;
        let mut trainers = Vec::new();
        for (_, weight, preset, sm) in &opts {
            let cfg = TrainConfig {
                motion_weight: *weight,
                flow_preset: preset.to_string(),
                scene_motion: sm.clone(),
                ..base.clone()
            };
            trainers.push(Trainer::new(gpu, &cfg, &data)?);
        }
        let times = time_interleaved(&mut trainers, warm, steps)?;
        for ((tr, t), (label, ..)) in trainers.iter().zip(times).zip(&opts) {
            rows.push(StepRow {
                scene: scene.clone(),
                method: "DispFlow step",
                kernels: label,
                gaussians: tr.n(),
                median_ms: median(t.iter().map(Timings::total_ms).collect()),
                zones: median_zones(&t),
            });
        }
    }
    Ok(rows)
}

/// (label, method preset, representation and scene motion when it has a motion term).
type MethodCase = (
    &'static str,
    Method,
    Option<(MotionRepresentation, SceneMotionKind)>,
);

fn method_cases() -> Vec<MethodCase> {
    use MotionRepresentation::{Displacement as Df, GaussianFlow as Gf};
    use SceneMotionKind::{Direct, Indirect, None as Pair};
    vec![
        ("3DGS", Method::Gs3d, None),
        ("Deformable 3DGS", Method::Deformable3dgs, None),
        (
            "Gaussian Flow + Indirect (MotionGS)",
            Method::Motiongs,
            Some((Gf, Indirect)),
        ),
        (
            "Gaussian Flow + Direct",
            Method::Dispflow,
            Some((Gf, Direct)),
        ),
        (
            "Displacement Flow + Indirect",
            Method::Dispflow,
            Some((Df, Indirect)),
        ),
        (
            "Displacement Flow + pair flow (no MD)",
            Method::Dispflow,
            Some((Df, Pair)),
        ),
        (
            "Displacement Flow + Direct (DispFlow-GS)",
            Method::Dispflow,
            Some((Df, Direct)),
        ),
    ]
}

/// Times `steps` steps (after `warm`) of each scene × compared method.
pub fn run_method_bench(gpu: &Gpu, warm: u32, steps: u32) -> Result<Vec<StepRow>> {
    let mut rows = Vec::new();
    let cases = method_cases();
    for (scene, dir) in scenes()? {
        let base = timed_config(0.1);
        let data = data::load(&dir, &base.load_options())?;
        let mut trainers = Vec::new();
        for (_, method, cell) in &cases {
            let mut cfg = base.clone();
            method.apply(&mut cfg);
            if let Some((rep, kind)) = cell {
                cfg.motion_representation = *rep;
                cfg.scene_motion.kind = *kind;
            }
            trainers.push(Trainer::new(gpu, &cfg, &data)?);
        }
        let times = time_interleaved(&mut trainers, warm, steps)?;
        for ((tr, t), (label, ..)) in trainers.iter().zip(times).zip(&cases) {
            rows.push(StepRow {
                scene: scene.clone(),
                method: "method step",
                kernels: label,
                gaussians: tr.n(),
                median_ms: median(t.iter().map(Timings::total_ms).collect()),
                zones: median_zones(&t),
            });
        }
    }
    Ok(rows)
}
