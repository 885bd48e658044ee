//! Sweep plans: scenes × named variants × seeds in one TOML file, expanded into cells and
//! checked as a whole before anything runs (unknown flags and fields, missing scenes, empty
//! grids, duplicate names are refused, naming the plan entry).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use clap::{CommandFactory, Parser};
use serde::Deserialize;

use crate::error::{Error, Result};
use crate::results::{cell_key, safe};
use crate::train::cli::{resolve_config_with, TrainArgs};

/// A plan file (`tools/plans/*.toml`; the format is in `docs/sweep.md`).
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plan {
    pub name: String,
    /// Output root, relative to the directory `sweep` runs in [default: sweeps/<name>].
    pub out: Option<PathBuf>,
    #[serde(default = "default_seeds")]
    pub seeds: Vec<u64>,
    /// `--iterations` of every cell (a variant's own flag wins).
    pub iterations: Option<u32>,
    /// Cells run at once [default: 1; timings are only comparable at 1 on one machine].
    pub jobs: Option<u32>,
    /// LPIPS weights for `eval` (relative to the plan file); without them LPIPS is n/a.
    pub lpips_weights: Option<PathBuf>,
    /// Which tables to write: image, motion, ablation, trade, benchmark [default: the first
    /// four].
    pub tables: Option<Vec<TableKind>>,
    /// `train` flags of every cell (a scene's or variant's flag of the same name wins).
    #[serde(default)]
    pub flags: BTreeMap<String, toml::Value>,
    /// Config fields of every cell (merged under the scenes' and variants' tables).
    #[serde(default)]
    pub config: toml::Table,
    #[serde(default, rename = "scene")]
    pub scenes: Vec<Scene>,
    #[serde(default, rename = "variant")]
    pub variants: Vec<Variant>,
    #[serde(default)]
    pub trade: TradeSpec,
    #[serde(default)]
    pub slurm: SlurmSpec,
}

fn default_seeds() -> Vec<u64> {
    vec![0]
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum TableKind {
    Image,
    Motion,
    Ablation,
    Trade,
    /// One row per scene and method with its budget, and the published rows of the same
    /// scenes apart (D-NeRF; issue 58). Only when a plan asks for it.
    Benchmark,
}

impl TableKind {
    pub const ALL: [TableKind; 4] = [Self::Image, Self::Motion, Self::Ablation, Self::Trade];
    pub fn name(self) -> &'static str {
        match self {
            Self::Image => "image",
            Self::Motion => "motion",
            Self::Ablation => "ablation",
            Self::Trade => "trade",
            Self::Benchmark => "benchmark",
        }
    }
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    pub name: String,
    /// Dataset directory relative to the plan file; absent = the built-in scene.
    pub data: Option<PathBuf>,
    #[serde(default)]
    pub flags: BTreeMap<String, toml::Value>,
    #[serde(default)]
    pub config: toml::Table,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Variant {
    pub name: String,
    #[serde(default)]
    pub flags: BTreeMap<String, toml::Value>,
    #[serde(default)]
    pub config: toml::Table,
}

/// How the trade table picks its recommendations.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TradeSpec {
    /// "Fastest acceptable": the fastest cell within this many dB of the scene's best PSNR.
    pub tolerance_db: f64,
    /// The variant closest to the paper's setting (named in the table), if any.
    pub paper: Option<String>,
}

impl Default for TradeSpec {
    fn default() -> Self {
        TradeSpec {
            tolerance_db: 0.5,
            paper: None,
        }
    }
}

/// Resources of each Slurm array task (`sweep --slurm`); absent fields are left to the
/// cluster's defaults.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SlurmSpec {
    pub partition: Option<String>,
    pub cpus_per_task: Option<u32>,
    pub mem: Option<String>,
    pub time: Option<String>,
    pub gres: Option<String>,
    /// Further `#SBATCH` options, verbatim (e.g. "--account=lab").
    #[serde(default)]
    pub extra: Vec<String>,
}

/// One run of the grid.
#[derive(Debug, Clone, PartialEq)]
pub struct Cell {
    /// Position in the plan's order (the Slurm array index).
    pub index: usize,
    pub scene: String,
    pub variant: String,
    pub seed: u64,
    /// `scene/variant/seedN` with file-name-safe parts: the cell's directory under `cells/`.
    pub key: String,
    pub data: Option<PathBuf>,
    /// `train` flags (without `--out`, `--resume` and `--config`).
    pub args: Vec<String>,
    /// Config fields merged from the plan, scene and variant tables (TOML; empty = none).
    pub config_toml: String,
}

/// Flags a plan may not set: the sweep owns them.
const OWNED: [(&str, &str); 5] = [
    (
        "out",
        "each cell trains into its own directory under the sweep's out",
    ),
    ("resume", "every cell resumes from its checkpoint"),
    ("seed", "use the plan's seeds = [...]"),
    ("data", "use a [[scene]]'s data ="),
    ("config", "use a config table in the plan"),
];

