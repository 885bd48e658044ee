//! Twin of `glsl/gflow/*` (Gaussian flow), in f64. A splat record is the rasteriser's
//! `[(μx, μy, depth, opacity), (conic a, b, c, radius), (rgb, 0)]`; the six channels are
//! `G = A − I` (row-major) and `b = μ2 − A·μ1` with `A = Σ2(t2)^½ · Σ2(t1)^-½` (symmetric
//! square roots, closed form from the conics; see glsl/gflow/gflow.glsl).

/// Row-major 2×2.
type M2 = [f64; 4];

fn mul(x: M2, y: M2) -> M2 {
    [
        x[0] * y[0] + x[1] * y[2],
        x[0] * y[1] + x[1] * y[3],
        x[2] * y[0] + x[3] * y[2],
        x[2] * y[1] + x[3] * y[3],
    ]
}

fn tr(x: M2) -> M2 {
    [x[0], x[2], x[1], x[3]]
}

/// sqrtm of the conic (a, b, c) as (U, d, t) with sqrtm = U / t; `None` when not positive
/// definite or not finite.
fn sqrtm(q: [f64; 3]) -> Option<(M2, f64, f64)> {
    let det = q[0] * q[2] - q[1] * q[1];
    if !(det > 0.0 && det.is_finite()) {
        return None;
    }
    let d = det.sqrt();
    let t = (q[0] + q[2] + 2.0 * d).sqrt();
    (t > 0.0 && t.is_finite()).then_some(([q[0] + d, q[1], q[1], q[2] + d], d, t))
}

struct Affine {
    s1: (M2, f64, f64),
    s2: (M2, f64, f64),
    p1: M2,
    n2: M2,
    a: M2,
}

fn affine(q1: [f64; 3], q2: [f64; 3]) -> Option<Affine> {
    let (s1, s2) = (sqrtm(q1)?, sqrtm(q2)?);
    let p1 = s1.0.map(|v| v / s1.2);
    let u = s2.0;
    let n2 = [u[3], -u[1], -u[2], u[0]].map(|v| v / (s2.1 * s2.2));
    let a = mul(n2, p1);
    a.iter()
        .all(|v| v.is_finite())
        .then_some(Affine { s1, s2, p1, n2, a })
}

/// The record's (μ, conic, radius).
fn parts(s: &[[f64; 4]]) -> ([f64; 2], [f64; 3], f64) {
    ([s[0][0], s[0][1]], [s[1][0], s[1][1], s[1][2]], s[1][3])
}

/// Splat records widened to f64 (the GPU's f32 inputs, exactly).
pub fn widen(s: &[[f32; 4]]) -> Vec<[f64; 4]> {
    s.iter().map(|r| r.map(|v| v as f64)).collect()
}

/// The six channels of one Gaussian, or `None` (zeros) when culled or degenerate.
fn channels(r1: &[[f64; 4]], r2: &[[f64; 4]]) -> Option<(Affine, [f64; 6])> {
    let ((m1, q1, rad1), (m2, q2, rad2)) = (parts(r1), parts(r2));
    if !(rad1 > 0.0 && rad2 > 0.0) {
        return None;
    }
    let af = affine(q1, q2)?;
    let a = af.a;
    let b = [
        m2[0] - (a[0] * m1[0] + a[1] * m1[1]),
        m2[1] - (a[2] * m1[0] + a[3] * m1[1]),
    ];
    if !(b[0].is_finite() && b[1].is_finite()) {
        return None;
    }
    Some((af, [a[0] - 1.0, a[1], a[2], a[3] - 1.0, b[0], b[1]]))
}

/// Twin of `gflow_feat`: [N,6] from the splat records at t1 and t2 ([N,3] vec4 each).
pub fn features(splats_t1: &[[f64; 4]], splats_t2: &[[f64; 4]]) -> Vec<f64> {
    splats_t1
        .chunks_exact(3)
        .zip(splats_t2.chunks_exact(3))
        .flat_map(|(r1, r2)| channels(r1, r2).map_or([0.0; 6], |c| c.1))
        .collect()
}

