//! Shared by the training tests: a generated tiny scene and a configuration that trains it in
//! seconds on lavapipe.
#![allow(dead_code)]

use std::path::PathBuf;

use dispflow_vk::data::synthetic::{self, Preset as ScenePreset};
use dispflow_vk::data::{self, Dataset, LoadOptions};
use dispflow_vk::train::config::TrainConfig;

/// Steps `tr` until it has completed `end` iterations.
pub fn run_to(tr: &mut dispflow_vk::train::Trainer, end: u32) {
    while tr.iteration < end {
        tr.step(false, false).unwrap();
    }
}

pub fn tiny_scene(dir: &std::path::Path) -> PathBuf {
    let d = dir.join("tiny");
    synthetic::generate(ScenePreset::Tiny, 3, &d).unwrap();
    d
}

/// The tiny scene generated into `dir` and loaded (no progress output).
pub fn tiny_dataset(dir: &std::path::Path) -> Dataset {
    let opts = LoadOptions {
        progress: false,
        ..LoadOptions::default()
    };
    data::load(&tiny_scene(dir), &opts).unwrap()
}

/// A configuration that trains the tiny scene in seconds: small MLP, early warm-up end and
/// densification inside the run.
pub fn tiny_config(iterations: u32) -> TrainConfig {
    let mut c = TrainConfig::fast();
    c.iterations = iterations;
    c.mlp_width = 16;
    c.mlp_depth = 2;
    c.warm_up = iterations / 2;
    c.sh_degree = 1;
    c.sh_interval = 100;
    c.densify.from = 40;
    c.densify.until = iterations;
    c.densify.interval = 50;
    c.densify.opacity_reset_interval = 10_000;
    c.densify.budget = 8000;
    c
}

/// `tiny_config(60)` with the motion term from 25 and densification at 20 and 40: every pass of
/// a DispFlow step inside a minute.
pub fn tiny_motion_config() -> TrainConfig {
    let mut cfg = tiny_config(60);
    cfg.warm_up = 20;
    cfg.motion_weight = 1.0;
    cfg.motion_start = 25;
    cfg.flow_preset = "fast".into();
    cfg.densify.from = 10;
    cfg.densify.interval = 20;
    cfg
}

/// Transients on, spawned every `every` steps between `from` and 90 % of the run from two
/// frames, 16 pixels each at two depths; every spawn spawns (no persist gate).
pub fn spawn_transients(c: &mut TrainConfig, every: u32, from: f32) {
    c.transient.mode = dispflow_vk::train::config::TransientMode::On;
    c.transient.every = every;
    c.transient.from = from;
    c.transient.until = 0.9;
    c.transient.frames = 2;
    c.transient.pixels = 16;
    c.transient.depths = 2;
    c.transient.min_error = 0.05;
    c.transient.persist = 0.0;
}

/// A run of 60 iterations on the tiny scene for the CLI tests: deformation from 20, motion
/// term from 40, densification, a checkpoint every `checkpoint_interval` iterations.
pub fn tiny_toml(checkpoint_interval: u32) -> String {
    format!(
        r#"
iterations = 60
mlp_width = 16
mlp_depth = 2
warm_up = 20
motion_start = 40
flow_preset = "fast"
sh_degree = 1
sh_interval = 30
log_interval = 10
checkpoint_interval = {checkpoint_interval}
[densify]
from = 20
until = 50
interval = 25
budget = 8000
"#
    )
}
