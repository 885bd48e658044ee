//! `dispflow-vk sweep`: a plan of scenes × variants × seeds run cell by cell (locally, or as
//! a Slurm job array), collected into `results.jsonl` and the paper-layout and trade tables.
//! Each cell is its own `train` + `eval` process; the tables are rebuilt from the results
//! alone (`sweep report`).

pub mod benchmark;
pub mod exec;
pub mod plan;
pub mod slurm;
pub mod tables;

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::results::{self, CellResult};
use crate::train::checkpoint::write_atomic;
use exec::CellEnv;
use plan::{Plan, TableKind, TradeSpec};

#[derive(clap::Args, Debug, Clone)]
#[command(args_conflicts_with_subcommands = true)]
pub struct SweepArgs {
    #[command(subcommand)]
    pub command: Option<SweepCommand>,
    /// The plan: scenes × variants (any `train` flag or config field) × seeds, as TOML (see
    /// docs/sweep.md and tools/plans/). Checked whole before anything runs.
    pub plan: Option<PathBuf>,
    /// Output root [default: the plan's `out`, else sweeps/<plan name>].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Cells run at once [default: the plan's `jobs`, else 1]. On one machine timings are
    /// only comparable at 1 (every cell would share the cores).
    #[arg(long)]
    pub jobs: Option<u32>,
    /// Write a Slurm job array (one task per unfinished cell, at most --jobs at once) and a
    /// gather job that writes the tables once every task succeeded, into OUT/slurm/.
    #[arg(long)]
    pub slurm: bool,
    /// With --slurm: submit both with sbatch (the gather job with --dependency=afterok).
    #[arg(long, requires = "slurm")]
    pub submit: bool,
    /// Run only the cell with this index in plan order (what a Slurm array task runs).
    #[arg(long, conflicts_with = "slurm")]
    pub cell: Option<usize>,
    /// Print the cells and their `train` commands, run nothing.
    #[arg(long)]
    pub dry_run: bool,
}

#[derive(clap::Subcommand, Debug, Clone)]
pub enum SweepCommand {
    /// Rebuild the tables, the Pareto plot and report.md of a sweep directory from its
    /// results (cells/**/cell.json, plus the results.jsonl lines of cells without one).
    Report(ReportArgs),
}

#[derive(clap::Args, Debug, Clone)]
pub struct ReportArgs {
    /// The sweep directory.
    pub dir: PathBuf,
    /// The plan, for its table choices, trade settings and cells (their order, and which
    /// results.jsonl lines without a cell file are kept) [default: those recorded in
    /// DIR/sweep.json, else every table and every line].
    #[arg(long)]
    pub plan: Option<PathBuf>,
}

/// What `sweep` records about its plan beside the results, so `sweep report` needs nothing
/// else.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct SweepMeta {
    pub name: String,
    pub plan: String,
    pub tables: Vec<TableKind>,
    pub tolerance_db: f64,
    pub paper: Option<String>,
    /// Cell keys in plan order.
    pub cells: Vec<String>,
}

const META: &str = "sweep.json";

impl SweepMeta {
    fn of(plan: &Plan, path: &Path, cells: &[plan::Cell]) -> Self {
        SweepMeta {
            name: plan.name.clone(),
            plan: path.display().to_string(),
            tables: plan.tables(),
            tolerance_db: plan.trade.tolerance_db,
            paper: plan.trade.paper.clone(),
            cells: cells.iter().map(|c| c.key.clone()).collect(),
        }
    }
}

