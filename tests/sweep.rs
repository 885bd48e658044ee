//! `dispflow-vk sweep` for real: a tiny plan (2 scenes × 2 variants) end to end with its
//! tables parsed back against the cells' own metrics; finished cells skipped on a re-run; a
//! cell killed with SIGKILL mid-training resumed from its checkpoint to the uninterrupted
//! result; bad plans refused by name before anything runs; and the Slurm path (job array +
//! `afterok` gather job) through real slurmctld/slurmd/munged daemons started by
//! tools/slurm_local.sh, including a failing cell that must cancel the gather job.
//!
//! Runs use serial lavapipe (`testing::LP_SERIAL`) so that a resumed run equals an uninterrupted one bit for bit.
//! (Over ~600 lines: one file because every test shares the tiny plan, its scenes and the
//! check of a finished sweep's tables.)

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use dispflow_vk::report::Table;
use dispflow_vk::results::{read_results, write_results, CellResult};

/// The tiny run of every cell: deformation from 10, motion term from 20, densification and
/// a checkpoint every 5 iterations.
const COMMON: &str = r#"
seeds = [0]
iterations = 30
[flags]
preset = "fast"
[config]
mlp_width = 16
mlp_depth = 2
warm_up = 10
motion_start = 20
flow_preset = "fast"
sh_degree = 1
log_interval = 5
checkpoint_interval = 5
[config.densify]
from = 8
until = 25
interval = 8
budget = 3500
"#;

const VARIANTS: &str = r#"
[[variant]]
name = "baseline"
flags = { method = "deformable-3dgs" }
[[variant]]
name = "DispFlow-GS"
flags = { method = "dispflow", deform-field = "nodes", nodes = 32 }
"#;

/// [`VARIANTS`]' first variant alone.
const BASELINE: &str = r#"
[[variant]]
name = "baseline"
flags = { method = "deformable-3dgs" }
"#;

struct Setup {
    root: PathBuf,
    _tmp: tempfile::TempDir,
}

impl Setup {
    fn new() -> Self {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path().to_path_buf();
        for (name, seed, motion) in [("moving", "3", "moving"), ("frozen", "5", "static")] {
            let st = Command::new(env!("CARGO_BIN_EXE_dispflow-vk"))
                .args([
                    "data", "gen", "--preset", "tiny", "--seed", seed, "--motion", motion,
                ])
                .arg("--out")
                .arg(root.join(name))
                .stdout(Stdio::null())
                .status()
                .unwrap();
            assert!(st.success());
        }
        Setup { root, _tmp: tmp }
    }

    fn cmd(&self) -> Command {
        let mut c = Command::new(env!("CARGO_BIN_EXE_dispflow-vk"));
        c.current_dir(&self.root)
            .env_remove("RUST_BACKTRACE")
            .env("LP_NUM_THREADS", dispflow_vk::testing::LP_SERIAL);
        dispflow_vk::testing::isolated_home(&mut c, &self.root);
        c
    }

    fn plan(&self, name: &str, body: &str) -> PathBuf {
        let p = self.root.join(format!("{name}.toml"));
        std::fs::write(&p, format!("name = {name:?}\n{body}")).unwrap();
        p
    }

    /// `sweep ARGS…`: (success, stdout + stderr).
    fn sweep(&self, args: &[&str]) -> (bool, String) {
        self.sweep_on(args, None)
    }

    /// `sweep ARGS…` with `SLURM_CONF` set when a cluster is given.
    fn sweep_on(&self, args: &[&str], slurm_conf: Option<&Path>) -> (bool, String) {
        let mut c = self.cmd();
        if let Some(conf) = slurm_conf {
            c.env("SLURM_CONF", conf);
        }
        let out = c.arg("sweep").args(args).output().unwrap();
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        (out.status.success(), text)
    }
}

fn two_scenes() -> String {
    two_scenes_with(VARIANTS)
}

