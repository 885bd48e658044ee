//! The cell-result format that `sweep` and `eval reference` write and `sweep report` reads:
//! one result per cell (`cells/<key>/cell.json`, the key `scene/variant/seedN` with
//! file-name-safe parts) and their concatenation in plan order, `results.jsonl`, which is all
//! `sweep report` needs to rebuild the tables.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::train::checkpoint::write_atomic;

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

/// A name as one file-name-safe path component.
pub fn safe(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// The key of a cell, `scene/variant/seedN` with file-name-safe parts: also its directory
/// under `cells/`.
pub fn cell_key(scene: &str, variant: &str, seed: u64) -> String {
    format!("{}/{}/seed{seed}", safe(scene), safe(variant))
}

/// Reads `results.jsonl`; a malformed line is refused with its line number.
pub fn read_results(path: &Path) -> Result<Vec<CellResult>> {
    let text = std::fs::read_to_string(path).map_err(Error::io(path))?;
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

/// Writes `r` as `dir/cell.json` (atomically).
pub fn write_cell(dir: &Path, r: &CellResult) -> Result<()> {
    let text = serde_json::to_string_pretty(r).expect("result serialises");
    write_atomic(&dir.join(CELL_JSON), text.as_bytes())
}

pub fn read_cell(path: &Path) -> Result<CellResult> {
    let text = std::fs::read_to_string(path).map_err(Error::io(path))?;
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
    write_atomic(&root.join(RESULTS), text.as_bytes())
}

/// The results of a sweep directory: `results.jsonl` alone when no cell has its own file;
/// else the cells' files plus the rows of `results.jsonl` for cells of `order` (all, when
/// empty) that have no file (finished where their directories were not kept, such as a
/// committed sweep that ships only its `results.jsonl`), ordered as `order` lists cell keys,
/// unknown ones last, and `results.jsonl` is rewritten from them. A cell's file wins over its
/// row: a re-run replaces it. (Without the rows, a `--cell` run into such a directory and
/// the next report rewrote `results.jsonl` with that cell alone.)
pub fn gather(root: &Path, order: &[String]) -> Result<Vec<CellResult>> {
    let files = cell_files(root);
    let p = root.join(RESULTS);
    if files.is_empty() && !p.is_file() {
        return Err(Error::Invalid(format!(
            "{}: no {RESULTS} and no cells/**/{CELL_JSON}: not a sweep directory, or no cell \
             has finished",
            root.display()
        )));
    }
    if files.is_empty() {
        return read_results(&p);
    }
    let mut results = files
        .iter()
        .map(|f| read_cell(f))
        .collect::<Result<Vec<_>>>()?;
    if p.is_file() {
        // A row of a cell the plan no longer has (its directory deleted with it) is dropped.
        let fresh: std::collections::HashSet<String> =
            results.iter().map(|r| r.cell.clone()).collect();
        let keep = |r: &CellResult| {
            !fresh.contains(&r.cell) && (order.is_empty() || order.contains(&r.cell))
        };
        results.extend(read_results(&p)?.into_iter().filter(keep));
    }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn row(cell: &str, psnr: f64) -> CellResult {
        let (scene, rest) = cell.split_once('/').unwrap();
        let variant = rest.split('/').next().unwrap();
        CellResult {
            cell: cell.into(),
            scene: scene.into(),
            variant: variant.into(),
            seed: 0,
            args: vec![],
            config_toml: String::new(),
            config: serde_json::Value::Null,
            method: "DispFlow-GS".into(),
            device: "test".into(),
            iterations: 1,
            num_gaussians: 1,
            psnr,
            ssim: 0.5,
            lpips: None,
            dynamic_psnr: None,
            static_psnr: None,
            mmap: None,
            drc: None,
            ms_per_step: None,
            train_seconds: None,
            cell_seconds: 1.0,
            jobs: 1,
            run: format!("cells/{cell}/run"),
            strip: None,
            status: None,
            status_note: None,
        }
    }

    fn put_cell(root: &Path, r: &CellResult) {
        let d = root.join("cells").join(&r.cell);
        std::fs::create_dir_all(&d).unwrap();
        write_cell(&d, r).unwrap();
    }

    #[test]
    fn cell_keys_are_file_name_safe() {
        assert_eq!(cell_key("D-NeRF lego", "a/b", 3), "D-NeRF_lego/a_b/seed3");
        assert_eq!(safe("x.y-z_ü"), "x.y-z__");
    }

    #[test]
    fn gather_keeps_the_rows_of_cells_without_files_and_a_file_wins() {
        let tmp = tempfile::tempdir().unwrap();
        let root = tmp.path();
        let keys = ["a/x/seed0", "a/y/seed0", "b/x/seed0", "gone/x/seed0"];
        // A committed sweep: results.jsonl only.
        let old: Vec<CellResult> = keys.iter().map(|k| row(k, 10.0)).collect();
        write_results(root, &old).unwrap();
        assert_eq!(gather(root, &[]).unwrap(), old);
        // One cell re-run into it, one new cell; the plan no longer has "gone".
        let (rerun, new) = (row("a/y/seed0", 20.0), row("c/x/seed0", 30.0));
        put_cell(root, &rerun);
        put_cell(root, &new);
        let order: Vec<String> = ["c/x/seed0", "a/x/seed0", "a/y/seed0", "b/x/seed0"]
            .map(String::from)
            .to_vec();
        let got = gather(root, &order).unwrap();
        let want = vec![new.clone(), old[0].clone(), rerun.clone(), old[2].clone()];
        assert_eq!(got, want);
        // results.jsonl now holds the same, so a report from it alone agrees.
        assert_eq!(read_results(&root.join(RESULTS)).unwrap(), want);
        // No order (a report without plan or sweep.json): every row without a file stays,
        // the unordered ones in file-then-row order.
        write_results(root, &old).unwrap();
        let got = gather(root, &[]).unwrap();
        let cells: Vec<&str> = got.iter().map(|r| r.cell.as_str()).collect();
        assert_eq!(
            cells,
            [
                "a/y/seed0",
                "c/x/seed0",
                "a/x/seed0",
                "b/x/seed0",
                "gone/x/seed0"
            ]
        );
        assert_eq!(got[0].psnr, 20.0);
    }
}
