//! `dispflow-vk bench sparsity`: the training step with the MLP over every Gaussian (dense,
//! `--sparsity off`) against split models with 50 %, 20 %, 5 % and 0 % dynamic Gaussians,
//! same scenes, methods and zones as `bench step`, steps interleaved. The split is a fixed
//! pseudo-random one (the cost of a step depends on how many Gaussians are dynamic, not on
//! which), so this isolates the speed side of the sparsity knob from training.

use super::step::{rows_of, scenes, time_interleaved, timed_config, StepRow};
use crate::data;
use crate::error::Result;
use crate::model::dynamic::SplitSnapshot;
use crate::train::config::SparsityMode;
use crate::train::plan::hash_uniform;
use crate::train::Trainer;
use crate::vk::Gpu;

/// (label, dynamic fraction; `None` = dense).
pub const SPLITS: [(&str, Option<f64>); 5] = [
    ("dense (--sparsity off)", None),
    ("split, 50 % dynamic", Some(0.5)),
    ("split, 20 % dynamic", Some(0.2)),
    ("split, 5 % dynamic", Some(0.05)),
    ("split, 0 % dynamic", Some(0.0)),
];

/// Times `steps` steps (after `warm`) of each scene × method × split.
pub fn run_sparsity_bench(gpu: &Gpu, warm: u32, steps: u32) -> Result<Vec<StepRow>> {
    let mut rows = Vec::new();
    for (scene, dir) in scenes()? {
        for (method, weight) in [("baseline", 0.0f32), ("DispFlow", 0.1)] {
            // The split (made after step 1) stays for the rest of the run.
            let mut cfg = timed_config(weight);
            cfg.sparsity.start = 0.0;
            cfg.sparsity.every = 1.0;
            cfg.sparsity.dense_window = 0.0;
            let data = data::load(&dir, &cfg.load_options())?;
            let mut trainers = Vec::new();
            for (_, frac) in SPLITS {
                let mut c = cfg.clone();
                c.sparsity.mode = match frac {
                    None => SparsityMode::Off,
                    Some(_) => SparsityMode::Auto,
                };
                let mut tr = Trainer::new(gpu, &c, &data)?;
                tr.step(false, false)?;
                if let Some(f) = frac {
                    let n = tr.n() as usize;
                    let split = SplitSnapshot {
                        flags: (0..n)
                            .map(|i| (hash_uniform(7, i as u64, 0) < f) as u32)
                            .collect(),
                        fixed: vec![0.0; 10 * n],
                    };
                    tr.model.dynamic.upload(gpu, Some(&split))?;
                }
                trainers.push(tr);
            }
            let times = time_interleaved(&mut trainers, warm, steps)?;
            let labels = SPLITS.iter().map(|s| s.0);
            rows.extend(rows_of(&scene, method, &trainers, times, labels));
        }
    }
    Ok(rows)
}