/// The two tiny scenes under `variants`.
fn two_scenes_with(variants: &str) -> String {
    format!(
        "{COMMON}\n[[scene]]\nname = \"moving\"\ndata = \"moving\"\n[[scene]]\nname = \"frozen\"\ndata = \"frozen\"\n{variants}"
    )
}

fn cell<'a>(rs: &'a [CellResult], scene: &str, variant: &str) -> &'a CellResult {
    rs.iter()
        .find(|r| r.scene == scene && r.variant == variant)
        .unwrap_or_else(|| panic!("no cell {scene}/{variant}"))
}

/// The results of a finished 2 × 2 sweep and its tables, checked against each other.
fn check_tables(dir: &Path) -> Vec<CellResult> {
    let rs = read_results(&dir.join("results.jsonl")).unwrap();
    assert_eq!(rs.len(), 4, "one line per cell");
    let keys: Vec<&str> = rs.iter().map(|r| r.cell.as_str()).collect();
    assert_eq!(
        keys,
        [
            "moving/baseline/seed0",
            "moving/DispFlow-GS/seed0",
            "frozen/baseline/seed0",
            "frozen/DispFlow-GS/seed0"
        ],
        "plan order"
    );
    for r in &rs {
        assert!(r.psnr.is_finite() && r.psnr > 5.0, "{r:?}");
        assert!(r.ms_per_step.is_some_and(|v| v > 0.0), "{r:?}");
        assert!(r.train_seconds.is_some_and(|v| v > 0.0), "{r:?}");
        assert_eq!(r.iterations, 30);
        assert!(
            r.strip.as_ref().is_some_and(|s| dir.join(s).is_file()),
            "{r:?}"
        );
        assert!(dir.join(&r.run).join("metrics.json").is_file());
    }
    // Metrics the scene has: masks (and so MMAP and dynamic PSNR) only where things move.
    assert!(cell(&rs, "moving", "baseline").mmap.is_some());
    assert!(cell(&rs, "frozen", "baseline").dynamic_psnr.is_none());
    assert_eq!(
        cell(&rs, "moving", "DispFlow-GS").config["deform_field"]["kind"],
        "nodes"
    );
    assert_eq!(cell(&rs, "moving", "baseline").config["motion_weight"], 0.0);

    // Image table: one row per variant, the cells' PSNR per scene (one seed: no ±).
    let md = std::fs::read_to_string(dir.join("tables/image.md")).unwrap();
    let t = Table::parse_markdown(&md).unwrap();
    assert_eq!(t.rows.len(), 2);
    let col = |name: &str| t.headers.iter().position(|h| h == name).unwrap();
    for (row, variant) in t.rows.iter().zip(["baseline", "DispFlow-GS"]) {
        assert_eq!(row[0], variant);
        for scene in ["moving", "frozen"] {
            let want = format!("{:.2}", cell(&rs, scene, variant).psnr);
            assert_eq!(
                row[col(&format!("{scene} PSNR"))],
                want,
                "{variant} {scene}"
            );
        }
        let mean = (cell(&rs, "moving", variant).psnr + cell(&rs, "frozen", variant).psnr) / 2.0;
        assert_eq!(row[col("mean PSNR")], format!("{mean:.2}"));
        assert_eq!(
            row[col("moving LPIPS")],
            "n/a",
            "no weights: never a made-up number"
        );
    }
    // The trade table's CSV carries the numbers themselves.
    let csv = std::fs::read_to_string(dir.join("tables/trade.csv")).unwrap();
    let mut lines = csv.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let at = |h: &str| head.iter().position(|x| *x == h).unwrap();
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), 4);
    for row in &rows {
        let r = cell(&rs, row[at("Scene")], row[at("Variant")]);
        let v: f64 = row[at("ms/step")].parse().unwrap();
        assert_eq!(v, r.ms_per_step.unwrap());
        let p: f64 = row[at("PSNR")].parse().unwrap();
        assert_eq!(p, r.psnr);
    }
    // Every scene has a Pareto-optimal variant, and the report links the plot.
    for scene in ["moving", "frozen"] {
        assert!(rows
            .iter()
            .any(|r| r[at("Scene")] == scene && r[at("Pareto")] == "✓"));
    }
    let report = std::fs::read_to_string(dir.join("report.md")).unwrap();
    assert!(report.contains("pareto.png") && dir.join("pareto.png").is_file());
    for k in ["motion", "ablation"] {
        let t = Table::parse_markdown(
            &std::fs::read_to_string(dir.join(format!("tables/{k}.md"))).unwrap(),
        )
        .unwrap();
        assert_eq!(t.rows.len(), 2, "{k}");
    }
    rs
}

