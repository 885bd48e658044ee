//! nerfies loader on hand-written fixtures: undistortion, scaling, time, split rule, points.

mod data_util;

use dispflow_vk::data::points::{read_ply, umeyama};
use dispflow_vk::data::{self, nerfies, Distortion, LoadOptions, PointSource};
use glam::{DMat3, DVec2, DVec3, Vec3};
use serde_json::json;

/// A smooth pattern on normalised pinhole coordinates.
fn pattern(x: f64, y: f64) -> f64 {
    0.5 + 0.4 * (6.0 * x).sin() * (5.0 * y).cos()
}

#[test]
fn distorted_images_are_resampled_to_the_pinhole_camera() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let (w, h) = (96u32, 80u32);
    let ids = data_util::nerfies_fixture(dir, 2, w, h);
    let (f, cx, cy) = (70.0, 52.0, 37.0);
    let dist = Distortion {
        k1: -0.25,
        k2: 0.05,
        k3: 0.0,
        p1: 0.02,
        p2: -0.01,
        skew: 0.0,
    };
    // Render the pattern as the distorted camera sees it.
    let mut px = Vec::new();
    for j in 0..h {
        for i in 0..w {
            let pd = DVec2::new((i as f64 + 0.5 - cx) / f, (j as f64 + 0.5 - cy) / f);
            let p = dist.undistort(pd);
            let v = (pattern(p.x, p.y) * 255.0).round() as u8;
            px.extend_from_slice(&[v, v, v]);
        }
    }
    for id in &ids {
        data_util::save_rgb8(&dir.join(format!("rgb/1x/{id}.png")), w, h, &px);
        data_util::write_json(
            &dir.join(format!("camera/{id}.json")),
            &data_util::nerfies_camera(
                [0.0, 0.0, -5.0],
                f,
                [cx, cy],
                [dist.k1, dist.k2, dist.k3],
                [dist.p1, dist.p2],
                [w, h],
            ),
        );
    }
    let ds = data::load(dir, &data_util::opts()).unwrap();
    let fr = &ds.train[0];
    assert_eq!(
        (fr.camera.cx, fr.camera.cy, fr.camera.fx),
        (52.0, 37.0, 70.0)
    );
    assert!(ds.warnings.iter().any(|w| w.contains("distortion")));
    let (mut err, mut err_raw, mut n) = (0.0, 0.0, 0);
    for j in 8..h - 8 {
        for i in 8..w - 8 {
            let x = (i as f64 + 0.5 - cx) / f;
            let y = (j as f64 + 0.5 - cy) / f;
            let want = pattern(x, y);
            err += (fr.image.pixel(i, j)[0] as f64 - want).abs();
            err_raw += (px[((j * w + i) * 3) as usize] as f64 / 255.0 - want).abs();
            n += 1;
        }
    }
    let (err, err_raw) = (err / n as f64, err_raw / n as f64);
    assert!(err < 0.01, "mean error after undistortion {err}");
    assert!(
        err_raw > 5.0 * err,
        "raw image error {err_raw} vs undistorted {err}"
    );
}

#[test]
fn cameras_times_and_normalisation_follow_the_json() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let ids = data_util::nerfies_fixture(dir, 5, 32, 24);
    let ds = data::load(dir, &data_util::opts()).unwrap();
    assert_eq!((ds.train.len(), ds.val.len()), (4, 1));
    assert_eq!(ds.val[0].id, ids[0]);
    // time_id 10, 12, ..., 18 → 0, 0.25, ..., 1.
    for f in ds.frames() {
        let k: usize = f.id[1..].parse().unwrap();
        assert!((f.time - k as f32 * 0.25).abs() < 1e-6);
        // (position − center)·scale with center (1,2,3), scale 0.5.
        let want = (Vec3::new(0.0, 0.0, -5.0 + 0.1 * k as f32) - Vec3::new(1.0, 2.0, 3.0)) * 0.5;
        assert!((f.camera.centre() - want).length() < 1e-6);
        assert_eq!((f.camera.cx, f.camera.cy), (18.0, 11.0));
    }
    assert_eq!(ds.near_far, Some((0.1, 5.0)));
}

