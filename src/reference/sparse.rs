//! Twin of `glsl/sparse/*`: the motion probe (f64 inside), the compaction of the dynamic set
//! and the row gather/expand, same inputs in the same binding order as the kernels.

use crate::kernels::deform::LOG_SCALE_MAX;
use crate::kernels::sparse::NO_ROW;

/// Returned for a non-finite motion (mirrors `HUGE` in motion_probe.comp).
pub const HUGE: f64 = 3.0e38;

/// Apparent motion in pixels of Gaussian `i` under one deformation sample `d` ([10]:
/// dx, dr, ds): the largest over the cameras `cams` ([centre, focal px]).
pub fn probe_pixels(d: &[f32], log_scales: &[f32], mean: &[f32], cams: &[[f32; 4]], near: f32) -> f64 {
    let f = |v: f32| v as f64;
    let dx = [f(d[0]), f(d[1]), f(d[2])];
    let dr = [f(d[3]), f(d[4]), f(d[5]), f(d[6])];
    let ds = [f(d[7]), f(d[8]), f(d[9])];
    let smax = log_scales
        .iter()
        .map(|&ls| f(ls.min(LOG_SCALE_MAX)).exp())
        .fold(0.0, f64::max);
    let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
    let m = norm(&dx) + ds.iter().map(|a| a.abs()).fold(0.0, f64::max) + norm(&dr) * smax;
    if !(m < HUGE) {
        return HUGE;
    }
    let x: Vec<f64> = (0..3).map(|a| f(mean[a]) + dx[a]).collect();
    let px = cams
        .iter()
        .map(|c| {
            let dist = norm(&[x[0] - f(c[0]), x[1] - f(c[1]), x[2] - f(c[2])]).max(f(near));
            m * f(c[3]) / dist
        })
        .fold(0.0, f64::max);
    if px < HUGE {
        px
    } else {
        HUGE
    }
}

/// One probe sample over every Gaussian: `deform` [N,10], `log_scales` [N,3], `means` [N,3],
/// `cams` [C]; updates `extent` [N] (restarted when `first`) and, when `last`, writes `flags`.
#[allow(clippy::too_many_arguments)] // the stage's bindings and its sample, each one named
pub fn motion_probe(
    deform: &[f32],
    log_scales: &[f32],
    means: &[f32],
    cams: &[[f32; 4]],
    extent: &mut [f32],
    flags: &mut [u32],
    first: bool,
    last: bool,
    threshold_px: f32,
    near: f32,
) {
    for i in 0..extent.len() {
        let r = |w: usize| i * w..(i + 1) * w;
        let px = probe_pixels(&deform[r(10)], &log_scales[r(3)], &means[r(3)], cams, near) as f32;
        let e = if first { px } else { extent[i].max(px) };
        extent[i] = e;
        if last {
            flags[i] = (e > threshold_px) as u32;
        }
    }
}

/// The dynamic indices in ascending order, each Gaussian's row (or [`NO_ROW`]) and the count.
pub fn dyn_compact(flags: &[u32]) -> (Vec<u32>, Vec<u32>, u32) {
    let mut idx = Vec::new();
    let row_of = flags
        .iter()
        .enumerate()
        .map(|(i, &f)| {
            if f != 0 {
                idx.push(i as u32);
                idx.len() as u32 - 1
            } else {
                NO_ROW
            }
        })
        .collect();
    let count = idx.len() as u32;
    (idx, row_of, count)
}

/// `dst[j] = src[idx[j]]` for rows of `width` floats.
pub fn rows_gather(idx: &[u32], src: &[f32], width: usize) -> Vec<f32> {
    idx.iter()
        .flat_map(|&i| src[i as usize * width..(i as usize + 1) * width].iter().copied())
        .collect()
}

/// `dst[i] = src[row_of[i]]`, zeros for [`NO_ROW`].
pub fn rows_expand(row_of: &[u32], src: &[f32], width: usize) -> Vec<f32> {
    row_of
        .iter()
        .flat_map(|&r| {
            (0..width).map(move |c| {
                if r == NO_ROW {
                    0.0
                } else {
                    src[r as usize * width + c]
                }
            })
        })
        .collect()
}