fn mtime(p: &Path) -> std::time::SystemTime {
    std::fs::metadata(p).unwrap().modified().unwrap()
}

#[test]
fn a_tiny_plan_runs_end_to_end_is_skipped_when_done_and_its_tables_rebuild() {
    let s = Setup::new();
    let plan = s.plan("tiny", &two_scenes());
    let (ok, out) = s.sweep(&[plan.to_str().unwrap(), "--out", "out"]);
    assert!(ok, "{out}");
    let dir = s.root.join("out");
    let rs = check_tables(&dir);

    // A second run finds every cell finished and runs nothing.
    let cell_json = dir.join("cells/moving/baseline/seed0/cell.json");
    let before = mtime(&cell_json);
    let (ok, out) = s.sweep(&[plan.to_str().unwrap(), "--out", "out"]);
    assert!(ok, "{out}");
    assert!(out.contains("4 finished, 0 to run"), "{out}");
    assert_eq!(mtime(&cell_json), before);

    // The tables come back from results.jsonl alone.
    let only = s.root.join("only");
    std::fs::create_dir_all(&only).unwrap();
    std::fs::copy(dir.join("results.jsonl"), only.join("results.jsonl")).unwrap();
    let (ok, out) = s.sweep(&["report", "only"]);
    assert!(ok, "{out}");
    assert_eq!(
        std::fs::read_to_string(only.join("tables/image.md")).unwrap(),
        std::fs::read_to_string(dir.join("tables/image.md")).unwrap()
    );
    assert_eq!(read_results(&only.join("results.jsonl")).unwrap(), rs);

    // Every cell carries its run's status; a cell that did not end ok is flagged in the
    // tables (its variant marked ⚠, a note naming the cell and why).
    assert!(
        rs.iter().all(|r| r.status.as_deref() == Some("ok")),
        "{rs:?}"
    );
    assert!(!std::fs::read_to_string(dir.join("tables/image.md"))
        .unwrap()
        .contains('⚠'));
    let mut bad = rs.clone();
    bad[0].status = Some("collapsed".into());
    bad[0].status_note = Some("ended below its initial test PSNR (7.03 < 13.15 dB)".into());
    let flagged = s.root.join("flagged");
    std::fs::create_dir_all(&flagged).unwrap();
    write_results(&flagged, &bad).unwrap();
    let (ok, out) = s.sweep(&["report", "flagged"]);
    assert!(ok, "{out}");
    for t in ["image", "motion", "trade"] {
        let md = std::fs::read_to_string(flagged.join(format!("tables/{t}.md"))).unwrap();
        assert!(md.contains("baseline ⚠"), "{t}: {md}");
        assert!(
            md.contains("moving/baseline/seed0 collapsed (ended below its initial test PSNR"),
            "{t}: {md}"
        );
        assert!(!md.contains("DispFlow-GS ⚠"), "{t}: {md}");
    }

    // A changed plan does not silently reuse a cell finished with other settings.
    let changed = s.plan("tiny", &two_scenes().replace("nodes = 32", "nodes = 16"));
    let (ok, out) = s.sweep(&[changed.to_str().unwrap(), "--out", "out"]);
    assert!(!ok);
    assert!(
        out.contains("moving/DispFlow-GS/seed0") && out.contains("other settings"),
        "{out}"
    );
}