#[test]
fn warp_id_legacy_tangential_and_split_rule() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let ids = data_util::nerfies_fixture(dir, 10, 16, 16);
    // No train_ids / val_ids: every 8th id is val.
    data_util::write_json(&dir.join("dataset.json"), &json!({"ids": ids}));
    // No time_id: warp_id (0..9).
    let meta: serde_json::Map<String, serde_json::Value> = ids
        .iter()
        .enumerate()
        .map(|(k, id)| (id.clone(), json!({"warp_id": 9 - k})))
        .collect();
    data_util::write_json(&dir.join("metadata.json"), &serde_json::Value::Object(meta));
    // An older camera file with `tangential`.
    let cam = dir.join(format!("camera/{}.json", ids[3]));
    let mut v: serde_json::Value = serde_json::from_slice(&std::fs::read(&cam).unwrap()).unwrap();
    let o = v.as_object_mut().unwrap();
    o.remove("tangential_distortion");
    o.insert("tangential".into(), json!([0.001, 0.002]));
    data_util::write_json(&cam, &v);
    let c = nerfies::read_camera(&cam).unwrap();
    assert_eq!((c.distortion.p1, c.distortion.p2), (0.001, 0.002));

    let ds = data::load(dir, &data_util::opts()).unwrap();
    let val: Vec<&str> = ds.val.iter().map(|f| f.id.as_str()).collect();
    assert_eq!(val, [ids[0].as_str(), ids[8].as_str()]);
    assert_eq!(ds.train.len(), 8);
    assert_eq!(ds.val[0].time, 1.0);
    assert!(ds.warnings.iter().any(|w| w.contains("not monotone")));
    assert!(ds.notes.iter().any(|n| n.contains("warp_id")));
}

#[test]
fn rgb_scale_directories_and_max_size() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let ids = data_util::nerfies_fixture(dir, 3, 40, 24);
    for id in &ids {
        data_util::save_rgb8(
            &dir.join(format!("rgb/2x/{id}.png")),
            20,
            12,
            &[128u8; 20 * 12 * 3],
        );
    }
    let load = |downscale, max_size| {
        data::load(
            dir,
            &LoadOptions {
                downscale,
                max_size,
                ..data_util::opts()
            },
        )
        .unwrap()
    };
    let c = load(None, None).train[0].camera;
    assert_eq!(
        (c.width, c.height, c.fx, c.cx, c.cy),
        (40, 24, 50.0, 22.0, 11.0)
    );
    let c = load(Some(2), None).train[0].camera;
    assert_eq!(
        (c.width, c.height, c.fx, c.cx, c.cy),
        (20, 12, 25.0, 11.0, 5.5)
    );
    // max 20 → rgb/2x; max 10 → rgb/2x then a further 2× box downscale.
    assert_eq!(load(None, Some(20)).train[0].camera.width, 20);
    let ds = load(None, Some(10));
    let c = ds.train[0].camera;
    assert_eq!((c.width, c.height, c.fx, c.cx), (10, 6, 12.5, 5.5));
    assert_eq!(ds.downscale, 2);
    assert_eq!(ds.train[0].image.pixel(3, 3), [128.0 / 255.0; 3]);
    // A missing scale directory is an error naming it.
    let e = data::load(
        dir,
        &LoadOptions {
            downscale: Some(4),
            ..data_util::opts()
        },
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("rgb/4x"), "{e}");
}

