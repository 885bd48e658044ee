//! The sweep's tables from its cell results alone: image metrics per scene (the paper's
//! Tab. 1 layout), motion metrics (Tab. 2), the ablation layout (Tabs. 4–7: every scene
//! averaged), and the speed/accuracy trade with its Pareto frontier; mean ± sample std over
//! seeds, as Markdown and CSV.

use super::plan::TableKind;
use crate::report::{Plot, Series, Table};
use crate::results::CellResult;

/// Mean and sample standard deviation of the seeds that have a value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stat {
    pub mean: f64,
    pub std: f64,
    pub n: usize,
}

pub fn stat(values: impl Iterator<Item = Option<f64>>) -> Option<Stat> {
    let v: Vec<f64> = values.flatten().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return None;
    }
    let n = v.len();
    let mean = v.iter().sum::<f64>() / n as f64;
    let std = if n > 1 {
        (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt()
    } else {
        0.0
    };
    Some(Stat { mean, std, n })
}

/// A table cell: text, or a statistic shown with `decimals`.
#[derive(Debug, Clone)]
pub(super) enum Val {
    Text(String),
    Num(Option<Stat>, usize),
}

/// A table that renders both as Markdown ("19.63 ± 0.02") and as CSV (mean and std in
/// separate columns, so a script reads numbers).
pub struct SweepTable {
    pub kind: TableKind,
    pub(super) headers: Vec<String>,
    pub(super) rows: Vec<Vec<Val>>,
    /// Lines printed under the Markdown table.
    pub notes: Vec<String>,
}

impl SweepTable {
    pub fn to_markdown(&self) -> String {
        let rows = self
            .rows
            .iter()
            .map(|r| {
                r.iter()
                    .map(|v| match v {
                        Val::Text(t) => t.clone(),
                        Val::Num(None, _) => "n/a".into(),
                        Val::Num(Some(s), d) if s.n > 1 => {
                            format!("{:.d$} ± {:.d$}", s.mean, s.std, d = *d)
                        }
                        Val::Num(Some(s), d) => format!("{:.d$}", s.mean, d = *d),
                    })
                    .collect()
            })
            .collect();
        let t = Table {
            headers: self.headers.clone(),
            rows,
        };
        let mut md = t.to_markdown();
        for n in &self.notes {
            md.push_str(&format!("\n{n}\n"));
        }
        md
    }

    pub fn to_csv(&self) -> String {
        let mut head = Vec::new();
        let numeric: Vec<bool> = (0..self.headers.len())
            .map(|i| {
                self.rows
                    .iter()
                    .any(|r| matches!(r.get(i), Some(Val::Num(..))))
            })
            .collect();
        for (h, &num) in self.headers.iter().zip(&numeric) {
            head.push(csv_field(h));
            if num {
                head.push(csv_field(&format!("{h} std")));
                head.push(csv_field(&format!("{h} n")));
            }
        }
        let mut out = head.join(",") + "\n";
        for r in &self.rows {
            let mut f = Vec::new();
            for (v, &num) in r.iter().zip(&numeric) {
                match v {
                    Val::Text(t) => {
                        f.push(csv_field(t));
                        if num {
                            f.extend([String::new(), String::new()]);
                        }
                    }
                    Val::Num(None, _) => f.extend([String::new(), String::new(), "0".into()]),
                    Val::Num(Some(s), _) => {
                        f.extend([s.mean.to_string(), s.std.to_string(), s.n.to_string()])
                    }
                }
            }
            out += &(f.join(",") + "\n");
        }
        out
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// Names in order of first appearance.
fn ordered<'a>(it: impl Iterator<Item = &'a str>) -> Vec<String> {
    let mut v: Vec<String> = Vec::new();
    for s in it {
        if !v.iter().any(|x| x == s) {
            v.push(s.to_string());
        }
    }
    v
}

/// The results grouped by scene and variant, in first-appearance order.
pub struct Grid<'a> {
    pub scenes: Vec<String>,
    pub variants: Vec<String>,
    results: &'a [CellResult],
}

