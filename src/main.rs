//! The `dispflow-vk` binary: parse, dispatch, report errors. All work lives in the library.

mod cli;

use clap::Parser;

fn main() -> anyhow::Result<()> {
    let cli = cli::Cli::parse();
    match cli.command {
        cli::Command::Devices => {}
        cli::Command::Bench(_args) => {}
        cli::Command::Data(a) => dispflow_vk::data::cli::run(&a)?,
    }
    Ok(())
}
