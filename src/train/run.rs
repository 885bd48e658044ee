//! What a training run is asked to do ([`RunSpec`]) and where it reports ([`Progress`]):
//! below both the set-up and finish (`session`) and the steps between them (`run_loop`).

use std::path::PathBuf;

use super::config::TrainConfig;

/// What one training run needs besides the device.
#[derive(Clone)]
pub struct RunSpec<'a> {
    pub cfg: &'a TrainConfig,
    pub data_dir: PathBuf,
    /// The scene's name in the report (by default the dataset directory's name).
    pub scene: String,
    pub out: PathBuf,
    /// Continue from `out/checkpoints/last.ckpt` when it exists.
    pub resume: bool,
    /// A per-kernel GPU time breakdown at every log line.
    pub verbose: bool,
}

/// Where a run reports its progress.
pub trait Progress {
    fn start(&mut self, total: u32, at: u32);
    fn position(&mut self, iteration: u32);
    /// The status line of a logged iteration.
    fn message(&mut self, iteration: u32, total: u32, msg: &str);
    /// An event worth a line of its own (device, resume, splits, collapses, warnings).
    fn note(&mut self, text: &str);
    fn finish(&mut self);
}
