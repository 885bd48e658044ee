//! `dispflow-vk bench mlp`: the deformation MLP's forward and forward + backward on the tiled
//! and the register kernels, in one run, as GFLOP/s and % of the FMA ceiling measured in the
//! same run (the criterion-free `cargo bench --bench mlp` prints the fuller table).

use super::step::fma_peak;
use super::{mlp_row, BenchRow, MlpImpl};
use crate::error::Result;
use crate::kernels::mlp_rows::{DeviceShape, MlpKernels};
use crate::model::deform::{MlpConfig, TimeEncoding};
use crate::vk::Gpu;

/// The fast preset's 4×64 network (direct time encoding) and the paper's 8×256 synthetic one.
pub fn configs() -> [(&'static str, MlpConfig); 2] {
    [
        (
            "4x64",
            MlpConfig {
                depth: 4,
                width: 64,
                skip: Some(2),
                x_freqs: 10,
                time: TimeEncoding::Direct { freqs: 10 },
            },
        ),
        ("8x256", MlpConfig::synthetic()),
    ]
}

pub fn mlp_rows(gpu: &Gpu, sizes: &[u32], reps: usize) -> Result<Vec<BenchRow>> {
    let peak = fma_peak(gpu, reps)?;
    println!("\nFMA ceiling (register-only `fma_peak`, same run): {peak:.2} GFLOP/s");
    println!("\n| MLP | kernels | N | fwd ms | fwd GFLOP/s | % FMA | fwd+bwd ms | fwd+bwd GFLOP/s | % FMA | err vs twin |");
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    let mut out = Vec::new();
    for (name, cfg) in configs() {
        for &n in sizes {
            for k in [MlpKernels::Tiled, MlpKernels::Rows] {
                let r = mlp_row(gpu, &cfg, name, n, MlpImpl::Layerwise(k), reps.min(3))?;
                let (tms, tg) = (
                    r.train_ms.unwrap_or(f64::NAN),
                    r.train_gflops.unwrap_or(0.0),
                );
                println!(
                    "| {name} | {} | {n} | {:.1} | {:.2} | {:.0}% | {tms:.1} | {tg:.2} | {:.0}% | {:.1e} |",
                    k.name(),
                    r.fwd_ms,
                    r.fwd_gflops,
                    100.0 * r.fwd_gflops / peak,
                    100.0 * tg / peak,
                    r.verify_err
                );
                out.push(BenchRow {
                    kernel: format!("mlp {name} fwd+bwd [{}]", k.name()),
                    n,
                    median_ms: tms,
                    m_per_s: n as f64 / tms / 1e3,
                    stages: r.stages,
                });
            }
        }
    }
    Ok(out)
}