/// ∂L/∂conic from ∂L/∂sqrtm(conic).
fn sqrtm_bwd(q: [f64; 3], (u, d, t): (M2, f64, f64), dp: M2) -> [f64; 3] {
    let du = dp.map(|v| v / t);
    let dt = -(0..4).map(|k| dp[k] * u[k]).sum::<f64>() / (t * t);
    let dd = du[0] + du[3] + dt / t;
    [
        du[0] + 0.5 * dt / t + dd * 0.5 * q[2] / d,
        du[1] + du[2] - dd * q[1] / d,
        du[3] + 0.5 * dt / t + dd * 0.5 * q[0] / d,
    ]
}

/// Twin of `gflow_feat_bwd`: the (mean2d, conic) gradients `[N, 5]` at t1 and at t2 (the
/// first five words of each 2D gradient record) from ∂L/∂channels [N,6].
pub fn features_bwd(
    splats_t1: &[[f64; 4]],
    splats_t2: &[[f64; 4]],
    d_feat: &[f64],
) -> (Vec<[f64; 5]>, Vec<[f64; 5]>) {
    let mut g1 = Vec::new();
    let mut g2 = Vec::new();
    for (i, (r1, r2)) in splats_t1
        .chunks_exact(3)
        .zip(splats_t2.chunks_exact(3))
        .enumerate()
    {
        let Some((af, _)) = channels(r1, r2) else {
            g1.push([0.0; 5]);
            g2.push([0.0; 5]);
            continue;
        };
        let ((m1, q1, _), (_, q2, _)) = (parts(r1), parts(r2));
        let df = &d_feat[6 * i..6 * i + 6];
        let db = [df[4], df[5]];
        let a = af.a;
        let da = [
            df[0] - db[0] * m1[0],
            df[1] - db[0] * m1[1],
            df[2] - db[1] * m1[0],
            df[3] - db[1] * m1[1],
        ];
        let dmu1 = [
            -(a[0] * db[0] + a[2] * db[1]),
            -(a[1] * db[0] + a[3] * db[1]),
        ];
        let dn2 = mul(da, tr(af.p1));
        let dp1 = mul(tr(af.n2), da);
        let dp2 = mul(mul(tr(af.n2), dn2), tr(af.n2)).map(|v| -v);
        let dq1 = sqrtm_bwd(q1, af.s1, dp1);
        let dq2 = sqrtm_bwd(q2, af.s2, dp2);
        g1.push([dmu1[0], dmu1[1], dq1[0], dq1[1], dq1[2]]);
        g2.push([db[0], db[1], dq2[0], dq2[1], dq2[2]]);
    }
    (g1, g2)
}

/// The Gaussian flow at pixel `p` of a `width`-wide image from the blended channels.
pub fn compose(feat: &[f64], p: usize, width: usize) -> [f64; 2] {
    let (x, y) = ((p % width) as f64 + 0.5, (p / width) as f64 + 0.5);
    let f = &feat[6 * p..6 * p + 6];
    [f[0] * x + f[1] * y + f[4], f[2] * x + f[3] * y + f[5]]
}

/// Twin of `gflow_l1`: ((1/N) Σ c·|e|₁, ∂(weight·that)/∂channels [H·W, 6]) with
/// e = (F − F_scene)/`scale`; zeros when `skip` (degenerate scene map).
pub fn l1(
    feat: &[f64],
    scene: &[[f64; 2]],
    conf: Option<&[f64]>,
    width: usize,
    scale: f64,
    weight: f64,
    skip: bool,
) -> (f64, Vec<f64>) {
    let n = scene.len();
    let mut d = vec![0.0; 6 * n];
    if skip {
        return (0.0, d);
    }
    let mut sum = 0.0;
    let sgn = |v: f64| {
        if v > 0.0 {
            1.0
        } else if v < 0.0 {
            -1.0
        } else {
            0.0
        }
    };
    for p in 0..n {
        let f = compose(feat, p, width);
        let c = conf.map_or(1.0, |c| c[p]);
        let e = [0, 1].map(|k| (f[k] - scene[p][k]) / scale);
        sum += c * (e[0].abs() + e[1].abs());
        let g = e.map(|v| weight * c * sgn(v) / (scale * n as f64));
        let (x, y) = ((p % width) as f64 + 0.5, (p / width) as f64 + 0.5);
        d[6 * p..6 * p + 6].copy_from_slice(&[g[0] * x, g[0] * y, g[1] * x, g[1] * y, g[0], g[1]]);
    }
    (sum / n.max(1) as f64, d)
}
