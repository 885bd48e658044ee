//! Helpers shared by the data tests: fixture writers and the shared-data lookup.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use dispflow_vk::data::LoadOptions;
use serde_json::{json, Value};

/// `../shared/data/<name>` relative to the crate root, or `None` (printing why) when absent.
pub fn shared_data(name: &str) -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data")
        .join(name);
    if p.is_dir() {
        Some(p)
    } else {
        dispflow_vk::testing::skip(
            &format!("tests on ../shared/data/{name}"),
            &format!("{} not found", p.display()),
        );
        None
    }
}

pub fn opts() -> LoadOptions {
    LoadOptions {
        progress: false,
        ..LoadOptions::default()
    }
}

pub fn write_json(path: &Path, v: &Value) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, serde_json::to_string_pretty(v).unwrap()).unwrap();
}

pub fn save_rgb8(path: &Path, w: u32, h: u32, data: &[u8]) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::save_buffer_with_format(
        path,
        data,
        w,
        h,
        image::ExtendedColorType::Rgb8,
        image::ImageFormat::Png,
    )
    .unwrap();
}

pub fn save_png(path: &Path, w: u32, h: u32, data: &[u8], ty: image::ExtendedColorType) {
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    image::save_buffer_with_format(path, data, w, h, ty, image::ImageFormat::Png).unwrap();
}

/// A nerfies camera JSON.
#[allow(clippy::too_many_arguments)]
pub fn nerfies_camera(
    position: [f64; 3],
    f: f64,
    pp: [f64; 2],
    radial: [f64; 3],
    tangential: [f64; 2],
    size: [u32; 2],
) -> Value {
    json!({
        "orientation": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        "position": position,
        "focal_length": f,
        "principal_point": pp,
        "skew": 0.0,
        "pixel_aspect_ratio": 1.0,
        "radial_distortion": radial,
        "tangential_distortion": tangential,
        "image_size": size,
    })
}

/// A minimal nerfies dataset with `n` frames of `w×h` grey images at rgb/1x (camera at
/// `(0, 0, -5 + k·0.1)` looking down +z), scene.json center (1,2,3) scale 0.5.
pub fn nerfies_fixture(dir: &Path, n: usize, w: u32, h: u32) -> Vec<String> {
    let ids: Vec<String> = (0..n).map(|k| format!("f{k:03}")).collect();
    write_json(
        &dir.join("dataset.json"),
        &json!({"count": n, "ids": ids, "train_ids": ids[1..], "val_ids": [ids[0]]}),
    );
    let meta: serde_json::Map<String, Value> = ids
        .iter()
        .enumerate()
        .map(|(k, id)| (id.clone(), json!({"time_id": 10 + 2 * k, "warp_id": k})))
        .collect();
    write_json(&dir.join("metadata.json"), &Value::Object(meta));
    write_json(
        &dir.join("scene.json"),
        &json!({"scale": 0.5, "center": [1.0, 2.0, 3.0], "near": 0.1, "far": 5.0}),
    );
    for (k, id) in ids.iter().enumerate() {
        write_json(
            &dir.join(format!("camera/{id}.json")),
            &nerfies_camera(
                [0.0, 0.0, -5.0 + 0.1 * k as f64],
                50.0,
                [w as f64 * 0.5 + 2.0, h as f64 * 0.5 - 1.0],
                [0.0; 3],
                [0.0; 2],
                [w, h],
            ),
        );
        let px: Vec<u8> = (0..w * h * 3).map(|i| (i * 7 % 251) as u8).collect();
        save_rgb8(&dir.join(format!("rgb/1x/{id}.png")), w, h, &px);
    }
    ids
}

/// A small D-NeRF dataset: 3 train frames and 1 test frame, 16×12 RGBA, masks for train.
/// Frame 0 camera is at (0,0,4) with the identity camera-to-world rotation (looking down −z).
pub fn blender_fixture(dir: &Path) {
    let (w, h) = (16u32, 12u32);
    let mut frames = Vec::new();
    for k in 0..3 {
        let x = k as f64 * 0.5;
        frames.push(json!({
            "file_path": format!("./train/r_{k:03}"),
            "time": k as f64 / 3.0,
            "transform_matrix": [[1.0, 0.0, 0.0, x], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 4.0], [0.0, 0.0, 0.0, 1.0]],
        }));
        let mut rgba = Vec::new();
        for j in 0..h {
            for i in 0..w {
                let a = if i < 4 {
                    0
                } else if i < 8 {
                    128
                } else {
                    255
                };
                rgba.extend_from_slice(&[200, (10 * j) as u8, (10 * k) as u8, a]);
            }
        }
        save_png(
            &dir.join(format!("train/r_{k:03}.png")),
            w,
            h,
            &rgba,
            image::ExtendedColorType::Rgba8,
        );
        let labels: Vec<u8> = (0..w * h)
            .map(|i| if i % w >= 12 { 2 } else { 0 })
            .collect();
        save_png(
            &dir.join(format!("train/masks/r_{k:03}.png")),
            w,
            h,
            &labels,
            image::ExtendedColorType::L8,
        );
    }
    write_json(
        &dir.join("transforms_train.json"),
        &json!({"camera_angle_x": 0.8, "frames": frames}),
    );
    write_json(
        &dir.join("transforms_test.json"),
        &json!({"camera_angle_x": 0.8, "frames": [{
            "file_path": "./test/r_000", "time": 0.5, "fl_x": 30.0, "fl_y": 31.0, "cx": 7.0, "cy": 5.5,
            "w": w, "h": h,
            "transform_matrix": [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 3.0], [0.0, 0.0, 0.0, 1.0]],
        }]}),
    );
    save_rgb8(
        &dir.join("test/r_000.png"),
        w,
        h,
        &vec![90u8; (w * h * 3) as usize],
    );
    let ply = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n0 0 0 255 0 0\n1 0 0 0 255 0\n0 1 0.5 0 0 255\n";
    std::fs::write(dir.join("points3d.ply"), ply).unwrap();
}

/// A little-endian `.npy` file with the given dtype descr (`<f4`, `<f8`, `<i4`) and raw data.
pub fn npy_bytes(descr: &str, shape: &[usize], data: &[u8]) -> Vec<u8> {
    let shape_s: Vec<String> = shape.iter().map(|s| s.to_string()).collect();
    let tail = if shape.len() == 1 { "," } else { "" };
    let mut header = format!(
        "{{'descr': '{descr}', 'fortran_order': False, 'shape': ({}{tail}), }}",
        shape_s.join(", ")
    );
    while (10 + header.len() + 1) % 64 != 0 {
        header.push(' ');
    }
    header.push('\n');
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(data);
    out
}

pub fn f32_bytes(v: &[f32]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}
