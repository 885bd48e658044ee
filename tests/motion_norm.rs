//! Magnitude normalisation (min-max, max-abs, z-score, IQR): the twin's backward pass against
//! central finite differences (f64), the GPU against the twin (forward values, statistics,
//! flag, backward), degenerate maps (flat, non-finite) and huge dynamic range.

use dispflow_vk::kernels::motion::{
    MotionNorm, NormBuffers, NormConfig, NormFlag, NormMagShape, NormMode, DEFAULT_EPS,
};
use dispflow_vk::kernels::shape::DeviceShape;
use dispflow_vk::reference::motion::{
    magnitudes, normalize_backward, normalize_f64, normalize_magnitudes, Normalized,
};
use dispflow_vk::testing::{self, max_abs, Noise, TestGpu};
use dispflow_vk::vk::Recorder;

/// The normalisation with each magnitude shape (tree, runs), whatever the device.
fn norms(gpu: &TestGpu) -> Vec<MotionNorm> {
    (NormMagShape::ALL.iter())
        .map(|&s| MotionNorm::with_shape(gpu, s).unwrap())
        .collect()
}

fn unit(r: &mut Noise) -> f64 {
    (r.next_u32() >> 8) as f64 / 16_777_216.0
}

/// Field components in [-1, 1).
fn field(seed: u64, n: usize) -> Vec<f64> {
    let mut r = Noise::new(seed);
    (0..n).map(|_| 2.0 * unit(&mut r) - 1.0).collect()
}

/// Smallest gap between distinct sorted magnitudes (FD must not reorder them).
fn min_gap(m: &[f64]) -> f64 {
    let mut s = m.to_vec();
    s.sort_by(f64::total_cmp);
    s.windows(2).map(|w| w[1] - w[0]).fold(f64::MAX, f64::min)
}

#[test]
fn twin_backward_matches_finite_differences() {
    let n = 7 * 5;
    for channels in [2usize, 3] {
        for mode in NormMode::ALL {
            // A seed whose magnitudes are well separated: no tie at min, max or a quantile
            // can be crossed by the ±h perturbation.
            let (v, seed) = (1..)
                .map(|s| (field(s * 31 + channels as u64, n * channels), s))
                .find(|(v, _)| {
                    min_gap(&dispflow_vk::reference::motion::magnitudes_f64(v, channels)) > 1e-4
                })
                .unwrap();
            let g: Vec<f64> = field(seed + 1000, n);
            let loss = |v: &[f64]| -> f64 {
                let r = normalize_f64(v, channels, mode, 1e-6);
                assert_eq!(r.stats.flag, NormFlag::Ok);
                r.m_hat.iter().zip(&g).map(|(a, b)| a * b).sum()
            };
            let fwd = normalize_f64(&v, channels, mode, 1e-6);
            let grad = normalize_backward(&v, channels, &fwd, mode, &g);
            let h = 1e-6;
            let scale = grad.iter().fold(0.0f64, |a, b| a.max(b.abs()));
            for i in 0..v.len() {
                let mut vp = v.clone();
                vp[i] += h;
                let mut vm = v.clone();
                vm[i] -= h;
                let fd = (loss(&vp) - loss(&vm)) / (2.0 * h);
                assert!(
                    (fd - grad[i]).abs() <= 1e-6 * scale.max(1.0),
                    "{} C={channels} component {i}: analytic {}, fd {fd}",
                    mode.name(),
                    grad[i]
                );
            }
            // The statistics really carry gradient: the plain g/d term alone differs from it.
            let plain: Vec<f64> = dispflow_vk::reference::motion::magnitude_backward(
                &v,
                channels,
                &g.iter().map(|x| x / fwd.stats.denom).collect::<Vec<_>>(),
            );
            let diff = plain
                .iter()
                .zip(&grad)
                .fold(0.0f64, |a, (p, q)| a.max((p - q).abs()));
            assert!(
                diff > 1e-3 * scale,
                "{}: statistics terms missing",
                mode.name()
            );
        }
    }
}

#[test]
fn twin_zero_vector_gets_zero_gradient() {
    let mut v = field(5, 20 * 3);
    v[9..12].fill(0.0); // pixel 3 is the argmin of min-max with m = 0
    let g = field(6, 20);
    for mode in NormMode::ALL {
        let fwd = normalize_f64(&v, 3, mode, 1e-6);
        let grad = normalize_backward(&v, 3, &fwd, mode, &g);
        assert!(grad.iter().all(|x| x.is_finite()));
        assert_eq!(&grad[9..12], &[0.0; 3], "{}", mode.name());
    }
}

