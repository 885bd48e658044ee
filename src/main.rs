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
            // The per-device kernel choices (override: DISPFLOW_MLP_KERNELS, DISPFLOW_BLEND_FWD,
            // DISPFLOW_BLEND_BWD, DISPFLOW_NODES_GATHER, DISPFLOW_LOSS_BLUR).
            println!(
                "kernels: MLP {}, blend forward {}, blend backward {}, node gather {}, loss blur {}",
                dispflow_vk::kernels::mlp_rows::MlpKernels::for_device(&gpu).name(),
                dispflow_vk::kernels::raster::BlendFwdVariant::for_device(&gpu.info).name(),
                dispflow_vk::kernels::raster::BlendBwdVariant::for_device(&gpu.info).name(),
                dispflow_vk::kernels::nodes::GatherShape::for_device(&gpu).name(),
                dispflow_vk::kernels::loss::BlurShape::for_device(&gpu).name()
            );
        }
        cli::Command::Bench(args) => {
            dispflow_vk::bench::run(&args)?;
        }
        cli::Command::Sweep(a) => dispflow_vk::sweep::run(&a)?,
        cli::Command::Data(a) => dispflow_vk::data::cli::run(&a)?,
    }
    Ok(())
}
