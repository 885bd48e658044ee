//! Slurm scale-out: one job-array task per unfinished cell (`sweep PLAN --cell $SLURM_ARRAY_TASK_ID`)
//! and a gather job that runs `sweep report` once every task succeeded (`afterok`). The
//! binary, plan and sweep directory must be on a file system the compute nodes share.

use std::path::{Path, PathBuf};
use std::process::Command;

use super::plan::{Cell, SlurmSpec};
use crate::error::{Error, Result};
use crate::train::checkpoint::write_atomic;

/// The two scripts `sweep --slurm` writes.
pub struct Scripts {
    pub cells: PathBuf,
    pub gather: PathBuf,
}

/// Shell-quotes `s` (single quotes).
fn q(s: &str) -> String {
    format!("'{}'", s.replace('\'', r"'\''"))
}

fn header(name: &str, log: &Path, spec: Option<&SlurmSpec>) -> String {
    let mut s = format!(
        "#!/bin/bash\n#SBATCH --job-name={name}\n#SBATCH --output={}\n",
        log.display()
    );
    if let Some(r) = spec {
        if let Some(p) = &r.partition {
            s += &format!("#SBATCH --partition={p}\n");
        }
        if let Some(c) = r.cpus_per_task {
            s += &format!("#SBATCH --cpus-per-task={c}\n");
        }
        if let Some(m) = &r.mem {
            s += &format!("#SBATCH --mem={m}\n");
        }
        if let Some(t) = &r.time {
            s += &format!("#SBATCH --time={t}\n");
        }
        if let Some(g) = &r.gres {
            s += &format!("#SBATCH --gres={g}\n");
        }
        for e in &r.extra {
            s += &format!("#SBATCH {e}\n");
        }
    }
    s
}

/// `0-3,7,9-10`: the array indices of `cells`, ranges folded.
pub fn array_spec(cells: &[&Cell]) -> String {
    let mut idx: Vec<usize> = cells.iter().map(|c| c.index).collect();
    idx.sort_unstable();
    let mut parts = Vec::new();
    let mut i = 0;
    while i < idx.len() {
        let mut j = i;
        while j + 1 < idx.len() && idx[j + 1] == idx[j] + 1 {
            j += 1;
        }
        parts.push(if i == j {
            idx[i].to_string()
        } else {
            format!("{}-{}", idx[i], idx[j])
        });
        i = j + 1;
    }
    parts.join(",")
}

/// Writes `ROOT/slurm/cells.sbatch` (an array over `todo`, at most `jobs` at once) and
/// `ROOT/slurm/gather.sbatch`; every path in them is absolute.
pub fn write_scripts(
    exe: &Path,
    plan: &Path,
    root: &Path,
    name: &str,
    todo: &[&Cell],
    jobs: u32,
    spec: &SlurmSpec,
) -> Result<Scripts> {
    let abs = |p: &Path| std::path::absolute(p).unwrap_or_else(|_| p.to_path_buf());
    let (exe, plan, root) = (abs(exe), abs(plan), abs(root));
    let dir = root.join("slurm");
    let logs = dir.join("logs");
    std::fs::create_dir_all(&logs).map_err(Error::io(&logs))?;
    let job = format!("dispflow-{}", crate::results::safe(name));
    let mut cells = header(&job, &logs.join("cell_%a.out"), Some(spec));
    cells += &format!("#SBATCH --array={}%{jobs}\n", array_spec(todo));
    cells += &format!(
        "set -euo pipefail\nexec {} sweep {} --out {} --cell \"$SLURM_ARRAY_TASK_ID\"\n",
        q(&exe.display().to_string()),
        q(&plan.display().to_string()),
        q(&root.display().to_string())
    );
    let mut gather = header(&format!("{job}-gather"), &logs.join("gather.out"), None);
    gather += &format!(
        "set -euo pipefail\nexec {} sweep report {} --plan {}\n",
        q(&exe.display().to_string()),
        q(&root.display().to_string()),
        q(&plan.display().to_string())
    );
    let s = Scripts {
        cells: dir.join("cells.sbatch"),
        gather: dir.join("gather.sbatch"),
    };
    write_atomic(&s.cells, cells.as_bytes())?;
    write_atomic(&s.gather, gather.as_bytes())?;
    Ok(s)
}

/// `sbatch --parsable [extra] script` → the job id.
fn sbatch(script: &Path, extra: &[String]) -> Result<String> {
    let out = Command::new("sbatch")
        .arg("--parsable")
        .args(extra)
        .arg(script)
        .output()
        .map_err(|e| {
            Error::Invalid(format!(
                "running sbatch for {}: {e} (is Slurm's client installed and SLURM_CONF set? \
                 tools/slurm_local.sh starts a one-node cluster)",
                script.display()
            ))
        })?;
    if !out.status.success() {
        return Err(Error::Invalid(format!(
            "sbatch {} failed ({}): {}",
            script.display(),
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        )));
    }
    // --parsable prints "jobid" or "jobid;cluster".
    let text = String::from_utf8_lossy(&out.stdout);
    let id = text.trim().split(';').next().unwrap_or("").to_string();
    if id.is_empty() || !id.chars().all(|c| c.is_ascii_digit()) {
        return Err(Error::Invalid(format!(
            "sbatch {}: expected a job id, got {:?}",
            script.display(),
            text.trim()
        )));
    }
    Ok(id)
}

/// Submits the array, then the gather job depending on it (`afterok`); returns both ids.
pub fn submit(s: &Scripts, with_cells: bool) -> Result<(Option<String>, String)> {
    let cells = if with_cells {
        Some(sbatch(&s.cells, &[])?)
    } else {
        None
    };
    let dep: Vec<String> = cells
        .iter()
        .map(|id| format!("--dependency=afterok:{id}"))
        .collect();
    let gather = sbatch(&s.gather, &dep)?;
    Ok((cells, gather))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn array_spec_folds_runs() {
        let mk = |i| Cell {
            index: i,
            scene: String::new(),
            variant: String::new(),
            seed: 0,
            key: String::new(),
            data: None,
            args: vec![],
            config_toml: String::new(),
        };
        let cells: Vec<Cell> = [0, 1, 2, 3, 7, 9, 10].into_iter().map(mk).collect();
        let refs: Vec<&Cell> = cells.iter().collect();
        assert_eq!(array_spec(&refs), "0-3,7,9-10");
        assert_eq!(q("a'b"), r"'a'\''b'");
    }
}