struct GpuOut {
    m: Vec<f32>,
    m_hat: Vec<f32>,
    dv: Vec<f32>,
    flag: NormFlag,
    stats: dispflow_vk::kernels::motion::GpuNormStats,
}

/// Forward and backward on the GPU, every scratch and output pre-filled with noise.
#[allow(clippy::too_many_arguments)]
fn run_gpu(
    gpu: &TestGpu,
    norm: &MotionNorm,
    w: u32,
    h: u32,
    channels: u32,
    v: &[f32],
    g: &[f32],
    cfg: NormConfig,
) -> GpuOut {
    let mut b: NormBuffers = norm.buffers(gpu, w, h, channels).unwrap();
    for (i, buf) in b.all_buffers().into_iter().enumerate() {
        testing::fill_noise(gpu, buf, 100 + i as u64);
    }
    let vb = gpu.buffer_from("field", v).unwrap();
    let gb = gpu.buffer_from("d m_hat", g).unwrap();
    let dv = gpu.buffer("d field", v.len() as u64 * 4).unwrap();
    testing::fill_noise(gpu, &dv, 7);
    let mut rec = Recorder::new(gpu).unwrap();
    norm.record(&mut rec, &mut b, vb.all(), cfg);
    norm.record_backward(&mut rec, &b, vb.all(), gb.all(), dv.all());
    rec.finish().unwrap();
    GpuOut {
        m: gpu.read(b.m()).unwrap(),
        m_hat: gpu.read(b.m_hat()).unwrap(),
        dv: gpu.read(dv.elems::<f32>(0, v.len() as u64)).unwrap(),
        flag: b.flag(gpu).unwrap(),
        stats: b.read_stats(gpu).unwrap(),
    }
}

/// Compares one GPU run with the twin evaluated on the GPU's own magnitudes (one stage at a
/// time: the magnitude stage is compared separately, so a 1-ulp difference in |v| cannot
/// change which pixel is the argmin or a quantile).
fn check_against_twin(
    ctx: &str,
    out: &GpuOut,
    v: &[f32],
    g: &[f32],
    channels: usize,
    mode: NormMode,
    eps: f64,
) -> Normalized {
    let tm = magnitudes(v, channels);
    for (p, (a, b)) in out.m.iter().zip(&tm).enumerate() {
        assert!(
            (a - b).abs() <= 4.0 * f32::EPSILON * b.abs(),
            "{ctx}: m[{p}] gpu {a}, twin {b}"
        );
    }
    let m64: Vec<f64> = out.m.iter().map(|&x| x as f64).collect();
    let tw = normalize_magnitudes(&m64, mode, eps);
    assert_eq!(out.flag, tw.stats.flag, "{ctx}: flag");
    if tw.stats.flag == NormFlag::Ok {
        let s = &out.stats;
        assert_eq!(
            (s.argmin, s.argmax),
            (tw.stats.argmin as u32, tw.stats.argmax as u32),
            "{ctx}: argmin/argmax"
        );
        let rel = |a: f64, b: f64| (a - b).abs() <= 1e-5 * b.abs().max(1e-30 + tw.stats.max);
        assert!(
            rel(s.offset, tw.stats.offset),
            "{ctx}: offset {} vs {}",
            s.offset,
            tw.stats.offset
        );
        assert!(
            rel(s.denom, tw.stats.denom),
            "{ctx}: denom {} vs {}",
            s.denom,
            tw.stats.denom
        );
        if mode == NormMode::Iqr {
            for k in 0..3 {
                let q = tw.stats.quantiles[k];
                assert_eq!(
                    s.quantile_pixels[k],
                    [q.lo as u32, q.hi as u32],
                    "{ctx}: quantile {k} pixels"
                );
            }
        }
    }
    // Forward: |m̂| is O(1) (min-max, max-abs ∈ [0, 1]; z-score, IQR a few units); f32
    // rounding of u, offset and the quotient costs a few ulps of the larger operand.
    let mh_scale = max_abs(&tw.m_hat).max(1.0);
    for (p, (a, b)) in out.m_hat.iter().zip(&tw.m_hat).enumerate() {
        assert!(a.is_finite(), "{ctx}: m_hat[{p}] = {a}");
        assert!(
            (*a as f64 - b).abs() <= 2e-6 * mh_scale,
            "{ctx}: m_hat[{p}] gpu {a}, twin {b}"
        );
    }
    // Backward: the sums G = Σg and H = Σg·m̂ are f32 tree sums over all pixels, so the error
    // is relative to the gradient's scale (worst ≈ 1e-6 measured; 2e-5 leaves margin).
    let v64: Vec<f64> = v.iter().map(|&x| x as f64).collect();
    let g64: Vec<f64> = g.iter().map(|&x| x as f64).collect();
    let tdv = normalize_backward(&v64, channels, &tw, mode, &g64);
    let scale = max_abs(&tdv).max(1e-30);
    let mut worst = 0.0f64;
    for (i, (a, b)) in out.dv.iter().zip(&tdv).enumerate() {
        assert!(a.is_finite(), "{ctx}: dv[{i}] = {a}");
        let err = (*a as f64 - b).abs() / scale;
        worst = worst.max(err);
        assert!(
            err <= 2e-5,
            "{ctx}: dv[{i}] gpu {a}, twin {b} (scale {scale})"
        );
    }
    eprintln!("{ctx}: worst backward error {worst:.1e} of scale {scale:.2e}");
    tw
}

