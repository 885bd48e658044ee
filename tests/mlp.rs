//! Deformation MLP on the GPU against the CPU twin (`reference::mlp`, f64 accumulation).
//!
//! Tolerances. The GPU accumulates in f32 over dot products of up to 349 terms per layer and
//! 8 + 2 layers; the rounding error of one dot product is ≈ √K·2⁻²⁴ of its ℓ1 mass, and the
//! ℓ1 mass of these layers is a few times the output, so outputs are compared normwise:
//! `max |gpu − twin| ≤ 1e-5 · max |twin|` (+ a tiny absolute floor); measured 1e-7..7e-7.
//! Gradients are sums over up to 65 537 Gaussians in f32 (16-row tiles, then ≤ 64 chunk
//! partials in fixed order); they are compared per tensor with
//! `max |gpu − twin| ≤ 1e-5 · max |twin|`; measured 2e-7..1e-6. The backward twin is fed
//! the GPU's stored forward activations (one stage at a time), so ReLU masks are identical and
//! a pre-activation within rounding of 0 cannot flip a mask between the two.

use dispflow_vk::kernels::mlp::{Mlp, MlpBuffers, MlpTime};
use dispflow_vk::kernels::mlp_fused::{MlpFused, Precision};
use dispflow_vk::model::deform::{MlpConfig, MlpLayout, TimeEncoding};
use dispflow_vk::reference::mlp::{self as twin, Activations, Times};
use dispflow_vk::testing::{self, Noise};
use dispflow_vk::vk::{Buffer, Gpu, Recorder};

fn unif(noise: &mut Noise, lo: f32, hi: f32) -> f32 {
    lo + (hi - lo) * (noise.next_u32() as f32 / u32::MAX as f32)
}

fn small(time_net: bool) -> MlpConfig {
    MlpConfig {
        depth: 4,
        width: 64,
        skip: Some(2),
        x_freqs: 10,
        time: if time_net {
            TimeEncoding::TimeNet {
                freqs: 6,
                hidden: 64,
                out: 30,
            }
        } else {
            TimeEncoding::Direct { freqs: 10 }
        },
    }
}

struct Case {
    lay: MlpLayout,
    n: usize,
    xyz: Vec<f32>,
    /// Per-Gaussian times, or None for the batch time `t`.
    times: Option<Vec<f32>>,
    t: f32,
    params: Vec<f32>,
    d_out: Vec<f32>,
}

impl Case {
    fn new(cfg: MlpConfig, n: usize, seed: u64, pos: f32, per_gaussian: bool) -> Case {
        let lay = MlpLayout::new(&cfg).unwrap();
        let mut noise = Noise::new(seed);
        let xyz = (0..3 * n).map(|_| unif(&mut noise, -pos, pos)).collect();
        let times = per_gaussian.then(|| (0..n).map(|_| unif(&mut noise, 0.0, 1.0)).collect());
        let d_out = (0..10 * n).map(|_| unif(&mut noise, -1.0, 1.0)).collect();
        Case {
            params: lay.init_params(seed),
            lay,
            n,
            xyz,
            times,
            t: unif(&mut noise, 0.0, 1.0),
            d_out,
        }
    }

    fn twin_times(&self) -> Times<'_> {
        match &self.times {
            Some(t) => Times::PerGaussian(t),
            None => Times::Batch(self.t),
        }
    }
}

/// Device-side inputs and outputs of one case.
struct Io {
    xyz: Buffer,
    times: Buffer,
    params: Buffer,
    out: Buffer,
    d_out: Buffer,
    grads: Buffer,
}

impl Io {
    fn new(gpu: &Gpu, c: &Case) -> Io {
        let n = c.n.max(1) as u64;
        let io = Io {
            xyz: gpu.buffer("test xyz", n * 12).unwrap(),
            times: gpu.buffer("test times", n * 4).unwrap(),
            params: gpu.buffer_from("test params", &c.params).unwrap(),
            out: gpu.buffer("test out", n * 40).unwrap(),
            d_out: gpu.buffer("test d_out", n * 40).unwrap(),
            grads: gpu.buffer("test grads", c.lay.total as u64 * 4).unwrap(),
        };
        testing::fill_noise(gpu, &io.out, 5);
        testing::fill_noise(gpu, &io.grads, 6);
        if c.n > 0 {
            gpu.upload(io.xyz.all(), &c.xyz).unwrap();
            gpu.upload(io.d_out.all(), &c.d_out).unwrap();
            if let Some(t) = &c.times {
                gpu.upload(io.times.all(), t).unwrap();
            }
        }
        io
    }

