//! The initial Gaussians from the dataset's points. Points that no training camera sees, or
//! that sit within the near range of a camera (an initial Gaussian there covers that whole
//! view, and the view's PSNR collapses while it shrinks), are dropped first; the rest is
//! evenly subsampled to the Gaussian budget.

use super::config::TrainConfig;
use crate::data::camera::Camera;
use crate::data::Dataset;
use crate::error::{Error, Result};
use crate::model::gaussians::HostGaussians;

/// How many of the dataset's points were dropped, and why.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct InitReport {
    /// Whether the filter ran (`init_filter`).
    pub filtered: bool,
    pub points: usize,
    /// Behind, or projecting outside (beyond a 10 % margin) of, every training camera.
    pub outside: usize,
    /// Within the near range of some training camera.
    pub near: usize,
    /// Kept, with the initial scale shrunk to [`MAX_FOOTPRINT`] of a view that sees it.
    pub shrunk: usize,
}

impl std::fmt::Display for InitReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if !self.filtered {
            return write!(
                f,
                "initial points: all {} kept (init filter off)",
                self.points
            );
        }
        write!(
            f,
            "initial points: kept {} of {} ({} outside every training view, {} within a \
             camera's near range); {} shrunk to cover at most {}% of a view's width",
            self.points - self.outside - self.near,
            self.points,
            self.outside,
            self.near,
            self.shrunk,
            MAX_FOOTPRINT * 100.0
        )
    }
}

/// Largest initial footprint: 3σ at most this fraction of the image width in every training
/// view that sees the Gaussian. A random point near a camera gets a kNN scale of the scene's
/// point spacing and would cover that whole view at the start. Half the width only catches
/// those: a cap of 10 % also shrank most of a sparse COLMAP cloud's Gaussians and cost
/// movingnerf-capture1 1.06 dB at the fast preset (18.45 vs 19.51 dB, measured).
pub const MAX_FOOTPRINT: f32 = 0.5;

/// Largest log-scale of a Gaussian at `p` whose 3σ footprint stays within [`MAX_FOOTPRINT`] of
/// the image width in every camera that sees it (`None` when none does).
pub fn max_log_scale(p: glam::Vec3, cams: &[Camera], near: f32) -> Option<f32> {
    cams.iter()
        .filter_map(|c| {
            let (px, z) = c.project(p)?;
            let inside =
                px.x >= 0.0 && px.y >= 0.0 && px.x < c.width as f32 && px.y < c.height as f32;
            (inside && z > near).then(|| (MAX_FOOTPRINT * c.width as f32 * z / (3.0 * c.fx)).ln())
        })
        .reduce(f32::min)
}

/// Indices of the points some camera sees: in front of it beyond `near`, projecting inside its
/// image with a 10 % margin; a point closer than `near` to any camera centre is dropped.
pub fn visible_points(points: &[[f32; 3]], cams: &[Camera], near: f32) -> (Vec<usize>, InitReport) {
    let centres: Vec<glam::Vec3> = cams.iter().map(Camera::centre).collect();
    let mut r = InitReport {
        filtered: true,
        points: points.len(),
        ..InitReport::default()
    };
    let mut keep = Vec::with_capacity(points.len());
    for (i, p) in points.iter().enumerate() {
        let p = glam::Vec3::from_array(*p);
        if centres.iter().any(|c| c.distance(p) < near) {
            r.near += 1;
            continue;
        }
        let seen = cams.iter().any(|c| {
            c.project(p).is_some_and(|(px, z)| {
                let (mx, my) = (0.1 * c.width as f32, 0.1 * c.height as f32);
                z > near
                    && px.x >= -mx
                    && px.y >= -my
                    && px.x < c.width as f32 + mx
                    && px.y < c.height as f32 + my
            })
        });
        if seen {
            keep.push(i);
        } else {
            r.outside += 1;
        }
    }
    (keep, r)
}

