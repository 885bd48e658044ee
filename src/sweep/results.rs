//! One result per cell (`cells/<key>/cell.json`) and their concatenation in plan order,
//! `results.jsonl`, which is all `sweep report` needs to rebuild the tables.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};

/// What a finished cell measured: the `train` report's speed, the `eval` report's quality.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CellResult {
    /// `scene/variant/seedN`.
    pub cell: String,
    pub scene: String,
    pub variant: String,
    pub seed: u64,
    /// The `train` flags the plan gave the cell (without out/resume/config).
    pub args: Vec<String>,
    /// The cell's config table (TOML text; empty = none).
    #[serde(default)]
    pub config_toml: String,
    /// The run's whole resolved configuration (its config.toml).
    pub config: serde_json::Value,
    pub method: String,
    pub device: String,
    pub iterations: u32,
    pub num_gaussians: u32,
    pub psnr: f64,
    pub ssim: f64,
    pub lpips: Option<f64>,
    pub dynamic_psnr: Option<f64>,
    pub static_psnr: Option<f64>,
    pub mmap: Option<f64>,
    pub drc: Option<f64>,
    /// Median wall ms per training step (of the last launch when the cell was resumed).
    pub ms_per_step: Option<f64>,
    /// Training seconds across resumes (probes and evaluation excluded).
    pub train_seconds: Option<f64>,
    /// Wall seconds of the cell's processes in its last launch (train + eval).
    pub cell_seconds: f64,
    /// Cells that ran at once when this one ran (timings compare only at 1).
    pub jobs: u32,
    /// The run directory, relative to the sweep's root.
    pub run: String,
    /// A test frame's picture strip (render, ground truth, error, flows, mask), relative to
    /// the sweep's root, when `eval` drew one.
    pub strip: Option<String>,
    /// How the training ended (`train`'s `metrics.json` `status`: ok, collapsed,
    /// rolled_back) and why when not ok; absent in results written before issue 36.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub status: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub status_note: Option<String>,
}

pub const RESULTS: &str = "results.jsonl";
pub const CELL_JSON: &str = "cell.json";

fn io(path: &Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |source| Error::Io {
        path: path.display().to_string(),
        source,
    }
}

/// Reads `results.jsonl`; a malformed line is refused with its line number.
pub fn read_results(path: &Path) -> Result<Vec<CellResult>> {
    let text = std::fs::read_to_string(path).map_err(io(path))?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            serde_json::from_str(l).map_err(|e| {
                Error::Invalid(format!(
                    "{} line {}: not a cell result: {e}",
                    path.display(),
                    i + 1
                ))
            })
        })
        .collect()
}

pub fn read_cell(path: &Path) -> Result<CellResult> {
    let text = std::fs::read_to_string(path).map_err(io(path))?;
    serde_json::from_str(&text)
        .map_err(|e| Error::Invalid(format!("{}: not a cell result: {e}", path.display())))
}

/// Every `cells/**/cell.json` under `root`, sorted by path.
pub fn cell_files(root: &Path) -> Vec<PathBuf> {
    fn walk(d: &Path, out: &mut Vec<PathBuf>) {
        let Ok(rd) = std::fs::read_dir(d) else { return };
        for e in rd.flatten() {
            let p = e.path();
            if p.is_dir() {
                if p.file_name().is_some_and(|n| n == "run") {
                    continue; // a cell's run directory holds no cell results
                }
                walk(&p, out);
            } else if p.file_name().is_some_and(|n| n == CELL_JSON) {
                out.push(p);
            }
        }
    }
    let mut out = Vec::new();
    walk(&root.join("cells"), &mut out);
    out.sort();
    out
}

/// Writes `results.jsonl` (atomically) from `results` in the given order.
pub fn write_results(root: &Path, results: &[CellResult]) -> Result<()> {
    let mut text = String::new();
    for r in results {
        text.push_str(&serde_json::to_string(r).expect("result serialises"));
        text.push('\n');
    }
    crate::train::checkpoint::write_atomic(&root.join(RESULTS), text.as_bytes())
}

/// The results of a sweep directory: the cells' own files when there are any (rewriting
/// `results.jsonl` from them, ordered as `order` lists cell keys, unknown ones last), else
/// `results.jsonl` alone.
pub fn gather(root: &Path, order: &[String]) -> Result<Vec<CellResult>> {
    let files = cell_files(root);
    if files.is_empty() {
        let p = root.join(RESULTS);
        if !p.is_file() {
            return Err(Error::Invalid(format!(
                "{}: no {RESULTS} and no cells/**/{CELL_JSON}: not a sweep directory, or no \
                 cell has finished",
                root.display()
            )));
        }
        return read_results(&p);
    }
    let mut results = files
        .iter()
        .map(|f| read_cell(f))
        .collect::<Result<Vec<_>>>()?;
    let pos = |r: &CellResult| {
        order
            .iter()
            .position(|k| *k == r.cell)
            .unwrap_or(usize::MAX)
    };
    results.sort_by_key(|r| pos(r));
    write_results(root, &results)?;
    Ok(results)
}
