//! CPU twin of the deformation MLP (`glsl/mlp/*.comp`, `kernels::mlp`): positional encoding,
//! forward, and backward to every weight and bias. Plain loops over Gaussians (rayon), f64
//! inside. Activations are kept the way the layer-wise GPU path stores them, so the backward can
//! be fed the GPU's own stored forward (one stage at a time, identical ReLU masks).

use rayon::prelude::*;

use crate::model::deform::{LinearSpec, MlpLayout, OUT_DIMS};

/// Time input: one value for the batch, or one per Gaussian (time noise).
#[derive(Clone, Copy, Debug)]
pub enum Times<'a> {
    Batch(f32),
    PerGaussian(&'a [f32]),
}

impl Times<'_> {
    pub fn at(&self, i: usize) -> f32 {
        match self {
            Times::Batch(t) => *t,
            Times::PerGaussian(t) => t[i],
        }
    }
}

/// γ(v) appended to `out`: `[v, sin(2^0 v), cos(2^0 v), …, sin(2^(L−1) v), cos(2^(L−1) v)]`
/// for one scalar component. The GPU interleaves the three components of x exactly as NeRF's
/// embedder does (see [`encode_x`]).
pub fn encode_scalar(v: f64, freqs: u32, out: &mut Vec<f64>) {
    out.push(v);
    for j in 0..freqs {
        let a = v * (1u64 << j) as f64;
        out.push(a.sin());
        out.push(a.cos());
    }
}

/// NeRF embedder for a vector: `[v, sin(v), cos(v), sin(2v), cos(2v), …]`, each function applied
/// to the whole vector (so x gives `x0 x1 x2 sin(x0) sin(x1) sin(x2) cos(x0) …`).
pub fn encode_x(v: &[f64], freqs: u32, out: &mut Vec<f64>) {
    out.extend_from_slice(v);
    for j in 0..freqs {
        let s = (1u64 << j) as f64;
        out.extend(v.iter().map(|x| (x * s).sin()));
        out.extend(v.iter().map(|x| (x * s).cos()));
    }
}

/// Everything the forward pass stores, per Gaussian, row-major.
#[derive(Clone, Debug, Default)]
pub struct Activations {
    pub n: usize,
    /// `[N][in_dims]`: γ(x) then time features.
    pub x0: Vec<f64>,
    /// `[N][t_enc_dims]`: γ(t) (time net only; empty otherwise).
    pub enc_t: Vec<f64>,
    /// `[N][hidden]`: the time net's hidden ReLU layer (time net only).
    pub ht: Vec<f64>,
    /// `[depth][N][width]`: post-ReLU trunk activations.
    pub h: Vec<Vec<f64>>,
    /// `[N][10]`: dx, dr, ds.
    pub out: Vec<f64>,
}

fn linear(l: &LinearSpec, p: &[f64], input: &[f64], relu: bool, out: &mut [f64]) {
    debug_assert_eq!(input.len(), l.fan_in);
    for (o, y) in out.iter_mut().enumerate() {
        let row = &p[l.w_off + o * l.fan_in..l.w_off + (o + 1) * l.fan_in];
        let mut acc = p[l.b_off + o];
        for (w, x) in row.iter().zip(input) {
            acc += w * x;
        }
        *y = if relu { acc.max(0.0) } else { acc };
    }
}

struct Row {
    x0: Vec<f64>,
    enc_t: Vec<f64>,
    ht: Vec<f64>,
    h: Vec<Vec<f64>>,
    out: Vec<f64>,
}