pub fn run(a: &SweepArgs) -> Result<()> {
    if let Some(SweepCommand::Report(r)) = &a.command {
        let results = report(r)?;
        println!(
            "{} cell results → {}",
            results.len(),
            r.dir.join("report.md").display()
        );
        return Ok(());
    }
    let path = a
        .plan
        .as_deref()
        .ok_or_else(|| Error::Invalid("sweep: give a plan file (or `sweep report DIR`)".into()))?;
    let (plan, cells) = Plan::load(path)?;
    let root = plan.out_dir(a.out.as_deref());
    let jobs = a.jobs.or(plan.jobs).unwrap_or(1);
    if jobs == 0 {
        return Err(Error::Invalid("--jobs 0: expected at least 1".into()));
    }
    let exe = std::env::current_exe().map_err(|source| Error::Io {
        path: "the running dispflow-vk binary".into(),
        source,
    })?;
    let base = path.parent().unwrap_or(Path::new("."));
    let env = CellEnv {
        exe,
        root: root.clone(),
        lpips: plan.lpips_path(base),
        jobs,
    };
    if a.dry_run {
        for c in &cells {
            let run = env.cell_dir(c).join("run");
            let cfg = (!c.config_toml.is_empty()).then(|| env.cell_dir(c).join("config.toml"));
            println!(
                "[{}] {}: dispflow-vk {}",
                c.index,
                c.key,
                plan::train_args(c, &run, cfg.as_deref()).join(" ")
            );
        }
        return Ok(());
    }
    if let Some(i) = a.cell {
        let c = cells.get(i).ok_or_else(|| {
            Error::Invalid(format!(
                "--cell {i}: the plan has {} cells (0..{})",
                cells.len(),
                cells.len()
            ))
        })?;
        let r = match env.finished(c)? {
            Some(r) => r,
            None => env.run_cell(c)?,
        };
        println!("{}", summary(&r));
        return Ok(());
    }
    std::fs::create_dir_all(&root).map_err(Error::io(&root))?;
    let meta = SweepMeta::of(&plan, path, &cells);
    write_atomic(
        &root.join(META),
        serde_json::to_string_pretty(&meta)
            .expect("meta serialises")
            .as_bytes(),
    )?;
    let mut todo = Vec::new();
    for c in &cells {
        if env.finished(c)?.is_none() {
            todo.push(c);
        }
    }
    if a.slurm {
        let s = slurm::write_scripts(&env.exe, path, &root, &plan.name, &todo, jobs, &plan.slurm)?;
        eprintln!(
            "{} of {} cells to run; wrote {} and {}",
            todo.len(),
            cells.len(),
            s.cells.display(),
            s.gather.display()
        );
        if a.submit {
            let (array, gather) = slurm::submit(&s, !todo.is_empty())?;
            match array {
                Some(id) => {
                    println!("submitted array job {id} and gather job {gather} (afterok:{id})")
                }
                None => println!("every cell has finished; submitted gather job {gather}"),
            }
        } else {
            println!(
                "submit with: sbatch --parsable {} and then sbatch --dependency=afterok:<its id> {}",
                s.cells.display(),
                s.gather.display()
            );
        }
        return Ok(());
    }
    eprintln!(
        "sweep {}: {} cells ({} finished, {} to run, {jobs} at a time) into {}",
        plan.name,
        cells.len(),
        cells.len() - todo.len(),
        todo.len(),
        root.display()
    );
    let pb = crate::report::progress(cells.len() as u64, "cells");
    pb.set_position((cells.len() - todo.len()) as u64);
    let todo: Vec<plan::Cell> = todo.into_iter().cloned().collect();
    let failures = exec::run_pool(&env, &todo, jobs as usize, &|c, r| {
        pb.inc(1);
        match r {
            // println would be dropped when stderr is not a terminal (the bar is hidden).
            Ok(r) => pb.suspend(|| eprintln!("{}", summary(r))),
            Err(e) => pb.suspend(|| eprintln!("{}: FAILED: {e}", c.key)),
        }
    });
    pb.finish_and_clear();
    let results = results::gather(&root, &meta.cells)?;
    write_report(&root, &results, &meta.tables, &trade_of(&meta))?;
    println!(
        "{} cells → {} and {}",
        results.len(),
        root.join(results::RESULTS).display(),
        root.join("report.md").display()
    );
    if !failures.is_empty() {
        let list: Vec<String> = failures.iter().map(|(k, e)| format!("{k}: {e}")).collect();
        return Err(Error::Invalid(format!(
            "{} of {} cells failed (rerun the same command to retry them; finished cells are \
             kept):\n{}",
            failures.len(),
            cells.len(),
            list.join("\n")
        )));
    }
    Ok(())
}

fn trade_of(m: &SweepMeta) -> TradeSpec {
    TradeSpec {
        tolerance_db: m.tolerance_db,
        paper: m.paper.clone(),
    }
}