#[derive(Parser)]
#[command(name = "train", no_binary_name = true)]
struct TrainOnly {
    #[command(flatten)]
    a: TrainArgs,
}

impl Plan {
    /// Reads and checks a plan; every cell's flags and config are resolved as `train` would.
    pub fn load(path: &Path) -> Result<(Plan, Vec<Cell>)> {
        let text = std::fs::read_to_string(path).map_err(Error::io(path))?;
        let plan: Plan = toml::from_str(&text)
            .map_err(|e| Error::Invalid(format!("plan {}: {e}", path.display())))?;
        let base = path.parent().unwrap_or(Path::new("."));
        let cells = plan
            .cells(base)
            .map_err(|m| Error::Invalid(format!("plan {}: {m}", path.display())))?;
        Ok((plan, cells))
    }

    /// The output root for `--out` (or the plan's own, or `sweeps/<name>`).
    pub fn out_dir(&self, over: Option<&Path>) -> PathBuf {
        over.map(Path::to_path_buf)
            .or_else(|| self.out.clone())
            .unwrap_or_else(|| PathBuf::from("sweeps").join(safe(&self.name)))
    }

    pub fn tables(&self) -> Vec<TableKind> {
        self.tables.clone().unwrap_or(TableKind::ALL.to_vec())
    }

    /// `path` relative to the plan's directory `base` (absolute paths stay).
    fn resolve(base: &Path, path: &Path) -> PathBuf {
        if path.is_absolute() {
            path.to_path_buf()
        } else {
            base.join(path)
        }
    }

    pub fn lpips_path(&self, base: &Path) -> Option<PathBuf> {
        self.lpips_weights
            .as_deref()
            .map(|p| Self::resolve(base, p))
            .map(|p| std::path::absolute(&p).unwrap_or(p))
    }

    /// Expands the grid in plan order (scene, then variant, then seed) and checks every cell.
    fn cells(&self, base: &Path) -> std::result::Result<Vec<Cell>, String> {
        if self.scenes.is_empty() {
            return Err("the grid is empty: no [[scene]]".into());
        }
        if self.variants.is_empty() {
            return Err("the grid is empty: no [[variant]]".into());
        }
        if self.seeds.is_empty() {
            return Err("the grid is empty: seeds = []".into());
        }
        if self.jobs == Some(0) {
            return Err("jobs = 0: expected at least 1".into());
        }
        if !(self.trade.tolerance_db.is_finite() && self.trade.tolerance_db >= 0.0) {
            return Err(format!(
                "trade.tolerance_db = {}: expected a finite value ≥ 0",
                self.trade.tolerance_db
            ));
        }
        unique("scene", self.scenes.iter().map(|s| s.name.as_str()))?;
        unique("variant", self.variants.iter().map(|v| v.name.as_str()))?;
        unique_seeds(&self.seeds)?;
        if let Some(p) = &self.trade.paper {
            if !self.variants.iter().any(|v| &v.name == p) {
                return Err(format!("trade.paper = {p:?}: no [[variant]] has that name"));
            }
        }
        if let Some(w) = self.lpips_path(base) {
            if !w.is_file() {
                return Err(format!(
                    "lpips_weights = {:?}: no such file ({})",
                    self.lpips_weights.as_ref().expect("set").display(),
                    w.display()
                ));
            }
        }
        check_flags("flags", &self.flags)?;
        let mut cells = Vec::new();
        for s in &self.scenes {
            // Absolute, so a Slurm task started in another directory finds the same data.
            let data = s
                .data
                .as_deref()
                .map(|d| Self::resolve(base, d))
                .map(|d| std::path::absolute(&d).unwrap_or(d));
            if let Some(d) = &data {
                if !d.is_dir() {
                    return Err(format!(
                        "scene {:?}: data = {:?}: no such directory ({})",
                        s.name,
                        s.data.as_ref().expect("set").display(),
                        d.display()
                    ));
                }
                crate::data::detect_format(d).map_err(|e| format!("scene {:?}: {e}", s.name))?;
            }
            let what = format!("scene {:?}", s.name);
            check_flags(&format!("{what}: flags"), &s.flags)?;
            for v in &self.variants {
                let what = format!("{what}, variant {:?}", v.name);
                check_flags(&format!("variant {:?}: flags", v.name), &v.flags)?;
                let mut flags = self.flags.clone();
                if let Some(i) = self.iterations {
                    flags.insert("iterations".into(), toml::Value::Integer(i as i64));
                }
                flags.extend(s.flags.clone());
                flags.extend(v.flags.clone());
                let mut config = self.config.clone();
                merge_table(&mut config, &s.config);
                merge_table(&mut config, &v.config);
                let config_toml = if config.is_empty() {
                    String::new()
                } else {
                    toml::to_string(&config).map_err(|e| format!("{what}: config: {e}"))?
                };
                for &seed in &self.seeds {
                    let mut args = to_args(&flags).map_err(|m| format!("{what}: {m}"))?;
                    args.extend(["--seed".into(), seed.to_string()]);
                    if let Some(d) = &data {
                        args.extend(["--data".into(), d.display().to_string()]);
                    }
                    check_cell(&args, &config_toml, &what)?;
                    cells.push(Cell {
                        index: cells.len(),
                        scene: s.name.clone(),
                        variant: v.name.clone(),
                        seed,
                        key: cell_key(&s.name, &v.name, seed),
                        data: data.clone(),
                        args,
                        config_toml: config_toml.clone(),
                    });
                }
            }
        }
        Ok(cells)
    }
}