#[test]
fn gpu_matches_twin() {
    let gpu = testing::gpu();
    for norm in norms(&gpu) {
        gpu_matches_twin_with(&gpu, &norm);
    }
}

fn gpu_matches_twin_with(gpu: &TestGpu, norm: &MotionNorm) {
    let mut seed = 1;
    for (w, h) in [(1u32, 1u32), (17, 13), (64, 48)] {
        for channels in [2u32, 3] {
            for mode in NormMode::ALL {
                seed += 1;
                let n = (w * h) as usize;
                let v: Vec<f32> = field(seed, n * channels as usize)
                    .iter()
                    .map(|&x| x as f32)
                    .collect();
                let g: Vec<f32> = field(seed + 500, n).iter().map(|&x| x as f32).collect();
                let cfg = NormConfig {
                    mode,
                    eps: DEFAULT_EPS,
                    detach_stats: false,
                };
                let out = run_gpu(gpu, norm, w, h, channels, &v, &g, cfg);
                let ctx = format!(
                    "{w}x{h} C={channels} {} {}",
                    mode.name(),
                    norm.mag_shape().name()
                );
                let tw = check_against_twin(&ctx, &out, &v, &g, channels as usize, mode, 1e-6);
                if n == 1 && mode == NormMode::MaxAbs {
                    assert_eq!(
                        (out.flag, out.m_hat[0]),
                        (NormFlag::Ok, 1.0),
                        "{ctx}: m / max"
                    );
                } else if n == 1 {
                    assert_eq!(
                        out.flag,
                        NormFlag::Flat,
                        "{ctx}: a single pixel has no spread"
                    );
                    assert!(out.m_hat.iter().chain(&out.dv).all(|&x| x == 0.0));
                } else {
                    assert_eq!(tw.stats.flag, NormFlag::Ok, "{ctx}");
                }
                if mode == NormMode::MinMax && n > 1 {
                    let (lo, hi) = out
                        .m_hat
                        .iter()
                        .fold((1f32, 0f32), |(a, b), &x| (a.min(x), b.max(x)));
                    assert!(
                        lo == 0.0 && (hi - 1.0).abs() < 1e-6,
                        "{ctx}: range [{lo}, {hi}]"
                    );
                }
            }
        }
    }
}

#[test]
fn degenerate_maps_flag_and_zero() {
    let gpu = testing::gpu();
    for norm in norms(&gpu) {
        degenerate_maps_flag_and_zero_with(&gpu, &norm);
    }
}