    fn time(&self, c: &Case) -> MlpTime<'_> {
        match c.times {
            Some(_) => MlpTime::PerGaussian(self.times.all()),
            None => MlpTime::Batch(c.t),
        }
    }
}

fn noisy_buffers(gpu: &Gpu, mlp: &Mlp, cap: u32) -> MlpBuffers {
    let b = mlp.buffers(gpu, cap).unwrap();
    for (i, buf) in [&b.x0, &b.enc_t, &b.ht].into_iter().chain(&b.h).enumerate() {
        testing::fill_noise(gpu, buf, 100 + i as u64);
    }
    b
}

/// Reads the stored forward activations back in the twin's shape.
fn read_acts(gpu: &Gpu, mlp: &Mlp, b: &MlpBuffers, n: usize) -> Activations {
    let cfg = &mlp.layout.cfg;
    let rd = |buf: &Buffer, d: usize| {
        gpu.read::<f32>(buf.elems::<f32>(0, (n * d) as u64))
            .unwrap()
    };
    let (ted, hid) = if cfg.time_net() {
        (cfg.t_enc_dims(), mlp.layout.time_net()[0].fan_out)
    } else {
        (0, 0)
    };
    let h: Vec<Vec<f32>> = b.h.iter().map(|x| rd(x, cfg.width as usize)).collect();
    Activations::from_f32(
        n,
        &rd(&b.x0, cfg.in_dims()),
        &rd(&b.enc_t, ted),
        &rd(&b.ht, hid),
        &h,
        &[],
    )
}

/// `max |got − want| ≤ rel · max |want| + abs`; returns the normwise error.
fn assert_close(what: &str, got: &[f32], want: &[f64], rel: f64, abs: f64) -> f64 {
    assert_eq!(got.len(), want.len(), "{what}: length");
    let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut worst = (0.0f64, 0usize);
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        let e = (*g as f64 - w).abs();
        assert!(g.is_finite(), "{what}[{i}] = {g} is not finite");
        if e > worst.0 {
            worst = (e, i);
        }
    }
    let tol = rel * scale + abs;
    assert!(
        worst.0 <= tol,
        "{what}: |gpu − twin| = {:.3e} at {} (gpu {}, twin {}) exceeds {tol:.3e} (scale {scale:.3e})",
        worst.0,
        worst.1,
        got[worst.1],
        want[worst.1]
    );
    if scale > 0.0 {
        worst.0 / scale
    } else {
        0.0
    }
}