/// The initial Gaussians from the dataset's points that some training camera sees (see
/// [`visible_points`]), evenly subsampled to the budget.
pub fn initial_gaussians(data: &Dataset, cfg: &TrainConfig) -> Result<(HostGaussians, InitReport)> {
    let all: Vec<[f32; 3]> = data.points.positions.iter().map(|p| p.to_array()).collect();
    let cams: Vec<Camera> = data.train.iter().map(|f| f.camera).collect();
    let (keep, report) = if cfg.init_filter {
        visible_points(&all, &cams, super::frames::near_of(data))
    } else {
        let r = InitReport {
            points: all.len(),
            ..InitReport::default()
        };
        ((0..all.len()).collect(), r)
    };
    if keep.is_empty() && !all.is_empty() {
        return Err(Error::Invalid(format!(
            "initial points: none of the {} points is in front of a training camera, inside \
             its image and beyond its near range ({} outside every view, {} within the near \
             range); the points and the cameras do not describe the same scene",
            all.len(),
            report.outside,
            report.near
        )));
    }
    let points: Vec<[f32; 3]> = keep.iter().map(|&i| all[i]).collect();
    let colors: Option<Vec<[f32; 3]>> = data
        .points
        .colors
        .as_ref()
        .map(|c| keep.iter().map(|&i| c[i]).collect());
    let mut host = HostGaussians::from_points(&points, colors.as_deref(), cfg.sh_degree)?;
    let mut report = report;
    if cfg.init_filter {
        let near = super::frames::near_of(data);
        for (p, ls) in host.means.iter().zip(host.log_scales.iter_mut()) {
            let Some(m) = max_log_scale(glam::Vec3::from_array(*p), &cams, near) else {
                continue;
            };
            if ls[0] > m {
                *ls = [m; 3];
                report.shrunk += 1;
            }
        }
    }
    // With transients on, the canonical population leaves their share of the budget free.
    let budget = cfg.canonical_budget() as usize;
    if host.len() <= budget {
        return Ok((host, report));
    }
    // Keep an even subsample: the budget bounds every buffer.
    let step = host.len() as f64 / budget as f64;
    let keep: Vec<usize> = (0..budget).map(|i| (i as f64 * step) as usize).collect();
    let r = 3 * (host.sh_coeffs as usize - 1);
    let sub = HostGaussians {
        sh_coeffs: host.sh_coeffs,
        means: keep.iter().map(|&i| host.means[i]).collect(),
        log_scales: keep.iter().map(|&i| host.log_scales[i]).collect(),
        quats: keep.iter().map(|&i| host.quats[i]).collect(),
        opacity: keep.iter().map(|&i| host.opacity[i]).collect(),
        sh_dc: keep.iter().map(|&i| host.sh_dc[i]).collect(),
        sh_rest: keep
            .iter()
            .flat_map(|&i| host.sh_rest[i * r..(i + 1) * r].to_vec())
            .collect(),
        ..Default::default()
    };
    Ok((sub, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat3, Vec3};

    #[test]
    fn points_outside_every_view_or_near_a_camera_are_dropped() {
        // Two cameras at z = −4 and x = −4, looking at the origin (+z / +x), 100×100, f 100.
        let a = Camera::from_centre(
            Mat3::IDENTITY,
            Vec3::new(0.0, 0.0, -4.0),
            [100.0, 100.0, 50.0, 50.0],
            100,
            100,
        );
        // Rows = camera axes in world: x_cam = −z_world, y_cam = y, z_cam = +x_world.
        let rot = Mat3::from_cols(Vec3::new(0.0, 0.0, 1.0), Vec3::Y, Vec3::new(-1.0, 0.0, 0.0));
        let b = Camera::from_centre(
            rot,
            Vec3::new(-4.0, 0.0, 0.0),
            [100.0, 100.0, 50.0, 50.0],
            100,
            100,
        );
        assert!(b.project(Vec3::ZERO).is_some(), "b looks at the origin");
        let pts = [
            [0.0, 0.0, 0.0],   // seen by both
            [0.0, 0.0, -5.0],  // behind a, and outside b's image: dropped
            [0.0, 30.0, 0.0],  // far above both images: dropped
            [0.0, 0.0, -3.95], // 0.05 from a's centre: near
            [-3.0, 0.0, 0.0],  // left of a's image, in front of b: kept
        ];
        let (keep, r) = visible_points(&pts, &[a, b], 0.1);
        assert_eq!(keep, vec![0, 4]);
        assert_eq!((r.points, r.outside, r.near), (5, 2, 1));
        assert!(r.to_string().contains("kept 2 of 5"));
        // The footprint cap: 3σ ≤ half of 100 px at the nearest view's depth (a: 4, b: 4).
        let cap = MAX_FOOTPRINT * 100.0 / 300.0;
        let m = max_log_scale(Vec3::ZERO, &[a, b], 0.1).unwrap();
        assert!((m.exp() - cap * 4.0).abs() < 1e-6);
        // Nearer to a (depth 0.5): the cap is set by a, the closer view.
        let m = max_log_scale(Vec3::new(0.0, 0.0, -3.5), &[a, b], 0.1).unwrap();
        assert!((m.exp() - cap * 0.5).abs() < 1e-6);
        assert_eq!(max_log_scale(Vec3::new(0.0, 0.0, -5.0), &[a], 0.1), None);
        // No camera: nothing is seen.
        assert_eq!(visible_points(&pts, &[], 0.1).0, Vec::<usize>::new());
    }
}
