//! The scoring half of the reference harness (`dispflow-vk score-renders`, issue 38): a
//! folder of renders in, a sweep cell and a `results.jsonl` line out, scored by this
//! project's evaluation. Renders made here: the tiny scene's test frames with a known
//! perturbation saved as 8-bit PNGs, so the expected PSNR is computed independently (on the
//! host, in f64) from the very pixels written.

mod train_common;

use std::path::Path;

use dispflow_vk::data::{self, LoadOptions};
use dispflow_vk::results::read_results;
use train_common::tiny_scene;

/// Writes `img` (RGB in [0,1], `w·h·3`) as an 8-bit PNG and returns the values as saved.
fn save_png(path: &Path, w: u32, h: u32, img: &[f32]) -> Vec<f32> {
    let bytes: Vec<u8> = img
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    image::RgbImage::from_raw(w, h, bytes.clone())
        .unwrap()
        .save(path)
        .unwrap();
    bytes.iter().map(|&b| b as f32 / 255.0).collect()
}

fn psnr(a: &[f32], b: &[f32]) -> f64 {
    let mse = a
        .iter()
        .zip(b)
        .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
        .sum::<f64>()
        / a.len() as f64;
    10.0 * (1.0 / mse).log10()
}

/// The tiny built-in scene written under `dir`, and loaded as `score-renders` loads it.
fn tiny(dir: &Path) -> (std::path::PathBuf, data::Dataset) {
    let scene = tiny_scene(dir);
    let opts = LoadOptions {
        progress: false,
        ..LoadOptions::default()
    };
    let ds = data::load(&scene, &opts).unwrap();
    (scene, ds)
}

fn score(args: &[&str]) -> (bool, String) {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_dispflow-vk"))
        .arg("score-renders")
        .args(args)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    (o.status.success(), text)
}