/// Forward (and backward) on the layer-wise GPU path vs the twin. Returns the normwise errors.
fn check_layerwise(gpu: &Gpu, c: &Case, backward: bool) -> (f64, f64) {
    let mlp = Mlp::new(gpu, &c.lay.cfg).unwrap();
    let b = noisy_buffers(gpu, &mlp, c.n.max(1) as u32);
    let io = Io::new(gpu, c);
    let n = c.n as u32;
    let mut rec = Recorder::new(gpu).unwrap();
    mlp.forward(
        &mut rec,
        &b,
        n,
        io.xyz.all(),
        io.time(c),
        io.params.all(),
        io.out.all(),
    );
    if backward {
        mlp.backward(
            &mut rec,
            &b,
            n,
            io.params.all(),
            io.d_out.all(),
            io.grads.all(),
            false,
        );
    }
    rec.finish().unwrap();
    let p64: Vec<f64> = c.params.iter().map(|&v| v as f64).collect();
    let want = twin::forward_f64(&c.lay, &p64, &c.xyz, c.twin_times());
    let got: Vec<f32> = gpu.read(io.out.elems::<f32>(0, c.n as u64 * 10)).unwrap();
    let label = format!("{:?} n={} fwd", c.lay.cfg, c.n);
    let ef = assert_close(&label, &got, &want.out, 1e-5, 1e-7);
    // The stored encoding matches the twin's: raw x exactly, sin/cos within 1e-5 absolute.
    // With the phase-exact reduction the error is the device's sin/cos on [−π, π] alone: it
    // does not grow with the frequency or with |x| (lavapipe: ≤ 2.3e-6 at every frequency, also
    // at |x| = 1e4, where a plain sin(2^9·x) in f32 is off by O(1)).
    let acts = read_acts(gpu, &mlp, &b, c.n);
    let (xd, ind) = (c.lay.cfg.x_dims(), c.lay.cfg.in_dims());
    for r in 0..c.n {
        for k in 0..xd {
            let (g, w) = (acts.x0[r * ind + k], want.x0[r * ind + k]);
            let tol = if k < 3 { 0.0 } else { 1e-5 };
            assert!(
                (g - w).abs() <= tol,
                "{label}: γ(x)[{r}][{k}] = {g}, twin {w}"
            );
        }
    }
    let mut eb = 0.0f64;
    if backward {
        let g = twin::backward(&c.lay, &p64, &acts, &c.d_out);
        let got: Vec<f32> = gpu
            .read(io.grads.elems::<f32>(0, c.lay.total as u64))
            .unwrap();
        for (li, l) in c.lay.linears.iter().enumerate() {
            let w = l.w_off..l.w_off + l.fan_in * l.fan_out;
            let bb = l.b_off..l.b_off + l.fan_out;
            let what = format!(
                "{:?} n={} grad of linear {li} ({:?})",
                c.lay.cfg, c.n, l.role
            );
            eb = eb.max(assert_close(
                &format!("{what} W"),
                &got[w.clone()],
                &g[w],
                1e-5,
                1e-8,
            ));
            eb = eb.max(assert_close(
                &format!("{what} b"),
                &got[bb.clone()],
                &g[bb],
                1e-5,
                1e-8,
            ));
        }
    }
    (ef, eb)
}

#[test]
fn layerwise_small_configs_match_twin() {
    let gpu = testing::gpu();
    for tn in [false, true] {
        for (k, n) in [1usize, 37, 4096, 65_537].into_iter().enumerate() {
            let c = Case::new(small(tn), n, 10 + k as u64, 1.5, k % 2 == 1);
            let (ef, eb) = check_layerwise(&gpu, &c, true);
            eprintln!("4x64 time_net={tn} n={n}: fwd {ef:.2e}, bwd {eb:.2e} (normwise)");
        }
    }
}

#[test]
fn layerwise_presets_match_twin() {
    let gpu = testing::gpu();
    for cfg in [MlpConfig::synthetic(), MlpConfig::real()] {
        for (k, n) in [1usize, 37, 4096].into_iter().enumerate() {
            let c = Case::new(cfg, n, 20 + k as u64, 1.5, k == 2);
            let (ef, eb) = check_layerwise(&gpu, &c, true);
            eprintln!(
                "8x256 time_net={} n={n}: fwd {ef:.2e}, bwd {eb:.2e}",
                cfg.time_net()
            );
        }
    }
    // No skip connection.
    let c = Case::new(
        MlpConfig {
            skip: None,
            ..MlpConfig::real()
        },
        300,
        29,
        1.5,
        false,
    );
    check_layerwise(&gpu, &c, true);
}

