//! D-NeRF / blender loader on a hand-written fixture: camera convention, intrinsics, RGBA
//! compositing, masks, PLY points, downscaling.

mod data_util;

use dispflow_vk::data::{self, Format, LoadOptions, PointSource};
use dispflow_vk::testing::{assert_close, Tol};
use glam::Vec3;

/// `|got − want| ≤ abs`.
const fn within(abs: f64) -> Tol {
    Tol::Elementwise { abs, rel: 0.0 }
}

#[test]
fn blender_cameras_follow_opencv_after_conversion() {
    let tmp = tempfile::tempdir().unwrap();
    data_util::blender_fixture(tmp.path());
    let ds = data::load(tmp.path(), &data_util::opts()).unwrap();
    assert_eq!(ds.format, Format::Blender);
    assert_eq!((ds.train.len(), ds.val.len()), (3, 1));
    let c = &ds.train[0].camera;
    // Identity camera-to-world in OpenGL: the camera at (0,0,4) looks down −z with y up.
    assert!((c.centre() - Vec3::new(0.0, 0.0, 4.0)).length() < 1e-6);
    assert!((c.forward() - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6);
    let fx = (0.5 * 16.0 / (0.5f64 * 0.8).tan()) as f32;
    assert_close("fx, fy", &[c.fx, c.fy], &[fx, fx], within(1e-3));
    assert_close("cx, cy", &[c.cx, c.cy], &[8.0f32, 6.0], within(1e-6));
    let (o, depth) = c.project(Vec3::ZERO).unwrap();
    assert_close("origin", &[o.x, o.y], &[8.0f32, 6.0], within(1e-4));
    assert_close("origin depth", &[depth], &[4.0f32], within(1e-5));
    // World +x is image right, world +y (up) is image up (smaller row).
    let (px, _) = c.project(Vec3::X).unwrap();
    assert_close("+x column", &[px.x], &[8.0 + fx / 4.0], within(1e-3));
    assert_close("+x row", &[px.y], &[6.0f32], within(1e-4));
    let (py, _) = c.project(Vec3::Y).unwrap();
    assert_close("+y row", &[py.y], &[6.0 - fx / 4.0], within(1e-3));
    // Per-frame intrinsics override camera_angle_x.
    let v = &ds.val[0].camera;
    assert_eq!((v.fx, v.fy, v.cx, v.cy), (30.0, 31.0, 7.0, 5.5));
    // Times kept as given (all in [0,1]).
    let times = [ds.train[2].time, ds.val[0].time];
    assert_close("times", &times, &[2.0f32 / 3.0, 0.5], within(1e-6));
}

#[test]
fn blender_rgba_composited_masks_and_ply() {
    let tmp = tempfile::tempdir().unwrap();
    data_util::blender_fixture(tmp.path());
    let opts = LoadOptions {
        background: [0.0, 0.0, 1.0],
        ..data_util::opts()
    };
    let ds = data::load(tmp.path(), &opts).unwrap();
    let im = &ds.train[1].image;
    // alpha 0 → background, alpha 255 → colour, alpha 128 → the mix.
    assert_eq!(im.pixel(0, 3), [0.0, 0.0, 1.0]);
    let c = im.pixel(10, 3);
    let colour = [200.0f32 / 255.0, 30.0 / 255.0];
    assert_close("colour", &c[..2], &colour, within(1e-6));
    let m = im.pixel(5, 0);
    let a = 128.0 / 255.0;
    let mix = [200.0f32 / 255.0 * a, 10.0 / 255.0 * a + (1.0 - a)];
    assert_close("half-transparent mix", &[m[0], m[2]], &mix, within(1e-5));
    // Masks: label > 0 → moving, train only.
    let mask = ds.train[0].mask.as_ref().unwrap();
    assert_eq!(mask[11], 0);
    assert_eq!(mask[12], 1);
    assert_eq!(mask.iter().map(|&v| v as usize).sum::<usize>(), 4 * 12);
    assert!(ds.val[0].mask.is_none());
    // PLY points with colours.
    assert!(matches!(ds.points.source, PointSource::Ply(_)));
    assert_eq!(ds.points.positions[2], Vec3::new(0.0, 1.0, 0.5));
    assert_eq!(ds.points.colors.as_ref().unwrap()[0], [1.0, 0.0, 0.0]);
    assert_eq!(ds.bounds.max, Vec3::new(1.0, 1.0, 0.5));
}

#[test]
fn blender_max_size_downscales_images_and_intrinsics() {
    let tmp = tempfile::tempdir().unwrap();
    data_util::blender_fixture(tmp.path());
    let opts = LoadOptions {
        max_size: Some(8),
        ..data_util::opts()
    };
    let ds = data::load(tmp.path(), &opts).unwrap();
    let f = &ds.val[0];
    assert_eq!((f.image.width, f.image.height), (8, 6));
    assert_eq!(f.image.data.len(), 8 * 6 * 3);
    assert_eq!((f.camera.fx, f.camera.cx, f.camera.cy), (15.0, 3.5, 2.75));
    assert_eq!(ds.train[0].mask.as_ref().unwrap().len(), 48);
    assert_eq!(ds.downscale, 2);
}

#[test]
fn blender_random_points_when_no_file() {
    let tmp = tempfile::tempdir().unwrap();
    data_util::blender_fixture(tmp.path());
    std::fs::remove_file(tmp.path().join("points3d.ply")).unwrap();
    let opts = LoadOptions {
        random_points: 500,
        ..data_util::opts()
    };
    let ds = data::load(tmp.path(), &opts).unwrap();
    assert_eq!(ds.points.source, PointSource::Random);
    assert_eq!(ds.points.positions.len(), 500);
    assert!(ds
        .points
        .positions
        .iter()
        .all(|p| p.cmpge(ds.bounds.min).all() && p.cmple(ds.bounds.max).all()));
}
