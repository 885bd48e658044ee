//! The `dispflow-vk` binary: parse, dispatch, report errors. All work lives in the library.

mod cli;

use anyhow::Context;
use clap::Parser;
use dispflow_vk::vk::Gpu;

fn main() -> anyhow::Result<()> {
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
