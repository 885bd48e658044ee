//! The MLP's CPU twin against central finite differences (f64 throughout), and its encoding
//! and shapes against hand-computed values.

use dispflow_vk::model::deform::{MlpConfig, MlpLayout, TimeEncoding};
use dispflow_vk::reference::mlp::{self, Times};
use dispflow_vk::testing::Noise;

/// Loss `Σ d_out · out` for parameters `p`.
fn loss(lay: &MlpLayout, p: &[f64], xyz: &[f32], t: Times<'_>, d_out: &[f32]) -> f64 {
    let a = mlp::forward_f64(lay, p, xyz, t);
    a.out.iter().zip(d_out).map(|(o, d)| o * *d as f64).sum()
}

/// Checks `idx` parameters of the twin's backward against central differences. The step 1e-6
/// gives an f64 truncation error ~1e-12·|f'''| and rounding ~1e-16/1e-6; a ReLU kink inside
/// ±1e-6 of a pre-activation would show as a large error (probability ~1e-5 per case).
fn check_fd(cfg: MlpConfig, n: usize, seed: u64, idx: Option<Vec<usize>>) {
    let lay = MlpLayout::new(&cfg).unwrap();
    let p: Vec<f64> = lay.init_params(seed).iter().map(|&v| v as f64).collect();
    let mut noise = Noise::new(seed);
    let xyz: Vec<f32> = (0..3 * n).map(|_| noise.uniform(-1.5, 1.5)).collect();
    let ts: Vec<f32> = (0..n).map(|_| noise.uniform(0.0, 1.0)).collect();
    let d_out: Vec<f32> = (0..10 * n).map(|_| noise.uniform(-1.0, 1.0)).collect();
    let t = Times::PerGaussian(&ts);
    let a = mlp::forward_f64(&lay, &p, &xyz, t);
    let g = mlp::backward(&lay, &p, &a, &d_out);
    let idx = idx.unwrap_or_else(|| {
        lay.linears
            .iter()
            .flat_map(|l| {
                (l.w_off..l.w_off + l.fan_in * l.fan_out).chain(l.b_off..l.b_off + l.fan_out)
            })
            .collect()
    });
    let h = 1e-6;
    let mut worst = 0.0f64;
    let gmax = g.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    for &i in &idx {
        let mut pp = p.clone();
        pp[i] += h;
        let lp = loss(&lay, &pp, &xyz, t, &d_out);
        pp[i] -= 2.0 * h;
        let lm = loss(&lay, &pp, &xyz, t, &d_out);
        let fd = (lp - lm) / (2.0 * h);
        let err = (fd - g[i]).abs() / (1e-3 * gmax + g[i].abs().max(fd.abs()));
        worst = worst.max(err);
        assert!(
            (fd - g[i]).abs() <= 1e-6 * gmax + 1e-5 * fd.abs(),
            "param {i}: backward {} vs finite difference {fd}",
            g[i]
        );
    }
    // Padding between tensors has no gradient.
    let used: std::collections::HashSet<usize> = lay
        .linears
        .iter()
        .flat_map(|l| (l.w_off..l.w_off + l.fan_in * l.fan_out).chain(l.b_off..l.b_off + l.fan_out))
        .collect();
    assert!(g
        .iter()
        .enumerate()
        .all(|(i, v)| used.contains(&i) || *v == 0.0));
    assert!(gmax > 0.0);
    eprintln!(
        "{cfg:?}: {} params checked, worst scaled error {worst:.2e}",
        idx.len()
    );
}

fn small(time: TimeEncoding, skip: Option<u32>) -> MlpConfig {
    MlpConfig {
        depth: 4,
        width: 12,
        skip,
        x_freqs: 3,
        time,
    }
}