pub(super) type Metric = fn(&CellResult) -> Option<f64>;

const PSNR: (&str, Metric, usize) = ("PSNR", |r| Some(r.psnr), 2);
const SSIM: (&str, Metric, usize) = ("SSIM", |r| Some(r.ssim), 4);
const LPIPS: (&str, Metric, usize) = ("LPIPS", |r| r.lpips, 4);
const DYN: (&str, Metric, usize) = ("dyn PSNR", |r| r.dynamic_psnr, 2);
const MMAP: (&str, Metric, usize) = ("MMAP", |r| r.mmap, 4);
const DRC: (&str, Metric, usize) = ("DRC", |r| r.drc, 4);
const MS: (&str, Metric, usize) = ("ms/step", |r| r.ms_per_step, 1);
const TRAIN_S: (&str, Metric, usize) = ("train s", |r| r.train_seconds, 1);
const GAUSS: (&str, Metric, usize) = ("Gaussians", |r| Some(r.num_gaussians as f64), 0);

impl<'a> Grid<'a> {
    pub fn new(results: &'a [CellResult]) -> Self {
        Grid {
            scenes: ordered(results.iter().map(|r| r.scene.as_str())),
            variants: ordered(results.iter().map(|r| r.variant.as_str())),
            results,
        }
    }

    pub(super) fn cells(&self, scene: &str, variant: &str) -> impl Iterator<Item = &CellResult> {
        let (s, v) = (scene.to_string(), variant.to_string());
        self.results
            .iter()
            .filter(move |r| r.scene == s && r.variant == v)
    }

    pub fn stat(&self, scene: &str, variant: &str, m: Metric) -> Option<Stat> {
        stat(self.cells(scene, variant).map(m))
    }

    /// Per seed the mean over scenes (only seeds every scene has), then mean ± std over seeds.
    fn across_scenes(&self, variant: &str, m: Metric) -> Option<Stat> {
        let seeds = ordered_seeds(self.results.iter().filter(|r| r.variant == variant));
        let per_seed = seeds.iter().map(|&seed| {
            let v: Vec<Option<f64>> = self
                .scenes
                .iter()
                .map(|s| {
                    self.cells(s, variant)
                        .find(|r| r.seed == seed)
                        .and_then(m)
                        .filter(|x| x.is_finite())
                })
                .collect();
            v.iter()
                .all(Option::is_some)
                .then(|| v.iter().flatten().sum::<f64>() / v.len() as f64)
        });
        stat(per_seed)
    }

