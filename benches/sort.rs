//! Criterion: radix sort and prefix sum, timed by GPU timestamps (`iter_custom` returns the
//! sum of GPU dispatch times, not host wall time). Inputs are built once per size; each case's
//! first result is verified against the CPU twin before timing.
//!
//!     cargo bench --bench sort            # all sizes 2^16..2^22
//!     DISPFLOW_DEVICE=nvidia cargo bench  # pick a device

use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use dispflow_vk::bench::{KeyShape, ScanCase, SortCase};
use dispflow_vk::vk::Gpu;

fn gpu_time(ms: f64) -> Duration {
    Duration::from_secs_f64(ms * 1e-3)
}

fn benches(c: &mut Criterion) {
    let gpu = Gpu::new_default().expect("Vulkan device");
    eprintln!("device: {}", gpu.info);
    let mut g = c.benchmark_group("radix_sort");
    g.sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(3));
    for lg in [16u32, 18, 20, 22] {
        let n = 1u32 << lg;
        for shape in [KeyShape::Random32, KeyShape::TileDepth64] {
            let case = SortCase::new(&gpu, n, shape).expect("sort case");
            case.verify(&gpu).expect("sort verified");
            g.throughput(Throughput::Elements(n as u64));
            g.bench_with_input(BenchmarkId::new(format!("{shape:?}"), n), &n, |b, _| {
                b.iter_custom(|iters| {
                    (0..iters)
                        .map(|_| gpu_time(case.run(&gpu).unwrap().0.total_ms()))
                        .sum()
                })
            });
        }
    }
    g.finish();
    let mut g = c.benchmark_group("scan");
    g.sample_size(10)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2));
    for lg in [16u32, 18, 20, 22] {
        let n = 1u32 << lg;
        let case = ScanCase::new(&gpu, n).expect("scan case");
        case.verify(&gpu).expect("scan verified");
        g.throughput(Throughput::Elements(n as u64));
        g.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            b.iter_custom(|iters| {
                (0..iters)
                    .map(|_| gpu_time(case.run(&gpu).unwrap().total_ms()))
                    .sum()
            })
        });
    }
    g.finish();
}

criterion_group!(sort, benches);
criterion_main!(sort);
