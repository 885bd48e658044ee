//! kill -9 for real: `dispflow-vk train` on the tiny scene is killed with SIGKILL at several
//! points (before its first checkpoint, between checkpoints with log lines past the last one,
//! while a checkpoint is being written, while the final outputs are written) and resumed
//! with `--resume` until it finishes. The outputs must equal an uninterrupted run's bit for
//! bit (metrics.json's values, point_cloud.ply, deform.bin, the last checkpoint), log.jsonl
//! must hold every iteration exactly once with the uninterrupted run's values, and no temp
//! file may be left behind.
//!
//! And a closed stdout pipe ends a command quietly, not with a panic.
//!
//! Both runs use serial lavapipe (`testing::LP_SERIAL`): lavapipe's float atomics then add in a fixed order, so the
//! run is reproducible bit for bit (see tests/train_resume.rs).

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use dispflow_vk::train::checkpoint::Checkpoint;

const ITERATIONS: u32 = 20;

/// Small and quick, but everything happens: densification (4, 8, 12, 16), the deformation
/// network from 7 on, the motion term from 12 on, a checkpoint every 5 iterations, a log line
/// every iteration.
const CONFIG: &str = "iterations = 20
mlp_width = 16
mlp_depth = 2
warm_up = 6
sh_degree = 1
sh_interval = 10
log_interval = 1
checkpoint_interval = 5
motion_start = 12
flow_preset = \"fast\"
[densify]
from = 3
until = 16
interval = 4
budget = 3500
opacity_reset_interval = 10000
";

struct Setup {
    root: PathBuf,
    scene: PathBuf,
    config: PathBuf,
}

impl Setup {
    fn cmd(&self) -> Command {
        let mut c = Command::new(env!("CARGO_BIN_EXE_dispflow-vk"));
        c.env_remove("RUST_BACKTRACE")
            .env("LP_NUM_THREADS", dispflow_vk::testing::LP_SERIAL);
        dispflow_vk::testing::isolated_home(&mut c, &self.root);
        c
    }

    /// `train` into `out`, stdout/stderr into `OUT.<tag>.log` beside it.
    fn spawn_train(&self, out: &Path, resume: bool, tag: &str) -> Child {
        let log = std::fs::File::create(self.root.join(format!("{tag}.stderr"))).unwrap();
        let mut c = self.cmd();
        c.arg("train")
            .arg("--data")
            .arg(&self.scene)
            .arg("--config")
            .arg(&self.config)
            .arg("--out")
            .arg(out)
            .stdout(Stdio::null())
            .stderr(log);
        if resume {
            c.arg("--resume");
        }
        c.spawn().unwrap()
    }

    fn stderr_of(&self, tag: &str) -> String {
        std::fs::read_to_string(self.root.join(format!("{tag}.stderr"))).unwrap_or_default()
    }
}

/// Iterations in a run's log.jsonl (complete lines only).
fn logged(out: &Path) -> Vec<serde_json::Value> {
    let text = std::fs::read_to_string(out.join("log.jsonl")).unwrap_or_default();
    text.split_inclusive('\n')
        .filter(|l| l.ends_with('\n'))
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect()
}

fn last_logged(out: &Path) -> u32 {
    logged(out)
        .last()
        .map_or(0, |l| l["iteration"].as_u64().unwrap() as u32)
}

#[derive(Clone, Copy, Debug)]
enum KillAt {
    /// Once log.jsonl has reached this iteration.
    Logged(u32),
    /// The moment `checkpoints/last.ckpt.tmp` exists (a checkpoint is being written).
    CheckpointWrite,
    /// The moment the final evaluation starts writing `renders/`.
    FinalOutputs,
}

/// What a trial found at the moment of the kill.
#[derive(Debug)]
struct Trial {
    at: KillAt,
    /// The iteration of `last.ckpt` after the kill (None: none written yet).
    checkpoint: Option<u32>,
    /// The last iteration in log.jsonl after the kill.
    logged: u32,
    /// `last.ckpt.tmp` was there after the kill: it died inside the checkpoint write.
    in_write: bool,
}