    fn across_scene_vals<'m>(
        &'m self,
        variant: &'m str,
        metrics: &'m [(&str, Metric, usize)],
    ) -> impl Iterator<Item = Val> + 'm {
        metrics
            .iter()
            .map(move |m| Val::Num(self.across_scenes(variant, m.1), m.2))
    }

    /// A variant's row label, marked ⚠ when one of its cells (of `scene`, or of any scene)
    /// did not end `ok` (a collapse, a rollback, or a final PSNR below the initial one).
    fn label(&self, variant: &str, scene: Option<&str>) -> String {
        let flagged = self
            .results
            .iter()
            .filter(|r| r.variant == variant && scene.map_or(true, |s| r.scene == s))
            .any(|r| r.status.as_deref().is_some_and(|st| st != "ok"));
        if flagged {
            format!("{variant} ⚠")
        } else {
            variant.to_string()
        }
    }

    /// `notes` plus one line naming every cell that did not end `ok`, and why.
    fn status_notes(&self, mut notes: Vec<String>) -> Vec<String> {
        let bad: Vec<String> = self
            .results
            .iter()
            .filter(|r| r.status.as_deref().is_some_and(|st| st != "ok"))
            .map(|r| {
                format!(
                    "{} {}{}",
                    r.cell,
                    r.status.as_deref().unwrap_or_default(),
                    r.status_note
                        .as_deref()
                        .map_or(String::new(), |n| format!(" ({n})"))
                )
            })
            .collect();
        if !bad.is_empty() {
            notes.push(format!(
                "⚠ cells that did not end ok (their means include them): {}.",
                bad.join("; ")
            ));
        }
        notes
    }

    /// Rows = variants; per scene one column per metric, then their means over scenes when
    /// there are several scenes.
    fn per_scene(&self, kind: TableKind, metrics: &[(&str, Metric, usize)]) -> SweepTable {
        let mut headers = vec!["Variant".to_string()];
        let several = self.scenes.len() > 1;
        for s in &self.scenes {
            headers.extend(metrics.iter().map(|m| format!("{s} {}", m.0)));
        }
        if several {
            headers.extend(metrics.iter().map(|m| format!("mean {}", m.0)));
        }
        let rows = self
            .variants
            .iter()
            .map(|v| {
                let mut row = vec![Val::Text(self.label(v, None))];
                for s in &self.scenes {
                    row.extend(metrics.iter().map(|m| Val::Num(self.stat(s, v, m.1), m.2)));
                }
                if several {
                    row.extend(self.across_scene_vals(v, metrics));
                }
                row
            })
            .collect();
        SweepTable {
            kind,
            headers,
            rows,
            notes: self.status_notes(vec![seed_note(self.results)]),
        }
    }

    fn ablation(&self) -> SweepTable {
        let metrics = [PSNR, SSIM, LPIPS, DYN, MMAP, DRC];
        let mut headers = vec!["Variant".to_string()];
        headers.extend(metrics.iter().map(|m| m.0.to_string()));
        let rows = self
            .variants
            .iter()
            .map(|v| {
                let mut row = vec![Val::Text(self.label(v, None))];
                row.extend(self.across_scene_vals(v, &metrics));
                row
            })
            .collect();
        SweepTable {
            kind: TableKind::Ablation,
            headers,
            rows,
            notes: self.status_notes(vec![format!(
                "Each value: the mean over the scenes ({}) per seed, then mean ± std over seeds. {}",
                self.scenes.join(", "),
                seed_note(self.results)
            )]),
        }
    }

    /// The resolution the scene's cells are scored at most often (`max_resolution`, 0 =
    /// as stored): PSNR at another resolution measures another image and is not compared.
    fn reference_resolution(&self, scene: &str) -> Option<i64> {
        let mut counts: Vec<(i64, usize)> = Vec::new();
        for r in self.results.iter().filter(|r| r.scene == scene) {
            let res = scored_at(r);
            match counts.iter_mut().find(|c| c.0 == res) {
                Some(c) => c.1 += 1,
                None => counts.push((res, 1)),
            }
        }
        // The most frequent; on a tie the first seen (plan order).
        let best = counts.iter().map(|c| c.1).max()?;
        counts.iter().find(|c| c.1 == best).map(|c| c.0)
    }

    /// Whether every cell of (scene, variant) is scored at the scene's reference resolution.
    fn comparable(&self, scene: &str, variant: &str) -> bool {
        let want = self.reference_resolution(scene);
        self.cells(scene, variant)
            .all(|r| Some(scored_at(r)) == want)
    }

    /// The (train seconds, PSNR) means of every variant of `scene` that has both and is
    /// scored at the scene's reference resolution.
    pub fn trade_points(&self, scene: &str) -> Vec<(String, f64, f64)> {
        self.variants
            .iter()
            .filter(|v| self.comparable(scene, v))
            .filter_map(|v| {
                let t = self.stat(scene, v, TRAIN_S.1)?;
                let p = self.stat(scene, v, PSNR.1)?;
                Some((v.clone(), t.mean, p.mean))
            })
            .collect()
    }

    fn trade(&self, tolerance_db: f64, paper: Option<&str>) -> SweepTable {
        let metrics = [MS, TRAIN_S, PSNR, DYN, SSIM, LPIPS, MMAP, DRC, GAUSS];
        let mut headers = vec!["Scene".to_string(), "Variant".to_string()];
        headers.extend(metrics.iter().map(|m| m.0.to_string()));
        headers.push("Pareto".into());
        let mut rows = Vec::new();
        let mut notes = Vec::new();
        for s in &self.scenes {
            let pts = self.trade_points(s);
            let front = pareto(&pts);
            let mut vs: Vec<&String> = self.variants.iter().collect();
            let secs = |v: &str| self.stat(s, v, TRAIN_S.1).map_or(f64::INFINITY, |x| x.mean);
            vs.sort_by(|a, b| secs(a).total_cmp(&secs(b)));
            for v in vs {
                if self.cells(s, v).next().is_none() {
                    continue;
                }
                let mut row = vec![Val::Text(s.clone()), Val::Text(self.label(v, Some(s)))];
                row.extend(metrics.iter().map(|m| Val::Num(self.stat(s, v, m.1), m.2)));
                let on = pts.iter().zip(&front).any(|(p, &f)| f && p.0 == *v);
                let mark = if !self.comparable(s, v) {
                    let res = self.cells(s, v).next().map_or(0, scored_at);
                    format!("scored at {}: not compared", px(res))
                } else if on {
                    "✓".into()
                } else {
                    String::new()
                };
                row.push(Val::Text(mark));
                rows.push(row);
            }
            if let Some(best) = pts.iter().max_by(|a, b| a.2.total_cmp(&b.2)) {
                notes.push(format!(
                    "**{s}**: most accurate: {} ({:.2} dB, {:.1} s).",
                    best.0, best.2, best.1
                ));
                if let Some(fast) = pts
                    .iter()
                    .filter(|p| p.2 >= best.2 - tolerance_db)
                    .min_by(|a, b| a.1.total_cmp(&b.1))
                {
                    let gain = if fast.0 == best.0 {
                        "the most accurate itself".to_string()
                    } else {
                        format!(
                            "{:.1}× less training time than the most accurate",
                            best.1 / fast.1.max(1e-9)
                        )
                    };
                    notes.push(format!(
                        "**{s}**: fastest acceptable (within {tolerance_db} dB of the best): {} \
                         ({:.2} dB, {:.1} s, {gain}).",
                        fast.0, fast.2, fast.1,
                    ));
                }
                if let Some(p) = paper.and_then(|p| pts.iter().find(|x| x.0 == p)) {
                    notes.push(format!(
                        "**{s}**: closest to the paper: {} ({:.2} dB, {:.1} s).",
                        p.0, p.2, p.1
                    ));
                }
            }
        }
        notes.push(format!(
            "Pareto: no other variant of the scene trains in less time with a higher PSNR \
             (means over seeds). Only cells scored at the scene's usual resolution are \
             compared: a lower `max_resolution` is scored on a smaller image, whose PSNR is not \
             the same measurement. {}",
            seed_note(self.results)
        ));
        SweepTable {
            kind: TableKind::Trade,
            headers,
            rows,
            notes: self.status_notes(notes),
        }
    }

    pub fn table(&self, kind: TableKind, tolerance_db: f64, paper: Option<&str>) -> SweepTable {
        match kind {
            TableKind::Image => self.per_scene(kind, &[PSNR, SSIM, LPIPS]),
            TableKind::Motion => self.per_scene(kind, &[MMAP, DRC, DYN]),
            TableKind::Ablation => self.ablation(),
            TableKind::Trade => self.trade(tolerance_db, paper),
            TableKind::Benchmark => super::benchmark::table(self),
        }
    }

    /// Which seeds and devices the results come from.
    pub(super) fn seed_note(&self) -> String {
        seed_note(self.results)
    }

    /// Per scene: every variant's (train seconds, PSNR) as a dot, the frontier as a line.
    pub fn pareto_plot(&self, width: u32) -> crate::error::Result<image::RgbImage> {
        let mut plots = Vec::new();
        for s in &self.scenes {
            let pts = self.trade_points(s);
            let front = pareto(&pts);
            let mut series: Vec<Series> = pts
                .iter()
                .enumerate()
                .map(|(i, p)| Series {
                    label: p.0.clone(),
                    points: vec![(p.1, p.2)],
                    color: color(i),
                })
                .collect();
            let mut fp: Vec<(f64, f64)> = pts
                .iter()
                .zip(&front)
                .filter(|(_, &f)| f)
                .map(|(p, _)| (p.1, p.2))
                .collect();
            fp.sort_by(|a, b| a.0.total_cmp(&b.0));
            // Drawn first, so each variant's dot stays visible on top of it.
            series.insert(
                0,
                Series {
                    label: "Pareto frontier".into(),
                    points: fp,
                    color: [60, 60, 60],
                },
            );
            plots.push(
                Plot {
                    title: format!("{s}: test PSNR against training time"),
                    x_label: "training seconds".into(),
                    y_label: "test PSNR (dB)".into(),
                    series,
                    width,
                    height: 420,
                }
                .render()?,
            );
        }
        crate::report::stacked(&plots)
    }
}

