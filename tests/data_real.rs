//! The real datasets in ../shared/data (skipped with a message when absent). Values are checked
//! by hand against the JSON files.

mod data_util;

use dispflow_vk::data::{self, LoadOptions, PointSource};
use glam::Vec3;

#[test]
fn movingnerf_capture1_loads_with_split_principal_point_and_undistortion() {
    let Some(dir) = data_util::shared_data("movingnerf-capture1") else {
        return;
    };
    let ds = data::load(&dir, &data_util::opts()).unwrap();
    assert_eq!((ds.train.len(), ds.val.len()), (90, 5));
    assert_eq!(ds.val[0].id, "000002");
    // camera/000004.json: focal 885.2943725585938, principal point (294.852…, 832.716…),
    // image_size 720×1280, loaded from rgb/4x → /4.
    let f = ds.train.iter().find(|f| f.id == "000004").unwrap();
    let c = &f.camera;
    assert_eq!((c.width, c.height), (180, 320));
    let pp = {
        let v: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("camera/000004.json")).unwrap())
                .unwrap();
        let p = &v["principal_point"];
        let pos = &v["position"];
        (
            p[0].as_f64().unwrap(),
            p[1].as_f64().unwrap(),
            Vec3::new(
                pos[0].as_f64().unwrap() as f32,
                pos[1].as_f64().unwrap() as f32,
                pos[2].as_f64().unwrap() as f32,
            ),
            v["focal_length"].as_f64().unwrap(),
        )
    };
    assert!((c.fx as f64 - pp.3 / 4.0).abs() < 1e-3, "fx {}", c.fx);
    assert!((c.fx as f64 - 221.3236).abs() < 1e-3);
    assert!((c.cx as f64 - pp.0 / 4.0).abs() < 1e-3 && (c.cy as f64 - pp.1 / 4.0).abs() < 1e-3);
    // Off-centre principal point kept (not replaced by the image centre).
    assert!((c.cy - 160.0).abs() > 40.0);
    // Camera centre = (position − center)·scale with scene.json.
    let center = Vec3::new(0.468_046_63, -2.315_746_8, 0.452_987_4);
    let want = (pp.2 - center) * 0.036_401_15;
    assert!(
        (c.centre() - want).length() < 1e-5,
        "{:?} vs {want:?}",
        c.centre()
    );
    // Time from warp_id (000004 has warp_id 0, the largest is 89).
    assert_eq!(f.time, 0.0);
    assert!(ds.frames().any(|f| f.time == 1.0));
    // Distortion handled: reported, and the loaded image differs from the raw PNG.
    assert!(ds.warnings.iter().any(|w| w.contains("distortion present")));
    let raw = image::open(&f.image_path).unwrap().into_rgb8();
    let diff: f32 = raw
        .pixels()
        .zip(f.image.data.chunks(3))
        .map(|(a, b)| (a[0] as f32 / 255.0 - b[0]).abs())
        .sum::<f32>()
        / (180.0 * 320.0);
    assert!(
        diff > 0.005,
        "undistorted image equals the raw one (mean diff {diff})"
    );
    // COLMAP points aligned to the JSON frame: most land in front of camera 000004 and inside it.
    match &ds.points.source {
        PointSource::Colmap { rms_residual, .. } => assert!(*rms_residual < 1e-4),
        other => panic!("expected aligned COLMAP points, got {other:?}"),
    }
    let n = ds.points.positions.len();
    let front = ds
        .points
        .positions
        .iter()
        .filter(|p| c.to_camera(**p).z > 0.0)
        .count();
    let inside = ds
        .points
        .positions
        .iter()
        .filter_map(|p| c.project(*p))
        .filter(|(px, _)| c.contains(*px))
        .count();
    assert!(front as f32 > 0.95 * n as f32, "{front} of {n} in front");
    assert!(inside as f32 > 0.85 * n as f32, "{inside} of {n} inside");
}

#[test]
fn movingnerf_capture1_downscale_picks_rgb_8x() {
    let Some(dir) = data_util::shared_data("movingnerf-capture1") else {
        return;
    };
    let opts = LoadOptions {
        max_size: Some(160),
        keep_pixels: false,
        ..data_util::opts()
    };
    let ds = data::load(&dir, &opts).unwrap();
    let c = &ds.train[0].camera;
    assert_eq!((c.width, c.height), (90, 160));
    assert!((c.fx - 885.294_4 / 8.0).abs() < 1e-3);
    assert!(ds.notes.iter().any(|n| n.contains("rgb/8x")));
}

fn check_mujoco(name: &str) {
    let Some(dir) = data_util::shared_data(name) else {
        return;
    };
    // Full resolution without keeping pixels: intrinsics as in the JSON.
    let full = data::load(
        &dir,
        &LoadOptions {
            keep_pixels: false,
            ..data_util::opts()
        },
    )
    .unwrap();
    let c0 = &full.train[0].camera;
    // transforms_train.json frame 0: fl_x 857.8027682038233, cx = cy = 400, w = h = 800.
    assert_eq!((c0.width, c0.height), (800, 800));
    assert!((c0.fx - 857.802_8).abs() < 1e-3 && c0.cx == 400.0 && c0.cy == 400.0);
    assert!(full.frames().all(|f| f.mask.is_some()));
    assert!(full.train.len() > 100 && !full.val.is_empty());
    // Reduced resolution with pixels: masks label > 0 cover the objects.
    let ds = data::load(
        &dir,
        &LoadOptions {
            max_size: Some(200),
            ..data_util::opts()
        },
    )
    .unwrap();
    let f = &ds.train[0];
    assert_eq!((f.image.width, f.image.height), (200, 200));
    assert!((f.camera.fx - 857.802_8 / 4.0).abs() < 1e-3);
    let m = f.mask.as_ref().unwrap();
    let frac = m.iter().map(|&v| v as f32).sum::<f32>() / m.len() as f32;
    assert!(frac > 0.001 && frac < 0.5, "moving fraction {frac}");
    assert!(ds.frames().all(|f| (0.0..=1.0).contains(&f.time)));
    assert_eq!(ds.points.positions.len(), 100_000);
    // mujoco-scene5's floor is transparent from the camera above (98 %) and opaque from the
    // side; mujoco-scene7's is opaque from everywhere (0.5–45 % transparent).
    let warned = ds.warnings.iter().any(|w| w.contains("views disagree"));
    assert_eq!(
        warned,
        name == "mujoco-scene5_rapid_motion",
        "{name}: {:?}",
        ds.warnings
    );
}

#[test]
fn mujoco_scene7_deformation_loads_with_masks() {
    if let Some(dir) = data_util::shared_data("mujoco-scene7_deformation") {
        // transforms_train.json frame 0: camera at (4.5, 0, 2.25).
        let ds = data::load(
            &dir,
            &LoadOptions {
                keep_pixels: false,
                ..data_util::opts()
            },
        )
        .unwrap();
        let c = ds.train[0].camera.centre();
        assert!((c - Vec3::new(4.5, 0.0, 2.25)).length() < 1e-5);
        // It looks towards the scene (the origin is in front and projects inside the image).
        let (px, _) = ds.train[0].camera.project(Vec3::ZERO).unwrap();
        assert!(ds.train[0].camera.contains(px), "{px:?}");
    }
    check_mujoco("mujoco-scene7_deformation");
}

#[test]
fn mujoco_scene5_rapid_motion_loads_with_masks() {
    check_mujoco("mujoco-scene5_rapid_motion");
}
