//! What each population costs per step, sampled at the log lines from the step's GPU
//! timestamps: the canonical Gaussians the deformation leaves still (static), those it moves
//! (deforming) and the transients alive at the step's time (the culled ones cost nothing
//! after the temporal stage).
//!
//! A kernel is the deformation's (MLP, control nodes, deform/displacement, the split's row
//! gathers), the transients' (`temporal_*`), per pixel (loss, SSIM, optical flow, the motion
//! term: no population's) or per splat (projection, sort, blending, optimiser, statistics).
//! The splat time is split by the rows each population draws: projection, sorting and
//! blending scale with them to first order (a large Gaussian covers more tiles than a small
//! one, so the split is an attribution, not a separate measurement).

use serde::Serialize;

use crate::vk::Timings;

/// Whose work a timed kernel is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KernelKind {
    /// The deformation's: paid for the deforming rows.
    Deformation,
    /// The temporal stage: paid for the transients.
    Temporal,
    /// Per pixel: the same whatever the Gaussians.
    Image,
    /// Per drawn Gaussian: split by rows.
    Splat,
}

/// The kind of a timing label (`zone/kernel` or `kernel`).
pub fn kind_of(label: &str) -> KernelKind {
    let (zone, kernel) = label.rsplit_once('/').unwrap_or(("", label));
    const DEFORM_ZONES: [&str; 2] = ["mlp", "nodes"];
    const DEFORM: [&str; 11] = [
        "linear",
        "encode",
        "transpose_w",
        "reduce_grad",
        "nodes",
        "mlp",
        "deform_apply",
        "displacement",
        "motion_probe",
        "dyn_",
        "rows_",
    ];
    const IMAGE_ZONES: [&str; 3] = ["loss", "flow", "motion"];
    const IMAGE: [&str; 13] = [
        "ssim",
        "blur",
        "loss",
        "tvl1",
        "grey",
        "downsample",
        "upsample",
        "gradient",
        "warp",
        "norm",
        "motion",
        "mmap",
        "drc",
    ];
    let starts = |s: &str, list: &[&str]| list.iter().any(|p| s.starts_with(p));
    if kernel.starts_with("temporal") {
        KernelKind::Temporal
    } else if starts(zone, &DEFORM_ZONES) || starts(kernel, &DEFORM) {
        KernelKind::Deformation
    } else if starts(zone, &IMAGE_ZONES) || starts(kernel, &IMAGE) {
        KernelKind::Image
    } else {
        KernelKind::Splat
    }
}

/// Rows drawn at one step.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Rows {
    /// Canonical rows the deformation does not move (all of them before it starts).
    pub still: u32,
    pub deforming: u32,
    /// Transients whose temporal weight at the step's time is above the cut-off.
    pub alive: u32,
    /// Every transient row, alive or culled.
    pub transients: u32,
}

#[derive(Clone, Copy, Debug, Default)]
struct Sample {
    rows: Rows,
    deform_ms: f64,
    temporal_ms: f64,
    image_ms: f64,
    splat_ms: f64,
}

/// The sampled steps of a run.
#[derive(Default)]
pub struct CostSampler {
    samples: Vec<Sample>,
}

impl CostSampler {
    /// One timed step: `t` its per-kernel GPU times, `rows` what it drew.
    pub fn add(&mut self, rows: Rows, t: &Timings) {
        let mut s = Sample {
            rows,
            ..Sample::default()
        };
        for (label, ms) in &t.entries {
            match kind_of(label) {
                KernelKind::Deformation => s.deform_ms += ms,
                KernelKind::Temporal => s.temporal_ms += ms,
                KernelKind::Image => s.image_ms += ms,
                KernelKind::Splat => s.splat_ms += ms,
            }
        }
        self.samples.push(s);
    }

    /// Means over the sampled steps; `None` before any.
    pub fn report(&self) -> Option<PopulationCost> {
        let k = self.samples.len();
        if k == 0 {
            return None;
        }
        let mean = |f: &dyn Fn(&Sample) -> f64| self.samples.iter().map(f).sum::<f64>() / k as f64;
        // Per sample: the splat time split by the rows drawn, plus the population's own.
        let share = |s: &Sample, rows: u32| {
            let all = (s.rows.still + s.rows.deforming + s.rows.alive) as f64;
            if all > 0.0 {
                s.splat_ms * rows as f64 / all
            } else {
                0.0
            }
        };
        let pop = |name: &str, rows: &dyn Fn(&Sample) -> u32, own: &dyn Fn(&Sample) -> f64| {
            PopulationMs {
                population: name.into(),
                rows: mean(&|s| rows(s) as f64),
                ms: mean(&|s| share(s, rows(s)) + own(s)),
            }
        };
        Some(PopulationCost {
            sampled_steps: k as u32,
            gpu_ms: mean(&|s| s.deform_ms + s.temporal_ms + s.image_ms + s.splat_ms),
            per_pixel_ms: mean(&|s| s.image_ms),
            transient_rows: mean(&|s| s.rows.transients as f64),
            populations: vec![
                pop("static", &|s| s.rows.still, &|_| 0.0),
                pop("deforming", &|s| s.rows.deforming, &|s| s.deform_ms),
                pop("transient", &|s| s.rows.alive, &|s| s.temporal_ms),
            ],
        })
    }
}

