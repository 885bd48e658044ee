//! Twin of `glsl/sparse/*`: the motion probe (whole, f64 inside), the compaction of the dynamic set
//! and the row gather/expand, same inputs in the same binding order as the kernels.

use crate::kernels::deform::LOG_SCALE_MAX;
use crate::kernels::sparse::NO_ROW;

/// Returned for a non-finite motion (mirrors `HUGE` in motion_probe.comp).
pub const HUGE: f64 = 3.0e38;

/// Apparent motion in pixels of one Gaussian over the probe from its per-component range of
/// D (`lo`, `hi` [10]: dx, dr, ds): half the range in scene units, over the cameras `cams`
/// ([centre, focal px]) at the midrange position.
pub fn probe_pixels(
    lo: &[f64],
    hi: &[f64],
    log_scales: &[f32],
    mean: &[f32],
    cams: &[[f32; 4]],
    near: f32,
) -> f64 {
    let f = |v: f32| v as f64;
    let d: Vec<f64> = (0..10).map(|c| hi[c] - lo[c]).collect();
    let smax = log_scales
        .iter()
        .map(|&ls| f(ls.min(LOG_SCALE_MAX)).exp())
        .fold(0.0, f64::max);
    let norm = |v: &[f64]| v.iter().map(|a| a * a).sum::<f64>().sqrt();
    let m = 0.5
        * (norm(&d[0..3])
            + d[7..10].iter().copied().fold(f64::MIN, f64::max)
            + norm(&d[3..7]) * smax);
    if m.is_nan() || m >= HUGE {
        return HUGE;
    }
    let x: Vec<f64> = (0..3).map(|a| f(mean[a]) + 0.5 * (lo[a] + hi[a])).collect();
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

/// The whole probe over every Gaussian: `samples` of D ([N,10] each), `log_scales` and
/// `means` [N,3], `cams` [C]. Returns (pixels [N], midrange [N,10]); a Gaussian with a
/// non-finite sample gets pixels = [`HUGE`].
pub fn motion_probe(
    samples: &[Vec<f32>],
    log_scales: &[f32],
    means: &[f32],
    cams: &[[f32; 4]],
    near: f32,
) -> (Vec<f32>, Vec<f32>) {
    let n = log_scales.len() / 3;
    let (mut px, mut mid) = (vec![0.0; n], vec![0.0; n * 10]);
    for i in 0..n {
        let r = |w: usize| i * w..(i + 1) * w;
        let rows: Vec<&[f32]> = samples.iter().map(|s| &s[r(10)]).collect();
        let finite = rows.iter().all(|row| row.iter().all(|v| v.is_finite()));
        let lo: Vec<f64> = (0..10)
            .map(|c| {
                rows.iter()
                    .map(|row| row[c] as f64)
                    .fold(f64::INFINITY, f64::min)
            })
            .collect();
        let hi: Vec<f64> = (0..10)
            .map(|c| {
                rows.iter()
                    .map(|row| row[c] as f64)
                    .fold(f64::NEG_INFINITY, f64::max)
            })
            .collect();
        for c in 0..10 {
            mid[10 * i + c] = (0.5 * (lo[c] + hi[c])) as f32;
        }
        px[i] = if finite {
            probe_pixels(&lo, &hi, &log_scales[r(3)], &means[r(3)], cams, near) as f32
        } else {
            HUGE as f32
        };
    }
    (px, mid)
}

/// Dynamic flags: pixels above the threshold.
pub fn dyn_flag(px: &[f32], threshold_px: f32) -> Vec<u32> {
    px.iter().map(|&p| (p > threshold_px) as u32).collect()
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
        .flat_map(|&i| {
            src[i as usize * width..(i as usize + 1) * width]
                .iter()
                .copied()
        })
        .collect()
}

/// `dst[i] = src[row_of[i]]`, or `fixed[i]` for [`NO_ROW`].
pub fn rows_expand(row_of: &[u32], src: &[f32], fixed: &[f32], width: usize) -> Vec<f32> {
    row_of
        .iter()
        .enumerate()
        .flat_map(|(i, &r)| {
            (0..width).map(move |c| {
                if r == NO_ROW {
                    fixed[i * width + c]
                } else {
                    src[r as usize * width + c]
                }
            })
        })
        .collect()
}