/// The `max_resolution` a cell was trained and scored at (0 = as stored).
pub(super) fn scored_at(r: &CellResult) -> i64 {
    r.config
        .get("max_resolution")
        .and_then(serde_json::Value::as_i64)
        .unwrap_or(0)
}

pub(super) fn px(res: i64) -> String {
    if res == 0 {
        "the stored resolution".into()
    } else {
        format!("{res} px")
    }
}

/// 18 distinct colours (Category10, then Dark2) before any repeats.
fn color(i: usize) -> [u8; 3] {
    let (a, b) = (&colorous::CATEGORY10, &colorous::DARK2);
    let c = match i % (a.len() + b.len()) {
        k if k < a.len() => a[k],
        k => b[k - a.len()],
    };
    [c.r, c.g, c.b]
}

fn ordered_seeds<'a>(it: impl Iterator<Item = &'a CellResult>) -> Vec<u64> {
    let mut v: Vec<u64> = it.map(|r| r.seed).collect();
    v.sort_unstable();
    v.dedup();
    v
}

fn seed_note(results: &[CellResult]) -> String {
    let seeds = ordered_seeds(results.iter());
    let devices = ordered(results.iter().map(|r| r.device.as_str()));
    format!(
        "Seeds {:?}; ± is the sample standard deviation over seeds; device {}.",
        seeds,
        devices.join(", ")
    )
}