#[test]
fn a_killed_cell_resumes_from_its_checkpoint() {
    let s = Setup::new();
    let body = format!(
        "{}\n[[scene]]\nname = \"moving\"\ndata = \"moving\"\n[[variant]]\nname = \"DispFlow-GS\"\n",
        COMMON.replace("iterations = 30", "iterations = 60")
    );
    let plan = s.plan("kill", &body);
    // The uninterrupted reference.
    let (ok, out) = s.sweep(&[plan.to_str().unwrap(), "--out", "whole"]);
    assert!(ok, "{out}");

    let mut child = {
        use std::os::unix::process::CommandExt;
        let mut c = s.cmd();
        c.args(["sweep", plan.to_str().unwrap(), "--out", "killed"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .process_group(0);
        c.spawn().unwrap()
    };
    let run = s.root.join("killed/cells/moving/DispFlow-GS/seed0/run");
    let t0 = Instant::now();
    // Past the first checkpoints, before the end.
    let logged = |it: u32| {
        std::fs::read_to_string(run.join("log.jsonl"))
            .map(|t| t.contains(&format!("\"iteration\":{it},")))
            .unwrap_or(false)
    };
    while !logged(25) {
        assert!(
            t0.elapsed() < Duration::from_secs(120),
            "the cell never reached iteration 25"
        );
        assert!(
            child.try_wait().unwrap().is_none(),
            "the sweep ended before it was killed"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // SIGKILL the sweep and its train process (one process group).
    let pid = child.id() as i32;
    // (procps' kill reads "-9 -PID" as a signal list; "-s KILL -- -PID" is the group.)
    let st = Command::new("kill")
        .args(["-s", "KILL", "--", &format!("-{pid}")])
        .status()
        .unwrap();
    assert!(st.success());
    child.wait().unwrap();
    assert!(
        !run.join("../cell.json").exists(),
        "killed before it finished"
    );
    assert!(!logged(60));

    let (ok, out) = s.sweep(&[plan.to_str().unwrap(), "--out", "killed"]);
    assert!(ok, "{out}");
    let log = std::fs::read_to_string(run.join("../train.log")).unwrap();
    assert!(
        log.contains("resumed from"),
        "the cell restarted instead of resuming:\n{log}"
    );
    let a = read_results(&s.root.join("whole/results.jsonl")).unwrap();
    let b = read_results(&s.root.join("killed/results.jsonl")).unwrap();
    assert_eq!((a.len(), b.len()), (1, 1));
    // Bit-exact resume (serial lavapipe): the same quality as the uninterrupted cell.
    assert_eq!(
        (a[0].psnr, a[0].ssim, a[0].mmap),
        (b[0].psnr, b[0].ssim, b[0].mmap)
    );
    assert_eq!(a[0].num_gaussians, b[0].num_gaussians);
}

#[test]
fn bad_plans_are_refused_by_name_before_anything_runs() {
    let s = Setup::new();
    let scene = "[[scene]]\nname = \"moving\"\ndata = \"moving\"\n";
    let variant = "[[variant]]\nname = \"v\"\n";
    let cases = [
        (
            "unknown flag",
            format!("{scene}[[variant]]\nname = \"v\"\nflags = {{ frobnicate = 1 }}\n"),
            "--frobnicate",
        ),
        (
            "unknown plan field",
            format!("colour = 3\n{scene}{variant}"),
            "colour",
        ),
        (
            "unknown config field",
            format!(
                "{scene}[[variant]]\nname = \"v\"\nconfig = {{ densify = {{ budgett = 3 }} }}\n"
            ),
            "budgett",
        ),
        (
            "bad flag value",
            format!("{scene}[[variant]]\nname = \"v\"\nflags = {{ mlp-width = \"wide\" }}\n"),
            "--mlp-width",
        ),
        (
            "out-of-range config",
            format!("{scene}[[variant]]\nname = \"v\"\nconfig = {{ iterations = 0 }}\n"),
            "iterations",
        ),
        (
            "a flag the sweep owns",
            format!("{scene}[[variant]]\nname = \"v\"\nflags = {{ seed = 3 }}\n"),
            "seeds",
        ),
        (
            "missing scene",
            format!("[[scene]]\nname = \"gone\"\ndata = \"nowhere\"\n{variant}"),
            "\"gone\"",
        ),
        ("no variants", scene.to_string(), "no [[variant]]"),
        ("no scenes", variant.to_string(), "no [[scene]]"),
        (
            "no seeds",
            format!("seeds = []\n{scene}{variant}"),
            "seeds = []",
        ),
        (
            "duplicate variants",
            format!("{scene}{variant}{variant}"),
            "duplicate variant name \"v\"",
        ),
        (
            "names colliding on disk",
            format!("{scene}{variant}[[variant]]\nname = \"v?\"\n[[variant]]\nname = \"v!\"\n"),
            "same directory",
        ),
        (
            "duplicate seeds",
            format!("seeds = [1, 1]\n{scene}{variant}"),
            "listed twice",
        ),
        (
            "unknown paper variant",
            format!("[trade]\npaper = \"nope\"\n{scene}{variant}"),
            "trade.paper",
        ),
    ];
    for (what, body, needle) in cases {
        let plan = s.plan("bad", &body);
        let (ok, out) = s.sweep(&[plan.to_str().unwrap(), "--out", "bad_out"]);
        assert!(!ok, "{what}: accepted");
        assert!(
            out.contains(needle),
            "{what}: the error does not name {needle:?}:\n{out}"
        );
        assert!(!out.contains("panicked"), "{what}: {out}");
        assert!(!s.root.join("bad_out").exists(), "{what}: something ran");
    }
}

/// A one-node Slurm cluster under `dir`, stopped (by PID) when dropped.
struct Cluster {
    dir: PathBuf,
    script: PathBuf,
}

impl Cluster {
    fn up(dir: &Path) -> Option<Cluster> {
        let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tools/slurm_local.sh");
        let missing: Vec<&str> = ["slurmctld", "slurmd", "munged", "sbatch", "squeue"]
            .into_iter()
            .filter(|c| {
                !Command::new("sh")
                    .args(["-c", &format!("command -v {c}")])
                    .stdout(Stdio::null())
                    .status()
                    .unwrap()
                    .success()
            })
            .collect();
        if !missing.is_empty() {
            dispflow_vk::testing::skip(
                "the Slurm sweep test",
                &format!(
                    "{} not installed (bash tools/setup.sh installs them)",
                    missing.join(", ")
                ),
            );
            return None;
        }
        let c = Cluster {
            dir: dir.to_path_buf(),
            script,
        };
        let out = Command::new("bash")
            .arg(&c.script)
            .arg("up")
            .arg(dir)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "slurm_local.sh up failed: {}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        Some(c)
    }

    fn conf(&self) -> PathBuf {
        self.dir.join("slurm.conf")
    }

    /// Jobs the controller still knows as pending or running.
    fn queued(&self) -> String {
        let out = Command::new("squeue")
            .args(["-h", "-o", "%i %T %r"])
            .env("SLURM_CONF", self.conf())
            .output()
            .unwrap();
        String::from_utf8_lossy(&out.stdout).trim().to_string()
    }

    fn wait_empty(&self, limit: Duration) {
        let t0 = Instant::now();
        loop {
            let q = self.queued();
            if q.is_empty() {
                return;
            }
            assert!(
                t0.elapsed() < limit,
                "Slurm jobs still queued after {limit:?}: {q}\n(logs in {})",
                self.dir.join("log").display()
            );
            std::thread::sleep(Duration::from_millis(250));
        }
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = Command::new("bash")
            .arg(&self.script)
            .arg("down")
            .arg(&self.dir)
            .status();
    }
}

#[test]
fn the_slurm_path_runs_a_job_array_and_a_dependent_gather_job() {
    let s = Setup::new();
    let Some(cluster) = Cluster::up(&s.root.join("slurm")) else {
        return;
    };
    let plan = s.plan("tiny", &two_scenes());
    let conf = cluster.conf();
    let (ok, text) = s.sweep_on(
        &[
            plan.to_str().unwrap(),
            "--out",
            "viaslurm",
            "--slurm",
            "--submit",
            "--jobs",
            "2",
        ],
        Some(&conf),
    );
    assert!(ok, "{text}");
    assert!(text.contains("submitted array job"), "{text}");
    let dir = s.root.join("viaslurm");
    let script = std::fs::read_to_string(dir.join("slurm/cells.sbatch")).unwrap();
    assert!(script.contains("#SBATCH --array=0-3%2"), "{script}");
    cluster.wait_empty(Duration::from_secs(300));
    assert!(
        dir.join("report.md").is_file(),
        "the gather job wrote no report; its log:\n{}",
        std::fs::read_to_string(dir.join("slurm/logs/gather.out")).unwrap_or_default()
    );
    check_tables(&dir);

    // A failing cell cancels the gather job instead of leaving it pending forever: submit the
    // written scripts by hand after the frozen scene's images have been damaged (the plan
    // still loads; its cells' training refuses the dataset). One variant: two cells, one
    // array step, the same failure (the second variant would only train another moving cell).
    let plan = s.plan("failing", &two_scenes_with(BASELINE));
    let (ok, text) = s.sweep_on(
        &[plan.to_str().unwrap(), "--out", "failing", "--slurm"],
        Some(&conf),
    );
    assert!(ok, "{text}");
    let mut damaged = 0;
    for e in walk(&s.root.join("frozen")) {
        if e.extension().is_some_and(|x| x == "png") {
            std::fs::write(&e, b"not a png").unwrap();
            damaged += 1;
        }
    }
    assert!(damaged > 0);
    let sbatch = |args: &[&str]| {
        let out = Command::new("sbatch")
            .arg("--parsable")
            .args(args)
            .env("SLURM_CONF", cluster.conf())
            .current_dir(&s.root)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).trim().to_string()
    };
    let dir = s.root.join("failing");
    let array = sbatch(&[dir.join("slurm/cells.sbatch").to_str().unwrap()]);
    sbatch(&[
        &format!("--dependency=afterok:{array}"),
        dir.join("slurm/gather.sbatch").to_str().unwrap(),
    ]);
    cluster.wait_empty(Duration::from_secs(300));
    assert!(
        !dir.join("report.md").exists(),
        "the gather job ran after a failed cell"
    );
    assert!(dir.join("cells/moving/baseline/seed0/cell.json").is_file());
    assert!(!dir.join("cells/frozen/baseline/seed0/cell.json").exists());
}

fn walk(d: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(d).unwrap().flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(walk(&p));
        } else {
            out.push(p);
        }
    }
    out
}

#[test]
fn the_shipped_plans_are_valid() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    if !root.join("../shared/data").is_dir() {
        dispflow_vk::testing::skip("the shipped plans' check", "../shared/data is missing");
        return;
    }
    let mut plans: Vec<PathBuf> = std::fs::read_dir(root.join("tools/plans"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    plans.sort();
    assert!(plans.len() >= 3, "{plans:?}");
    for p in plans {
        let out = Command::new(env!("CARGO_BIN_EXE_dispflow-vk"))
            .args(["sweep", "--dry-run", "--out", "/nonexistent/never-written"])
            .arg(&p)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout).to_string()
            + &String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{}: {text}", p.display());
        assert!(text.lines().count() >= 4, "{}: {text}", p.display());
    }
}
