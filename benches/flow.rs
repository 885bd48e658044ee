//! Criterion: TV-L1 optical flow per preset (the speed/accuracy knob) and image size, timed by
//! GPU timestamps (`iter_custom` returns the sum of the flow's dispatch times, not host wall
//! time). Inputs (a smooth texture and its copy shifted by (2.3, −1.7) px) are built once per
//! size; each case's first flow is checked against the known shift before timing.
//!
//!     cargo bench --bench flow
//!     DISPFLOW_DEVICE=nvidia cargo bench --bench flow

use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use dispflow_vk::kernels::flow::{FlowConfig, FlowEstimator, TvL1Flow};
use dispflow_vk::vk::{Gpu, Recorder};

const SHIFT: [f64; 2] = [2.3, -1.7];

fn texture(x: f64, y: f64) -> [f32; 4] {
    let g = 0.5
        + 0.12 * (0.61 * x + 0.23 * y + 0.4).sin()
        + 0.10 * (-0.31 * x + 0.52 * y + 1.3).sin()
        + 0.08 * (0.17 * x - 0.71 * y + 2.1).sin()
        + 0.06 * (0.83 * x + 0.44 * y).sin();
    let g = g as f32;
    [g, 0.9 * g + 0.05, 1.1 * g - 0.05, 1.0]
}

fn images(w: u32, h: u32) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for y in 0..h {
        for x in 0..w {
            let (xf, yf) = (x as f64, y as f64);
            a.push(texture(xf, yf));
            b.push(texture(xf - SHIFT[0], yf - SHIFT[1]));
        }
    }
    (a, b)
}

fn benches(c: &mut Criterion) {
    let gpu = Gpu::new_default().expect("Vulkan device");
    eprintln!("device: {}", gpu.info);
    let mut g = c.benchmark_group("flow_tvl1");
    g.sample_size(10)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(2));
    for (w, h) in [(96u32, 72u32), (192, 144)] {
        let (a, b) = images(w, h);
        let ab = gpu.buffer_from("bench flow a", &a).unwrap();
        let bb = gpu.buffer_from("bench flow b", &b).unwrap();
        let out = gpu.buffer("bench flow out", (w * h) as u64 * 8).unwrap();
        for name in ["fast", "default", "accurate"] {
            let est = TvL1Flow::new(&gpu, FlowConfig::preset(name).unwrap()).unwrap();
            let s = est.scratch(&gpu, w, h).unwrap();
            let run = || {
                let mut rec = Recorder::timed(&gpu).unwrap();
                est.record(&mut rec, &s, ab.all(), bb.all(), out.all());
                rec.finish().unwrap().total_ms()
            };
            run();
            // Verify: mean end-point error against the known shift, 8 px inside the border.
            let f: Vec<[f32; 2]> = gpu.read(out.all()).unwrap();
            let (mut e, mut n) = (0.0, 0);
            for y in 8..h as usize - 8 {
                for x in 8..w as usize - 8 {
                    let p = f[y * w as usize + x];
                    e += ((p[0] as f64 - SHIFT[0]).powi(2) + (p[1] as f64 - SHIFT[1]).powi(2))
                        .sqrt();
                    n += 1;
                }
            }
            let epe = e / n as f64;
            eprintln!("{name} {w}x{h}: EPE {epe:.4} px");
            assert!(epe < 0.2, "{name} {w}x{h}: EPE {epe}");
            g.throughput(Throughput::Elements((w * h) as u64));
            g.bench_with_input(BenchmarkId::new(name, format!("{w}x{h}")), &(), |bch, _| {
                bch.iter_custom(|iters| {
                    (0..iters)
                        .map(|_| Duration::from_secs_f64(run() * 1e-3))
                        .sum()
                })
            });
        }
    }
    g.finish();
}

criterion_group!(flow, benches);
criterion_main!(flow);
