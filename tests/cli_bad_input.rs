//! Bad input through the real binary (DESIGN §7): invalid flag values, configuration files
//! with syntax errors or values that would crash or poison training, missing or malformed
//! datasets, run directories with truncated or corrupt files (`eval`, `render`) and bad
//! checkpoints (`train --resume`).
//!
//! Every case must exit with a non-zero code, print a message that names the file or field and
//! what was expected, print no panic, and leave no partial output behind.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

use dispflow_vk::train::checkpoint::{Checkpoint, CHECKPOINT_VERSION};

/// A fixture directory under the target's temp dir: the tiny scene, a cache/home for the
/// child processes and one short trained run (for eval, render and resume cases).
struct Fixture {
    root: PathBuf,
    scene: PathBuf,
    run: PathBuf,
}

const SMALL_CONFIG: &str = "iterations = 4
mlp_width = 16
mlp_depth = 2
warm_up = 1
sh_degree = 1
log_interval = 1
checkpoint_interval = 2
motion_start = 3
flow_preset = \"fast\"
[densify]
from = 1
until = 4
interval = 2
budget = 4000
opacity_reset_interval = 10000
";

fn bin(root: &Path) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_dispflow-vk"));
    // What a user sees (no backtrace of the error); never the user's own cache or home.
    c.env_remove("RUST_BACKTRACE")
        .env_remove("RUST_LIB_BACKTRACE");
    dispflow_vk::testing::isolated_home(&mut c, root);
    c
}

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let root = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("cli_bad_input");
        let _ = std::fs::remove_dir_all(&root);
        std::fs::create_dir_all(&root).unwrap();
        let scene = root.join("tiny");
        let o = bin(&root)
            .args(["data", "gen", "--preset", "tiny", "--seed", "3", "--out"])
            .arg(&scene)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let cfg = root.join("small.toml");
        std::fs::write(&cfg, SMALL_CONFIG).unwrap();
        let run = root.join("run");
        let o = bin(&root)
            .arg("train")
            .arg("--data")
            .arg(&scene)
            .arg("--out")
            .arg(&run)
            .arg("--config")
            .arg(&cfg)
            .output()
            .unwrap();
        assert!(
            o.status.success(),
            "the fixture run trains: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        // `--background auto` (the fast preset's) is resolved before training: the run says
        // which and why, config.toml keeps the colour, metrics.json both.
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            err.contains("background: black (auto: the images carry no alpha"),
            "{err}"
        );
        let cfg = std::fs::read_to_string(run.join("config.toml")).unwrap();
        assert!(cfg.contains("background = \"black\""), "{cfg}");
        let m: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(run.join("metrics.json")).unwrap())
                .unwrap();
        assert_eq!(m["background"], "black");
        assert!(m["background_reason"]
            .as_str()
            .unwrap()
            .contains("no alpha"));
        Fixture { root, scene, run }
    })
}

/// Every file under `dir` with its contents (to prove a failed command changed nothing).
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.insert(p.clone(), std::fs::read(&p).unwrap());
            }
        }
    }
    out
}

/// Runs the binary with `args`, expects a clean failure whose stderr contains every string
/// of `want`, and returns stderr.
fn fails(args: &[&str], want: &[&str]) -> String {
    let f = fixture();
    let o: Output = bin(&f.root).args(args).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    let shown = format!("dispflow-vk {}\n--- stderr:\n{err}", args.join(" "));
    assert!(!o.status.success(), "succeeded: {shown}");
    assert_ne!(o.status.code(), None, "killed by a signal: {shown}");
    assert!(
        !err.contains("panicked") && !err.contains("RUST_BACKTRACE"),
        "panicked: {shown}"
    );
    for w in want {
        assert!(err.contains(w), "stderr lacks {w:?}: {shown}");
    }
    err
}

/// `fails` for a `train` into a fresh output directory that must not be created.
fn train_fails(extra: &[&str], want: &[&str]) {
    let f = fixture();
    let out = f.root.join(format!("out-{}", unique()));
    let mut args = vec!["train", "--data", f.scene.to_str().unwrap()];
    args.extend(["--out", out.to_str().unwrap()]);
    args.extend(extra);
    fails(&args, want);
    assert!(
        !out.exists(),
        "a refused run created its output directory: {}",
        args.join(" ")
    );
}