#[test]
fn backward_matches_finite_differences_small_all_params() {
    let tn = TimeEncoding::TimeNet {
        freqs: 2,
        hidden: 9,
        out: 5,
    };
    check_fd(small(tn, Some(1)), 6, 1, None);
    check_fd(
        small(TimeEncoding::Direct { freqs: 4 }, Some(2)),
        6,
        2,
        None,
    );
    check_fd(small(TimeEncoding::Direct { freqs: 2 }, None), 5, 3, None);
}

#[test]
fn backward_matches_finite_differences_presets_sampled() {
    for (k, cfg) in [MlpConfig::synthetic(), MlpConfig::real()]
        .into_iter()
        .enumerate()
    {
        let lay = MlpLayout::new(&cfg).unwrap();
        let mut noise = Noise::new(40 + k as u64);
        // A few parameters from every tensor (weights and biases).
        let idx: Vec<usize> = lay
            .linears
            .iter()
            .flat_map(|l| {
                let mut v: Vec<usize> = (0..3)
                    .map(|_| l.w_off + (noise.next_u32() as usize) % (l.fan_in * l.fan_out))
                    .collect();
                v.push(l.b_off + (noise.next_u32() as usize) % l.fan_out);
                v
            })
            .collect();
        check_fd(cfg, 3, 10 + k as u64, Some(idx));
    }
}

#[test]
fn encoding_layout_is_nerf_embedder() {
    let mut e = Vec::new();
    mlp::encode_x(&[0.5, -1.0, 2.0], 2, &mut e);
    let want = [
        0.5,
        -1.0,
        2.0,
        0.5f64.sin(),
        (-1.0f64).sin(),
        2.0f64.sin(),
        0.5f64.cos(),
        (-1.0f64).cos(),
        2.0f64.cos(),
        1.0f64.sin(),
        (-2.0f64).sin(),
        4.0f64.sin(),
        1.0f64.cos(),
        (-2.0f64).cos(),
        4.0f64.cos(),
    ];
    assert_eq!(e, want);
    let mut t = Vec::new();
    mlp::encode_scalar(0.25, 3, &mut t);
    assert_eq!(t.len(), 7);
    assert_eq!(t[5], 1.0f64.sin());
}

#[test]
fn forward_is_finite_at_extremes() {
    let lay = MlpLayout::new(&MlpConfig::synthetic()).unwrap();
    let p = lay.init_params(3);
    let xyz = [1e4f32, -1e4, 0.0, -1e4, 1e4, 1e4];
    let out = mlp::forward(&lay, &p, &xyz, Times::PerGaussian(&[-3.0, 7.5]));
    assert_eq!(out.len(), 20);
    assert!(out.iter().all(|v| v.is_finite()));
    assert!(mlp::forward(&lay, &p, &[], Times::Batch(0.5)).is_empty());
}

#[test]
fn f16_rounding_saturates_and_ties_to_even() {
    use mlp::to_f16;
    assert_eq!(to_f16(65504.0), 65504.0);
    assert_eq!(to_f16(65519.0), 65504.0);
    assert_eq!(to_f16(1e5), 65504.0, "saturates instead of overflowing");
    assert_eq!(to_f16(-f64::INFINITY), -65504.0);
    assert_eq!(to_f16(1.0 + 2f64.powi(-11)), 1.0, "tie to even");
    assert_eq!(
        to_f16(1.0 + 3.0 * 2f64.powi(-11)),
        1.0 + 2f64.powi(-9),
        "tie to even"
    );
    assert_eq!(to_f16(1000.3), 1000.5, "spacing 0.5 in [512, 1024)");
    assert_eq!(to_f16(2f64.powi(-24)), 2f64.powi(-24), "smallest subnormal");
    assert_eq!(to_f16(2f64.powi(-25)), 0.0, "tie to even (0)");
    assert_eq!(to_f16(3.0 * 2f64.powi(-25)), 2f64.powi(-23));
    assert_eq!(to_f16(-0.1), -0.0999755859375);
    assert!(to_f16(f64::NAN).is_nan());
}