/// Runs `train` (resuming when asked) and SIGKILLs it at `at`. Returns None when the run
/// finished before the kill point came.
fn kill_trial(s: &Setup, out: &Path, resume: bool, at: KillAt, tag: &str) -> Option<Trial> {
    let tmp = out.join("checkpoints/last.ckpt.tmp");
    if matches!(at, KillAt::CheckpointWrite) {
        assert!(
            !tmp.exists(),
            "{tag}: a temp file of an earlier kill is still there"
        );
    }
    let mut child = s.spawn_train(out, resume, tag);
    let ckpt = out.join("checkpoints/last.ckpt");
    let start = Instant::now();
    loop {
        let due = match at {
            KillAt::Logged(i) => last_logged(out) >= i,
            // Busy polling: the write lasts about a millisecond.
            KillAt::CheckpointWrite => tmp.exists(),
            KillAt::FinalOutputs => out.join("renders").exists(),
        };
        if due {
            child.kill().unwrap(); // SIGKILL on Unix
            let status = child.wait().unwrap();
            assert!(!status.success());
            break;
        }
        if let Some(status) = child.try_wait().unwrap() {
            assert!(status.success(), "{tag}: {}", s.stderr_of(tag));
            return None;
        }
        assert!(
            start.elapsed() < Duration::from_secs(300),
            "{tag}: no progress: {}",
            s.stderr_of(tag)
        );
        if !matches!(at, KillAt::CheckpointWrite) {
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    let checkpoint = ckpt.is_file().then(|| {
        Checkpoint::load(&ckpt)
            .unwrap_or_else(|e| panic!("{tag}: the kill left a corrupt checkpoint: {e}"))
            .iteration
    });
    Some(Trial {
        at,
        checkpoint,
        logged: last_logged(out),
        in_write: tmp.exists(),
    })
}

fn metrics(out: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(out.join("metrics.json")).unwrap();
    let mut m: serde_json::Value = serde_json::from_str(&text).unwrap();
    let o = m.as_object_mut().unwrap();
    // Where and how fast it ran, what its last launch did, and the initial PSNR (measured
    // only by a run that starts at iteration 0) are not results of the training.
    for k in [
        "run",
        "ms_per_step",
        "ms_per_step_by_phase",
        "train_seconds",
        "cost_per_step",
        "mean_dynamic_fraction",
        "initial_psnr",
    ] {
        o.remove(k);
    }
    m
}

fn temp_files(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.to_string_lossy().ends_with(".tmp") {
                found.push(p);
            }
        }
    }
    found
}

