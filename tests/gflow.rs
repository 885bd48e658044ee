//! Gaussian flow (GaussianFlow / MotionGS) stages vs their twin: the six per-Gaussian channels
//! and their backward to both projections' 2D gradient records, with the extremes (culled at
//! either time, singular and indefinite Σ2D, NaN conics, needles, far-off means); the twin's
//! backward against central finite differences in f64; the vector L1 and its gradient against
//! the twin and finite differences, including the degenerate-scene skip; and what the
//! channels mean (a translated Gaussian flows by its translation, a scaled one by its scale).

use dispflow_vk::kernels::gflow::{GFlowLossIo, GaussianFlow};
use dispflow_vk::kernels::raster::G2D_STRIDE;
use dispflow_vk::reference::gflow as twin;
use dispflow_vk::testing::{self, Noise};
use dispflow_vk::vk::Recorder;

/// A splat record with mean `mu`, a random 2D covariance (σ in [0.7, 6] px, any angle) plus
/// the rasteriser's 0.3 dilation, as its conic, radius 3.
fn record(r: &mut Noise, mu: [f64; 2]) -> [[f32; 4]; 3] {
    let (s1, s2) = (
        0.7 + 5.3 * r.uniform(0.0f64, 1.0),
        0.7 + 5.3 * r.uniform(0.0f64, 1.0),
    );
    let th = std::f64::consts::PI * r.uniform(0.0f64, 1.0);
    let (c, s) = (th.cos(), th.sin());
    let (a, b, d) = (
        c * c * s1 * s1 + s * s * s2 * s2 + 0.3,
        c * s * (s1 * s1 - s2 * s2),
        s * s * s1 * s1 + c * c * s2 * s2 + 0.3,
    );
    let det = a * d - b * b;
    let q = [d / det, -b / det, a / det];
    [
        [mu[0] as f32, mu[1] as f32, 2.0, 0.8],
        [q[0] as f32, q[1] as f32, q[2] as f32, 3.0],
        [0.5, 0.5, 0.5, 0.0],
    ]
}

/// `n` Gaussians at t1 and t2 (t2 moved, rotated and rescaled), every 7th one an extreme.
fn scene(n: usize, seed: u64, extremes: bool) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    let mut r = Noise::new(seed);
    let (mut s1, mut s2) = (Vec::new(), Vec::new());
    for i in 0..n {
        let mu = [64.0 * r.uniform(0.0f64, 1.0), 48.0 * r.uniform(0.0f64, 1.0)];
        let mu2 = [
            mu[0] + 6.0 * r.uniform(0.0f64, 1.0) - 3.0,
            mu[1] + 6.0 * r.uniform(0.0f64, 1.0) - 3.0,
        ];
        let (mut a, mut b) = (record(&mut r, mu), record(&mut r, mu2));
        if extremes {
            match i % 7 {
                1 => a[1][3] = 0.0,                              // culled at t1
                2 => b[1][3] = 0.0,                              // behind the camera at t2
                3 => b[1] = [1.0, 1.0, 1.0, 3.0],                // singular conic (det 0)
                4 => a[1] = [1.0, 2.0, 1.0, 3.0],                // indefinite
                5 => b[1][1] = f32::NAN,                         // not a number
                6 if i % 2 == 0 => b[1] = [1e4, 0.0, 1e-6, 3.0], // a needle
                6 => {
                    a[0][0] = 1e7; // far off screen
                    b[0][0] = 1e7 + 1.0;
                }
                _ => {}
            }
        }
        s1.extend(a);
        s2.extend(b);
    }
    (s1, s2)
}

fn rand_vec(r: &mut Noise, n: usize, scale: f64) -> Vec<f32> {
    (0..n)
        .map(|_| ((r.uniform(0.0f64, 1.0) - 0.5) * 2.0 * scale) as f32)
        .collect()
}