#[test]
fn backward_accumulates_and_zero_gaussians_give_zero() {
    let gpu = testing::gpu();
    let c = Case::new(small(true), 200, 31, 1.0, true);
    let mlp = Mlp::new(&gpu, &c.lay.cfg).unwrap();
    let b = noisy_buffers(&gpu, &mlp, 200);
    let io = Io::new(&gpu, &c);
    let mut rec = Recorder::new(&gpu).unwrap();
    mlp.forward(
        &mut rec,
        &b,
        200,
        io.xyz.all(),
        io.time(&c),
        io.params.all(),
        io.out.all(),
    );
    mlp.backward(
        &mut rec,
        &b,
        200,
        io.params.all(),
        io.d_out.all(),
        io.grads.all(),
        false,
    );
    mlp.backward(
        &mut rec,
        &b,
        200,
        io.params.all(),
        io.d_out.all(),
        io.grads.all(),
        true,
    );
    rec.finish().unwrap();
    let got: Vec<f32> = gpu
        .read(io.grads.elems::<f32>(0, c.lay.total as u64))
        .unwrap();
    let p64: Vec<f64> = c.params.iter().map(|&v| v as f64).collect();
    let acts = read_acts(&gpu, &mlp, &b, 200);
    let g: Vec<f64> = twin::backward(&c.lay, &p64, &acts, &c.d_out)
        .iter()
        .map(|v| 2.0 * v)
        .collect();
    for l in &c.lay.linears {
        let w = l.w_off..l.b_off + l.fan_out;
        let (gg, ww): (Vec<f32>, Vec<f64>) = w
            .filter(|i| *i < l.w_off + l.fan_in * l.fan_out || *i >= l.b_off)
            .map(|i| (got[i], g[i]))
            .unzip();
        assert_close("accumulated grads (2×)", &gg, &ww, 1e-5, 1e-8);
    }
    // Zero Gaussians: nothing dispatched over rows, gradients written as exact zeros.
    let mut rec = Recorder::new(&gpu).unwrap();
    mlp.forward(
        &mut rec,
        &b,
        0,
        io.xyz.all(),
        MlpTime::Batch(0.5),
        io.params.all(),
        io.out.all(),
    );
    mlp.backward(
        &mut rec,
        &b,
        0,
        io.params.all(),
        io.d_out.all(),
        io.grads.all(),
        false,
    );
    rec.finish().unwrap();
    let got: Vec<f32> = gpu
        .read(io.grads.elems::<f32>(0, c.lay.total as u64))
        .unwrap();
    for l in &c.lay.linears {
        assert!(got[l.w_off..l.w_off + l.fan_in * l.fan_out]
            .iter()
            .all(|v| *v == 0.0));
        assert!(got[l.b_off..l.b_off + l.fan_out].iter().all(|v| *v == 0.0));
    }
}

#[test]
fn extremes_positions_1e4_and_time_outside_unit_interval() {
    let gpu = testing::gpu();
    // |x| up to 1e4: 2^9·x ≈ 5e6 rad; the phase-exact encoding keeps γ(x) within ~1e-6 of f64.
    let mut c = Case::new(small(true), 64, 41, 1e4, true);
    for (i, t) in c.times.as_mut().unwrap().iter_mut().enumerate() {
        *t = [-2.0, 5.5, 1e3, -0.25][i % 4];
    }
    c.xyz[0] = 1e4;
    c.xyz[1] = -1e4;
    let (ef, eb) = check_layerwise(&gpu, &c, true);
    eprintln!("|x| ≤ 1e4, t ∉ [0,1]: fwd {ef:.2e}, bwd {eb:.2e}");
    let c = Case::new(MlpConfig::real(), 16, 42, 1e4, false);
    let c = Case { t: -3.5, ..c };
    check_layerwise(&gpu, &c, false);
}

