//! Running cells: each as its own `dispflow-vk train` then `eval` process, so a crash or a
//! kill takes one cell and nothing else; resumable at both levels (finished cells are
//! skipped, an unfinished one resumes from its checkpoint).

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use super::plan::{train_args, Cell};
use crate::error::{Error, Result};
use crate::results::{read_cell, write_cell, CellResult, CELL_JSON};
use crate::train::checkpoint::write_atomic;

/// Markers of a finished stage, so a re-run never retrains (which would overwrite the
/// run's speed figures with an empty resumed launch's) nor re-evaluates.
const TRAIN_OK: &str = "train.ok";
const EVAL_OK: &str = "eval.ok";

/// What the cells share: the binary, the sweep root, LPIPS weights.
pub struct CellEnv {
    pub exe: PathBuf,
    pub root: PathBuf,
    pub lpips: Option<PathBuf>,
    pub jobs: u32,
}

impl CellEnv {
    pub fn cell_dir(&self, c: &Cell) -> PathBuf {
        self.root.join("cells").join(&c.key)
    }

    /// The finished result of `c`, if it has one; a result written for other settings is
    /// refused (the plan changed under a half-finished sweep).
    pub fn finished(&self, c: &Cell) -> Result<Option<CellResult>> {
        let dir = self.cell_dir(c);
        let p = dir.join(CELL_JSON);
        if !p.is_file() {
            // Settings of an unfinished cell are checked by `train --resume` itself.
            return Ok(None);
        }
        let r = read_cell(&p)?;
        if r.args != c.args || r.config_toml != c.config_toml {
            return Err(Error::Invalid(format!(
                "{}: cell {} finished with other settings (flags {:?}, config {:?}) than the \
                 plan now gives it (flags {:?}, config {:?}); delete {} to rerun it, or sweep \
                 into another --out",
                p.display(),
                c.key,
                r.args.join(" "),
                r.config_toml,
                c.args.join(" "),
                c.config_toml,
                dir.display()
            )));
        }
        Ok(Some(r))
    }

    /// Runs (or finishes) one cell and writes its `cell.json`.
    pub fn run_cell(&self, c: &Cell) -> Result<CellResult> {
        let dir = self.cell_dir(c);
        std::fs::create_dir_all(&dir).map_err(Error::io(&dir))?;
        let run = dir.join("run");
        let config = if c.config_toml.is_empty() {
            None
        } else {
            let p = dir.join("config.toml");
            write_atomic(&p, c.config_toml.as_bytes())?;
            Some(p)
        };
        let t0 = Instant::now();
        if !dir.join(TRAIN_OK).is_file() {
            self.child(&dir, "train", &train_args(c, &run, config.as_deref()))?;
            write_atomic(&dir.join(TRAIN_OK), b"")?;
        }
        if !dir.join(EVAL_OK).is_file() {
            let mut a = vec![
                "eval".to_string(),
                "--run".into(),
                run.display().to_string(),
            ];
            if let Some(w) = &self.lpips {
                a.extend(["--lpips-weights".into(), w.display().to_string()]);
            }
            self.child(&dir, "eval", &a)?;
            write_atomic(&dir.join(EVAL_OK), b"")?;
        }
        let r = self.result(c, &run, t0.elapsed().as_secs_f64())?;
        write_cell(&dir, &r)?;
        Ok(r)
    }

    /// Runs `exe args…` with its output appended to `DIR/<stage>.log`; a failure names the
    /// log and quotes its last lines.
    fn child(&self, dir: &Path, stage: &str, args: &[String]) -> Result<()> {
        let log = dir.join(format!("{stage}.log"));
        let f = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(&log)
            .map_err(Error::io(&log))?;
        let f2 = f.try_clone().map_err(Error::io(&log))?;
        let status = Command::new(&self.exe)
            .args(args)
            .stdin(Stdio::null())
            .stdout(f)
            .stderr(f2)
            .status()
            .map_err(Error::io(&self.exe))?;
        if status.success() {
            return Ok(());
        }
        let text = std::fs::read_to_string(&log).unwrap_or_default();
        let tail: Vec<&str> = text.lines().rev().take(4).collect();
        let tail: Vec<&str> = tail.into_iter().rev().collect();
        Err(Error::Invalid(format!(
            "`dispflow-vk {}` failed ({status}); its output is in {}:\n  {}",
            args.join(" "),
            log.display(),
            tail.join("\n  ")
        )))
    }

