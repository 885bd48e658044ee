//! The `dispflow-vk` binary: parse, dispatch, report errors. All work lives in the library.

mod cli;

use anyhow::Context;
use clap::Parser;
use dispflow_vk::vk::Gpu;

fn main() -> anyhow::Result<()> {
    default_sigpipe();
    let cli = cli::Cli::parse();
    match cli.command {
        cli::Command::Train(args) => {
            dispflow_vk::train::cli::run(&args)?;
        }
        cli::Command::Eval(args) => {
            dispflow_vk::eval::run::run_eval(&args)?;
        }
        cli::Command::Signal(args) => {
            dispflow_vk::eval::signal::run_signal(&args)?;
        }
        cli::Command::Render(args) => {
            dispflow_vk::eval::render::run_render(&args)?;
        }
        cli::Command::ScoreRenders(args) => {
            dispflow_vk::eval::reference::run_score(&args)?;
        }
        cli::Command::Devices => {
            for (i, (name, kind)) in dispflow_vk::vk::list_devices()?.iter().enumerate() {
                println!("{i}: {name} ({kind})");
            }
            let gpu = Gpu::new_default().context("opening the selected device")?;
            println!("\nselected: {:#?}", gpu.info);
            println!("kernels (each overridden by its variable):");
            for (what, shape, env) in dispflow_vk::kernels::shape::device_choices(&gpu.info) {
                println!("  {what}: {shape} ({env})");
            }
        }
        cli::Command::Bench(args) => {
            dispflow_vk::bench::run(&args)?;
        }
        cli::Command::Sweep(a) => dispflow_vk::sweep::run(&a)?,
        cli::Command::Data(a) => dispflow_vk::data::cli::run(&a)?,
    }
    Ok(())
}

/// Rust starts with SIGPIPE ignored, so a print into a closed pipe
/// (`dispflow-vk sweep PLAN --dry-run | head -3`) fails and `println!` panics with a backtrace.
/// The default action ends the process quietly instead, as other Unix tools do.
fn default_sigpipe() {
    #[cfg(unix)]
    // SAFETY: called first in `main`, before any thread exists; SIG_DFL is a valid action.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}