/// Fused forward (f32) and its fp16 variant against the twin; returns the fp16 error.
fn check_fused(gpu: &Gpu, c: &Case, f16_rel: f64) -> Option<f64> {
    let p64: Vec<f64> = c.params.iter().map(|&v| v as f64).collect();
    let want = twin::forward_f64(&c.lay, &p64, &c.xyz, c.twin_times()).out;
    let io = Io::new(gpu, c);
    let n = c.n as u32;
    let fused = MlpFused::new(gpu, &c.lay.cfg, Precision::F32).unwrap();
    let mut rec = Recorder::new(gpu).unwrap();
    fused.forward(
        &mut rec,
        n,
        io.xyz.all(),
        io.time(c),
        io.params.all(),
        io.out.all(),
    );
    rec.finish().unwrap();
    let got: Vec<f32> = gpu.read(io.out.elems::<f32>(0, c.n as u64 * 10)).unwrap();
    let label = format!("{:?} n={} fused f32", c.lay.cfg, c.n);
    assert_close(&label, &got, &want, 1e-5, 1e-7);
    if !(gpu.info.shader_float16 && gpu.info.storage_16bit) {
        dispflow_vk::testing::skip(
            "the fp16 MLP forward",
            &format!(
                "{} lacks shaderFloat16/storageBuffer16BitAccess",
                gpu.info.name
            ),
        );
        return None;
    }
    let f16 = MlpFused::new(gpu, &c.lay.cfg, Precision::F16).unwrap();
    let p16 = gpu
        .buffer("test params f16", f16.f16_params_bytes())
        .unwrap();
    testing::fill_noise(gpu, &io.out, 9);
    let mut rec = Recorder::new(gpu).unwrap();
    f16.convert_params(&mut rec, io.params.all(), p16.all());
    f16.forward(
        &mut rec,
        n,
        io.xyz.all(),
        io.time(c),
        p16.all(),
        io.out.all(),
    );
    rec.finish().unwrap();
    let got: Vec<f32> = gpu.read(io.out.elems::<f32>(0, c.n as u64 * 10)).unwrap();
    Some(assert_close(
        &format!("{label} → fp16"),
        &got,
        &want,
        f16_rel,
        0.0,
    ))
}

#[test]
fn fused_forward_matches_twin_and_fp16_error_is_bounded() {
    let gpu = testing::gpu();
    // fp16 storage: each stored activation/weight has relative error ≤ 2⁻¹¹ ≈ 4.9e-4; over 10
    // layers the normwise output error is expected around 1e-3 (measured 3e-4..6e-4),
    // asserted below 2e-3.
    for (k, (cfg, n)) in [
        (MlpConfig::synthetic(), 37usize),
        (MlpConfig::real(), 1),
        (MlpConfig::synthetic(), 1024),
        (MlpConfig::real(), 1024),
        (small(true), 4096),
        (small(false), 100),
        (small(false), 0),
    ]
    .into_iter()
    .enumerate()
    {
        let c = Case::new(cfg, n, 50 + k as u64, 1.5, k % 2 == 0);
        if let Some(e) = check_fused(&gpu, &c, 2e-3) {
            eprintln!(
                "fp16 vs f64 twin, {}x{} time_net={} n={n}: normwise {e:.2e}",
                cfg.depth,
                cfg.width,
                cfg.time_net()
            );
        }
    }
}

#[test]
fn fp16_stays_finite_at_extremes() {
    let gpu = testing::gpu();
    // Positions at ±1e4 enter the trunk raw: f16 keeps them (max 65504) with spacing 8, so the
    // error is large relative to the twin but the output stays finite (saturating stores).
    let c = Case::new(MlpConfig::synthetic(), 64, 61, 1e4, true);
    check_fused(&gpu, &c, 1.0);
}

#[test]
fn fused_rejects_too_wide_configs() {
    let gpu = testing::gpu();
    let cfg = MlpConfig {
        width: 512,
        ..MlpConfig::real()
    };
    let e = MlpFused::new(&gpu, &cfg, Precision::F32)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("width 512"), "{e}");
}

#[test]
fn capacity_beyond_the_storage_buffer_range_is_a_clear_error() {
    let gpu = testing::gpu();
    let mlp = Mlp::new(&gpu, &MlpConfig::synthetic()).unwrap();
    let too_many = (gpu.info.max_storage_buffer_range as u64 / (256 * 4) + 1).min(u32::MAX as u64);
    if too_many >= u32::MAX as u64 {
        eprintln!(
            "{}: storage-buffer range allows every u32 capacity; nothing to check",
            gpu.info.name
        );
        return;
    }
    let e = mlp
        .buffers(&gpu, too_many as u32)
        .err()
        .expect("capacity error")
        .to_string();
    assert!(
        e.contains("maxStorageBufferRange") && e.contains(&too_many.to_string()),
        "{e}"
    );
    assert!(mlp.buffers(&gpu, 1000).is_ok());
}

dispflow_vk::subgroup_reruns!();