fn unique() -> usize {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static N: AtomicUsize = AtomicUsize::new(0);
    N.fetch_add(1, Ordering::Relaxed)
}

/// Invalid flag values and datasets of `train`.
#[test]
fn train_flags_and_datasets() {
    let f = fixture();
    let flag_cases: &[(&[&str], &[&str])] = &[
        (&["--iterations=-5"], &["--iterations", "-5", "1.."]),
        (&["--iterations", "abc"], &["--iterations", "abc"]),
        (&["--iterations", "0"], &["--iterations", "0 is not in 1.."]),
        (
            &["--motion-weight", "nan"],
            &["motion_weight = NaN", "finite"],
        ),
        (&["--motion-weight=-1"], &["motion_weight = -1", ">= 0"]),
        (
            &["--motion-weight", "inf"],
            &["motion_weight = inf", "finite"],
        ),
        (&["--sh-degree", "4"], &["sh_degree = 4", "0, 1, 2 or 3"]),
        (&["--mlp-width", "0"], &["mlp_width = 0", "1..=4096"]),
        (&["--mlp-depth", "65"], &["mlp_depth = 65", "1..=64"]),
        (&["--budget", "0"], &["densify.budget = 0", "at least 1"]),
        (
            &["--budget", "4000000000"],
            &["densify.budget = 4000000000", "at most"],
        ),
        (&["--pair-gap", "0"], &["pair_gap = 0", "at least 1"]),
        (
            &["--flow-preset", "turbo"],
            &["flow_preset", "turbo", "fast"],
        ),
        (
            &["--motion-flow", "oracle", "--motion-order", "reverse"],
            &["motion_flow", "direct"],
        ),
        (&["--preset", "huge"], &["--preset", "huge", "paper"]),
        (
            &["--motion-normalize", "sideways"],
            &["--motion-normalize", "sideways"],
        ),
        (
            &["--background", "purple"],
            &["--background", "purple", "black"],
        ),
        (&["--max-resolution", "1.5"], &["--max-resolution", "1.5"]),
        (&["--seed", "-1"], &["-1"]),
        (&["--no-such-flag"], &["--no-such-flag"]),
        (
            &["--config", "/no/such/config.toml"],
            &["/no/such/config.toml", "No such file"],
        ),
    ];
    for (extra, want) in flag_cases {
        train_fails(extra, want);
    }
    // `--data` without a value, pointing nowhere, at a file, at a directory of no format.
    fails(&["train", "--data"], &["--data", "a value is required"]);
    let file = f.scene.join("dataset.json");
    let empty = f.root.join("empty-dataset");
    std::fs::create_dir_all(&empty).unwrap();
    let data_cases: [(&Path, &[&str]); 3] = [
        (
            Path::new("/no/such/dataset"),
            &["/no/such/dataset", "no such directory"],
        ),
        (&file, &["dataset.json", "not a directory"]),
        (
            &empty,
            &["empty-dataset", "dataset.json", "transforms_train.json"],
        ),
    ];
    for (data, want) in data_cases {
        let out = f.root.join(format!("out-{}", unique()));
        let args = [
            "train",
            "--data",
            data.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        fails(&args, want);
        assert!(!out.exists(), "{}", args.join(" "));
    }
    let n = flag_cases.len() + 1 + data_cases.len();
    eprintln!("{n} flag and dataset cases");
    assert_eq!(n, 25);
}

/// A `--config` TOML with syntax errors, unknown fields, wrong types, and every field that can
/// crash or poison training set to zero, negative, NaN or infinity.
#[test]
fn train_config_files() {
    let f = fixture();
    let cases: &[(&str, &[&str])] = &[
        // Syntax and types.
        (
            "[densify\nbudget = 3\n",
            &["line 1", "invalid table header"],
        ),
        ("iterations =\n", &["line 1", "iterations ="]),
        (
            "iterations = 10\n[densify]\nbudgget = 3\n",
            &["budgget", "unknown field"],
        ),
        ("iterations = \"many\"\n", &["iterations", "expected u32"]),
        ("log_interval = -1\n", &["log_interval", "expected u32"]),
        ("seed = -3\n", &["seed", "expected u64"]),
        (
            "zero_deform_head = \"yes\"\n",
            &["zero_deform_head", "expected a boolean"],
        ),
        (
            "densify = 3\n",
            &["densify", "expected struct DensifyConfig"],
        ),
        (
            "background = \"purple\"\n",
            &["background", "purple", "black"],
        ),
        ("time_noise = \"maybe\"\n", &["time_noise", "maybe", "auto"]),
        (
            "motion_normalize = \"sideways\"\n",
            &["motion_normalize", "sideways"],
        ),
        ("motion_order = \"sideways\"\n", &["motion_order", "direct"]),
        (
            "motion_norm_grad = \"half\"\n",
            &["motion_norm_grad", "detached"],
        ),
        ("motion_flow = \"magic\"\n", &["motion_flow", "tvl1"]),
        // Divisors: `iteration % interval` panicked on 0.
        (
            "checkpoint_interval = 0\n",
            &["checkpoint_interval = 0", "at least 1"],
        ),
        ("log_interval = 0\n", &["log_interval = 0", "at least 1"]),
        ("sh_interval = 0\n", &["sh_interval = 0", "at least 1"]),
        (
            "[densify]\ninterval = 0\n",
            &["densify.interval = 0", "at least 1"],
        ),
        (
            "[densify]\nopacity_reset_interval = 0\n",
            &["densify.opacity_reset_interval = 0", "at least 1"],
        ),
        ("pair_gap = 0\n", &["pair_gap = 0", "at least 1"]),
        ("iterations = 0\n", &["iterations = 0", "at least 1"]),
        // Sizes.
        ("sh_degree = 9\n", &["sh_degree = 9", "0, 1, 2 or 3"]),
        ("mlp_depth = 0\n", &["mlp_depth = 0", "1..=64"]),
        ("mlp_width = 5000\n", &["mlp_width = 5000", "1..=4096"]),
        (
            "[densify]\nbudget = 0\n",
            &["densify.budget = 0", "at least 1"],
        ),
        (
            "[densify]\nbudget = 100000000\n",
            &["densify.budget = 100000000", "at most"],
        ),
        // Weights.
        ("motion_weight = nan\n", &["motion_weight = NaN", "finite"]),
        ("motion_weight = -0.5\n", &["motion_weight = -0.5", ">= 0"]),
        ("motion_weight = inf\n", &["motion_weight = inf", "finite"]),
        ("lambda_ssim = 1.5\n", &["lambda_ssim = 1.5", "[0, 1]"]),
        ("lambda_ssim = -0.1\n", &["lambda_ssim = -0.1", "[0, 1]"]),
        ("lambda_ssim = nan\n", &["lambda_ssim = NaN", "[0, 1]"]),
        // Learning rates: every one.
        (
            "[lr]\nposition_init = -1e-4\n",
            &["lr.position_init = -0.0001", ">= 0"],
        ),
        (
            "[lr]\nposition_final = nan\n",
            &["lr.position_final = NaN", "finite"],
        ),
        (
            "[lr]\nposition_delay_mult = inf\n",
            &["lr.position_delay_mult = inf", "[0, 1]"],
        ),
        ("[lr]\nfeature = nan\n", &["lr.feature = NaN", "finite"]),
        (
            "[lr]\nfeature_rest_div = 0\n",
            &["lr.feature_rest_div = 0", "> 0"],
        ),
        ("[lr]\nopacity = inf\n", &["lr.opacity = inf", "finite"]),
        ("[lr]\nscaling = -1\n", &["lr.scaling = -1", ">= 0"]),
        ("[lr]\nrotation = nan\n", &["lr.rotation = NaN", "finite"]),
        (
            "[lr]\ndeform_init = -inf\n",
            &["lr.deform_init = -inf", "finite"],
        ),
        (
            "[lr]\ndeform_final = nan\n",
            &["lr.deform_final = NaN", "finite"],
        ),
        // One zero end of an exponential schedule: ln(0)·0 = NaN at the last iteration.
        (
            "[lr]\ndeform_init = 0.0\n",
            &["lr.deform_init/lr.deform_final", "both > 0"],
        ),
        (
            "[lr]\nposition_final = 0.0\n",
            &["lr.position_init/lr.position_final", "both"],
        ),
        // Densification thresholds.
        (
            "[densify]\ngrad_threshold = nan\n",
            &["densify.grad_threshold = NaN", "finite"],
        ),
        (
            "[densify]\npercent_dense = -1\n",
            &["densify.percent_dense = -1", ">= 0"],
        ),
        (
            "[densify]\nmin_opacity = 2\n",
            &["densify.min_opacity = 2", "[0, 1]"],
        ),
        (
            "[densify]\nmax_screen_size = -inf\n",
            &["densify.max_screen_size = -inf", ">= 0"],
        ),
        // Motion settings.
        (
            "flow_preset = \"turbo\"\n",
            &["flow_preset = \"turbo\"", "fast"],
        ),
        (
            "motion_flow = \"oracle\"\nmotion_order = \"reverse\"\n",
            &["motion_flow", "motion_order = \"direct\""],
        ),
    ];
    for (i, (toml, want)) in cases.iter().enumerate() {
        let p = f.root.join(format!("bad-{i}.toml"));
        std::fs::write(&p, toml).unwrap();
        let mut want = want.to_vec();
        let name = format!("bad-{i}.toml");
        want.push(&name); // the message names the file
        train_fails(&["--config", p.to_str().unwrap()], &want);
    }
    eprintln!("{} configuration-file cases", cases.len());
    assert_eq!(cases.len(), 50);
}

/// A copy of the fixture run's files (`eval`/`render` inputs and the checkpoint).
fn copy_run(name: &str) -> PathBuf {
    let f = fixture();
    let dst = f.root.join(name);
    let _ = std::fs::remove_dir_all(&dst);
    std::fs::create_dir_all(dst.join("checkpoints")).unwrap();
    for file in [
        "config.toml",
        "metrics.json",
        "point_cloud.ply",
        "deform.bin",
        "log.jsonl",
        "checkpoints/last.ckpt",
    ] {
        std::fs::copy(f.run.join(file), dst.join(file)).unwrap();
    }
    dst
}

fn edit(path: &Path, f: impl FnOnce(&mut Vec<u8>)) {
    let mut b = std::fs::read(path).unwrap();
    f(&mut b);
    std::fs::write(path, b).unwrap();
}

/// `eval` and `render` on run directories with missing, truncated or corrupt files.
#[test]
fn eval_and_render_bad_run_directories() {
    let f = fixture();
    // The control: an intact copy evaluates.
    let ok = copy_run("run-ok");
    let o = bin(&f.root)
        .args(["eval", "--no-pictures", "--run", ok.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        o.status.success() && ok.join("eval/metrics.json").is_file(),
        "the intact run evaluates: {}",
        String::from_utf8_lossy(&o.stderr)
    );

    type Damage = fn(&Path);
    let cases: &[(&str, Damage, &[&str])] = &[
        (
            "metrics.json cut in half",
            |r| edit(&r.join("metrics.json"), |b| b.truncate(b.len() / 2)),
            &["metrics.json", "EOF", "expected the JSON object"],
        ),
        (
            "metrics.json empty",
            |r| edit(&r.join("metrics.json"), |b| b.clear()),
            &["metrics.json", "EOF"],
        ),
        (
            "metrics.json without iterations",
            |r| {
                edit(&r.join("metrics.json"), |b| {
                    let t = String::from_utf8(b.clone()).unwrap().replacen(
                        "\"iterations\"",
                        "\"iters\"",
                        1,
                    );
                    *b = t.into_bytes();
                })
            },
            &["metrics.json", "iterations", "non-negative integer"],
        ),
        (
            "metrics.json naming a dataset that is gone",
            |r| {
                edit(&r.join("metrics.json"), |b| {
                    let t = String::from_utf8(b.clone()).unwrap();
                    let v: serde_json::Value = serde_json::from_str(&t).unwrap();
                    let d = v["dataset"].as_str().unwrap().to_string();
                    *b = t.replace(&d, "/no/such/dataset").into_bytes();
                })
            },
            &["/no/such/dataset", "--data"],
        ),
        (
            "metrics.json missing",
            |r| std::fs::remove_file(r.join("metrics.json")).unwrap(),
            &["metrics.json", "missing"],
        ),
        (
            "deform.bin cut by 3 bytes",
            |r| edit(&r.join("deform.bin"), |b| b.truncate(b.len() - 3)),
            &["deform.bin", "bytes", "truncated"],
        ),
        (
            "deform.bin cut in half",
            |r| edit(&r.join("deform.bin"), |b| b.truncate(b.len() / 8 * 4)),
            &["deform.bin", "bytes", "truncated"],
        ),
        (
            "deform.bin empty",
            |r| edit(&r.join("deform.bin"), |b| b.clear()),
            &["deform.bin", "0 bytes"],
        ),
        (
            "deform.bin missing",
            |r| std::fs::remove_file(r.join("deform.bin")).unwrap(),
            &["deform.bin", "missing"],
        ),
        (
            "deform.bin with a NaN",
            |r| {
                edit(&r.join("deform.bin"), |b| {
                    b[8..12].copy_from_slice(&f32::NAN.to_le_bytes())
                })
            },
            &["deform.bin", "weight 2 is NaN", "finite"],
        ),
        (
            "point_cloud.ply cut",
            |r| edit(&r.join("point_cloud.ply"), |b| b.truncate(b.len() - 100)),
            &["point_cloud.ply", "truncated"],
        ),
        (
            "point_cloud.ply header only",
            |r| edit(&r.join("point_cloud.ply"), |b| b.truncate(40)),
            &["point_cloud.ply", "end_header"],
        ),
        (
            "point_cloud.ply with an infinite mean",
            |r| {
                edit(&r.join("point_cloud.ply"), |b| {
                    let at = b.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
                    b[at..at + 4].copy_from_slice(&f32::INFINITY.to_le_bytes());
                })
            },
            &["point_cloud.ply", "Gaussian 0", "means", "finite"],
        ),
        (
            "config.toml with a syntax error",
            |r| edit(&r.join("config.toml"), |b| b.extend_from_slice(b"\n[lr\n")),
            &["config.toml", "TOML parse error"],
        ),
        (
            "config.toml with checkpoint_interval = 0",
            |r| {
                edit(&r.join("config.toml"), |b| {
                    let t = String::from_utf8(b.clone()).unwrap();
                    *b = t
                        .replace("checkpoint_interval = 2", "checkpoint_interval = 0")
                        .into_bytes();
                })
            },
            &["config.toml", "checkpoint_interval = 0"],
        ),
        (
            "config.toml of another MLP",
            |r| {
                edit(&r.join("config.toml"), |b| {
                    let t = String::from_utf8(b.clone()).unwrap();
                    *b = t.replace("mlp_width = 16", "mlp_width = 24").into_bytes();
                })
            },
            &["deform.bin", "2×24", "another run"],
        ),
        (
            "config.toml of another SH degree",
            |r| {
                edit(&r.join("config.toml"), |b| {
                    let t = String::from_utf8(b.clone()).unwrap();
                    *b = t.replace("sh_degree = 1", "sh_degree = 2").into_bytes();
                })
            },
            &["point_cloud.ply", "4 SH coefficients", "sh_degree = 2"],
        ),
    ];
    let mut n = 1;
    fails(
        &["eval", "--run", "/no/such/run"],
        &["/no/such/run", "not a directory"],
    );
    for (i, (what, damage, want)) in cases.iter().enumerate() {
        for cmd in ["eval", "render"] {
            let r = copy_run(&format!("run-bad-{i}-{cmd}"));
            damage(&r);
            let before = snapshot(&r);
            let err = fails(&[cmd, "--run", r.to_str().unwrap()], want);
            assert!(
                snapshot(&r) == before,
                "{cmd} on a run with {what} changed the run directory:\n{err}"
            );
            n += 1;
        }
    }
    // render's own arguments.
    let render_cases: &[(&[&str], &[&str])] = &[
        (&["--camera", "99"], &["--camera 99", "test cameras"]),
        (&["--time", "1.5"], &["--time 1.5", "[0, 1]"]),
        (&["--time", "nan"], &["--time NaN", "[0, 1]"]),
        (&["--path", "zigzag"], &["--path", "zigzag", "orbit"]),
    ];
    for (extra, want) in render_cases {
        let r = copy_run("run-render-args");
        let before = snapshot(&r);
        let mut args = vec!["render", "--run", r.to_str().unwrap()];
        args.extend(*extra);
        fails(&args, want);
        assert!(
            snapshot(&r) == before,
            "render wrote something: {}",
            args.join(" ")
        );
        n += 1;
    }
    eprintln!("{n} eval/render cases");
    assert_eq!(n, 1 + 2 * cases.len() + render_cases.len());
}

/// `eval --lpips-weights` with files that are not usable weights: refused before anything is
/// evaluated, naming the file and the tensor; a valid file fills the LPIPS column.
#[test]
fn eval_bad_lpips_weights() {
    use dispflow_vk::train::score::lpips::{random_weights, to_safetensors};
    let f = fixture();
    let w = random_weights(9);
    let dir = f.root.join("lpips-weights");
    std::fs::create_dir_all(&dir).unwrap();
    let mut nan = w.lin_weight(1).to_vec();
    nan[3] = f32::NAN;
    let files: Vec<(&str, Vec<u8>, Vec<&str>)> = vec![
        (
            "torch.pth",
            b"PK\x03\x04 a pickled torch file".to_vec(),
            vec!["not a safetensors file", "tools/lpips_weights.py"],
        ),
        (
            "missing.safetensors",
            to_safetensors(&w, Some("conv5.bias"), None),
            vec!["conv5.bias", "missing", "[256]"],
        ),
        (
            "shape.safetensors",
            to_safetensors(
                &w,
                None,
                Some(("conv1.weight", vec![64, 3, 7, 7], vec![0.0; 64 * 3 * 49])),
            ),
            vec!["conv1.weight", "[64, 3, 7, 7]", "expected [64, 3, 11, 11]"],
        ),
        (
            "nan.safetensors",
            to_safetensors(&w, None, Some(("lin2.weight", vec![1, 192, 1, 1], nan))),
            vec!["lin2.weight", "element 3", "NaN"],
        ),
    ];
    for (n, (name, bytes, mut want)) in files.into_iter().enumerate() {
        let p = dir.join(name);
        std::fs::write(&p, bytes).unwrap();
        let r = copy_run(&format!("run-lpips-{n}"));
        let before = snapshot(&r);
        want.push(name);
        fails(
            &[
                "eval",
                "--no-pictures",
                "--run",
                r.to_str().unwrap(),
                "--lpips-weights",
                p.to_str().unwrap(),
            ],
            &want,
        );
        assert!(
            snapshot(&r) == before,
            "eval with bad {name} changed the run directory"
        );
    }
    let gone = dir.join("no-such.safetensors");
    fails(
        &[
            "eval",
            "--run",
            f.run.to_str().unwrap(),
            "--lpips-weights",
            gone.to_str().unwrap(),
        ],
        &["no-such.safetensors", "LPIPS", "tools/lpips_weights.py"],
    );
    // The control: valid weights evaluate and fill the column.
    let good = dir.join("good.safetensors");
    std::fs::write(&good, to_safetensors(&w, None, None)).unwrap();
    let r = copy_run("run-lpips-ok");
    let o = bin(&f.root)
        .args([
            "eval",
            "--no-pictures",
            "--run",
            r.to_str().unwrap(),
            "--lpips-weights",
        ])
        .arg(&good)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let m: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(r.join("eval/metrics.json")).unwrap())
            .unwrap();
    assert!(
        m["lpips"]
            .as_f64()
            .is_some_and(|v| v.is_finite() && v > 0.0),
        "{}",
        m["lpips"]
    );
}

/// `train --resume` from a bad checkpoint or under another configuration: refused before the
/// run directory changes.
#[test]
fn resume_bad_checkpoints() {
    let f = fixture();
    let base = [
        "train",
        "--data",
        f.scene.to_str().unwrap(),
        "--config",
        f.root.join("small.toml").to_str().unwrap(),
    ]
    .map(String::from);
    type Damage = fn(&Path);
    let cases: &[(&str, Damage, &[&str], &[&str])] = &[
        (
            "a flipped byte in a blob",
            |r| {
                edit(&r.join("checkpoints/last.ckpt"), |b| {
                    let n = b.len();
                    b[n - 5] ^= 0x10;
                })
            },
            &[],
            &["last.ckpt", "blob max_radii", "checksum mismatch"],
        ),
        (
            "a truncated checkpoint",
            |r| {
                edit(&r.join("checkpoints/last.ckpt"), |b| {
                    b.truncate(b.len() / 2)
                })
            },
            &[],
            &["last.ckpt", "truncated"],
        ),
        (
            "a NaN saved in the checkpoint",
            |r| {
                let p = r.join("checkpoints/last.ckpt");
                let mut c = Checkpoint::load(&p).unwrap();
                c.model.gaussians.log_scales[3][2] = f32::NAN;
                c.save(&p).unwrap();
            },
            &[],
            &[
                "last.ckpt",
                "cannot resume",
                "blob log_scales",
                "Gaussian 3",
                "NaN",
            ],
        ),
        (
            "a checkpoint of format version 1",
            |r| {
                edit(&r.join("checkpoints/last.ckpt"), |b| {
                    let hl = u64::from_le_bytes(b[8..16].try_into().unwrap()) as usize;
                    let h = String::from_utf8(b[16..16 + hl].to_vec()).unwrap();
                    let current = format!("\"version\":{CHECKPOINT_VERSION}");
                    let h1 = h.replacen(&current, "\"version\":1", 1);
                    assert_ne!(h, h1);
                    b.splice(16..16 + hl, h1.into_bytes());
                })
            },
            &[],
            &["last.ckpt", "format version 1", "reads version"],
        ),
        (
            "flags that differ from the run's config.toml",
            |_| {},
            &["--mlp-width", "24"],
            &["config.toml", "mlp_width = 24 (the run has 16)"],
        ),
        (
            "a checkpoint of another MLP under a matching config.toml",
            |r| {
                edit(&r.join("config.toml"), |b| {
                    let t = String::from_utf8(b.clone()).unwrap();
                    *b = t.replace("mlp_width = 16", "mlp_width = 24").into_bytes();
                })
            },
            &["--mlp-width", "24"],
            &["last.ckpt", "cannot resume", "2×16", "mlp_width = 24"],
        ),
        (
            "a checkpoint of another budget under a matching config.toml",
            |r| {
                edit(&r.join("config.toml"), |b| {
                    let t = String::from_utf8(b.clone()).unwrap();
                    *b = t.replace("budget = 4000", "budget = 5000").into_bytes();
                })
            },
            &["--budget", "5000"],
            &["last.ckpt", "budget = 4000", "5000"],
        ),
        (
            "a checkpoint past the configured iterations",
            |r| {
                // The run's configuration as `--iterations 3` makes it (the schedule scales).
                let p = r.join("config.toml");
                let c = dispflow_vk::train::config::TrainConfig::from_toml_over(
                    &dispflow_vk::train::config::TrainConfig::fast(),
                    &p,
                )
                .unwrap();
                std::fs::write(&p, c.with_iterations(3).to_toml()).unwrap();
            },
            &["--iterations", "3"],
            &["last.ckpt", "iteration 4", "iterations = 3"],
        ),
    ];
    for (i, (what, damage, flags, want)) in cases.iter().enumerate() {
        let r = copy_run(&format!("run-resume-{i}"));
        damage(&r);
        let before = snapshot(&r);
        let mut args: Vec<&str> = base.iter().map(String::as_str).collect();
        args.extend(["--out", r.to_str().unwrap(), "--resume"]);
        args.extend(*flags);
        let err = fails(&args, want);
        assert!(
            snapshot(&r) == before,
            "resuming from {what} changed the run directory:\n{err}"
        );
    }
    eprintln!("{} resume cases", cases.len());
    assert_eq!(cases.len(), 8);
}
