//! Twin of `glsl/deform/*`: mean = x + dx, scale = exp(min(s, LOG_SCALE_MAX)) + ds,
//! rot = normalize(q) + dr, and its backward (f64; no gradient to s above the clamp).

use crate::kernels::deform::LOG_SCALE_MAX;

/// The log-scale `exp` is taken of: clamped at `LOG_SCALE_MAX` (NaN stays NaN, as on the GPU).
fn clamp_log_scale(s: f64) -> f64 {
    if s > LOG_SCALE_MAX as f64 {
        LOG_SCALE_MAX as f64
    } else {
        s
    }
}

/// Drawn (mean, scale, rot) of one Gaussian.
pub fn deform_apply(
    x: [f64; 3],
    s: [f64; 3],
    q: [f64; 4],
    d: Option<&[f64; 10]>,
) -> ([f64; 3], [f64; 3], [f64; 4]) {
    let z = [0.0; 10];
    let d = d.unwrap_or(&z);
    let len = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let qn = if len > 1e-12 {
        q.map(|v| v / len)
    } else {
        [1.0, 0.0, 0.0, 0.0]
    };
    (
        [0, 1, 2].map(|a| x[a] + d[a]),
        [0, 1, 2].map(|a| clamp_log_scale(s[a]).exp() + d[7 + a]),
        [0, 1, 2, 3].map(|a| qn[a] + d[3 + a]),
    )
}

/// (∂L/∂x, ∂L/∂s, ∂L/∂q, ∂L/∂d) from the gradients wrt the drawn (mean, scale, rot).
pub fn deform_apply_bwd(
    s: [f64; 3],
    q: [f64; 4],
    dm: [f64; 3],
    ds: [f64; 3],
    dq: [f64; 4],
) -> ([f64; 3], [f64; 3], [f64; 4], [f64; 10]) {
    let len = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    let gq = if len > 1e-12 {
        let qn = q.map(|v| v / len);
        let dot: f64 = (0..4).map(|a| qn[a] * dq[a]).sum();
        [0, 1, 2, 3].map(|a| (dq[a] - qn[a] * dot) / len)
    } else {
        [0.0; 4]
    };
    let mut dd = [0.0; 10];
    dd[..3].copy_from_slice(&dm);
    dd[3..7].copy_from_slice(&dq);
    dd[7..].copy_from_slice(&ds);
    let gs = [0, 1, 2].map(|a| {
        if s[a] <= LOG_SCALE_MAX as f64 {
            ds[a] * s[a].exp()
        } else {
            0.0
        }
    });
    (dm, gs, gq, dd)
}