fn degenerate_maps_flag_and_zero_with(gpu: &TestGpu, norm: &MotionNorm) {
    let (w, h) = (9u32, 7u32);
    let n = (w * h) as usize;
    let g: Vec<f32> = field(3, n).iter().map(|&x| x as f32).collect();
    let zero = vec![0.0f32; 2 * n];
    let constant: Vec<f32> = (0..n).flat_map(|_| [0.3f32, -0.4]).collect();
    let mut nan = field(4, 2 * n)
        .iter()
        .map(|&x| x as f32)
        .collect::<Vec<_>>();
    nan[17] = f32::NAN;
    let mut inf = nan.clone();
    inf[17] = f32::INFINITY;
    let mut overflow = inf.clone();
    overflow[16] = 3e38;
    overflow[17] = -3e38; // |v| = 4.2e38 overflows f32
                          // IQR of a map that is 0 on more than 3/4 of the pixels: q75 = q25 = 0.
    let mostly_zero: Vec<f32> = (0..2 * n)
        .map(|i| {
            if i < 2 * n / 5 {
                (i % 7) as f32 + 1.0
            } else {
                0.0
            }
        })
        .collect();
    // Differences the f32 map cannot resolve: 1000 ± a few ulps.
    let near_flat: Vec<f32> = (0..n)
        .flat_map(|i| [1000.0f32 + (i % 3) as f32 * 6.1e-5, 0.0])
        .collect();
    let cases: Vec<(&str, &[f32], NormMode, NormFlag)> = vec![
        ("zero", &zero, NormMode::MinMax, NormFlag::Flat),
        ("zero", &zero, NormMode::MaxAbs, NormFlag::Flat),
        ("zero", &zero, NormMode::ZScore, NormFlag::Flat),
        ("zero", &zero, NormMode::Iqr, NormFlag::Flat),
        ("constant", &constant, NormMode::MinMax, NormFlag::Flat),
        ("constant", &constant, NormMode::ZScore, NormFlag::Flat),
        ("constant", &constant, NormMode::Iqr, NormFlag::Flat),
        ("constant", &constant, NormMode::MaxAbs, NormFlag::Ok),
        ("nan", &nan, NormMode::MinMax, NormFlag::NonFinite),
        ("nan", &nan, NormMode::ZScore, NormFlag::NonFinite),
        ("inf", &inf, NormMode::MaxAbs, NormFlag::NonFinite),
        ("inf", &inf, NormMode::Iqr, NormFlag::NonFinite),
        ("overflow", &overflow, NormMode::MinMax, NormFlag::NonFinite),
        ("mostly zero", &mostly_zero, NormMode::Iqr, NormFlag::Flat),
        ("mostly zero", &mostly_zero, NormMode::MinMax, NormFlag::Ok),
        ("near flat", &near_flat, NormMode::MinMax, NormFlag::Flat),
        ("near flat", &near_flat, NormMode::ZScore, NormFlag::Flat),
    ];
    for (name, v, mode, want) in cases {
        let cfg = NormConfig {
            mode,
            eps: DEFAULT_EPS,
            detach_stats: false,
        };
        let out = run_gpu(gpu, norm, w, h, 2, v, &g, cfg);
        let ctx = format!("{name} {} {}", mode.name(), norm.mag_shape().name());
        assert_eq!(out.flag, want, "{ctx}");
        if want.is_degenerate() {
            assert!(out.m_hat.iter().all(|&x| x == 0.0), "{ctx}: m_hat not zero");
            assert!(out.dv.iter().all(|&x| x == 0.0), "{ctx}: gradient not zero");
        } else {
            assert!(
                out.m_hat.iter().chain(&out.dv).all(|x| x.is_finite()),
                "{ctx}"
            );
        }
        let tw = normalize_magnitudes(
            &out.m.iter().map(|&x| x as f64).collect::<Vec<_>>(),
            mode,
            DEFAULT_EPS as f64,
        );
        assert_eq!(tw.stats.flag, want, "{ctx}: twin flag");
    }
    // eps is absolute: a map of spread 1e-7 is flat at the default eps, normalised at eps = 0.
    let small: Vec<f32> = field(8, 2 * n).iter().map(|&x| (x * 1e-7) as f32).collect();
    for (eps, want) in [(DEFAULT_EPS, NormFlag::Flat), (0.0, NormFlag::Ok)] {
        let cfg = NormConfig::new(NormMode::MinMax, eps).unwrap();
        let out = run_gpu(gpu, norm, w, h, 2, &small, &g, cfg);
        assert_eq!(out.flag, want, "spread 1e-7 at eps {eps}");
        if want == NormFlag::Ok {
            check_against_twin("small", &out, &small, &g, 2, NormMode::MinMax, 0.0);
        }
    }
}

