//! Twin of `glsl/check/count_nonfinite.comp`: the non-finite floats of `x[first, first +
//! count)` and the smallest offending index, relative to `first`.

use crate::kernels::check::NonFinite;

pub fn count_nonfinite(x: &[f32], first: usize, count: usize) -> NonFinite {
    let bad: Vec<u32> = x[first..first + count]
        .iter()
        .enumerate()
        .filter(|(_, v)| !v.is_finite())
        .map(|(j, _)| j as u32)
        .collect();
    NonFinite {
        count: bad.len() as u32,
        first: bad.first().copied(),
    }
}
