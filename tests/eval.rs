//! `eval` and `render` on a tiny trained run: metrics JSON schema and values, the Markdown
//! table, picture sizes, PLY exports that read back, and clear errors for broken runs.

mod train_common;

use std::path::{Path, PathBuf};

use dispflow_vk::eval::render::{run_render, CameraPath, RenderArgs};
use dispflow_vk::eval::run::{load_trainer, open_run, run_eval, EvalArgs};
use dispflow_vk::report::Table;
use dispflow_vk::testing;
use dispflow_vk::train::checkpoint::read_ply;
use dispflow_vk::train::cli::TrainArgs;
use train_common::{tiny_scene, tiny_toml};

fn train(data: &Path, out: &Path, motion_weight: f32) -> PathBuf {
    let cfg = out.with_extension("toml");
    std::fs::write(&cfg, tiny_toml(60)).unwrap();
    let a = TrainArgs {
        data: Some(data.to_path_buf()),
        out: Some(out.to_path_buf()),
        config: Some(cfg),
        motion_weight: Some(motion_weight),
        ..TrainArgs::default()
    };
    dispflow_vk::train::cli::run(&a).unwrap();
    out.to_path_buf()
}

fn eval_args(runs: Vec<PathBuf>) -> EvalArgs {
    EvalArgs {
        run: runs,
        data: None,
        lpips_weights: None,
        table: None,
        curves: None,
        no_pictures: false,
    }
}