#[test]
fn huge_dynamic_range_is_finite() {
    let gpu = testing::gpu();
    for norm in norms(&gpu) {
        huge_dynamic_range_is_finite_with(&gpu, &norm);
    }
}

fn huge_dynamic_range_is_finite_with(gpu: &TestGpu, norm: &MotionNorm) {
    let (w, h) = (31u32, 17u32);
    let n = (w * h) as usize;
    let mut r = Noise::new(11);
    // Components log-uniform in [1e-30, 1e30] with random signs, some exact zero pixels, and
    // one pixel near the top of the f32 range.
    let mut v: Vec<f32> = (0..3 * n)
        .map(|_| {
            let e = -30.0 + 60.0 * unit(&mut r);
            let s = if r.next_u32() & 1 == 0 { 1.0 } else { -1.0 };
            (s * 10f64.powf(e)) as f32
        })
        .collect();
    for p in [0usize, 5, 77] {
        v[3 * p..3 * p + 3].fill(0.0);
    }
    let mut v_top = v.clone();
    v_top[3 * 10..3 * 10 + 3].copy_from_slice(&[1.5e38, -1.2e38, 0.9e38]);
    let g: Vec<f32> = field(12, n).iter().map(|&x| x as f32).collect();
    for (name, v) in [("1e±30", &v), ("near f32 max", &v_top)] {
        for mode in NormMode::ALL {
            let cfg = NormConfig {
                mode,
                eps: DEFAULT_EPS,
                detach_stats: false,
            };
            let out = run_gpu(gpu, norm, w, h, 3, v, &g, cfg);
            let ctx = format!("{name} {} {}", mode.name(), norm.mag_shape().name());
            assert_eq!(out.flag, NormFlag::Ok, "{ctx}");
            check_against_twin(&ctx, &out, v, &g, 3, mode, DEFAULT_EPS as f64);
            for p in [0usize, 5, 77] {
                assert_eq!(&out.dv[3 * p..3 * p + 3], &[0.0; 3], "{ctx}: |v| = 0");
            }
        }
    }
}

/// The magnitude pass's shapes write the same bits: m, the statistics (ties broken by the
/// first pixel), m̂ and the gradient, on maps whose magnitudes tie across workgroups and
/// across a lane's run, with partial last groups, a non-finite pixel and every mode.
#[test]
fn both_magnitude_shapes_write_the_same_bits() {
    let gpu = testing::gpu();
    let [tree, runs] = &norms(&gpu)[..] else {
        panic!("two shapes")
    };
    for (w, h) in [(17u32, 13u32), (33, 17), (64, 48)] {
        let n = (w * h) as usize;
        // Eight distinct magnitudes over every pixel: min and max tie hundreds of times.
        let ties: Vec<f32> = (0..n)
            .flat_map(|p| [((p * 7) % 8) as f32 * 0.125 + 0.5, 0.0])
            .collect();
        let noise: Vec<f32> = field(n as u64, 2 * n).iter().map(|&x| x as f32).collect();
        let mut nan = noise.clone();
        nan[2 * (n - 1)] = f32::NAN;
        let g: Vec<f32> = field(9, n).iter().map(|&x| x as f32).collect();
        for (name, v) in [("ties", &ties), ("noise", &noise), ("nan", &nan)] {
            for mode in NormMode::ALL {
                let cfg = NormConfig::new(mode, DEFAULT_EPS).unwrap();
                let a = run_gpu(&gpu, tree, w, h, 2, v, &g, cfg);
                let b = run_gpu(&gpu, runs, w, h, 2, v, &g, cfg);
                let ctx = format!("{w}x{h} {name} {}", mode.name());
                let bits = |x: &[f32]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&a.m), bits(&b.m), "{ctx}: m");
                assert_eq!(format!("{:?}", a.stats), format!("{:?}", b.stats), "{ctx}");
                assert_eq!(bits(&a.m_hat), bits(&b.m_hat), "{ctx}: m_hat");
                assert_eq!(bits(&a.dv), bits(&b.dv), "{ctx}: gradient");
                if name == "ties" && mode == NormMode::MinMax {
                    // The first pixel of the smallest and of the largest magnitude.
                    assert_eq!((a.stats.argmin, a.stats.argmax), (0, 1), "{ctx}");
                }
            }
        }
    }
}