#[test]
fn features_and_backward_match_twin_with_extremes() {
    let gpu = testing::gpu();
    let k = GaussianFlow::new(&gpu).unwrap();
    let n = 1001;
    let (s1, s2) = scene(n, 1, true);
    let mut r = Noise::new(2);
    let d_feat = rand_vec(&mut r, 6 * n, 1.0);
    let s = G2D_STRIDE as usize;
    let (g1_init, g2_init) = (rand_vec(&mut r, s * n, 1.0), rand_vec(&mut r, s * n, 1.0));
    let b4 = |v: &[[f32; 4]]| gpu.buffer_from("splats", v).unwrap();
    let bf = |v: &[f32]| gpu.buffer_from("floats", v).unwrap();
    let (b1, b2, bd) = (b4(&s1), b4(&s2), bf(&d_feat));
    let (g1, g2) = (bf(&g1_init), bf(&g2_init));
    let feat = gpu.buffer("feat", 24 * n as u64).unwrap();
    testing::fill_noise(&gpu, &feat, 3);
    let mut rec = Recorder::new(&gpu).unwrap();
    k.features(&mut rec, n as u32, b1.all(), b2.all(), feat.all());
    k.features_bwd(
        &mut rec,
        n as u32,
        [b1.all(), b2.all()],
        bd.all(),
        [g1.all(), g2.all()],
    );
    rec.finish().unwrap();

    let (w1, w2) = (twin::widen(&s1), twin::widen(&s2));
    let want = twin::features(&w1, &w2);
    let got: Vec<f32> = gpu.read(feat.all()).unwrap();
    let mut valid = 0;
    for i in 0..n {
        let w = &want[6 * i..6 * i + 6];
        let g = &got[6 * i..6 * i + 6];
        if w.iter().any(|v| *v != 0.0) {
            valid += 1;
        }
        // Scale of the channels: |A| for G, |A|·|μ1| + |μ2| for b (its cancellation).
        let a_norm = 1.0 + w[..4].iter().map(|v| v.abs()).sum::<f64>();
        let mu = w1[3 * i][0].abs() + w1[3 * i][1].abs() + w2[3 * i][0].abs() + w2[3 * i][1].abs();
        for c in 0..6 {
            let scale = if c < 4 { a_norm } else { a_norm * (1.0 + mu) };
            assert!(g[c].is_finite(), "Gaussian {i} channel {c}: {}", g[c]);
            assert!(
                (g[c] as f64 - w[c]).abs() <= 2e-5 * scale,
                "Gaussian {i} channel {c}: gpu {} twin {} (scale {scale:.3e})",
                g[c],
                w[c]
            );
        }
    }
    let extremes_zero = (0..n).filter(|i| (1..=5).contains(&(i % 7))).all(|i| {
        want[6 * i..6 * i + 6].iter().all(|v| *v == 0.0)
            && got[6 * i..6 * i + 6].iter().all(|v| *v == 0.0)
    });
    assert!(
        extremes_zero,
        "culled, singular, indefinite and NaN Gaussians give zeros"
    );
    // Every ordinary Gaussian, needle and far-off one has a map (2 of every 7).
    let ordinary = (0..n).filter(|i| i % 7 == 0 || i % 7 == 6).count();
    assert_eq!(valid, ordinary, "Gaussians with a map");

    let dw: Vec<f64> = d_feat.iter().map(|&v| v as f64).collect();
    let (t1, t2) = twin::features_bwd(&w1, &w2, &dw);
    for (name, buf, init, tw) in [("t1", &g1, &g1_init, &t1), ("t2", &g2, &g2_init, &t2)] {
        let got: Vec<f32> = gpu.read(buf.all()).unwrap();
        let scale = tw
            .iter()
            .map(|r| r.iter().fold(0.0f64, |m, v| m.max(v.abs())))
            .collect::<Vec<_>>();
        for i in 0..n {
            for c in 0..s {
                let want = init[s * i + c] as f64 + if c < 5 { tw[i][c] } else { 0.0 };
                let g = got[s * i + c] as f64;
                assert!(g.is_finite(), "{name} Gaussian {i} word {c}: {g}");
                assert!(
                    (g - want).abs() <= 1e-4 * (1.0 + scale[i]) + 1e-6 * want.abs(),
                    "{name} Gaussian {i} word {c}: gpu {g} want {want} (|grad| {:.3e})",
                    scale[i]
                );
            }
        }
    }
}

/// Σ d_feat · features over the records (f64): the scalar the backward differentiates.
fn dot(s1: &[[f64; 4]], s2: &[[f64; 4]], d: &[f64]) -> f64 {
    twin::features(s1, s2)
        .iter()
        .zip(d)
        .map(|(a, b)| a * b)
        .sum()
}

