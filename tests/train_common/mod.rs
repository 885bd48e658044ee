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