fn summary(r: &CellResult) -> String {
    let f = |v: Option<f64>, d: usize| v.map_or("n/a".into(), |x| format!("{x:.d$}"));
    format!(
        "{}: PSNR {:.2} dB (dynamic {}), SSIM {:.4}, MMAP {}, {} ms/step, {} s training",
        r.cell,
        r.psnr,
        f(r.dynamic_psnr, 2),
        r.ssim,
        f(r.mmap, 3),
        f(r.ms_per_step, 1),
        f(r.train_seconds, 1)
    )
}

/// `sweep report`: gathers the results and writes every table.
pub fn report(a: &ReportArgs) -> Result<Vec<CellResult>> {
    let recorded: Option<SweepMeta> = std::fs::read_to_string(a.dir.join(META))
        .ok()
        .map(|t| {
            serde_json::from_str(&t)
                .map_err(|e| Error::Invalid(format!("{}: {e}", a.dir.join(META).display())))
        })
        .transpose()?;
    let (tables, trade, order) = match (&a.plan, &recorded) {
        (Some(p), _) => {
            let (plan, cells) = Plan::load(p)?;
            let order = cells.iter().map(|c| c.key.clone()).collect();
            (plan.tables(), plan.trade.clone(), order)
        }
        (None, Some(m)) => (m.tables.clone(), trade_of(m), m.cells.clone()),
        (None, None) => (TableKind::ALL.to_vec(), TradeSpec::default(), Vec::new()),
    };
    let results = results::gather(&a.dir, &order)?;
    write_report(&a.dir, &results, &tables, &trade)?;
    Ok(results)
}

/// `tables/<kind>.md` and `.csv`, `pareto.png` (with the trade table) and `report.md`.
pub fn write_report(
    root: &Path,
    results: &[CellResult],
    kinds: &[TableKind],
    trade: &TradeSpec,
) -> Result<()> {
    if results.is_empty() {
        return Err(Error::Invalid(format!(
            "{}: no cell has finished; nothing to tabulate",
            root.display()
        )));
    }
    let grid = tables::Grid::new(results);
    let dir = root.join("tables");
    std::fs::create_dir_all(&dir).map_err(Error::io(&dir))?;
    let mut md = format!(
        "# Sweep report\n\n{} cells: {} scene(s) × {} variant(s); regenerate with \
         `dispflow-vk sweep report {}`.\n",
        results.len(),
        grid.scenes.len(),
        grid.variants.len(),
        root.display()
    );
    for &k in kinds {
        let t = grid.table(k, trade.tolerance_db, trade.paper.as_deref());
        let text = t.to_markdown();
        write_atomic(&dir.join(format!("{}.md", k.name())), text.as_bytes())?;
        write_atomic(
            &dir.join(format!("{}.csv", k.name())),
            t.to_csv().as_bytes(),
        )?;
        md += &format!("\n## {}\n\n{text}", title(k));
        if k == TableKind::Trade && grid.scenes.iter().any(|s| !grid.trade_points(s).is_empty()) {
            crate::report::save_png(&grid.pareto_plot(900)?, &root.join("pareto.png"))?;
            md += "\n![Pareto plot](pareto.png)\n";
        }
    }
    // Only strips present beside this copy of the results (a results.jsonl copied elsewhere
    // has none).
    let strips: Vec<&CellResult> = results
        .iter()
        .filter(|r| r.strip.as_ref().is_some_and(|s| root.join(s).is_file()))
        .collect();
    if !strips.is_empty() {
        md +=
            "\n## Renders\n\nOne test frame per cell: render, ground truth, error, flows, mask.\n";
    }
    for r in strips {
        md += &format!(
            "\n**{}** ({:.2} dB)\n\n![{}]({})\n",
            r.cell,
            r.psnr,
            r.cell,
            r.strip.as_deref().expect("filtered")
        );
    }
    write_atomic(&root.join("report.md"), md.as_bytes())
}

fn title(k: TableKind) -> &'static str {
    match k {
        TableKind::Image => "Image quality per scene (Tab. 1 layout)",
        TableKind::Motion => "Motion per scene (Tab. 2 layout)",
        TableKind::Ablation => "Averaged over scenes (ablation layout, Tabs. 4–7)",
        TableKind::Trade => "Speed / accuracy trade",
        TableKind::Benchmark => "Per scene and method, with the published rows apart",
    }
}