#[test]
fn twin_backward_matches_finite_differences() {
    let n = 40;
    let (s1, s2) = scene(n, 5, false);
    let (mut w1, mut w2) = (twin::widen(&s1), twin::widen(&s2));
    let mut r = Noise::new(6);
    let d: Vec<f64> = (0..6 * n).map(|_| r.uniform(0.0f64, 1.0) - 0.5).collect();
    let (g1, g2) = twin::features_bwd(&w1, &w2, &d);
    // (record, row, column) of each differentiated input: μ (row 0, x/y), conic (row 1, a/b/c).
    let slots = [(0, 0), (0, 1), (1, 0), (1, 1), (1, 2)];
    let mut worst = 0.0f64;
    for i in 0..n {
        for (k, &(row, col)) in slots.iter().enumerate() {
            for t in 0..2 {
                let w = if t == 0 { &mut w1 } else { &mut w2 };
                let x = w[3 * i + row][col];
                let h = 1e-6 * (1.0 + x.abs());
                w[3 * i + row][col] = x + h;
                let up = dot(&w1, &w2, &d);
                let w = if t == 0 { &mut w1 } else { &mut w2 };
                w[3 * i + row][col] = x - h;
                let down = dot(&w1, &w2, &d);
                let w = if t == 0 { &mut w1 } else { &mut w2 };
                w[3 * i + row][col] = x;
                let fd = (up - down) / (2.0 * h);
                let an = if t == 0 { g1[i][k] } else { g2[i][k] };
                let err = (fd - an).abs() / (1.0 + an.abs());
                worst = worst.max(err);
                assert!(
                    err < 1e-5,
                    "Gaussian {i} time {t} input {k}: analytic {an} finite difference {fd}"
                );
            }
        }
    }
    eprintln!("worst relative FD error {worst:.2e}");
}

#[test]
fn channels_mean_translation_and_scale() {
    let mut r = Noise::new(8);
    let a = record(&mut r, [20.0, 10.0]);
    // Moved by (3, −2), same shape: A = I, b = Δμ, so F(p) = Δμ at every pixel.
    let mut b = a;
    b[0][0] += 3.0;
    b[0][1] -= 2.0;
    let f = twin::features(&twin::widen(&a), &twin::widen(&b));
    let want = [0.0, 0.0, 0.0, 0.0, 3.0, -2.0];
    for c in 0..6 {
        assert!(
            (f[c] - want[c]).abs() < 1e-5,
            "translation: channel {c} = {}",
            f[c]
        );
    }
    // Twice the size about the same mean: Σ2 = 4·Σ1, A = 2·I, F(p) = p − μ.
    let mut b = a;
    for c in 0..3 {
        b[1][c] = a[1][c] / 4.0;
    }
    let f = twin::features(&twin::widen(&a), &twin::widen(&b));
    for p in [[20.5f64, 10.5], [0.5, 0.5], [40.5, 3.5]] {
        let fx = f[0] * p[0] + f[1] * p[1] + f[4];
        let fy = f[2] * p[0] + f[3] * p[1] + f[5];
        let (ex, ey) = (p[0] - 20.0, p[1] - 10.0);
        assert!(
            (fx - ex).abs() < 1e-4 && (fy - ey).abs() < 1e-4,
            "scale: F({p:?}) = ({fx}, {fy}), want ({ex}, {ey})"
        );
    }
}

/// Statistics words as `MotionNorm` writes them: flag, exponent e, offset, denominator (u
/// domain); the L1's scale is denom·2^e.
fn stats(flag: u32, exp: i32, denom: f32) -> Vec<u32> {
    let mut w = vec![0u32; 19];
    w[0] = flag;
    w[1] = exp as u32;
    w[3] = denom.to_bits();
    w
}

