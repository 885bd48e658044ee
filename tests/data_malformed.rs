//! Hundreds of malformed variants of small valid datasets: each must give an error that names
//! the offending file, never a panic and never a half-loaded dataset.

mod data_util;

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use dispflow_vk::data::{self, synthetic, LoadOptions};
use serde_json::{json, Value};

/// A named JSON edit and the substring its error must contain.
type Edit = (&'static str, Box<dyn Fn(&mut Value)>, &'static str);

/// One single-file mutation: the file's new bytes (`None` deletes it) and a substring the error
/// message must contain.
struct Variant {
    name: String,
    file: String,
    bytes: Option<Vec<u8>>,
    expect: String,
}

fn variant(name: impl Into<String>, file: &str, bytes: Option<Vec<u8>>, expect: &str) -> Variant {
    Variant {
        name: name.into(),
        file: file.into(),
        bytes,
        expect: expect.into(),
    }
}

fn json_edit(dir: &Path, file: &str, edit: impl FnOnce(&mut Value)) -> Vec<u8> {
    let mut v: Value = serde_json::from_slice(&std::fs::read(dir.join(file)).unwrap()).unwrap();
    edit(&mut v);
    serde_json::to_vec_pretty(&v).unwrap()
}

fn png(w: u32, h: u32, ty: image::ExtendedColorType, ch: usize) -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    image::write_buffer_with_format(
        &mut out,
        &vec![100u8; w as usize * h as usize * ch],
        w,
        h,
        ty,
        image::ImageFormat::Png,
    )
    .unwrap();
    out.into_inner()
}

/// Truncations and syntax breakage of a JSON file.
fn broken_json(dir: &Path, file: &str, out: &mut Vec<Variant>) {
    let orig = std::fs::read(dir.join(file)).unwrap();
    let base = Path::new(file)
        .file_name()
        .unwrap()
        .to_string_lossy()
        .into_owned();
    for k in 0..10 {
        let n = orig.len() * k / 10;
        out.push(variant(
            format!("{file} truncated to {n}"),
            file,
            Some(orig[..n].to_vec()),
            &base,
        ));
    }
    let s = String::from_utf8(orig.clone()).unwrap();
    let garbles: Vec<(&str, Vec<u8>)> = vec![
        ("colon→semicolon", s.replacen(':', ";", 1).into_bytes()),
        ("leading {{", format!("{{{{{s}").into_bytes()),
        ("last }} → ]", {
            let i = s.rfind('}').unwrap();
            format!("{}]{}", &s[..i], &s[i + 1..]).into_bytes()
        }),
        ("invalid utf-8", {
            let mut b = orig.clone();
            b.insert(orig.len() / 2, 0xff);
            b
        }),
        ("single quotes", s.replacen('"', "'", 1).into_bytes()),
        ("trailing garbage", format!("{s},,").into_bytes()),
    ];
    for (g, bytes) in garbles {
        out.push(variant(format!("{file} {g}"), file, Some(bytes), &base));
    }
}