/// `store` is applied to every value the network keeps between layers (the encoding, hidden
/// activations, time features; not the output): the identity for the f64 twin, f16 rounding
/// for the fp16 one.
fn forward_row(
    lay: &MlpLayout,
    p: &[f64],
    x: [f32; 3],
    t: f32,
    store: impl Fn(f64) -> f64 + Copy,
) -> Row {
    let cfg = &lay.cfg;
    let keep = |v: &mut Vec<f64>| v.iter_mut().for_each(|a| *a = store(*a));
    let mut x0 = Vec::with_capacity(cfg.in_dims());
    encode_x(&x.map(f64::from), cfg.x_freqs, &mut x0);
    keep(&mut x0);
    let mut enc_t = Vec::new();
    encode_scalar(t as f64, cfg.t_freqs(), &mut enc_t);
    keep(&mut enc_t);
    let mut ht = Vec::new();
    if cfg.time_net() {
        let tn = lay.time_net();
        ht = vec![0.0; tn[0].fan_out];
        linear(&tn[0], p, &enc_t, true, &mut ht);
        keep(&mut ht);
        let mut tf = vec![0.0; tn[1].fan_out];
        linear(&tn[1], p, &ht, false, &mut tf);
        keep(&mut tf);
        x0.extend_from_slice(&tf);
    } else {
        x0.extend_from_slice(&enc_t);
        enc_t.clear();
    }
    let w = cfg.width as usize;
    let mut h: Vec<Vec<f64>> = Vec::with_capacity(cfg.depth as usize);
    let mut cat = Vec::new();
    for (i, l) in lay.trunk().iter().enumerate() {
        let input: &[f64] = if i == 0 {
            &x0
        } else if cfg.skip.map(|s| s as usize + 1) == Some(i) {
            cat.clear();
            cat.extend_from_slice(&x0);
            cat.extend_from_slice(&h[i - 1]);
            &cat
        } else {
            &h[i - 1]
        };
        let mut y = vec![0.0; w];
        linear(l, p, input, true, &mut y);
        keep(&mut y);
        h.push(y);
    }
    let mut out = vec![0.0; OUT_DIMS];
    linear(lay.head(), p, h.last().unwrap(), false, &mut out);
    Row {
        x0,
        enc_t,
        ht,
        h,
        out,
    }
}

/// Forward pass in f64 (parameters given in f64 so finite differences can perturb them).
/// `xyz` is `[N][3]`.
pub fn forward_f64(lay: &MlpLayout, params: &[f64], xyz: &[f32], times: Times<'_>) -> Activations {
    assert!(params.len() >= lay.total);
    let n = xyz.len() / 3;
    let rows: Vec<Row> = (0..n)
        .into_par_iter()
        .map(|i| {
            forward_row(
                lay,
                params,
                [xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]],
                times.at(i),
                |v| v,
            )
        })
        .collect();
    let mut a = Activations {
        n,
        h: vec![Vec::new(); lay.cfg.depth as usize],
        ..Default::default()
    };
    for r in rows {
        a.x0.extend(r.x0);
        a.enc_t.extend(r.enc_t);
        a.ht.extend(r.ht);
        for (d, s) in a.h.iter_mut().zip(r.h) {
            d.extend(s);
        }
        a.out.extend(r.out);
    }
    a
}

/// Forward pass: `[N][10]` outputs (dx, dr, ds) for f32 parameters.
pub fn forward(lay: &MlpLayout, params: &[f32], xyz: &[f32], times: Times<'_>) -> Vec<f32> {
    let p: Vec<f64> = params.iter().map(|&v| v as f64).collect();
    forward_f64(lay, &p, xyz, times)
        .out
        .iter()
        .map(|&v| v as f32)
        .collect()
}

/// Largest finite f16, the saturation bound of the fp16 path.
pub const F16_MAX: f64 = 65504.0;

/// f16 storage as the fp16 kernels do it (`float16_t(clamp(v, −65504, 65504))`): saturate at
/// ±65504 instead of overflowing to ±∞, then round to nearest even with 11 significant bits
/// (subnormals below 2⁻¹⁴ keep spacing 2⁻²⁴). NaN stays NaN.
pub fn to_f16(v: f64) -> f64 {
    let v = v.clamp(-F16_MAX, F16_MAX);
    if v == 0.0 || v.is_nan() {
        return v;
    }
    let e = ((v.abs().to_bits() >> 52) as i64 - 1023).max(-14);
    let ulp = (2.0f64).powi(e as i32 - 10);
    (v / ulp).round_ties_even() * ulp
}

/// Twin of the fp16-storage fused forward (`glsl/mlp/fused_fwd_f16.comp`): the weights and
/// every stored value (encoding, hidden activations, time features) pass through [`to_f16`],
/// arithmetic is f64, the `[N][10]` outputs are not rounded (the kernel writes them as f32).
/// So inputs, weights and activations beyond ±65504 saturate exactly as on the GPU.
pub fn forward_f16(lay: &MlpLayout, params: &[f32], xyz: &[f32], times: Times<'_>) -> Vec<f64> {
    assert!(params.len() >= lay.total);
    let p: Vec<f64> = params.iter().map(|&v| to_f16(v as f64)).collect();
    let n = xyz.len() / 3;
    (0..n)
        .into_par_iter()
        .flat_map_iter(|i| {
            let x = [xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]];
            forward_row(lay, &p, x, times.at(i), to_f16).out
        })
        .collect()
}

