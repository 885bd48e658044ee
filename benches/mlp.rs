//! Deformation MLP: layer-wise tiled GEMM (forward and forward + backward), fused forward
//! (f32) and fused forward with fp16 storage, plus the GEMM microbenchmark giving the
//! device's achievable FLOP/s. Times are GPU timestamps (median of reps after one warm-up);
//! every case's first output is verified against the CPU twin.
//!
//! Not a criterion harness: on lavapipe one 8×256 forward + backward of 10^5 Gaussians takes
//! about a minute, far beyond criterion's minimum of 10 samples. Prints a markdown table.
//!
//!     cargo bench --bench mlp                               # N = 10^4, 10^5; 8×256 synthetic
//!     DISPFLOW_MLP_SIZES=10000 DISPFLOW_MLP_REPS=3 cargo bench --bench mlp
//!     DISPFLOW_MLP_CONFIGS=synthetic,real,4x64 cargo bench --bench mlp
//!     DISPFLOW_DEVICE=nvidia cargo bench --bench mlp       # pick a device

use dispflow_vk::bench::{gemm_peak, mlp_row, MlpImpl};
use dispflow_vk::kernels::mlp_rows::MlpKernels;
use dispflow_vk::model::deform::{MlpConfig, TimeEncoding};
use dispflow_vk::vk::Gpu;

fn env_list(name: &str, default: &str) -> Vec<String> {
    std::env::var(name)
        .unwrap_or_else(|_| default.to_string())
        .split(',')
        .filter(|s| !s.is_empty())
        .map(str::to_string)
        .collect()
}

fn config(name: &str) -> MlpConfig {
    match name {
        "synthetic" => MlpConfig::synthetic(),
        "real" => MlpConfig::real(),
        "4x64" => MlpConfig {
            depth: 4,
            width: 64,
            skip: Some(2),
            x_freqs: 10,
            time: TimeEncoding::Direct { freqs: 10 },
        },
        other => panic!("DISPFLOW_MLP_CONFIGS: unknown config {other:?} (synthetic, real, 4x64)"),
    }
}

fn main() {
    // `cargo bench` passes --bench; `cargo test --benches` passes nothing: only run when benched.
    if !std::env::args().any(|a| a == "--bench") {
        return;
    }
    let gpu = Gpu::new_default().expect("Vulkan device");
    eprintln!("device: {}", gpu.info);
    let reps: usize = std::env::var("DISPFLOW_MLP_REPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    let sizes: Vec<u32> = env_list("DISPFLOW_MLP_SIZES", "10000,100000")
        .iter()
        .map(|s| {
            s.parse()
                .expect("DISPFLOW_MLP_SIZES: comma-separated integers")
        })
        .collect();
    let peak = gemm_peak(&gpu, 16384, reps.max(3)).expect("GEMM microbenchmark");
    println!("device: {}", gpu.info);
    println!(
        "FMA peak (register-only): {:.2} GFLOP/s; tiled GEMM {}×{}×{}: {:.2} GFLOP/s",
        peak.fma_gflops, peak.gemm_shape.0, peak.gemm_shape.1, peak.gemm_shape.2, peak.gemm_gflops
    );
    println!();
    println!("| config | impl | N | fwd ms | fwd Gauss/s | fwd GFLOP/s | % FMA peak | fwd+bwd ms | fwd+bwd Gauss/s | fwd+bwd GFLOP/s | % FMA peak | bytes/Gauss | err vs twin |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut notes = Vec::new();
    for name in env_list("DISPFLOW_MLP_CONFIGS", "synthetic") {
        let cfg = config(&name);
        for &n in &sizes {
            for imp in [
                MlpImpl::Layerwise(MlpKernels::Tiled),
                MlpImpl::Layerwise(MlpKernels::Rows),
                MlpImpl::Fused,
                MlpImpl::FusedF16,
            ] {
                let row = match mlp_row(&gpu, &cfg, &name, n, imp, reps) {
                    Ok(r) => r,
                    Err(e) => {
                        println!("| {name} | {imp:?} | {n} | skipped: {e} |");
                        continue;
                    }
                };
                let pct = |g: f64| 100.0 * g / peak.fma_gflops;
                let st: Vec<String> = row
                    .stages
                    .iter()
                    .map(|(l, p)| format!("{l} {p:.0}%"))
                    .collect();
                notes.push(format!("{name} {imp:?} N={n}: {}", st.join(", ")));
                let (tms, tgs, tgf, tp) = match (row.train_ms, row.train_gflops) {
                    (Some(ms), Some(g)) => (
                        format!("{ms:.1}"),
                        format!("{:.3e}", n as f64 / (ms * 1e-3)),
                        format!("{g:.2}"),
                        format!("{:.0}%", pct(g)),
                    ),
                    _ => ("–".into(), "–".into(), "–".into(), "–".into()),
                };
                println!(
                    "| {name} | {:?} | {n} | {:.1} | {:.3e} | {:.2} | {:.0}% | {tms} | {tgs} | {tgf} | {tp} | {} | {:.1e} |",
                    imp,
                    row.fwd_ms,
                    n as f64 / (row.fwd_ms * 1e-3),
                    row.fwd_gflops,
                    pct(row.fwd_gflops),
                    row.bytes_per_gaussian,
                    row.verify_err
                );
            }
        }
    }
    println!();
    println!("GPU time per kernel (last timed run):");
    for n in notes {
        println!("- {n}");
    }
}