#[test]
fn config_and_shapes_are_checked() {
    assert!(NormConfig::new(NormMode::Iqr, f32::NAN).is_err());
    assert!(NormConfig::new(NormMode::Iqr, -1.0).is_err());
    assert_eq!("z-score".parse::<NormMode>().unwrap(), NormMode::ZScore);
    assert!("l2".parse::<NormMode>().is_err());
    let gpu = testing::gpu();
    let norm = MotionNorm::new(&gpu).unwrap();
    assert!(norm.buffers(&gpu, 4, 4, 4).is_err(), "4 channels");
    assert!(norm.buffers(&gpu, 0, 4, 2).is_err(), "empty image");
}

#[test]
fn detached_statistics_twin_matches_finite_differences_with_frozen_stats() {
    // With `detach_stats` the statistics are constants of the backward pass: the gradient is
    // that of m̂ = (|v| − o)/d with o, d frozen at the forward's values.
    use dispflow_vk::reference::motion::{magnitude_backward, norm_backward_detached};
    let (n, channels) = (6 * 5, 3usize);
    let v = field(41, n * channels);
    let g = field(42, n);
    for mode in NormMode::ALL {
        let fwd = normalize_f64(&v, channels, mode, 1e-6);
        let (o, d) = (fwd.stats.offset, fwd.stats.denom);
        let loss = |v: &[f64]| -> f64 {
            let m = dispflow_vk::reference::motion::magnitudes_f64(v, channels);
            m.iter().zip(&g).map(|(m, g)| (m - o) / d * g).sum()
        };
        let grad = magnitude_backward(&v, channels, &norm_backward_detached(&fwd, &g));
        let scale = max_abs(&grad).max(1.0);
        let h = 1e-6;
        for i in 0..v.len() {
            let (mut vp, mut vm) = (v.clone(), v.clone());
            vp[i] += h;
            vm[i] -= h;
            let fd = (loss(&vp) - loss(&vm)) / (2.0 * h);
            assert!(
                (fd - grad[i]).abs() <= 1e-6 * scale,
                "{} component {i}: analytic {}, fd {fd}",
                mode.name(),
                grad[i]
            );
        }
    }
}

#[test]
fn detached_statistics_gpu_matches_twin() {
    use dispflow_vk::reference::motion::{magnitude_backward, norm_backward_detached};
    let gpu = testing::gpu();
    let norm = MotionNorm::new(&gpu).unwrap();
    let (w, h) = (37u32, 29u32);
    for channels in [2u32, 3] {
        for mode in NormMode::ALL {
            let n = (w * h) as usize;
            let v: Vec<f32> = field(70 + channels as u64, n * channels as usize)
                .iter()
                .map(|&x| x as f32)
                .collect();
            let g: Vec<f32> = field(80, n).iter().map(|&x| x as f32).collect();
            let cfg = NormConfig {
                mode,
                eps: DEFAULT_EPS,
                detach_stats: true,
            };
            let out = run_gpu(&gpu, &norm, w, h, channels, &v, &g, cfg);
            let m64: Vec<f64> = out.m.iter().map(|&x| x as f64).collect();
            let tw = normalize_magnitudes(&m64, mode, 1e-6);
            let v64: Vec<f64> = v.iter().map(|&x| x as f64).collect();
            let g64: Vec<f64> = g.iter().map(|&x| x as f64).collect();
            let tdv =
                magnitude_backward(&v64, channels as usize, &norm_backward_detached(&tw, &g64));
            let scale = max_abs(&tdv);
            assert!(scale > 0.0);
            for (i, (a, b)) in out.dv.iter().zip(&tdv).enumerate() {
                assert!(
                    (*a as f64 - b).abs() <= 1e-5 * scale,
                    "C={channels} {}: dv[{i}] gpu {a}, twin {b}",
                    mode.name()
                );
            }
            // Unlike the full backward, no pixel gets the image-wide sum: the argmax pixel's
            // gradient is its own g/d.
            if mode == NormMode::MinMax {
                let p = out.stats.argmax as usize;
                let c = channels as usize;
                let here = (0..c).map(|k| tdv[p * c + k].powi(2)).sum::<f64>().sqrt();
                assert!(here <= (g64[p] / tw.stats.denom).abs() * (1.0 + 1e-9) + 1e-12);
            }
        }
    }
}

dispflow_vk::subgroup_reruns!();