#[test]
fn sigkilled_runs_resume_to_the_uninterrupted_result() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().to_path_buf();
    let s = Setup {
        scene: root.join("tiny"),
        config: root.join("small.toml"),
        root,
    };
    std::fs::write(&s.config, CONFIG).unwrap();
    let o = s
        .cmd()
        .args(["data", "gen", "--preset", "tiny", "--seed", "3", "--out"])
        .arg(&s.scene)
        .output()
        .unwrap();
    assert!(o.status.success());

    // The uninterrupted run.
    let straight = s.root.join("straight");
    let st = s.spawn_train(&straight, false, "straight").wait().unwrap();
    assert!(st.success(), "{}", s.stderr_of("straight"));

    // The interrupted one.
    let out = s.root.join("killed");
    let mut trials = Vec::new();
    let mut launches = 0;
    let mut trial = |at: KillAt, trials: &mut Vec<Trial>| {
        let tag = format!("killed-{launches}");
        let t = kill_trial(&s, &out, launches > 0, at, &tag);
        launches += 1;
        let t = t.unwrap_or_else(|| panic!("the run finished before {at:?}"));
        eprintln!("{tag}: {t:?}");
        trials.push(t);
    };
    // 1. Before the first checkpoint: the resume starts over.
    trial(KillAt::Logged(2), &mut trials);
    assert_eq!(trials[0].checkpoint, None);
    // 2. Between checkpoints, with log lines past the last checkpoint.
    trial(KillAt::Logged(8), &mut trials);
    // 3. Inside a checkpoint write (the file in flight is the temp file; last.ckpt stays the
    //    previous, intact one). The write lasts about a millisecond: up to three tries.
    for _ in 0..3 {
        trial(KillAt::CheckpointWrite, &mut trials);
        if trials.last().unwrap().in_write {
            break;
        }
    }
    // 4. While the final outputs are written (after the last checkpoint).
    trial(KillAt::FinalOutputs, &mut trials);
    assert_eq!(trials.last().unwrap().checkpoint, Some(ITERATIONS));
    // Then resume until it finishes.
    let tag = format!("killed-{launches}");
    let st = s.spawn_train(&out, true, &tag).wait().unwrap();
    assert!(st.success(), "{}", s.stderr_of(&tag));

    let in_write = trials
        .iter()
        .filter(|t| matches!(t.at, KillAt::CheckpointWrite) && t.in_write)
        .count();
    let past = trials
        .iter()
        .filter(|t| t.logged > t.checkpoint.unwrap_or(0))
        .count();
    eprintln!(
        "{} kills ({in_write} inside a checkpoint write, {past} with log lines past the checkpoint), {} launches",
        trials.len(),
        launches + 1
    );
    assert!(
        in_write >= 1,
        "no kill landed inside a checkpoint write: {trials:?}"
    );
    assert!(
        past >= 1,
        "no kill left log lines past its checkpoint: {trials:?}"
    );

    // Bit for bit the uninterrupted result.
    assert_eq!(metrics(&out), metrics(&straight), "metrics.json");
    for f in ["point_cloud.ply", "deform.bin", "checkpoints/last.ckpt"] {
        assert!(
            std::fs::read(out.join(f)).unwrap() == std::fs::read(straight.join(f)).unwrap(),
            "{f} differs from the uninterrupted run's"
        );
    }
    // Every iteration logged once, in order, with the uninterrupted run's values.
    let (a, b) = (logged(&out), logged(&straight));
    let iters: Vec<u64> = a.iter().map(|l| l["iteration"].as_u64().unwrap()).collect();
    assert_eq!(
        iters,
        (1..=ITERATIONS as u64).collect::<Vec<_>>(),
        "log.jsonl"
    );
    for (x, y) in a.iter().zip(&b) {
        for k in [
            "iteration",
            "loss",
            "psnr",
            "num_gaussians",
            "motion_weight",
            "dynamic_fraction",
        ] {
            assert_eq!(
                x[k], y[k],
                "log.jsonl field {k} at iteration {}",
                x["iteration"]
            );
        }
    }
    assert_eq!(temp_files(&out), Vec::<PathBuf>::new(), "temp files left");
    assert_eq!(
        temp_files(&straight),
        Vec::<PathBuf>::new(),
        "temp files left"
    );
}

/// A closed pipe ends a command quietly (SIGPIPE's default action), as `dispflow-vk sweep PLAN
/// --dry-run | head -1` should: the reading end is closed before the command writes its first
/// line, which `println!` would otherwise turn into a panic and a backtrace.
#[test]
fn a_closed_stdout_pipe_ends_a_command_without_a_panic() {
    use std::os::fd::{FromRawFd, OwnedFd};
    use std::os::unix::process::ExitStatusExt;
    let mut fds = [0i32; 2];
    // SAFETY: `fds` has room for the two descriptors `pipe` writes.
    assert_eq!(unsafe { libc::pipe(fds.as_mut_ptr()) }, 0);
    // SAFETY: both descriptors were just created and nothing else owns them.
    let (read, write) = unsafe { (OwnedFd::from_raw_fd(fds[0]), OwnedFd::from_raw_fd(fds[1])) };
    drop(read);
    let plan = concat!(env!("CARGO_MANIFEST_DIR"), "/tools/plans/trade.toml");
    let out = Command::new(env!("CARGO_BIN_EXE_dispflow-vk"))
        .args(["sweep", plan, "--dry-run"])
        .env_remove("RUST_BACKTRACE")
        .stdout(Stdio::from(write))
        .stderr(Stdio::piped())
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(
        out.status.signal(),
        Some(libc::SIGPIPE),
        "{:?}: {stderr}",
        out.status
    );
}