fn png_size(p: &Path) -> (u32, u32) {
    let img = image::open(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    (img.width(), img.height())
}

fn pngs(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    v.sort();
    v
}

// One test: every stage opens its own Vulkan device, and validated devices must not be
// created from parallel threads (DESIGN §8).
#[test]
fn eval_and_render_a_tiny_run() {
    testing::validate_command_devices();
    let tmp = tempfile::tempdir().unwrap();
    let data = tiny_scene(tmp.path());
    let motion = train(&data, &tmp.path().join("dispflow"), 0.1);
    let base = train(&data, &tmp.path().join("baseline"), 0.0);
    let log = std::fs::read_to_string(motion.join("log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), 6, "one log line per 10 iterations");
    let lines: Vec<serde_json::Value> = log
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    for l in &lines {
        // The logged view is one of the interval's views, so the worst is at most its PSNR.
        let (worst, psnr) = (
            l["worst_psnr"]
                .as_f64()
                .unwrap_or_else(|| panic!("no worst_psnr: {l}")),
            l["psnr"].as_f64().unwrap_or_else(|| panic!("no psnr: {l}")),
        );
        assert!(worst <= psnr + 1e-9, "{l}");
        assert!(l["worst_view"].is_string());
        // The test-PSNR probe runs every test_interval (the fast preset's 50) and at the end.
        let it = l["iteration"].as_u64().unwrap();
        assert_eq!(l["test_psnr"].is_number(), it == 50 || it == 60, "{l}");
    }

    // --- eval, two runs, combined table ---
    let table_path = tmp.path().join("combined.md");
    let mut a = eval_args(vec![motion.clone(), base.clone()]);
    a.table = Some(table_path.clone());
    let curves = tmp.path().join("curves.png");
    a.curves = Some(curves.clone());
    let reports = run_eval(&a).unwrap();
    assert_eq!(reports.len(), 2);
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(motion.join("eval/metrics.json")).unwrap())
            .unwrap();
    let train_metrics: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(motion.join("metrics.json")).unwrap())
            .unwrap();
    let n_val = json["per_frame"].as_array().unwrap().len();
    assert!(n_val >= 2, "the tiny scene has test frames");
    let unit = |v: &serde_json::Value| v.as_f64().is_some_and(|x| (0.0..=1.0).contains(&x));
    assert!(json["psnr"].as_f64().unwrap().is_finite());
    assert!(unit(&json["ssim"]) && unit(&json["mmap"]) && unit(&json["drc"]));
    assert!(json["lpips"].is_null());
    assert!(json["lpips_note"].as_str().unwrap().contains("unavailable"));
    let method = json["method"].as_str().unwrap();
    assert_eq!(
        method, "Displacement Flow + Direct Scene Motion (DispFlow-GS)",
        "the paper's row name"
    );
    assert!(unit(&json["flow_mmap"]));
    // Re-evaluating the saved model reproduces the numbers training reported.
    for k in ["psnr", "ssim", "mmap", "drc"] {
        let (e, t) = (
            json[k].as_f64().unwrap(),
            train_metrics[k].as_f64().unwrap(),
        );
        assert!((e - t).abs() < 1e-3, "{k}: eval {e} vs train {t}");
    }
    for f in json["per_frame"].as_array().unwrap() {
        assert!(f["id"].is_string() && f["time"].is_number() && f["psnr"].is_number());
        assert!(unit(&f["ssim"]) && f["has_mask"].is_boolean());
        assert!(f["drc"].is_null() || unit(&f["drc"]));
    }
    // The final probe is the mean PSNR of its frames (at most 4, spread over the split) as the
    // full evaluation measures them.
    let probes = dispflow_vk::train::curve::probe_frames(n_val);
    let probe_mean = probes
        .iter()
        .map(|&i| json["per_frame"][i]["psnr"].as_f64().unwrap())
        .sum::<f64>()
        / probes.len() as f64;
    let last_probe = lines[5]["test_psnr"].as_f64().unwrap();
    assert!(
        (last_probe - probe_mean).abs() < 1e-3,
        "probe {last_probe} vs eval {probe_mean}"
    );
    // time_to_psnr: the first probe at or above each threshold reached.
    let reached = train_metrics["time_to_psnr"]
        .as_array()
        .cloned()
        .unwrap_or_default();
    for t in &reached {
        let db = t["psnr_db"].as_f64().unwrap();
        let first = lines
            .iter()
            .find(|l| l["test_psnr"].as_f64().is_some_and(|p| p >= db))
            .unwrap();
        assert_eq!(t["iteration"], first["iteration"]);
        assert_eq!(t["wall_s"], first["wall_s"]);
    }
    // Loss, training PSNR, Gaussians, test PSNR vs seconds, and on this scene (masks and
    // ground-truth flow) the probe's region PSNRs and the displacement EPE.
    let probed = lines.iter().find(|l| l["test_psnr"].is_f64()).unwrap();
    assert!(probed["test_dynamic_psnr"].is_f64() && probed["test_static_psnr"].is_f64());
    assert!(probed["motion_epe"].as_f64().unwrap() >= 0.0);
    assert!(probed["motion_gt_px"].as_f64().unwrap() > 0.0);
    assert_eq!(png_size(&motion.join("training.png")), (640, 1200));
    assert!(json["dynamic_psnr"].is_f64() && json["static_psnr"].is_f64());
    assert_eq!(png_size(&curves), (800, 400));
    let mean_psnr = json["per_frame"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["psnr"].as_f64().unwrap())
        .sum::<f64>()
        / n_val as f64;
    assert!((mean_psnr - json["psnr"].as_f64().unwrap()).abs() < 1e-9);

    let t = Table::parse_markdown(&std::fs::read_to_string(motion.join("eval/table.md")).unwrap())
        .unwrap();
    assert_eq!(t.rows.len(), 1);
    assert_eq!(t.headers[0], "Method");
    let col = |name: &str| t.headers.iter().position(|h| h.starts_with(name)).unwrap();
    let psnr_cell: f64 = t.rows[0][col("PSNR")].parse().unwrap();
    assert!((psnr_cell - json["psnr"].as_f64().unwrap()).abs() <= 0.005 + 1e-9);
    assert_eq!(t.rows[0][col("LPIPS")], "n/a");
    // --- eval with LPIPS weights (the reference fixture's): per-frame values and the column ---
    let mut a = eval_args(vec![base.clone()]);
    a.no_pictures = true;
    a.lpips_weights =
        Some(Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/lpips/alex_random_f16.safetensors"));
    let r = run_eval(&a).unwrap();
    let per: Vec<f64> = r[0].per_frame.iter().map(|f| f.lpips.unwrap()).collect();
    assert!(per.iter().all(|v| v.is_finite() && *v > 0.0), "{per:?}");
    let mean = per.iter().sum::<f64>() / per.len() as f64;
    assert!((r[0].lpips.unwrap() - mean).abs() < 1e-12);
    assert!(
        r[0].lpips_note.contains("alex_random_f16"),
        "{}",
        r[0].lpips_note
    );
    let lj: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(base.join("eval/metrics.json")).unwrap())
            .unwrap();
    assert!(lj["per_frame"][0]["lpips"].is_number() && lj["lpips"].is_number());
    let lt = Table::parse_markdown(&std::fs::read_to_string(base.join("eval/table.md")).unwrap())
        .unwrap();
    let cell: f64 = lt.rows[0][col("LPIPS")].parse().unwrap();
    assert!((cell - mean).abs() <= 5e-5 + 1e-9);

    let combined = Table::parse_markdown(&std::fs::read_to_string(&table_path).unwrap()).unwrap();
    assert_eq!(combined.rows.len(), 2);
    assert!(
        combined.rows[1][0].starts_with("Deformable 3DGS"),
        "the paper's row name"
    );

    // Pictures: one strip per test frame (render, gt, error, displacement flow, optical flow,
    // mask, dynamic mask: 7 panels of 64×64
    // with 2-px gaps under a 12-px label band), the per-frame and training plots.
    let strips = pngs(&motion.join("eval/frames"));
    assert_eq!(strips.len(), n_val);
    for p in &strips {
        assert_eq!(png_size(p), (7 * 64 + 6 * 2, 64 + 12), "{}", p.display());
    }
    assert_eq!(png_size(&motion.join("eval/per_frame.png")), (640, 480));
    assert_eq!(png_size(&motion.join("eval/training.png")), (640, 1200));

    // --- render: test path with the flow heatmap and PLY exports ---
    let out = tmp.path().join("render-test");
    let written = run_render(&RenderArgs {
        run: motion.clone(),
        data: None,
        path: CameraPath::Test,
        time: None,
        camera: None,
        frames: 60,
        flow: true,
        ply: true,
        zip: true,
        gif: true,
        fps: 12,
        out: Some(out.clone()),
    })
    .unwrap();
    assert_eq!(written.len(), n_val);
    for p in &written {
        assert_eq!(png_size(p), (3 * 64 + 2 * 2, 64 + 12)); // render | flow | dynamic
    }
    let canonical = read_ply(&out.join("ply/canonical.ply")).unwrap();
    assert_eq!(
        canonical,
        read_ply(&motion.join("point_cloud.ply")).unwrap()
    );
    // A frame's PLY reads back as exactly the deformed Gaussians of its time.
    let run = open_run(&motion, None).unwrap();
    let gpu = testing::serial_gpu();
    let (_ds, mut tr) = load_trainer(&gpu, &run).unwrap();
    let mut test: Vec<f32> = tr.val.iter().map(|f| f.time).collect();
    test.sort_by(f32::total_cmp);
    let g = tr.deformed_gaussians(test[1]).unwrap();
    let back = read_ply(&out.join("ply/frame_0001.ply")).unwrap();
    assert_eq!(back, g);
    assert_eq!(back.len(), canonical.len());
    assert_ne!(
        back.means, canonical.means,
        "the deformation moved Gaussians"
    );
    drop(tr);
    check_gif(&out.join("animation.gif"), n_val, (3 * 64 + 2 * 2, 64 + 12));
    check_sequence_zip(&out.join("ply"), n_val);

    // --- render: orbit with frozen time, fixed camera over time ---
    for (path, frames, time, camera) in [
        (CameraPath::Orbit, 4, Some(0.5), None),
        (CameraPath::Spiral, 3, None, None),
        (CameraPath::Fixed, 3, None, Some(0)),
    ] {
        let out = tmp.path().join(format!("render-{path:?}"));
        let w = run_render(&RenderArgs {
            run: motion.clone(),
            data: None,
            path,
            time,
            camera,
            frames,
            flow: false,
            ply: false,
            zip: false,
            gif: false,
            fps: 12,
            out: Some(out),
        })
        .unwrap();
        assert_eq!(w.len(), frames as usize);
        for p in &w {
            assert_eq!(png_size(p), (64, 64));
        }
    }
    let e = run_render(&RenderArgs {
        run: motion.clone(),
        data: None,
        path: CameraPath::Fixed,
        time: None,
        camera: Some(999),
        frames: 2,
        flow: false,
        ply: false,
        zip: false,
        gif: false,
        fps: 12,
        out: Some(tmp.path().join("bad")),
    })
    .unwrap_err()
    .to_string();
    assert!(e.contains("--camera 999"), "{e}");

    // A deform.bin of the wrong size is refused, before the device opens.
    let broken = tmp.path().join("broken");
    copy_run(&motion, &broken);
    std::fs::write(broken.join("deform.bin"), [0u8; 40]).unwrap();
    let e = run_eval(&eval_args(vec![broken])).unwrap_err().to_string();
    assert!(e.contains("deform.bin: 40 bytes"), "{e}");
}

fn copy_run(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for f in [
        "config.toml",
        "metrics.json",
        "point_cloud.ply",
        "deform.bin",
    ] {
        std::fs::copy(from.join(f), to.join(f)).unwrap();
    }
}

#[test]
fn broken_run_directories_give_clear_errors() {
    // All of these fail before a device is opened.
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("nope");
    let e = run_eval(&eval_args(vec![missing])).unwrap_err().to_string();
    assert!(e.contains("nope") && e.contains("not a directory"), "{e}");

    let run = tmp.path().join("run");
    std::fs::create_dir_all(&run).unwrap();
    let e = open_run(&run, None).err().unwrap().to_string();
    assert!(e.contains("config.toml") && e.contains("missing"), "{e}");

    std::fs::write(run.join("config.toml"), "iterations = 5\n").unwrap();
    std::fs::write(run.join("metrics.json"), "{ not json").unwrap();
    let e = open_run(&run, None).err().unwrap().to_string();
    assert!(e.contains("metrics.json"), "{e}");

    std::fs::write(run.join("metrics.json"), r#"{"iterations": 5}"#).unwrap();
    let e = open_run(&run, None).err().unwrap().to_string();
    assert!(e.contains("dataset"), "{e}");

    let data = tmp.path().join("data");
    std::fs::create_dir_all(&data).unwrap();
    let e = open_run(&run, Some(&data)).err().unwrap().to_string();
    assert!(
        e.contains("point_cloud.ply") && e.contains("missing"),
        "{e}"
    );

    std::fs::write(run.join("point_cloud.ply"), b"ply\nformat binary").unwrap();
    std::fs::write(run.join("deform.bin"), [0u8; 8]).unwrap();
    let e = open_run(&run, Some(&data)).err().unwrap().to_string();
    assert!(e.contains("point_cloud.ply"), "{e}");

    std::fs::write(run.join("config.toml"), "iterations = \"many\"\n").unwrap();
    let e = open_run(&run, Some(&data)).err().unwrap().to_string();
    assert!(e.contains("config.toml"), "{e}");

    let mut a = eval_args(vec![run]);
    a.lpips_weights = Some(tmp.path().join("alex.pth"));
    let e = run_eval(&a).unwrap_err().to_string();
    assert!(e.contains("alex.pth") && e.contains("LPIPS"), "{e}");
}

#[test]
fn look_at_gives_an_upright_opencv_pose() {
    use dispflow_vk::eval::render::look_at;
    use glam::Vec3;
    let (eye, target, up) = (Vec3::new(3.0, 1.0, -2.0), Vec3::new(0.5, 0.2, 0.3), Vec3::Z);
    let (r, t) = look_at(eye, target, up);
    let to_cam = |p: Vec3| r * p + t;
    // Orthonormal and right-handed.
    assert!((r.determinant() - 1.0).abs() < 1e-5);
    assert!((r * r.transpose() - glam::Mat3::IDENTITY).abs_diff_eq(glam::Mat3::ZERO, 1e-5));
    // The eye is the origin, the target straight ahead on +z.
    assert!(to_cam(eye).length() < 1e-5);
    let c = to_cam(target);
    assert!(c.z > 0.0 && c.x.abs() < 1e-5 && c.y.abs() < 1e-5);
    // A point above the target is above the image centre (OpenCV: smaller y).
    assert!(to_cam(target + up).y < 0.0);
}

/// A run of the control-node field exports its nodes (`nodes.bin`) and evaluates to exactly
/// the numbers training reported; a truncated `nodes.bin` is refused by name.
#[test]
fn a_nodes_run_evaluates_to_its_training_numbers() {
    testing::validate_command_devices();
    let tmp = tempfile::tempdir().unwrap();
    let data = tiny_scene(tmp.path());
    let out = tmp.path().join("nodes");
    let cfg = out.with_extension("toml");
    std::fs::write(&cfg, tiny_toml(60)).unwrap();
    let a = TrainArgs {
        data: Some(data.clone()),
        out: Some(out.clone()),
        config: Some(cfg),
        motion_weight: Some(0.1),
        deform_field: Some(dispflow_vk::model::nodes::FieldKind::Nodes),
        nodes: Some(16),
        ..TrainArgs::default()
    };
    dispflow_vk::train::cli::run(&a).unwrap();
    let nodes = std::fs::read(out.join("nodes.bin")).unwrap();
    assert_eq!(nodes.len(), 16 * 16, "16 nodes × (position, log-radius)");
    let reports = run_eval(&eval_args(vec![out.clone()])).unwrap();
    assert_eq!(reports.len(), 1);
    let read = |p: PathBuf| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    let (e, t) = (
        read(out.join("eval/metrics.json")),
        read(out.join("metrics.json")),
    );
    for k in ["psnr", "ssim", "mmap", "drc"] {
        let (a, b) = (e[k].as_f64().unwrap(), t[k].as_f64().unwrap());
        assert!((a - b).abs() < 1e-3, "{k}: eval {a} vs train {b}");
    }
    std::fs::write(out.join("nodes.bin"), &nodes[..7]).unwrap();
    let err = match open_run(&out, None) {
        Err(e) => e.to_string(),
        Ok(_) => panic!("a truncated nodes.bin loaded"),
    };
    assert!(
        err.contains("nodes.bin") && err.contains("16 per control node"),
        "{err}"
    );
}

/// The GIF decodes to one frame per rendered view, each the size of the strips.
fn check_gif(path: &Path, frames: usize, size: (u32, u32)) {
    use image::AnimationDecoder;
    let f = std::io::BufReader::new(std::fs::File::open(path).unwrap());
    let dec = image::codecs::gif::GifDecoder::new(f).unwrap();
    let frames_read = dec.into_frames().collect_frames().unwrap();
    assert_eq!(frames_read.len(), frames);
    for f in &frames_read {
        assert_eq!(f.buffer().dimensions(), size);
        // GIF stores hundredths of a second: 1/12 s is 8 of them.
        let (n, d) = f.delay().numer_denom_ms();
        assert_eq!(n as f64 / d as f64, 80.0);
    }
}

/// `ply/sequence.zip` as brush reads it: entries streamed from the local headers (stored,
/// sizes and CRC in the header, no data descriptor), the `.ply` names in natural order are
/// the frames; and as a central-directory reader (the zip crate) reads it: the same files.
fn check_sequence_zip(ply_dir: &Path, frames: usize) {
    let bytes = std::fs::read(ply_dir.join("sequence.zip")).unwrap();
    let u16_at = |o: usize| u16::from_le_bytes([bytes[o], bytes[o + 1]]) as usize;
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
    let mut at = 0;
    let mut streamed = Vec::new();
    while u32_at(at) == 0x0403_4b50 {
        assert_eq!(
            u16_at(at + 6) & 0x8,
            0,
            "no data descriptor: a stream reader needs sizes"
        );
        assert_eq!(u16_at(at + 8), 0, "stored");
        let (crc, size) = (u32_at(at + 14), u32_at(at + 18) as usize);
        assert_eq!(u32_at(at + 22) as usize, size);
        let (n, extra) = (u16_at(at + 26), u16_at(at + 28));
        let name = String::from_utf8(bytes[at + 30..at + 30 + n].to_vec()).unwrap();
        let data = &bytes[at + 30 + n + extra..at + 30 + n + extra + size];
        assert_eq!(dispflow_vk::eval::export::crc32(data), crc, "{name}");
        assert_eq!(data, std::fs::read(ply_dir.join(&name)).unwrap(), "{name}");
        streamed.push(name);
        at += 30 + n + extra + size;
    }
    assert_eq!(
        u32_at(at),
        0x0201_4b50,
        "the central directory follows the entries"
    );
    let want: Vec<String> = (0..frames).map(|k| format!("frame_{k:04}.ply")).collect();
    let mut plys: Vec<String> = streamed
        .iter()
        .filter(|n| n.ends_with(".ply"))
        .cloned()
        .collect();
    plys.sort(); // zero-padded: natural order is byte order
    assert_eq!(plys, want, "the frames, and nothing that would play as one");
    assert_eq!(streamed, want);

    let mut z = zip::ZipArchive::new(std::io::Cursor::new(&bytes)).unwrap();
    assert_eq!(z.len(), frames);
    for (i, name) in want.iter().enumerate() {
        let mut f = z.by_index(i).unwrap();
        assert_eq!(f.name(), name);
        let mut data = Vec::new();
        std::io::Read::read_to_end(&mut f, &mut data).unwrap(); // checks the CRC
        assert_eq!(data, std::fs::read(ply_dir.join(name)).unwrap());
    }
}

/// Evaluation renders on the colour the ground truth was composited on: with `--background
/// white` it drew on black, so every test PSNR, probe (the collapse guard) and spawn compared a
/// black render with white-composited images.
#[test]
fn evaluation_renders_on_the_datasets_background() {
    use dispflow_vk::train::config::Background;
    let tmp = tempfile::tempdir().unwrap();
    let gpu = testing::serial_gpu();
    let dir = tiny_scene(tmp.path());
    for (bg, colour) in [(Background::Black, 0.0f32), (Background::White, 1.0)] {
        let mut cfg = train_common::tiny_config(1);
        cfg.background = bg;
        let opts = dispflow_vk::data::LoadOptions {
            progress: false,
            ..cfg.load_options()
        };
        let ds = dispflow_vk::data::load(&dir, &opts).unwrap();
        let mut tr = dispflow_vk::train::Trainer::new(&gpu, &cfg, &ds).unwrap();
        // Nothing drawn: every Gaussian fully transparent.
        let g = &tr.model.gaussians;
        let mut host = g.download(&gpu).unwrap();
        host.opacity.iter_mut().for_each(|o| *o = -40.0);
        host.upload(&gpu, &g.layout, &g.params).unwrap();
        let e = tr.evaluate_one(0, true).unwrap();
        let im = e.images.expect("images asked for");
        assert!(
            im.render
                .iter()
                .all(|p| p[..3].iter().all(|&c| (c - colour).abs() < 1e-5)),
            "{bg:?}: the empty render is not the dataset's background {colour}"
        );
    }
}
