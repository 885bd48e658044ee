//! `dispflow-vk bench motion`: the DispFlow step with each scene-motion option (issue 16's
//! knobs: flow preset, finest level, photo blur, texture split, residual correction,
//! confidence) next to the baseline step without a motion term, same scenes and zones as
//! `bench step`, steps interleaved. `--motion-every k` costs (1 − 1/k)·baseline + (1/k)·row.

use super::median;
use super::step::{median_zones, scenes, time_interleaved, timed_config, StepRow};
use crate::data;
use crate::error::Result;
use crate::train::cli::load_options;
use crate::train::config::{SceneMotionConfig, TrainConfig};
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
        let data = data::load(&dir, &load_options(&base))?;
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
