//! Twin of `glsl/motion/*`: per-pixel magnitude of a vector field, its normalisation over the
//! image (min-max, max-abs, z-score, IQR) and the backward pass through both, as autograd would
//! differentiate it (statistics included). Plain f64 loops; it works in the magnitude domain
//! directly (the GPU rescales by a power of two first — the result is scale invariant), so the
//! two cannot share a scaling mistake.
//!
//! Conventions (the GPU follows them; see `kernels::motion` for the full list):
//! - `v` is interleaved `[H·W, C]`, C = 2 or 3; `m(p) = |v(p)|`.
//! - argmin/argmax: the first (lowest) pixel index among equal values.
//! - quantiles: linear interpolation between order statistics (torch.quantile / numpy
//!   default): position `q·(N − 1)` in the stable ascending order (ties by pixel index).
//! - z-score uses the population standard deviation (divide by N).
//! - degenerate: any non-finite magnitude, or a denominator `d` with `!(d >= eps)` or
//!   `d < REL_FLAT · 2^e` (e: the binary exponent of the max, `max = f·2^e`, f ∈ [0.5, 1);
//!   IQR: `d < REL_FLAT · q75`), or `d·2^-e` below the smallest normal f32: output zeros and
//!   zero gradient.

use crate::kernels::motion::{quantile_position, NormFlag, NormMode, REL_FLAT};

/// One linear-interpolated quantile: `value = m[lo] + frac·(m[hi] − m[lo])` (pixel indices).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Quantile {
    pub lo: usize,
    pub hi: usize,
    pub frac: f64,
    pub value: f64,
}

/// Statistics of one magnitude map and the affine map they define: `m̂ = (m − offset) / denom`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NormStats {
    pub flag: NormFlag,
    pub min: f64,
    pub max: f64,
    pub argmin: usize,
    pub argmax: usize,
    pub mean: f64,
    /// Population standard deviation.
    pub std: f64,
    /// q25, q50 (median), q75.
    pub quantiles: [Quantile; 3],
    pub offset: f64,
    pub denom: f64,
}

/// Forward result: magnitudes, normalised map (zeros when degenerate) and statistics.
#[derive(Clone, Debug)]
pub struct Normalized {
    pub m: Vec<f64>,
    pub m_hat: Vec<f64>,
    pub stats: NormStats,
}

fn norm64(v: &[f64]) -> f64 {
    v.iter().map(|x| x * x).sum::<f64>().sqrt()
}

/// `|v(p)|` per pixel, exact in f64 (f32 inputs cannot overflow f64).
pub fn magnitudes_f64(v: &[f64], channels: usize) -> Vec<f64> {
    v.chunks_exact(channels).map(norm64).collect()
}

/// `|v(p)|` rounded to f32, as the GPU stores it (an overflow to ∞ is what the GPU sees too).
pub fn magnitudes(v: &[f32], channels: usize) -> Vec<f32> {
    v.chunks_exact(channels)
        .map(|p| norm64(&p.iter().map(|&x| x as f64).collect::<Vec<_>>()) as f32)
        .collect()
}

/// Binary exponent `e` of `x > 0` with `x = f·2^e`, f ∈ [0.5, 1) (C `frexp`, GLSL `frexp`);
/// 0 for 0 or non-finite.
pub fn frexp_exponent(x: f64) -> i32 {
    if x == 0.0 || !x.is_finite() {
        return 0;
    }
    let mut e = x.abs().log2().floor() as i32 + 1;
    // Guard the log2 rounding at exact powers of two.
    while 2f64.powi(e - 1) > x.abs() {
        e -= 1;
    }
    while 2f64.powi(e) <= x.abs() {
        e += 1;
    }
    e
}

/// Statistics of `m` and the offset/denominator of `mode` (degenerate flag included).
pub fn norm_stats(m: &[f64], mode: NormMode, eps: f64) -> NormStats {
    let n = m.len();
    let mut s = NormStats::default();
    if n == 0 {
        s.flag = NormFlag::Flat;
        return s;
    }
    if m.iter().any(|x| !x.is_finite()) {
        s.flag = NormFlag::NonFinite;
        return s;
    }
    let (mut imin, mut imax) = (0, 0);
    for (i, &x) in m.iter().enumerate() {
        if x < m[imin] {
            imin = i;
        }
        if x > m[imax] {
            imax = i;
        }
    }
    s.argmin = imin;
    s.argmax = imax;
    s.min = m[imin];
    s.max = m[imax];
    s.mean = m.iter().sum::<f64>() / n as f64;
    s.std = (m.iter().map(|x| (x - s.mean).powi(2)).sum::<f64>() / n as f64).sqrt();
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| m[a].total_cmp(&m[b]).then(a.cmp(&b)));
    for (k, q) in [0.25, 0.5, 0.75].into_iter().enumerate() {
        let (lo, frac) = quantile_position(n as u32, q);
        let lo = lo as usize;
        let hi = (lo + 1).min(n - 1);
        let frac = frac as f64;
        let (a, b) = (m[order[lo]], m[order[hi]]);
        s.quantiles[k] = Quantile {
            lo: order[lo],
            hi: order[hi],
            frac,
            value: a + frac * (b - a),
        };
    }
    let (offset, denom) = match mode {
        NormMode::MinMax => (s.min, s.max - s.min),
        NormMode::MaxAbs => (0.0, s.max),
        NormMode::ZScore => (s.mean, s.std),
        NormMode::Iqr => (
            s.quantiles[1].value,
            s.quantiles[2].value - s.quantiles[0].value,
        ),
    };
    s.offset = offset;
    s.denom = denom;
    let scale = match mode {
        NormMode::Iqr => s.quantiles[2].value,
        _ => 2f64.powi(frexp_exponent(s.max)),
    };
    // The GPU works on u = m·2^-e and needs a normal f32 denominator there.
    let denom_u = denom * 2f64.powi(-frexp_exponent(s.max));
    // Magnitudes are finite here, so `denom` is not NaN: `< eps` is the GPU's `!(d >= eps)`.
    let flat = denom < eps || denom < REL_FLAT as f64 * scale || denom_u < f32::MIN_POSITIVE as f64;
    s.flag = if flat { NormFlag::Flat } else { NormFlag::Ok };
    s
}

