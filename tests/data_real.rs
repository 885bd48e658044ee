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
    // `--background auto` composites it on the floor's colour (white) and warns no more.
    let pick = data::background::pick_background(&dir).unwrap();
    assert_eq!(pick.white, warned, "{name}: {}", pick.reason);
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

/// `../shared/data/dnerf/<scene>`.
fn dnerf(scene: &str) -> Option<std::path::PathBuf> {
    data_util::shared_data(&format!("dnerf/{scene}"))
}

#[test]
fn dnerf_first_test_frame_has_the_camera_its_json_gives() {
    let Some(dir) = dnerf("hook") else {
        return;
    };
    let ds = data::load(&dir, &data_util::opts()).unwrap();
    // The protocol scores the test split (transforms_test.json: 20 frames; 100 to train).
    assert_eq!((ds.train.len(), ds.val.len()), (100, 20));
    let f = &ds.val[0];
    assert_eq!(f.id, "./test/r_000");
    assert_eq!(f.time, 0.0);
    let c = &f.camera;
    // By hand from transforms_test.json: camera_angle_x 0.6911112070083618 at 400 px gives
    // fx = fy = 200 / tan(0.3455556) = 555.5555; centre = the matrix's last column; the
    // camera looks along minus its third column (OpenGL z backward).
    assert_eq!((c.width, c.height), (400, 400));
    assert!(
        (c.fx - 555.555_5).abs() < 1e-3 && (c.fy - c.fx).abs() < 1e-6,
        "{c:?}"
    );
    assert!(c.cx == 200.0 && c.cy == 200.0);
    let centre = Vec3::new(0.389_316_27, 2.121_521_5, 3.405_521_9);
    assert!((c.centre() - centre).length() < 1e-5, "{:?}", c.centre());
    let forward = -Vec3::new(0.096_577_47, 0.526_284_7, 0.844_806);
    assert!((c.forward() - forward).length() < 1e-5, "{:?}", c.forward());
    // The object at the origin is in front of the camera, inside the image.
    let (px, depth) = c.project(Vec3::ZERO).unwrap();
    assert!(c.contains(px) && depth > 0.0, "{px:?} {depth}");
}

#[test]
fn dnerf_split_quirks_lego_val_and_jumpingjacks_stray_copies() {
    let (Some(lego), Some(jj)) = (dnerf("lego"), dnerf("jumpingjacks")) else {
        return;
    };
    // lego's val split has 11 frames (the others 20); the test split (20) is what is scored.
    assert_eq!(
        data::blender::read_transforms(&lego, "val").unwrap().len(),
        11
    );
    assert_eq!(data::blender::val_split_name(&lego), Some("test"));
    // jumpingjacks carries train/transforms.json-style copies inside its split folders: the
    // loader reads transforms_<split>.json only (200 train, 20 test frames, images from train/).
    assert!(jj.join("train/transforms.json").is_file());
    let opts = LoadOptions {
        keep_pixels: false,
        ..data_util::opts()
    };
    let ds = data::load(&jj, &opts).unwrap();
    assert_eq!((ds.train.len(), ds.val.len()), (200, 20));
    assert!(ds.train.iter().all(|f| f.id.starts_with("./train/r_")));
    assert!(ds.val.iter().all(|f| f.id.starts_with("./test/r_")));
}

#[test]
fn dnerf_rgba_is_composited_on_the_protocols_background() {
    let Some(dir) = dnerf("mutant") else {
        return;
    };
    // Every D-NeRF view is mostly transparent (one object): `auto` keeps the official black.
    let pick = data::background::pick_background(&dir).unwrap();
    assert!(
        !pick.white && pick.reason.contains("agree"),
        "{}",
        pick.reason
    );
    let load = |bg: [f32; 3]| {
        let opts = LoadOptions {
            background: bg,
            max_size: Some(100),
            ..data_util::opts()
        };
        data::load(&dir, &opts).unwrap()
    };
    let (black, white) = (load([0.0; 3]), load([1.0; 3]));
    let (b, w) = (&black.val[0].image, &white.val[0].image);
    // A corner is clear: the background itself. Where the two differ they differ by the
    // clear fraction (c·a + bg·(1 − a)), never by more than 1.
    assert_eq!((b.pixel(0, 0), w.pixel(0, 0)), ([0.0; 3], [1.0; 3]));
    let clear: Vec<f32> = (b.data.iter().zip(&w.data)).map(|(b, w)| w - b).collect();
    assert!(clear.iter().all(|d| (-1e-6..=1.0 + 1e-6).contains(d)));
    let opaque = clear.chunks(3).filter(|d| d[0] < 0.01).count() as f32;
    let n = (b.width * b.height) as f32;
    assert!(
        opaque / n > 0.02 && opaque / n < 0.6,
        "object covers {}",
        opaque / n
    );
}
