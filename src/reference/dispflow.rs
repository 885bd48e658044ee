//! Twin of `glsl/dispflow/*`. Generic over the float type: f32 is what the GPU stores (bit for
//! bit), f64 is what the whole-step twin (`reference::step`) composes.

use std::ops::Sub;

/// δ_i = dx_i(t2) − dx_i(t1) from [N,10] MLP outputs.
pub fn displacement<T: Copy + Sub<Output = T>>(out_t1: &[T], out_t2: &[T]) -> Vec<T> {
    out_t1
        .chunks_exact(10)
        .zip(out_t2.chunks_exact(10))
        .flat_map(|(a, b)| [b[0] - a[0], b[1] - a[1], b[2] - a[2]])
        .collect()
}

/// (updated ∂L/∂out(t1), ∂L/∂out(t2)) from ∂L/∂δ.
pub fn displacement_bwd<T: Copy + Default + Sub<Output = T>>(
    d_delta: &[T],
    d_out_t1: &[T],
) -> (Vec<T>, Vec<T>) {
    let mut d1 = d_out_t1.to_vec();
    let mut d2 = vec![T::default(); d_out_t1.len()];
    for (i, g) in d_delta.chunks_exact(3).enumerate() {
        for a in 0..3 {
            d1[10 * i + a] = d1[10 * i + a] - g[a];
            d2[10 * i + a] = g[a];
        }
    }
    (d1, d2)
}

/// (mean |m_scene − m_disp|, ∂(weight · mean)/∂m_disp); zeros when `skip` (degenerate map).
pub fn motion_l1<T: Copy + Into<f64>>(
    m_disp: &[T],
    m_scene: &[T],
    weight: f64,
    skip: bool,
) -> (f64, Vec<f64>) {
    let n = m_disp.len().max(1) as f64;
    if skip {
        return (0.0, vec![0.0; m_disp.len()]);
    }
    let mut sum = 0.0;
    let g = m_disp
        .iter()
        .zip(m_scene)
        .map(|(&a, &b)| {
            let e = a.into() - b.into();
            sum += e.abs();
            weight
                * if e > 0.0 {
                    1.0
                } else if e < 0.0 {
                    -1.0
                } else {
                    0.0
                }
                / n
        })
        .collect();
    (sum / n, g)
}
