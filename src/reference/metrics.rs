//! Twin of `glsl/metrics/*`: per-frame average precision of a motion score against a motion
//! mask (the MMAP term) and Deformation-Rendering Consistency (DRC). Plain loops, f64 sums;
//! the AP twin sorts with the standard library and groups ties by equality (not by key bits).

use crate::kernels::metrics::DRC_EPS;

/// Step-wise average precision `AP = Σ_n (R_n − R_{n−1})·P_n` of `scores` (higher = more
/// likely moving) against `mask` (non-zero = moving), with one threshold per distinct score
/// (a run of equal scores is admitted at once). `None` when the mask has no positive pixel.
/// Scores must not be NaN; −0 and +0 are the same score.
pub fn average_precision(scores: &[f32], mask: &[u32]) -> Option<f64> {
    assert_eq!(scores.len(), mask.len());
    let positives = mask.iter().filter(|&&l| l != 0).count();
    if positives == 0 {
        return None;
    }
    let mut order: Vec<usize> = (0..scores.len()).collect();
    order.sort_by(|&a, &b| scores[b].partial_cmp(&scores[a]).expect("NaN score"));
    let (mut tp, mut tp_prev, mut ap) = (0usize, 0usize, 0.0f64);
    for (k, &i) in order.iter().enumerate() {
        tp += (mask[i] != 0) as usize;
        let run_ends = k + 1 == order.len() || scores[order[k + 1]] != scores[i];
        if run_ends {
            let precision = tp as f64 / (k + 1) as f64;
            ap += (tp - tp_prev) as f64 / positives as f64 * precision;
            tp_prev = tp;
        }
    }
    Some(ap)
}

/// `DRC = Σ_p F̂(p)·[ΔE(p) > 0] / (Σ_p F̂(p) + ε)`, ΔE(p) = mean_c |I_frozen − I_gt| −
/// mean_c |I_full − I_gt| over RGB. The indicator is evaluated in f32 exactly as the GPU does
/// (`Σ_c |frozen − gt| > Σ_c |full − gt|`, channels added in order), the sums in f64.
pub fn drc(score: &[f32], frozen: &[[f32; 4]], full: &[[f32; 4]], gt: &[[f32; 4]]) -> f64 {
    let n = score.len();
    assert!(frozen.len() == n && full.len() == n && gt.len() == n);
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for p in 0..n {
        let err = |img: &[f32; 4]| {
            (img[0] - gt[p][0]).abs() + (img[1] - gt[p][1]).abs() + (img[2] - gt[p][2]).abs()
        };
        let f = score[p] as f64;
        if err(&frozen[p]) > err(&full[p]) {
            num += f;
        }
        den += f;
    }
    num / (den + DRC_EPS)
}