    fn result(&self, c: &Cell, run: &Path, cell_seconds: f64) -> Result<CellResult> {
        let read = |p: PathBuf| -> Result<serde_json::Value> {
            let t = std::fs::read_to_string(&p).map_err(Error::io(&p))?;
            serde_json::from_str(&t).map_err(|e| Error::Invalid(format!("{}: {e}", p.display())))
        };
        let train = read(run.join("metrics.json"))?;
        let eval = read(run.join("eval").join("metrics.json"))?;
        let cfg_path = run.join("config.toml");
        let cfg_text = std::fs::read_to_string(&cfg_path).map_err(Error::io(&cfg_path))?;
        let config: toml::Value = toml::from_str(&cfg_text)
            .map_err(|e| Error::Invalid(format!("{}: {e}", cfg_path.display())))?;
        let f = |v: &serde_json::Value, k: &str| v.get(k).and_then(serde_json::Value::as_f64);
        let need = |k: &str| {
            f(&eval, k).ok_or_else(|| {
                Error::Invalid(format!(
                    "{}: no number {k:?}",
                    run.join("eval/metrics.json").display()
                ))
            })
        };
        let s = |v: &serde_json::Value, k: &str| {
            v.get(k)
                .and_then(serde_json::Value::as_str)
                .unwrap_or_default()
                .to_string()
        };
        let rel = |p: &Path| {
            p.strip_prefix(&self.root)
                .unwrap_or(p)
                .display()
                .to_string()
        };
        let frames = run.join("eval").join("frames");
        let strip = std::fs::read_dir(&frames).ok().and_then(|rd| {
            let mut v: Vec<PathBuf> = rd.flatten().map(|e| e.path()).collect();
            v.sort();
            v.into_iter().next()
        });
        Ok(CellResult {
            cell: c.key.clone(),
            scene: c.scene.clone(),
            variant: c.variant.clone(),
            seed: c.seed,
            args: c.args.clone(),
            config_toml: c.config_toml.clone(),
            config: serde_json::to_value(&config).expect("TOML converts to JSON"),
            method: s(&eval, "method"),
            device: s(&train, "device"),
            iterations: f(&eval, "iterations").unwrap_or(0.0) as u32,
            num_gaussians: f(&eval, "num_gaussians").unwrap_or(0.0) as u32,
            psnr: need("psnr")?,
            ssim: need("ssim")?,
            lpips: f(&eval, "lpips"),
            dynamic_psnr: f(&eval, "dynamic_psnr"),
            static_psnr: f(&eval, "static_psnr"),
            mmap: f(&eval, "mmap"),
            drc: f(&eval, "drc"),
            ms_per_step: f(&train, "ms_per_step"),
            train_seconds: f(&train, "train_seconds"),
            cell_seconds,
            jobs: self.jobs,
            run: rel(run),
            strip: strip.as_deref().map(rel),
            status: train
                .get("status")
                .and_then(serde_json::Value::as_str)
                .map(str::to_string),
            status_note: train
                .get("status_note")
                .and_then(serde_json::Value::as_str)
                .map(str::to_string),
        })
    }
}

/// The `status` of the finished run in `run` (its `metrics.json`; `None` when it has none).
pub fn cell_status(run: &Path) -> Result<Option<String>> {
    let p = run.join("metrics.json");
    let t = std::fs::read_to_string(&p).map_err(Error::io(&p))?;
    let v: serde_json::Value =
        serde_json::from_str(&t).map_err(|e| Error::Invalid(format!("{}: {e}", p.display())))?;
    Ok(v.get("status")
        .and_then(serde_json::Value::as_str)
        .map(str::to_string))
}

/// Runs `todo` with at most `jobs` at once; `done(cell, result)` is called on the calling
/// thread's behalf as each ends (under a lock). Returns the failures.
pub fn run_pool(
    env: &CellEnv,
    todo: &[Cell],
    jobs: usize,
    done: &(dyn Fn(&Cell, &Result<CellResult>) + Sync),
) -> Vec<(String, Error)> {
    let next = AtomicUsize::new(0);
    let failures = Mutex::new(Vec::new());
    let lock = Mutex::new(());
    std::thread::scope(|s| {
        for _ in 0..jobs.max(1).min(todo.len().max(1)) {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::SeqCst);
                let Some(c) = todo.get(i) else { break };
                let r = env.run_cell(c);
                let _g = lock.lock().expect("lock");
                done(c, &r);
                if let Err(e) = r {
                    failures.lock().expect("lock").push((c.key.clone(), e));
                }
            });
        }
    });
    failures.into_inner().expect("lock")
}
