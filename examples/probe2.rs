// EXPERIMENT (not committed)
use dispflow_vk::bench::median;
use dispflow_vk::kernels::mlp::MlpLinearParams;
use dispflow_vk::kernels::mlp_fused::FmaPeak;
use dispflow_vk::shaders;
use dispflow_vk::vk::{Gpu, Recorder};

fn main() {
    let gpu = Gpu::new_default().unwrap();
    let fma = FmaPeak::new(&gpu).unwrap();
    let out = gpu.buffer("o", 512 * 256 * 4).unwrap();
    let n: u32 = 16384;
    let (k, m) = (64u32, 64u32);
    let w: Vec<f32> = (0..k * m + m)
        .map(|i| ((i % 13) as f32 - 6.0) * 0.01)
        .collect();
    let a: Vec<f32> = (0..n * k).map(|i| ((i % 7) as f32 - 3.0) * 0.1).collect();
    let wb = gpu.buffer_from("w", &w).unwrap();
    let ab = gpu.buffer_from("a", &a).unwrap();
    let ob = gpu.buffer("o", (n * m * 4) as u64).unwrap();
    let vars: Vec<(&str, u32, &'static dispflow_vk::shaders::ShaderInfo)> = vec![
        ("tiled (today)", 0, &shaders::mlp::LINEAR_FWD),
        ("unroll r4 o4", 4, &shaders::mlp::PROBE_UNROLL_K64_R4_O4),
        ("unroll r8 o2", 8, &shaders::mlp::PROBE_UNROLL_K64_R8_O2),
        ("dyn r4 o4", 4, &shaders::mlp::PROBE_DYN_R4_O4),
        ("ku4 r4 o4", 4, &shaders::mlp::PROBE_KU_R4_O4),
        ("ku4 r8 o4", 8, &shaders::mlp::PROBE_KU_R8_O4),
        ("ku4 r4 o8", 4, &shaders::mlp::PROBE_KU_R4_O8),
    ];
    let pipes: Vec<_> = vars.iter().map(|v| gpu.pipeline(v.2).unwrap()).collect();
    let mut res = vec![vec![]; vars.len() + 1];
    let mut flop = 0.0;
    for _ in 0..5 {
        let mut rec = Recorder::timed(&gpu).unwrap();
        flop = fma.record(&mut rec, out.all(), 512, 2048);
        res[vars.len()].push(rec.finish().unwrap().total_ms());
        for (i, v) in vars.iter().enumerate() {
            let mut rec = Recorder::timed(&gpu).unwrap();
            if v.1 == 0 {
                let pc = MlpLinearParams {
                    n,
                    fan_in: k,
                    fan_out: m,
                    ka: k,
                    a_stride: k,
                    b_stride: k,
                    out_stride: m,
                    out_col: 0,
                    w_off: 0,
                    b_off: k * m,
                    relu: 1,
                    pad: 0,
                };
                rec.dispatch(
                    &pipes[i],
                    &pc,
                    &[wb.all(), ab.all(), ab.all(), ob.all()],
                    [1, n / 64, 1],
                );
            } else {
                let pc = MlpLinearParams {
                    n,
                    fan_in: k,
                    fan_out: m,
                    ka: k,
                    a_stride: n,
                    b_stride: 0,
                    out_stride: n,
                    out_col: 0,
                    w_off: 0,
                    b_off: 0,
                    relu: 1,
                    pad: m,
                };
                rec.dispatch(
                    &pipes[i],
                    &pc,
                    &[wb.slice(0, 16384), ab.all(), ab.all(), ob.all()],
                    [n / (64 * v.1), 1, 1],
                );
            }
            res[i].push(rec.finish().unwrap().total_ms());
        }
    }
    let peak = flop / (median(res[vars.len()].clone()) * 1e6);
    println!("fma peak {peak:.2} GFLOP/s");
    for (i, v) in vars.iter().enumerate() {
        let ms = median(res[i].clone());
        let g = 2.0 * (n * k * m) as f64 / (ms * 1e6);
        println!(
            "{k}x{m} {} {:.3} ms {:.2} GFLOP/s {:.0}%",
            v.0,
            ms,
            g,
            100.0 * g / peak
        );
    }
}