/// `grad[W] += dz ⊗ input`, `grad[b] += dz`; returns `Wᵀ dz` when asked.
fn linear_bwd(
    l: &LinearSpec,
    p: &[f64],
    input: &[f64],
    dz: &[f64],
    grad: &mut [f64],
    want_din: bool,
) -> Vec<f64> {
    let mut din = if want_din {
        vec![0.0; l.fan_in]
    } else {
        Vec::new()
    };
    for (o, &g) in dz.iter().enumerate() {
        if g == 0.0 {
            continue;
        }
        grad[l.b_off + o] += g;
        let w0 = l.w_off + o * l.fan_in;
        for (k, &x) in input.iter().enumerate() {
            grad[w0 + k] += g * x;
        }
        if want_din {
            for (k, d) in din.iter_mut().enumerate() {
                *d += g * p[w0 + k];
            }
        }
    }
    din
}

/// Gradient of `Σ_n Σ_j d_out[n][j] · out[n][j]` with respect to every parameter (the flat
/// layout, padding zero), from the stored activations `a` of a forward pass. x and t are
/// detached: nothing flows to them. `d_out` is `[N][10]` (dx, dr, ds gradients), f32 as the GPU
/// stores them or f64 (the whole-step twin).
pub fn backward<T: Copy + Into<f64> + Sync>(
    lay: &MlpLayout,
    params: &[f64],
    a: &Activations,
    d_out: &[T],
) -> Vec<f64> {
    let cfg = &lay.cfg;
    let (ind, w) = (cfg.in_dims(), cfg.width as usize);
    let ted = cfg.t_enc_dims();
    let hid = lay.time_net().first().map_or(0, |l| l.fan_out);
    let skip_layer = cfg.skip.map(|s| s as usize + 1);
    let per_row = |grad: &mut Vec<f64>, n: usize| {
        let row = |v: &[f64], d: usize| v[n * d..(n + 1) * d].to_vec();
        let h: Vec<Vec<f64>> = a.h.iter().map(|l| row(l, w)).collect();
        let x0 = row(&a.x0, ind);
        let dz: Vec<f64> = d_out[n * OUT_DIMS..(n + 1) * OUT_DIMS]
            .iter()
            .map(|&v| v.into())
            .collect();
        let mut dh = linear_bwd(lay.head(), params, &h[h.len() - 1], &dz, grad, true);
        let mut dx0 = vec![0.0; ind];
        for (i, l) in lay.trunk().iter().enumerate().rev() {
            let dz: Vec<f64> = dh
                .iter()
                .zip(&h[i])
                .map(|(g, y)| if *y > 0.0 { *g } else { 0.0 })
                .collect();
            if i == 0 {
                let din = linear_bwd(l, params, &x0, &dz, grad, cfg.time_net());
                dx0.iter_mut().zip(&din).for_each(|(a, b)| *a += b);
            } else if skip_layer == Some(i) {
                let mut cat = x0.clone();
                cat.extend_from_slice(&h[i - 1]);
                let din = linear_bwd(l, params, &cat, &dz, grad, true);
                dx0.iter_mut().zip(&din[..ind]).for_each(|(a, b)| *a += b);
                dh = din[ind..].to_vec();
            } else {
                dh = linear_bwd(l, params, &h[i - 1], &dz, grad, true);
            }
        }
        if cfg.time_net() {
            let tn = lay.time_net();
            let ht = row(&a.ht, hid);
            let dtf = &dx0[cfg.x_dims()..];
            let dht = linear_bwd(&tn[1], params, &ht, dtf, grad, true);
            let dz: Vec<f64> = dht
                .iter()
                .zip(&ht)
                .map(|(g, y)| if *y > 0.0 { *g } else { 0.0 })
                .collect();
            linear_bwd(&tn[0], params, &row(&a.enc_t, ted), &dz, grad, false);
        }
    };
    (0..a.n)
        .into_par_iter()
        .fold(
            || vec![0.0f64; lay.total],
            |mut g, n| {
                per_row(&mut g, n);
                g
            },
        )
        .reduce(
            || vec![0.0f64; lay.total],
            |mut a, b| {
                a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
                a
            },
        )
}

impl Activations {
    /// Activations as the GPU stores them (f32, row-major, same shapes).
    pub fn from_f32(
        n: usize,
        x0: &[f32],
        enc_t: &[f32],
        ht: &[f32],
        h: &[Vec<f32>],
        out: &[f32],
    ) -> Self {
        let c = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<f64>>();
        Activations {
            n,
            x0: c(x0),
            enc_t: c(enc_t),
            ht: c(ht),
            h: h.iter().map(|l| c(l)).collect(),
            out: c(out),
        }
    }
}
