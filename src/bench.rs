//! `dispflow-vk bench`.

#[derive(clap::Args, Debug)]
pub struct BenchArgs {}