fn run_variants(dir: &Path, variants: Vec<Variant>) -> usize {
    let opts = LoadOptions {
        random_points: 100,
        ..data_util::opts()
    };
    assert!(data::load(dir, &opts).is_ok(), "the base dataset must load");
    let mut failures = Vec::new();
    let n = variants.len();
    for v in variants {
        let path = dir.join(&v.file);
        let orig = std::fs::read(&path).ok();
        match &v.bytes {
            Some(b) => std::fs::write(&path, b).unwrap(),
            None => std::fs::remove_file(&path).unwrap(),
        }
        let r = catch_unwind(AssertUnwindSafe(|| data::load(dir, &opts)));
        match r {
            Err(_) => failures.push(format!("{}: PANICKED", v.name)),
            Ok(Ok(_)) => failures.push(format!("{}: loaded without error", v.name)),
            Ok(Err(e)) => {
                let msg = e.to_string();
                println!("{}: {msg}", v.name);
                if !msg.contains(&v.expect) {
                    failures.push(format!("{}: message {msg:?} lacks {:?}", v.name, v.expect));
                }
            }
        }
        match orig {
            Some(b) => std::fs::write(&path, b).unwrap(),
            None => {
                let _ = std::fs::remove_file(&path);
            }
        }
    }
    assert!(
        data::load(dir, &opts).is_ok(),
        "the base dataset must load after restoring"
    );
    assert!(
        failures.is_empty(),
        "{} of {n} variants failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
    n
}

#[test]
fn malformed_nerfies_variants_all_give_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    synthetic::generate(synthetic::Preset::Tiny, 11, dir).unwrap();
    let mut vs = Vec::new();

    // Deleted files.
    vs.push(variant(
        "no dataset.json",
        "dataset.json",
        None,
        "unknown dataset format",
    ));
    for f in [
        "metadata.json",
        "scene.json",
        "camera/000000.json",
        "camera/000013.json",
        "rgb/1x/000000.png",
        "rgb/1x/000020.png",
        "mask/1x/000005.png.png",
    ] {
        vs.push(variant(format!("deleted {f}"), f, None, f));
    }
    // Truncated / garbled JSON.
    for f in [
        "dataset.json",
        "metadata.json",
        "scene.json",
        "camera/000000.json",
        "camera/000007.json",
    ] {
        broken_json(dir, f, &mut vs);
    }
    // Wrong types and values in camera files.
    for id in ["000000", "000011", "000023"] {
        let f = format!("camera/{id}.json");
        let fields = [
            "orientation",
            "position",
            "focal_length",
            "principal_point",
            "image_size",
        ];
        for field in fields {
            let bad: [(&str, Option<Value>); 5] = [
                ("removed", None),
                ("string", Some(json!("x"))),
                ("null", Some(Value::Null)),
                ("short array", Some(json!([1.0]))),
                ("object", Some(json!({"a": 1}))),
            ];
            for (what, val) in bad {
                let bytes = json_edit(dir, &f, |v| {
                    let o = v.as_object_mut().unwrap();
                    match val {
                        None => {
                            o.remove(field);
                        }
                        Some(x) => {
                            o.insert(field.into(), x);
                        }
                    }
                });
                vs.push(variant(
                    format!("{f} {field} {what}"),
                    &f,
                    Some(bytes),
                    field,
                ));
            }
        }
        let png_name = format!("{id}.png");
        let values: Vec<(&str, Value, &str)> = vec![
            ("focal_length", json!(-1.0), "focal_length"),
            ("focal_length", json!(0.0), "focal_length"),
            ("image_size", json!([32, 32]), png_name.as_str()),
            ("image_size", json!([64.5, 64]), "image_size"),
            ("image_size", json!([0, 64]), "image_size"),
            (
                "orientation",
                json!([[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
                "orientation",
            ),
            (
                "orientation",
                json!([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], "x"]),
                "orientation[2]",
            ),
            (
                "orientation",
                json!([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]]),
                "orientation",
            ),
            ("pixel_aspect_ratio", json!("x"), "pixel_aspect_ratio"),
            ("pixel_aspect_ratio", json!(-1.0), "pixel_aspect_ratio"),
            ("radial_distortion", json!("x"), "radial_distortion"),
            (
                "radial_distortion",
                json!([1, 2, 3, 4, 5]),
                "radial_distortion",
            ),
            (
                "tangential_distortion",
                json!([1.0]),
                "tangential_distortion",
            ),
            ("skew", json!("x"), "skew"),
            ("position", json!([1.0, "y", 2.0]), "position[1]"),
        ];
        for (field, val, expect) in values {
            let bytes = json_edit(dir, &f, |v| {
                v.as_object_mut().unwrap().insert(field.into(), val.clone());
            });
            vs.push(variant(
                format!("{f} {field} = {val}"),
                &f,
                Some(bytes),
                expect,
            ));
        }
    }
    // dataset.json semantics.
    let ds_edits: Vec<Edit> = vec![
        ("ids number", Box::new(|v| v["ids"] = json!(5)), "ids"),
        ("ids empty", Box::new(|v| v["ids"] = json!([])), "ids"),
        (
            "ids numbers",
            Box::new(|v| v["ids"] = json!([1, 2])),
            "ids[0]",
        ),
        (
            "ids duplicate",
            Box::new(|v| v["ids"][1] = v["ids"][0].clone()),
            "ids[1]",
        ),
        (
            "ids path",
            Box::new(|v| v["ids"][2] = json!("../x")),
            "ids[2]",
        ),
        (
            "train empty",
            Box::new(|v| {
                v["val_ids"] = v["ids"].clone();
                v["train_ids"] = json!([]);
            }),
            "train_ids",
        ),
        (
            "train unknown id",
            Box::new(|v| v["train_ids"][0] = json!("nope")),
            "train_ids[0]",
        ),
        (
            "val_ids string",
            Box::new(|v| v["val_ids"] = json!("x")),
            "val_ids",
        ),
        (
            "not an object",
            Box::new(|v| *v = json!([1, 2])),
            "dataset.json",
        ),
    ];
    for (what, edit, expect) in ds_edits {
        let bytes = json_edit(dir, "dataset.json", edit);
        vs.push(variant(
            format!("dataset.json {what}"),
            "dataset.json",
            Some(bytes),
            expect,
        ));
    }
    // metadata.json.
    let md_edits: Vec<Edit> = vec![
        (
            "entry missing",
            Box::new(|v| {
                v.as_object_mut().unwrap().remove("000003");
            }),
            "000003",
        ),
        (
            "time_id string",
            Box::new(|v| v["000004"]["time_id"] = json!("x")),
            "000004.time_id",
        ),
        (
            "no time field",
            Box::new(|v| v["000005"] = json!({"camera_id": 0})),
            "000005.time_id",
        ),
        (
            "entry number",
            Box::new(|v| v["000006"] = json!(3)),
            "000006",
        ),
    ];
    for (what, edit, expect) in md_edits {
        let bytes = json_edit(dir, "metadata.json", edit);
        vs.push(variant(
            format!("metadata.json {what}"),
            "metadata.json",
            Some(bytes),
            expect,
        ));
    }
    // scene.json.
    let sc_edits: Vec<Edit> = vec![
        (
            "scale string",
            Box::new(|v| v["scale"] = json!("x")),
            "scale",
        ),
        ("scale zero", Box::new(|v| v["scale"] = json!(0.0)), "scale"),
        (
            "scale negative",
            Box::new(|v| v["scale"] = json!(-2.0)),
            "scale",
        ),
        (
            "center short",
            Box::new(|v| v["center"] = json!([1.0, 2.0])),
            "center",
        ),
        (
            "center missing",
            Box::new(|v| {
                v.as_object_mut().unwrap().remove("center");
            }),
            "center",
        ),
        (
            "near > far",
            Box::new(|v| {
                v["near"] = json!(5.0);
                v["far"] = json!(1.0);
            }),
            "near/far",
        ),
        (
            "bbox short",
            Box::new(|v| v["bbox"] = json!([[1.0, 2.0, 3.0]])),
            "bbox",
        ),
    ];
    for (what, edit, expect) in sc_edits {
        let bytes = json_edit(dir, "scene.json", edit);
        vs.push(variant(
            format!("scene.json {what}"),
            "scene.json",
            Some(bytes),
            expect,
        ));
    }
    // Images and masks.
    for id in ["000000", "000009", "000023"] {
        let f = format!("rgb/1x/{id}.png");
        let orig = std::fs::read(dir.join(&f)).unwrap();
        vs.push(variant(
            format!("{f} truncated"),
            &f,
            Some(orig[..50].to_vec()),
            &f,
        ));
        vs.push(variant(
            format!("{f} garbage"),
            &f,
            Some(b"not a png at all".to_vec()),
            &f,
        ));
        vs.push(variant(
            format!("{f} 32x32"),
            &f,
            Some(png(32, 32, image::ExtendedColorType::Rgb8, 3)),
            &f,
        ));
        vs.push(variant(format!("{f} empty"), &f, Some(Vec::new()), &f));
    }
    let m = "mask/1x/000002.png.png";
    vs.push(variant(
        "mask wrong size",
        m,
        Some(png(64, 32, image::ExtendedColorType::L8, 1)),
        m,
    ));
    vs.push(variant("mask garbage", m, Some(vec![0u8; 100]), m));
    // points.npy.
    let p = "points.npy";
    let f4 = |shape: &[usize], v: &[f32]| {
        Some(data_util::npy_bytes("<f4", shape, &data_util::f32_bytes(v)))
    };
    vs.push(variant(
        "points NaN",
        p,
        f4(&[2, 3], &[0.0, f32::NAN, 0.0, 1.0, 1.0, 1.0]),
        p,
    ));
    vs.push(variant(
        "points Inf",
        p,
        f4(&[2, 3], &[0.0, 0.0, 0.0, 1.0, f32::INFINITY, 1.0]),
        p,
    ));
    vs.push(variant("points N×2", p, f4(&[3, 2], &[0.0; 6]), p));
    vs.push(variant("points 1-D", p, f4(&[6], &[0.0; 6]), p));
    vs.push(variant("points empty", p, f4(&[0, 3], &[]), p));
    vs.push(variant("points truncated", p, f4(&[100, 3], &[1.0; 30]), p));
    vs.push(variant(
        "points int32",
        p,
        Some(data_util::npy_bytes("<i4", &[2, 3], &[0u8; 24])),
        p,
    ));
    vs.push(variant(
        "points garbage",
        p,
        Some(b"\x93NUMPY garbage".to_vec()),
        p,
    ));
    vs.push(variant(
        "points huge shape",
        p,
        Some(data_util::npy_bytes("<f4", &[1 << 40, 3], &[0u8; 12])),
        p,
    ));
    // flow.
    let fl = "flow/000001.npy";
    vs.push(variant(
        "flow wrong shape",
        fl,
        f4(&[64, 64], &[0.0; 64 * 64]),
        fl,
    ));
    vs.push(variant(
        "flow NaN",
        fl,
        f4(&[64, 64, 2], &[f32::NAN; 64 * 64 * 2]),
        fl,
    ));
    vs.push(variant("flow garbage", fl, Some(vec![1u8; 10]), fl));

    let n = run_variants(dir, vs);
    println!("{n} nerfies variants");
    assert!(n >= 200, "only {n} variants");
}

#[test]
fn malformed_blender_variants_all_give_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    data_util::blender_fixture(dir);
    let mut vs = Vec::new();
    let t = "transforms_train.json";
    vs.push(variant(
        "no transforms_train.json",
        t,
        None,
        "unknown dataset format",
    ));
    broken_json(dir, t, &mut vs);
    broken_json(dir, "transforms_test.json", &mut vs);
    let edits: Vec<Edit> = vec![
        (
            "frames empty",
            Box::new(|v| v["frames"] = json!([])),
            "frames",
        ),
        (
            "frames object",
            Box::new(|v| v["frames"] = json!({})),
            "frames",
        ),
        (
            "frame not object",
            Box::new(|v| v["frames"][1] = json!(3)),
            "frames[1]",
        ),
        (
            "time string",
            Box::new(|v| v["frames"][0]["time"] = json!("x")),
            "frames[0].time",
        ),
        (
            "time missing",
            Box::new(|v| {
                v["frames"][2].as_object_mut().unwrap().remove("time");
            }),
            "frames[2].time",
        ),
        (
            "matrix 3 rows",
            Box::new(|v| {
                v["frames"][0]["transform_matrix"]
                    .as_array_mut()
                    .unwrap()
                    .pop();
            }),
            "frames[0].transform_matrix",
        ),
        (
            "matrix scaled",
            Box::new(|v| v["frames"][0]["transform_matrix"][0][0] = json!(2.0)),
            "transform_matrix",
        ),
        (
            "matrix string entry",
            Box::new(|v| v["frames"][1]["transform_matrix"][2][1] = json!("x")),
            "frames[1].transform_matrix[2][1]",
        ),
        (
            "file_path missing",
            Box::new(|v| {
                v["frames"][0].as_object_mut().unwrap().remove("file_path");
            }),
            "frames[0].file_path",
        ),
        (
            "file_path number",
            Box::new(|v| v["frames"][0]["file_path"] = json!(7)),
            "frames[0].file_path",
        ),
        (
            "file_path escapes",
            Box::new(|v| v["frames"][0]["file_path"] = json!("../../etc/x")),
            "file_path",
        ),
        (
            "file_path missing image",
            Box::new(|v| v["frames"][0]["file_path"] = json!("./train/none")),
            "none.png",
        ),
        (
            "fl_x negative",
            Box::new(|v| v["frames"][0]["fl_x"] = json!(-1.0)),
            "fl_x",
        ),
        (
            "no focal",
            Box::new(|v| {
                v.as_object_mut().unwrap().remove("camera_angle_x");
            }),
            "fl_x",
        ),
        (
            "angle too big",
            Box::new(|v| v["camera_angle_x"] = json!(4.0)),
            "camera_angle_x",
        ),
        (
            "w wrong",
            Box::new(|v| v["frames"][1]["w"] = json!(17)),
            "r_001.png",
        ),
        (
            "h fractional",
            Box::new(|v| v["frames"][1]["h"] = json!(12.5)),
            "frames[1].h",
        ),
    ];
    for (what, edit, expect) in edits {
        let bytes = json_edit(dir, t, edit);
        vs.push(variant(format!("{t} {what}"), t, Some(bytes), expect));
    }
    let im = "train/r_001.png";
    vs.push(variant("image deleted", im, None, im));
    vs.push(variant("image garbage", im, Some(b"garbage".to_vec()), im));
    let mk = "train/masks/r_002.png";
    vs.push(variant("mask deleted", mk, None, mk));
    vs.push(variant(
        "mask wrong size",
        mk,
        Some(png(8, 8, image::ExtendedColorType::L8, 1)),
        mk,
    ));
    let ply = "points3d.ply";
    vs.push(variant("ply garbage", ply, Some(b"garbage".to_vec()), ply));
    vs.push(variant(
        "ply nan",
        ply,
        Some(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\nnan 0 0\n".to_vec()),
        ply,
    ));
    vs.push(variant(
        "ply truncated binary",
        ply,
        Some(b"ply\nformat binary_little_endian 1.0\nelement vertex 1000\nproperty float x\nproperty float y\nproperty float z\nend_header\n\0\0\0\0".to_vec()),
        ply,
    ));
    vs.push(variant(
        "ply no xyz",
        ply,
        Some(
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float a\nend_header\n1\n".to_vec(),
        ),
        ply,
    ));
    let n = run_variants(dir, vs);
    assert!(n >= 40, "{n}");
}

#[test]
fn missing_directory_and_unknown_format() {
    let tmp = tempfile::tempdir().unwrap();
    let e = data::load(&tmp.path().join("nope"), &data_util::opts())
        .unwrap_err()
        .to_string();
    assert!(e.contains("nope") && e.contains("no such directory"), "{e}");
    assert!(!e.contains("unknown dataset format"), "{e}");
    std::fs::write(tmp.path().join("readme.txt"), "hi").unwrap();
    let e = data::load(tmp.path(), &data_util::opts())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("dataset.json") && e.contains("transforms_train.json"),
        "{e}"
    );
}