#[test]
fn points_from_npy_then_ply_then_random() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    data_util::nerfies_fixture(dir, 2, 16, 16);
    // Random fallback in the camera bounds (no scene bbox).
    let ds = data::load(
        dir,
        &LoadOptions {
            random_points: 64,
            ..data_util::opts()
        },
    )
    .unwrap();
    assert_eq!(ds.points.source, PointSource::Random);
    assert_eq!(ds.points.positions.len(), 64);
    // PLY, normalised like the cameras.
    std::fs::write(
        dir.join("points3d.ply"),
        "ply\nformat ascii 1.0\nelement vertex 2\nproperty double x\nproperty double y\nproperty double z\nend_header\n1 2 3\n3 2 1\n",
    )
    .unwrap();
    let ds = data::load(dir, &data_util::opts()).unwrap();
    assert!(matches!(ds.points.source, PointSource::Ply(_)));
    assert_eq!(
        ds.points.positions,
        vec![Vec3::ZERO, Vec3::new(1.0, 0.0, -1.0)]
    );
    // points.npy wins.
    std::fs::write(
        dir.join("points.npy"),
        npy_f32(&[2, 3], &[1.0, 2.0, 5.0, 1.0, 2.0, 3.0]),
    )
    .unwrap();
    let ds = data::load(dir, &data_util::opts()).unwrap();
    assert!(matches!(ds.points.source, PointSource::Npy(_)));
    assert_eq!(ds.points.positions[0], Vec3::new(0.0, 0.0, 1.0));
    // ...unless overridden.
    let ds = data::load(
        dir,
        &LoadOptions {
            points: data::PointsPreference::Ply,
            ..data_util::opts()
        },
    )
    .unwrap();
    assert!(matches!(ds.points.source, PointSource::Ply(_)));
}

/// A little-endian float32 .npy file (written by hand here to test the reader independently).
pub fn npy_f32(shape: &[usize], data: &[f32]) -> Vec<u8> {
    let shape_s: Vec<String> = shape.iter().map(|s| s.to_string()).collect();
    let tail = if shape.len() == 1 { "," } else { "" };
    let mut header = format!(
        "{{'descr': '<f4', 'fortran_order': False, 'shape': ({}{tail}), }}",
        shape_s.join(", ")
    );
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

#[test]
fn binary_ply_is_read() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("b.ply");
    let mut bytes = b"ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n".to_vec();
    for (xyz, rgb) in [
        ([1.0f32, 2.0, 3.0], [255u8, 0, 51]),
        ([-1.0, 0.5, 0.25], [0, 255, 0]),
    ] {
        for v in xyz {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        bytes.extend_from_slice(&rgb);
    }
    std::fs::write(&p, bytes).unwrap();
    let (pts, cols) = read_ply(&p).unwrap();
    assert_eq!(
        pts,
        vec![DVec3::new(1.0, 2.0, 3.0), DVec3::new(-1.0, 0.5, 0.25)]
    );
    assert_eq!(cols.unwrap()[0], [1.0, 0.0, 0.2]);
}

#[test]
fn umeyama_recovers_a_similarity() {
    let rot = DMat3::from_axis_angle(DVec3::new(0.2, -0.7, 0.4).normalize(), 2.1);
    let (s, t) = (3.7, DVec3::new(-1.0, 4.0, 0.5));
    let src: Vec<DVec3> = (0..20)
        .map(|i| {
            let i = i as f64;
            DVec3::new((i * 0.37).sin() * 3.0, (i * 0.91).cos(), i * 0.1)
        })
        .collect();
    let dst: Vec<DVec3> = src.iter().map(|p| s * (rot * *p) + t).collect();
    let (sim, rms) = umeyama(&src, &dst).unwrap();
    assert!(rms < 1e-9, "{rms}");
    assert!((sim.scale - s).abs() < 1e-9);
    assert!((sim.translation - t).length() < 1e-9);
    assert!((sim.rotation - rot)
        .to_cols_array()
        .iter()
        .all(|e| e.abs() < 1e-9));
    // Too few or degenerate pairs give None.
    assert!(umeyama(&src[..2], &dst[..2]).is_none());
    let same = vec![DVec3::ONE; 5];
    assert!(umeyama(&same, &same).is_none());
}