/// Refuses duplicate names, and names that map to the same directory.
fn unique<'a>(what: &str, names: impl Iterator<Item = &'a str>) -> std::result::Result<(), String> {
    let mut seen: BTreeMap<String, &str> = BTreeMap::new();
    for n in names {
        if n.is_empty() {
            return Err(format!("a [[{what}]] has an empty name"));
        }
        if let Some(prev) = seen.insert(safe(n), n) {
            return Err(if prev == n {
                format!("duplicate {what} name {n:?}")
            } else {
                format!(
                    "{what} names {prev:?} and {n:?} map to the same directory {:?}",
                    safe(n)
                )
            });
        }
    }
    Ok(())
}

fn unique_seeds(seeds: &[u64]) -> std::result::Result<(), String> {
    let mut s = seeds.to_vec();
    s.sort_unstable();
    match s.windows(2).find(|w| w[0] == w[1]) {
        Some(w) => Err(format!("seeds: {} is listed twice", w[0])),
        None => Ok(()),
    }
}

/// Every flag must be one of `train`'s and not one the sweep owns.
fn check_flags(
    what: &str,
    flags: &BTreeMap<String, toml::Value>,
) -> std::result::Result<(), String> {
    let cmd = TrainOnly::command();
    for k in flags.keys() {
        if let Some((_, why)) = OWNED.iter().find(|(o, _)| o == k) {
            return Err(format!("{what}.{k}: the sweep sets --{k} itself ({why})"));
        }
        if !cmd.get_arguments().any(|a| a.get_long() == Some(k)) {
            return Err(format!(
                "{what}.{k}: `dispflow-vk train` has no flag --{k} (see `dispflow-vk train --help`)"
            ));
        }
    }
    Ok(())
}

/// Flags as command-line arguments: `true` for a switch gives the bare flag, `false` none;
/// other values give `--flag value`.
fn to_args(flags: &BTreeMap<String, toml::Value>) -> std::result::Result<Vec<String>, String> {
    let cmd = TrainOnly::command();
    let mut out = Vec::new();
    for (k, v) in flags {
        let arg = cmd
            .get_arguments()
            .find(|a| a.get_long() == Some(k))
            .ok_or_else(|| format!("flags.{k}: `dispflow-vk train` has no flag --{k}"))?;
        let switch = matches!(arg.get_action(), clap::ArgAction::SetTrue);
        let value = match v {
            toml::Value::String(s) => s.clone(),
            toml::Value::Integer(i) => i.to_string(),
            toml::Value::Float(f) => f.to_string(),
            toml::Value::Boolean(b) if switch => {
                if *b {
                    out.push(format!("--{k}"));
                }
                continue;
            }
            toml::Value::Boolean(b) => b.to_string(),
            other => {
                return Err(format!(
                    "flags.{k} = {other}: expected a string, number or boolean"
                ))
            }
        };
        if switch {
            return Err(format!(
                "flags.{k} = {v}: --{k} is a switch; write true or false"
            ));
        }
        out.extend([format!("--{k}"), value]);
    }
    Ok(out)
}

/// Parses a cell's flags as `train` would and resolves its configuration.
fn check_cell(args: &[String], config_toml: &str, what: &str) -> std::result::Result<(), String> {
    let parsed = TrainOnly::try_parse_from(args).map_err(|e| {
        let msg = e.to_string();
        let first = msg
            .lines()
            .next()
            .unwrap_or("")
            .trim_start_matches("error: ");
        format!("{what}: flags {}: {first}", args.join(" "))
    })?;
    let extra = (!config_toml.is_empty()).then_some((config_toml, "config table"));
    resolve_config_with(&parsed.a, false, extra).map_err(|e| match e {
        Error::Invalid(m) => format!("{what}: {m}"),
        e => format!("{what}: {e}"),
    })?;
    Ok(())
}

/// Merges `over` into `base`, table by table.
fn merge_table(base: &mut toml::Table, over: &toml::Table) {
    for (k, v) in over {
        match (base.get_mut(k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge_table(b, o),
            _ => {
                base.insert(k.clone(), v.clone());
            }
        }
    }
}

/// `train` arguments for a cell: its flags plus output, resume and its config file.
pub fn train_args(cell: &Cell, run: &Path, config: Option<&Path>) -> Vec<String> {
    let mut a = vec!["train".to_string()];
    a.extend(cell.args.iter().cloned());
    a.extend(["--out".into(), run.display().to_string(), "--resume".into()]);
    if let Some(c) = config {
        a.extend(["--config".into(), c.display().to_string()]);
    }
    a
}
