//! The model's own motion in pixels, scored against a scene's ground-truth flow: each
//! Gaussian's mean at t and at the next time is projected by the frame's camera, the 2D
//! difference is α-blended by the render at (v, t) (the same weights the displacement flow
//! uses), and the end-point error against the ground-truth flow is averaged over the motion
//! mask. It shows *when* a run learns the motion: a deformation that only wiggles has an EPE
//! near the objects' own speed, one that learnt the motion near 0.
//!
//! The projection and the scoring are host code (a few thousand Gaussians and pixels per
//! probe frame); the blend is the rasteriser's, so the twin of the whole probe is
//! [`crate::reference::raster`]'s blend of the same per-Gaussian features.

use crate::kernels::raster::Camera;

/// Pixel position of world point `p` under `cam` (`None` at or behind the near plane).
pub fn project(cam: &Camera, p: [f32; 3]) -> Option<[f64; 2]> {
    let mut c = [0.0f64; 3];
    for (i, ci) in c.iter_mut().enumerate() {
        *ci = cam.trans[i] as f64
            + (0..3)
                .map(|j| cam.rot[i][j] as f64 * p[j] as f64)
                .sum::<f64>();
    }
    if c[2].partial_cmp(&(cam.near as f64)) != Some(std::cmp::Ordering::Greater)
        || !c.iter().all(|v| v.is_finite())
    {
        return None;
    }
    Some([
        cam.fx as f64 * c[0] / c[2] + cam.cx as f64,
        cam.fy as f64 * c[1] / c[2] + cam.cy as f64,
    ])
}

/// Each Gaussian's projected motion from `a` to `b` (means at the two times) under `cam`, as
/// 3-channel features `(dx, dy, 0)` for the rasteriser's feature blend; 0 where either end is
/// behind the near plane.
pub fn projected_motion(cam: &Camera, a: &[[f32; 3]], b: &[[f32; 3]]) -> Vec<[f32; 3]> {
    a.iter()
        .zip(b)
        .map(|(&pa, &pb)| match (project(cam, pa), project(cam, pb)) {
            (Some(u), Some(v)) => [(v[0] - u[0]) as f32, (v[1] - u[1]) as f32, 0.0],
            _ => [0.0; 3],
        })
        .collect()
}

/// Mean end-point error of the blended flow `blended` ([H·W] × 3 channels, x and y first)
/// against `gt` ([H·W] × 2) over the pixels where `mask` is set (`None`: empty mask).
pub fn masked_epe(blended: &[f32], gt: &[f32], mask: &[u8]) -> Option<f64> {
    assert!(
        blended.len() == 3 * mask.len() && gt.len() == 2 * mask.len(),
        "masked_epe: sizes differ"
    );
    let (mut sum, mut n) = (0.0f64, 0u64);
    for (p, &m) in mask.iter().enumerate() {
        if m == 0 {
            continue;
        }
        let dx = blended[3 * p] as f64 - gt[2 * p] as f64;
        let dy = blended[3 * p + 1] as f64 - gt[2 * p + 1] as f64;
        sum += (dx * dx + dy * dy).sqrt();
        n += 1;
    }
    (n > 0).then(|| sum / n as f64)
}

/// The `q`-quantile (0..=1, nearest rank) of the Gaussians' projected motion lengths.
pub fn motion_quantile(features: &[[f32; 3]], q: f64) -> Option<f64> {
    let mut len: Vec<f64> = features
        .iter()
        .map(|f| (f[0] as f64).hypot(f[1] as f64))
        .collect();
    if len.is_empty() {
        return None;
    }
    len.sort_by(f64::total_cmp);
    let k = ((q.clamp(0.0, 1.0) * (len.len() - 1) as f64).round()) as usize;
    Some(len[k])
}

/// What the probe measured on one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MotionProbe {
    /// Mean EPE (pixels) of the blended projected motion inside the mask.
    pub epe: Option<f64>,
    /// Mean ground-truth flow length inside the mask (the EPE of a model that does not move).
    pub gt_len: Option<f64>,
    /// Median and 99th percentile of the Gaussians' projected motion lengths (pixels).
    pub p50: Option<f64>,
    pub p99: Option<f64>,
}

/// The mean ground-truth flow length over the mask: the EPE of a motionless model.
pub fn masked_len(gt: &[f32], mask: &[u8]) -> Option<f64> {
    let zero = vec![0.0f32; 3 * mask.len()];
    masked_epe(&zero, gt, mask)
}