/// `m̂ = (m − offset) / denom`, zeros when degenerate.
pub fn norm_apply(m: &[f64], s: &NormStats) -> Vec<f64> {
    if s.flag != NormFlag::Ok {
        return vec![0.0; m.len()];
    }
    m.iter().map(|x| (x - s.offset) / s.denom).collect()
}

/// Normalises magnitudes given directly (exact, f64).
pub fn normalize_magnitudes(m: &[f64], mode: NormMode, eps: f64) -> Normalized {
    let stats = norm_stats(m, mode, eps);
    Normalized {
        m: m.to_vec(),
        m_hat: norm_apply(m, &stats),
        stats,
    }
}

/// What the GPU computes: magnitudes rounded to f32, then statistics and `m̂` in f64.
pub fn normalize(v: &[f32], channels: usize, mode: NormMode, eps: f64) -> Normalized {
    let m: Vec<f64> = magnitudes(v, channels).iter().map(|&x| x as f64).collect();
    normalize_magnitudes(&m, mode, eps)
}

/// Exact f64 forward (no f32 rounding of the magnitudes), for finite differences.
pub fn normalize_f64(v: &[f64], channels: usize, mode: NormMode, eps: f64) -> Normalized {
    normalize_magnitudes(&magnitudes_f64(v, channels), mode, eps)
}

/// ∂L/∂m from ∂L/∂m̂ through the normalisation, statistics included (autograd semantics:
/// argmin/argmax pixels, every pixel through mean and std, the quantile pixels with their
/// interpolation weights). Zero when degenerate.
pub fn norm_backward(n: &Normalized, mode: NormMode, d_m_hat: &[f64]) -> Vec<f64> {
    let s = &n.stats;
    let len = n.m.len();
    assert_eq!(d_m_hat.len(), len);
    let mut dm = vec![0.0; len];
    if s.flag != NormFlag::Ok {
        return dm;
    }
    let d = s.denom;
    // m̂_p = (m_p − o)/d: ∂L/∂o = −Σ g/d = −G/d, ∂L/∂d = −Σ g·m̂/d = −H/d.
    let g_sum: f64 = d_m_hat.iter().sum();
    let h_sum: f64 = d_m_hat.iter().zip(&n.m_hat).map(|(g, y)| g * y).sum();
    let dl_do = -g_sum / d;
    let dl_dd = -h_sum / d;
    for (q, x) in dm.iter_mut().enumerate() {
        *x = d_m_hat[q] / d;
    }
    match mode {
        NormMode::MinMax => {
            // o = min, d = max − min.
            dm[s.argmin] += dl_do - dl_dd;
            dm[s.argmax] += dl_dd;
        }
        NormMode::MaxAbs => dm[s.argmax] += dl_dd,
        NormMode::ZScore => {
            // ∂mean/∂m_q = 1/N, ∂std/∂m_q = (m_q − mean)/(N·std) = m̂_q/N.
            let inv_n = 1.0 / len as f64;
            for (q, x) in dm.iter_mut().enumerate() {
                *x += dl_do * inv_n + dl_dd * n.m_hat[q] * inv_n;
            }
        }
        NormMode::Iqr => {
            let [q25, q50, q75] = s.quantiles;
            for (q, w) in [(q50, dl_do), (q75, dl_dd), (q25, -dl_dd)] {
                dm[q.lo] += w * (1.0 - q.frac);
                dm[q.hi] += w * q.frac;
            }
        }
    }
    dm
}

/// ∂L/∂m with the statistics held constant (`detach_stats`): `∂L/∂m̂ / d` per pixel, zero
/// when degenerate.
pub fn norm_backward_detached(n: &Normalized, d_m_hat: &[f64]) -> Vec<f64> {
    assert_eq!(d_m_hat.len(), n.m.len());
    if n.stats.flag != NormFlag::Ok {
        return vec![0.0; d_m_hat.len()];
    }
    d_m_hat.iter().map(|g| g / n.stats.denom).collect()
}

/// ∂L/∂v ([H·W, C] interleaved) from ∂L/∂m through `m = |v|` (0 where |v| = 0).
pub fn magnitude_backward(v: &[f64], channels: usize, d_m: &[f64]) -> Vec<f64> {
    let mut out = vec![0.0; v.len()];
    for (p, (vp, op)) in v
        .chunks_exact(channels)
        .zip(out.chunks_exact_mut(channels))
        .enumerate()
    {
        let m = norm64(vp);
        if m > 0.0 {
            for c in 0..channels {
                op[c] = d_m[p] * vp[c] / m;
            }
        }
    }
    out
}

/// ∂L/∂v through the whole forward (normalisation then magnitude).
pub fn normalize_backward(
    v: &[f64],
    channels: usize,
    n: &Normalized,
    mode: NormMode,
    d_m_hat: &[f64],
) -> Vec<f64> {
    magnitude_backward(v, channels, &norm_backward(n, mode, d_m_hat))
}