/// GPU milliseconds per step by population: means over the steps timed at the log lines.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PopulationCost {
    pub sampled_steps: u32,
    /// Every kernel of the step.
    pub gpu_ms: f64,
    /// Loss, SSIM, optical flow and the motion term: per pixel, no population's.
    pub per_pixel_ms: f64,
    /// Transient rows held (alive or culled); the transient population's `rows` are the alive.
    pub transient_rows: f64,
    /// static, deforming, transient: rows drawn and their ms (own kernels + the splat share).
    pub populations: Vec<PopulationMs>,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PopulationMs {
    pub population: String,
    pub rows: f64,
    pub ms: f64,
}

impl PopulationCost {
    /// One line for the end of training.
    pub fn summary(&self) -> String {
        let pops: Vec<String> = self
            .populations
            .iter()
            .map(|p| {
                let of = if p.population == "transient" {
                    format!(" alive of {:.0}", self.transient_rows)
                } else {
                    String::new()
                };
                format!("{} {:.0} rows{of} {:.2} ms", p.population, p.rows, p.ms)
            })
            .collect();
        format!(
            "GPU ms per step by population (mean of {} timed steps, {:.2} ms in all): {}, per \
             pixel {:.2} ms",
            self.sampled_steps,
            self.gpu_ms,
            pops.join(", "),
            self.per_pixel_ms
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_of_a_dispflow_step_with_nodes_and_transients_sort_by_whose_work() {
        use KernelKind::*;
        let cases = [
            ("mlp fwd/linear_rows", Deformation),
            ("mlp bwd/reduce_grad", Deformation),
            ("nodes knn/radix_scatter_u32", Deformation),
            ("nodes blend bwd/nodes_gather", Deformation),
            ("deform/deform_apply", Deformation),
            ("deform bwd/deform_apply_bwd", Deformation),
            ("deform/displacement", Deformation),
            ("deform/rows_gather", Deformation),
            ("deform/temporal_fwd", Temporal),
            ("deform bwd/temporal_bwd", Temporal),
            ("deform/temporal_disp", Temporal),
            ("loss/blur_h", Image),
            ("flow/tvl1", Image),
            ("motion norm/norm_mag", Image),
            ("motion/motion_l1", Image),
            ("motion/gflow_l1", Image),
            ("raster/project", Splat),
            ("raster/radix_scatter_u64", Splat),
            ("intermediate/blend_fwd_tile_f0", Splat),
            ("raster bwd/project_bwd", Splat),
            ("deform/deform_static", Splat),
            ("adam/adam", Splat),
            ("densify stats/densify_stats", Splat),
        ];
        for (label, kind) in cases {
            assert_eq!(kind_of(label), kind, "{label}");
        }
    }

    fn timings(e: &[(&str, f64)]) -> Timings {
        Timings {
            entries: e.iter().map(|(l, ms)| (l.to_string(), *ms)).collect(),
        }
    }

    #[test]
    fn splat_time_is_split_by_rows_drawn_and_everything_adds_up() {
        let mut c = CostSampler::default();
        assert!(c.report().is_none());
        let t = timings(&[
            ("raster/project", 6.0),
            ("raster bwd/blend_bwd_tile_f3", 6.0),
            ("mlp fwd/linear_rows", 2.0),
            ("deform/temporal_fwd", 0.5),
            ("loss/blur_h", 1.5),
        ]);
        let rows = Rows {
            still: 300,
            deforming: 600,
            alive: 300,
            transients: 1000,
        };
        c.add(rows, &t);
        // Warm-up: nothing deforms or lives, the static rows take the whole splat time.
        let t0 = timings(&[("raster/project", 4.0), ("loss/blur_h", 1.5)]);
        c.add(
            Rows {
                still: 900,
                ..Rows::default()
            },
            &t0,
        );
        let r = c.report().unwrap();
        assert_eq!(r.sampled_steps, 2);
        let ms: Vec<f64> = r.populations.iter().map(|p| p.ms).collect();
        // static (3 + 4) / 2, deforming (6 + 2) / 2, transient (3 + 0.5) / 2.
        let want = [3.5, 4.0, 1.75];
        for (a, b) in ms.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{ms:?}");
        }
        assert!((r.per_pixel_ms - 1.5).abs() < 1e-12);
        assert!((r.gpu_ms - (16.0 + 5.5) / 2.0).abs() < 1e-12);
        assert!((ms.iter().sum::<f64>() + r.per_pixel_ms - r.gpu_ms).abs() < 1e-12);
        assert_eq!(r.populations[2].rows, 150.0);
        assert_eq!(r.transient_rows, 500.0);
        assert!(r.summary().contains("transient 150 rows alive of 500"));
    }

    #[test]
    fn a_step_that_draws_nothing_attributes_its_splat_time_to_nobody() {
        let mut c = CostSampler::default();
        c.add(Rows::default(), &timings(&[("raster/project", 1.0)]));
        let r = c.report().unwrap();
        assert!(r.populations.iter().all(|p| p.ms == 0.0 && p.rows == 0.0));
        assert!(r.populations.iter().all(|p| p.ms.is_finite()));
    }
}