#[test]
fn l1_matches_twin_and_finite_differences() {
    let gpu = testing::gpu();
    let k = GaussianFlow::new(&gpu).unwrap();
    let (w, h) = (67usize, 45usize);
    let px = w * h;
    let mut r = Noise::new(11);
    let feat: Vec<f32> = (0..px)
        .flat_map(|_| {
            let g = rand_vec(&mut r, 4, 0.05);
            let b = rand_vec(&mut r, 2, 3.0);
            [g[0], g[1], g[2], g[3], b[0], b[1]]
        })
        .collect();
    let scene: Vec<[f32; 2]> = rand_vec(&mut r, 2 * px, 4.0)
        .chunks(2)
        .map(|c| [c[0], c[1]])
        .collect();
    let conf: Vec<f32> = (0..px).map(|_| r.uniform(0.0f64, 1.0) as f32).collect();
    let fb = gpu.buffer_from("feat", &feat).unwrap();
    let sb = gpu.buffer_from("scene", &scene).unwrap();
    let cb = gpu.buffer_from("conf", &conf).unwrap();
    let d = gpu.buffer("d feat", 24 * px as u64).unwrap();
    let sums = gpu.buffer("sums", 4 * px.div_ceil(256) as u64).unwrap();
    let fw: Vec<f64> = feat.iter().map(|&v| v as f64).collect();
    let sw: Vec<[f64; 2]> = scene.iter().map(|v| [v[0] as f64, v[1] as f64]).collect();
    let cw: Vec<f64> = conf.iter().map(|&v| v as f64).collect();
    let weight = 0.3;
    // (flag, exponent, denominator, confidence, skipped)
    for (flag, e, den, with_conf, skip) in [
        (0, 3, 0.75f32, false, false),
        (0, -2, 0.6, true, false),
        (1, 3, 0.75, false, true),
        (0, 0, 0.0, true, true),
    ] {
        let st = gpu.buffer_from("stats", &stats(flag, e, den)).unwrap();
        testing::fill_noise(&gpu, &d, 12);
        let mut rec = Recorder::new(&gpu).unwrap();
        let io = GFlowLossIo {
            feat: fb.all(),
            scene: sb.all(),
            stats: st.all(),
            d_feat: d.all(),
            sums: sums.all(),
            conf: with_conf.then(|| cb.all()),
        };
        k.l1(&mut rec, px as u32, w as u32, weight, &io);
        rec.finish().unwrap();
        let scale = den as f64 * 2f64.powi(e);
        let c = with_conf.then_some(&cw[..]);
        let (val, grad) = twin::l1(&fw, &sw, c, w, scale, weight as f64, skip);
        let got_sum: f64 = gpu
            .read::<f32>(sums.all())
            .unwrap()
            .iter()
            .map(|&v| v as f64)
            .sum();
        let got_val = got_sum / px as f64;
        assert!(
            (got_val - val).abs() <= 1e-5 * (1.0 + val),
            "flag {flag} e {e}: value gpu {got_val} twin {val}"
        );
        let got: Vec<f32> = gpu.read(d.all()).unwrap();
        for (i, (g, t)) in got.iter().zip(&grad).enumerate() {
            assert!(
                (*g as f64 - t).abs() <= 1e-5 * t.abs() + 1e-12,
                "flag {flag} e {e}: d_feat[{i}] gpu {g} twin {t}"
            );
        }
        if skip {
            assert!(val == 0.0 && got.iter().all(|&g| g == 0.0), "skipped");
            continue;
        }
        // The twin's gradient against central differences, away from the L1's kinks.
        for p in (0..px).step_by(97) {
            let f = twin::compose(&fw, p, w);
            let e = [0, 1].map(|k| (f[k] - sw[p][k]) / scale);
            if e.iter().any(|v| v.abs() < 1e-3) {
                continue;
            }
            for ch in 0..6 {
                let mut fp = fw.clone();
                let hh = 1e-6;
                fp[6 * p + ch] += hh;
                let up = twin::l1(&fp, &sw, c, w, scale, weight as f64, false).0;
                fp[6 * p + ch] -= 2.0 * hh;
                let down = twin::l1(&fp, &sw, c, w, scale, weight as f64, false).0;
                let fd = weight as f64 * (up - down) / (2.0 * hh);
                let an = grad[6 * p + ch];
                assert!(
                    (fd - an).abs() <= 1e-6 * (1.0 + an.abs()) + 1e-9,
                    "pixel {p} channel {ch}: analytic {an} finite difference {fd}"
                );
            }
        }
    }
}

dispflow_vk::subgroup_reruns!();