/// Which points are on the frontier: no other point has time ≤ and PSNR ≥ with one strict.
pub fn pareto(pts: &[(String, f64, f64)]) -> Vec<bool> {
    pts.iter()
        .map(|a| {
            !pts.iter()
                .any(|b| b.1 <= a.1 && b.2 >= a.2 && (b.1 < a.1 || b.2 > a.2))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stat_is_the_sample_mean_and_std() {
        let s = stat([Some(1.0), None, Some(3.0)].into_iter()).unwrap();
        assert_eq!((s.mean, s.n), (2.0, 2));
        assert!((s.std - 2f64.sqrt()).abs() < 1e-12);
        assert_eq!(stat([None, Some(f64::NAN)].into_iter()), None);
        assert_eq!(stat([Some(5.0)].into_iter()).unwrap().std, 0.0);
    }

    #[test]
    fn pareto_keeps_the_undominated_points() {
        let p = |n: &str, t, q| (n.to_string(), t, q);
        let pts = [
            p("a", 10.0, 20.0),
            p("b", 5.0, 19.0),
            p("c", 12.0, 19.5),
            p("d", 5.0, 19.0),
        ];
        // c is dominated by a; b and d tie and neither dominates the other.
        assert_eq!(pareto(&pts), vec![true, true, false, true]);
    }
}
