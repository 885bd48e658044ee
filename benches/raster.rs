//! Criterion: rasteriser forward and forward+backward, timed by GPU timestamps (`iter_custom`
//! returns the sum of GPU dispatch times). Sweeps the Gaussian count at 256² and the resolution
//! at 10^4 Gaussians. Sizes beyond what lavapipe finishes quickly are opt-in:
//!
//!     cargo bench --bench raster                       # 10^3..10^5, 128²..512²
//!     DISPFLOW_BENCH_LARGE=1 cargo bench --bench raster # adds 10^6 and 1024² (use a GPU)
//!
//! `blend_backward` times the blend-backward dispatch alone, every `BlendBwdVariant` on the
//! issue-14 scenes (D-NeRF-like 114×114 with 20k Gaussians, built-in 160×120 with 10k).

use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use dispflow_vk::bench::raster_scenes::RasterScene;
use dispflow_vk::bench::RasterCase;
use dispflow_vk::kernels::raster::{BlendBwdVariant, DeviceShape};
use dispflow_vk::vk::Gpu;

fn benches(c: &mut Criterion) {
    let gpu = Gpu::new_default().expect("Vulkan device");
    eprintln!("device: {}", gpu.info);
    let large = std::env::var("DISPFLOW_BENCH_LARGE").as_deref() == Ok("1");
    let mut counts = vec![1_000u32, 10_000, 100_000];
    let mut resolutions = vec![128u32, 256, 512];
    if large {
        counts.push(1_000_000);
        resolutions.push(1024);
    }
    let mut cases: Vec<(u32, u32)> = counts
        .iter()
        .map(|&n| (n, 256))
        .chain(resolutions.iter().map(|&r| (10_000, r)))
        .collect();
    // (10^4, 256²) is in both sweeps; criterion panics on a repeated benchmark id.
    let mut seen = std::collections::HashSet::new();
    cases.retain(|c| seen.insert(*c));
    for (name, bwd) in [("raster_forward", false), ("raster_forward_backward", true)] {
        let mut g = c.benchmark_group(name);
        g.sample_size(10)
            .warm_up_time(Duration::from_millis(300))
            .measurement_time(Duration::from_secs(3));
        for &(n, res) in &cases {
            let case = RasterCase::new(&gpu, n, res).expect("raster case");
            g.throughput(Throughput::Elements(n as u64));
            g.bench_with_input(BenchmarkId::new(format!("{res}px"), n), &n, |b, _| {
                b.iter_custom(|iters| {
                    (0..iters)
                        .map(|_| {
                            Duration::from_secs_f64(case.run(&gpu, bwd).unwrap().total_ms() * 1e-3)
                        })
                        .sum()
                })
            });
        }
        g.finish();
    }
    let mut g = c.benchmark_group("blend_backward");
    g.sample_size(10)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(3));
    for scene in [RasterScene::Dnerf, RasterScene::Builtin] {
        let (h, cam) = scene.build();
        let mut case = RasterCase::from_host(&gpu, &h, cam).expect("raster case");
        for v in BlendBwdVariant::ALL {
            case.set_blend_bwd_variant(v);
            let id = BenchmarkId::new(v.name(), scene.label());
            g.bench_function(id, |b| {
                b.iter_custom(|iters| {
                    (0..iters)
                        .map(|_| {
                            let t = case.run_backward(&gpu).unwrap();
                            let ms: f64 = t
                                .by_label()
                                .iter()
                                .filter(|(l, _)| l.starts_with("blend_bwd"))
                                .map(|(_, ms)| ms)
                                .sum();
                            Duration::from_secs_f64(ms * 1e-3)
                        })
                        .sum()
                })
            });
        }
    }
    g.finish();
}

criterion_group!(raster, benches);
criterion_main!(raster);