#[test]
fn renders_are_scored_into_a_sweep_cell_that_the_report_tables() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, ds) = tiny(tmp.path());
    assert!(ds.val.len() >= 2, "the tiny scene has test frames");
    let renders = tmp.path().join("renders");
    std::fs::create_dir_all(&renders).unwrap();
    let mut want = Vec::new();
    for (i, f) in ds.val.iter().enumerate() {
        let (w, h) = (f.image.width, f.image.height);
        // A deterministic perturbation whose size differs per frame: a known PSNR each.
        let amp = 0.02 * (i + 1) as f32;
        let noisy: Vec<f32> = f
            .image
            .data
            .iter()
            .enumerate()
            .map(|(k, v)| v + amp * if (k * 7 + i) % 3 == 0 { 1.0 } else { -1.0 })
            .collect();
        let saved = save_png(&renders.join(format!("{i:05}.png")), w, h, &noisy);
        want.push(psnr(&saved, &f.image.data));
    }
    let out = tmp.path().join("sweep");
    let (ok, text) = score(&[
        "--data",
        scene.to_str().unwrap(),
        "--renders",
        renders.to_str().unwrap(),
        "--iterations",
        "1000",
        "--train-seconds",
        "50",
        "--commit",
        "ac42372",
        "--scene",
        "tiny",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    let cell = out.join("cells/tiny/official_Deformable-3DGS/seed0");
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(cell.join("metrics.json")).unwrap()).unwrap();
    let per = m["per_frame"].as_array().unwrap();
    assert_eq!(per.len(), ds.val.len());
    for (p, w) in per.iter().zip(&want) {
        let got = p["psnr"].as_f64().unwrap();
        assert!((got - w).abs() < 1e-3, "{}: {got} vs {w}", p["file"]);
        let ssim = p["ssim"].as_f64().unwrap();
        assert!(ssim > 0.0 && ssim < 1.0, "{p}");
        // The tiny scene has motion masks: both regions are scored.
        assert!(
            p["dynamic_psnr"].is_f64() && p["static_psnr"].is_f64(),
            "{p}"
        );
    }
    assert_eq!(m["seconds_per_iteration"].as_f64(), Some(0.05));
    let worst = want.iter().copied().fold(f64::INFINITY, f64::min);
    assert!((m["worst_psnr"].as_f64().unwrap() - worst).abs() < 1e-3);

    // The results line: a cell result the sweep's report reads.
    let rs = read_results(&out.join("results.jsonl")).unwrap();
    assert_eq!(rs.len(), 1);
    let r = &rs[0];
    assert_eq!(
        (r.method.as_str(), r.scene.as_str(), r.iterations),
        ("official Deformable-3DGS", "tiny", 1000)
    );
    assert_eq!(r.config["commit"], "ac42372");
    assert_eq!(r.ms_per_step, Some(50.0));
    let mean = want.iter().sum::<f64>() / want.len() as f64;
    assert!((r.psnr - mean).abs() < 1e-3, "{} vs {mean}", r.psnr);
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_dispflow-vk"))
        .args(["sweep", "report"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let image = std::fs::read_to_string(out.join("tables/image.md")).unwrap();
    assert!(image.contains("official Deformable-3DGS"), "{image}");
}

/// The dataset's own frames scored against themselves (the official run's `gt/` folder at the
/// stored resolution): every frame is pixel-identical and scores the cap, 100 dB, in a cell
/// the report reads (∞ would be written as JSON null and refused).
#[test]
fn identical_frames_score_the_cap() {
    let tmp = tempfile::tempdir().unwrap();
    let (scene, ds) = tiny(tmp.path());
    let gt = tmp.path().join("gt");
    std::fs::create_dir_all(&gt).unwrap();
    for (i, f) in ds.val.iter().enumerate() {
        let saved = save_png(
            &gt.join(format!("{i:05}.png")),
            f.image.width,
            f.image.height,
            &f.image.data,
        );
        assert_eq!(
            saved, f.image.data,
            "the 8-bit frames survive a PNG round trip"
        );
    }
    let out = tmp.path().join("sweep");
    let (ok, text) = score(&[
        "--data",
        scene.to_str().unwrap(),
        "--renders",
        gt.to_str().unwrap(),
        "--iterations",
        "1",
        "--scene",
        "gt",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{text}");
    let rs = read_results(&out.join("results.jsonl")).unwrap();
    assert_eq!(rs[0].psnr, dispflow_vk::eval::reference::PSNR_CAP);
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_dispflow-vk"))
        .args(["sweep", "report"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn a_wrong_folder_is_refused_by_name() {
    let tmp = tempfile::tempdir().unwrap();
    let scene = tiny_scene(tmp.path());
    let renders = tmp.path().join("renders");
    std::fs::create_dir_all(&renders).unwrap();
    // One render too few.
    save_png(&renders.join("00000.png"), 64, 64, &vec![0.5; 64 * 64 * 3]);
    let sweep = tmp.path().join("s");
    let base = [
        "--data",
        scene.to_str().unwrap(),
        "--renders",
        renders.to_str().unwrap(),
        "--iterations",
        "10",
        "--out",
        sweep.to_str().unwrap(),
    ];
    let (ok, text) = score(&base);
    assert!(!ok);
    assert!(
        text.contains("1 PNG files") && text.contains("one render per frame"),
        "{text}"
    );
    // The right count at the wrong size.
    let ds = data::load(
        &scene,
        &LoadOptions {
            progress: false,
            ..LoadOptions::default()
        },
    )
    .unwrap();
    for i in 0..ds.val.len() {
        save_png(
            &renders.join(format!("{i:05}.png")),
            32,
            32,
            &vec![0.5; 32 * 32 * 3],
        );
    }
    let (ok, text) = score(&base);
    assert!(!ok);
    assert!(
        text.contains("32×32 pixels") && text.contains("64×64"),
        "{text}"
    );
    let mut zero = base;
    zero[5] = "0";
    let (ok, text) = score(&zero);
    assert!(!ok && text.contains("--iterations 0"), "{text}");
}
