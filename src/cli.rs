//! Command-line interface (clap derive). `main.rs` only parses and dispatches.

use clap::{Parser, Subcommand};

#[derive(Parser, Debug)]
#[command(
    name = "dispflow-vk",
    version,
    about = "Monocular deformable 3D Gaussian splatting with displacement-flow supervision, on Vulkan",
    long_about = "Monocular deformable 3D Gaussian splatting with displacement-flow supervision \
(DispFlow-GS), on hand-written Vulkan compute kernels.\n\nDevice selection: DISPFLOW_DEVICE=<index|name \
substring> picks a Vulkan device (default: the first discrete GPU, else integrated, else lavapipe)."
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Train a deformable Gaussian model (default: the built-in synthetic scene, fast preset).
    Train(dispflow_vk::train::cli::TrainArgs),
    /// Evaluate trained runs on their test split: metrics JSON, Markdown table, picture strips,
    /// per-frame and training plots (into RUN/eval/).
    Eval(dispflow_vk::eval::run::EvalArgs),
    /// Render a trained run along a camera path (test cameras, a fixed camera over time, an
    /// orbit or a spiral) to PNGs, optionally with the displacement-flow heatmap and per-frame
    /// 3DGS .ply exports.
    Render(dispflow_vk::eval::render::RenderArgs),
    /// Score the scene motion a motion step would learn from, at each kept checkpoint of a
    /// run: flow_mmap of every estimator variant against the motion masks, next to the
    /// ground-truth flow's (RUN/signal.json and signal.md).
    Signal(dispflow_vk::eval::signal::SignalArgs),
    /// Score another implementation's test renders (a folder of PNGs, one per test frame, in
    /// the split's order) with this project's evaluation: PSNR, SSIM, dynamic/static PSNR by
    /// the motion masks, LPIPS with weights. Writes a sweep cell (cells/<scene>/<variant>/
    /// seed<N>/) so `sweep report` tables it beside this project's runs (docs/reference.md).
    ScoreRenders(dispflow_vk::eval::reference::ScoreArgs),
    /// List the Vulkan devices and the limits that matter to the kernels.
    Devices,
    /// Time the GPU kernels (sort, scan, rasteriser forward/backward) with GPU timestamps and
    /// print a table of medians.
    Bench(dispflow_vk::bench::BenchArgs),
    /// Run a plan of scenes × variants × seeds (each cell its own train + eval process,
    /// resumable; locally or as a Slurm job array) and write results.jsonl, the paper-layout
    /// tables and the speed/accuracy trade with its Pareto plot. `sweep report DIR` rebuilds
    /// the tables from the results.
    Sweep(dispflow_vk::sweep::SweepArgs),
    /// Generate or check datasets.
    Data(dispflow_vk::data::cli::DataArgs),
}
