//! CPU twin of `glsl/optim/adam.comp`: PyTorch's bias-corrected Adam on one range of a flat
//! buffer, with an optional per-row visibility mask. Scalar loop, f64 inside.

use crate::model::optim::AdamHyper;

/// One Adam step on `p[range]` (with `g`, `m`, `v` over the same indices). `mask`, when given,
/// holds one u32 per row of `row_len` floats counted from `range.start`; rows with 0 are left
/// untouched (p, m, v). `step` is 1-based.
#[allow(clippy::too_many_arguments)]
pub fn adam_step(
    p: &mut [f32],
    g: &[f32],
    m: &mut [f32],
    v: &mut [f32],
    range: std::ops::Range<usize>,
    mask: Option<(&[u32], usize)>,
    lr: f32,
    h: &AdamHyper,
    step: u32,
) {
    let (bc1, bc2) = h.bias_corrections(step);
    let (b1, b2) = (h.beta1 as f64, h.beta2 as f64);
    for i in range.clone() {
        if let Some((mask, row_len)) = mask {
            if mask[(i - range.start) / row_len] == 0 {
                continue;
            }
        }
        let gi = g[i] as f64;
        let mi = b1 * m[i] as f64 + (1.0 - b1) * gi;
        let vi = b2 * v[i] as f64 + (1.0 - b2) * gi * gi;
        m[i] = mi as f32;
        v[i] = vi as f32;
        let upd = lr as f64 * (mi / bc1 as f64) / ((vi / bc2 as f64).sqrt() + h.eps as f64);
        p[i] = (p[i] as f64 - upd) as f32;
    }
}
