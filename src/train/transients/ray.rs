//! Ray maths of the transients' room: the ray through a pixel and where it crosses the
//! scene's bounds (spawning back-projects along it; the tracker samples depths on it).

use crate::data::Bounds;
use crate::kernels::raster::Camera;

/// The ray through pixel centre `(x + 0.5, y + 0.5)`: origin (the camera centre) and direction
/// scaled so that the parameter is the camera depth z.
pub fn pixel_ray(cam: &Camera, x: u32, y: u32) -> ([f32; 3], [f32; 3]) {
    let c = cam.centre();
    let d_cam = [
        (x as f32 + 0.5 - cam.cx) / cam.fx,
        (y as f32 + 0.5 - cam.cy) / cam.fy,
        1.0,
    ];
    // Rows of `rot` are the camera axes in world coordinates: d = rotᵀ·d_cam.
    let d = std::array::from_fn(|a| (0..3).map(|r| cam.rot[r][a] * d_cam[r]).sum());
    ([c[0] as f32, c[1] as f32, c[2] as f32], d)
}

/// The depths along ray `(o, d)` inside `b` (slab test), from at least `near`: `(z0, z1)`.
pub fn ray_box(o: [f32; 3], d: [f32; 3], b: &Bounds, near: f32) -> Option<(f32, f32)> {
    let (mut lo, mut hi) = (near, f32::INFINITY);
    let (bmin, bmax) = (b.min.to_array(), b.max.to_array());
    for a in 0..3 {
        if d[a].abs() < 1e-12 {
            if o[a] < bmin[a] || o[a] > bmax[a] {
                return None;
            }
            continue;
        }
        let (t0, t1) = ((bmin[a] - o[a]) / d[a], (bmax[a] - o[a]) / d[a]);
        lo = lo.max(t0.min(t1));
        hi = hi.min(t0.max(t1));
    }
    (lo < hi && hi.is_finite()).then_some((lo, hi))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pixel_ray_back_projects_to_its_pixel_inside_the_box() {
        let cam = Camera {
            rot: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            trans: [0.0, 0.0, 5.0],
            fx: 50.0,
            fy: 50.0,
            cx: 32.0,
            cy: 32.0,
            width: 64,
            height: 64,
            near: 0.01,
        };
        let b = Bounds {
            min: glam::Vec3::splat(-1.0),
            max: glam::Vec3::splat(1.0),
        };
        let (o, d) = pixel_ray(&cam, 31, 31);
        let (z0, z1) = ray_box(o, d, &b, 0.01).expect("hits the box");
        assert!(
            (z0 - 4.0).abs() < 1e-4 && (z1 - 6.0).abs() < 1e-4,
            "{z0} {z1}"
        );
        // A slanted ray leaves through a side: y = −1 at depth 1/(11.5/50) from the centre.
        let (o, d) = pixel_ray(&cam, 40, 20);
        let (z0, z1) = ray_box(o, d, &b, 0.01).expect("hits the box");
        assert!(
            (z0 - 4.0).abs() < 1e-4 && (z1 - 50.0 / 11.5).abs() < 1e-4,
            "{z0} {z1}"
        );
        let p: [f32; 3] = std::array::from_fn(|a| o[a] + d[a] * 5.0);
        let q: [f32; 3] = std::array::from_fn(|r| {
            (0..3).map(|a| cam.rot[r][a] * p[a]).sum::<f32>() + cam.trans[r]
        });
        let (u, v) = (cam.fx * q[0] / q[2] + cam.cx, cam.fy * q[1] / q[2] + cam.cy);
        assert!((u - 40.5).abs() < 1e-3 && (v - 20.5).abs() < 1e-3 && (q[2] - 5.0).abs() < 1e-4);
        // A ray that misses the box.
        assert!(ray_box(o, [0.0, 1.0, 0.0], &b, 0.01).is_none());
    }
}
