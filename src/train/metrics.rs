//! The one `metrics.json` schema, written by `train` (`RUN/metrics.json`, with its training
//! figures) and by `eval` (`RUN/eval/metrics.json`), and the paper-style Markdown table.

use serde::Serialize;

use super::score::FrameEval;
use crate::report::{self, Table};
use crate::train::config::{DeformMode, NormGrad, TrainConfig};

/// Scores of a run on its test split.
#[derive(Debug, Serialize)]
pub struct Report {
    pub run: String,
    pub method: String,
    pub scene: String,
    pub dataset: String,
    pub device: String,
    pub iterations: u32,
    /// The background trained and scored on (`black`, `white`, `random`).
    pub background: String,
    /// Why, when `--background auto` picked it (`train` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub background_reason: Option<String>,
    pub num_gaussians: u32,
    pub psnr: f64,
    pub ssim: f64,
    pub l1: f64,
    /// `None` (null) unless LPIPS weights were given; see `lpips_note`.
    pub lpips: Option<f64>,
    pub lpips_note: String,
    /// Mean AP over test frames with a non-empty motion mask (present when the split has masks).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mmap: Option<f64>,
    /// Mean DRC over test frames that have an earlier time in the dataset.
    pub drc: Option<f64>,
    /// Mean PSNR inside the dilated motion masks, and outside them, over the test frames with
    /// a non-empty mask (absent without masks): a smeared or missing moving object shows here.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dynamic_psnr: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub static_psnr: Option<f64>,
    /// MMAP of the optical flow frozen render → ground truth: how well the motion loss's
    /// signal separates moving pixels.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flow_mmap: Option<f64>,
    /// Test PSNR of the initial model (`train` only; absent for a resumed run).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub initial_psnr: Option<f64>,
    /// Median wall-clock milliseconds per training step (`train` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ms_per_step: Option<f64>,
    /// Fraction of the canonical Gaussians the deformation moves at the end (1 = dense model;
    /// transients are never in it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dynamic_fraction: Option<f64>,
    /// Mean dynamic fraction over the last launch's training steps that ran the MLP (`train`
    /// only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_dynamic_fraction: Option<f64>,
    /// Median wall ms per step of the last launch by what the step ran (`train` only).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub ms_per_step_by_phase: Vec<PhaseMs>,
    /// Wall seconds of the training steps across resumes (`train` only; as `log.jsonl`'s
    /// `wall_s`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub train_seconds: Option<f64>,
    /// Training seconds until the test-PSNR probe first read each threshold (`train` only;
    /// from `log.jsonl`, across resumes).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub time_to_psnr: Vec<crate::train::curve::TimeTo>,
    /// Collapses the run confirmed (`train` only; from `log.jsonl`, across resumes): when,
    /// the probe views' PSNR before and after, and any rollback.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub collapses: Vec<crate::train::collapse::CollapseEvent>,
    /// Densification steps that removed most of the Gaussians (`train` only; from
    /// `log.jsonl`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub mass_prunes: Vec<crate::train::collapse::PruneEvent>,
    /// How the run ended (`train` only): `ok`, `collapsed` (a collapse not rolled back, or a
    /// final test PSNR below the initial one) or `rolled_back` (`rollbacks` times, and then
    /// trained on), with the reason when not ok.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub status: Option<crate::train::collapse::RunStatus>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub status_note: Option<String>,
    #[serde(skip_serializing_if = "is_zero")]
    pub rollbacks: u32,
    /// The populations at the end (`train` only, with transients on): canonical Gaussians (the
    /// deformation's; `dynamic_fraction` of them move when the model is split) and transient
    /// ones, and the transients' share of the budget.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gaussians_canonical: Option<u32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gaussians_transient: Option<u32>,
    /// The iteration after which this launch first spawned transients (`--transients auto`:
    /// when its gate opened); absent when none spawned.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub transients_first_spawn: Option<u32>,
    /// GPU ms per step by population (`train` only): static, deforming and transient rows
    /// drawn and what each costs, from the steps timed at the log lines of this launch
    /// (`train::cost`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cost_per_step: Option<crate::train::cost::PopulationCost>,
    pub per_frame: Vec<FrameEval>,
}

fn is_zero(v: &u32) -> bool {
    *v == 0
}

/// Median wall ms per training step of one kind (what the step ran).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct PhaseMs {
    /// `no MLP` (warm-up or `--deform off`), `MLP over all` or `MLP over dynamic`, each
    /// `+ motion` when the step had the motion term.
    pub phase: String,
    pub steps: u32,
    pub median_ms: f64,
}

/// What a report says about where it came from.
pub struct ReportContext {
    pub run: String,
    pub scene: String,
    pub dataset: String,
    pub device: String,
    pub iterations: u32,
    pub num_gaussians: u32,
}

impl Report {
    /// Means over the frames (non-finite PSNRs, e.g. of a perfect frame, left out).
    pub fn new(cfg: &TrainConfig, c: ReportContext, per: Vec<FrameEval>) -> Report {
        let (mmap, drc) = motion_means(&per);
        let flow_mmap = mmap.and(crate::kernels::metrics::mmap(per.iter().map(|e| e.flow_ap)));
        Report {
            run: c.run,
            method: method_name(cfg),
            scene: c.scene,
            dataset: c.dataset,
            device: c.device,
            iterations: c.iterations,
            background: format!("{:?}", cfg.background).to_lowercase(),
            background_reason: None,
            num_gaussians: c.num_gaussians,
            psnr: mean(per.iter().map(|e| e.psnr)),
            ssim: mean(per.iter().map(|e| e.ssim)),
            l1: mean(per.iter().map(|e| e.l1)),
            lpips: None,
            lpips_note: "unavailable: no --lpips-weights given".into(),
            mmap,
            drc,
            dynamic_psnr: mean_some(per.iter().map(|e| e.dynamic_psnr)),
            static_psnr: mean_some(per.iter().map(|e| e.static_psnr)),
            flow_mmap,
            initial_psnr: None,
            ms_per_step: None,
            dynamic_fraction: None,
            mean_dynamic_fraction: None,
            ms_per_step_by_phase: Vec::new(),
            train_seconds: None,
            time_to_psnr: Vec::new(),
            collapses: Vec::new(),
            mass_prunes: Vec::new(),
            status: None,
            status_note: None,
            rollbacks: 0,
            gaussians_canonical: None,
            gaussians_transient: None,
            transients_first_spawn: None,
            cost_per_step: None,
            per_frame: per,
        }
    }

    /// The mean of the per-frame LPIPS values, computed with the weights in `weights`.
    pub fn set_lpips(&mut self, weights: &std::path::Path) {
        let v: Vec<f64> = self.per_frame.iter().filter_map(|e| e.lpips).collect();
        self.lpips = (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
        self.lpips_note = format!(
            "AlexNet LPIPS (lpips v0.1) of the render vs ground truth, mean over {} test frames, \
             weights {}",
            v.len(),
            weights.display()
        );
    }

    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("report serialises")
    }
}

/// MMAP (when any frame has a mask) and mean DRC of evaluated frames.
pub fn motion_means(per: &[FrameEval]) -> (Option<f64>, Option<f64>) {
    let mmap = if per.iter().any(|e| e.has_mask) {
        crate::kernels::metrics::mmap(per.iter().map(|e| e.ap))
    } else {
        None
    };
    let drcs: Vec<f64> = per.iter().filter_map(|e| e.drc).collect();
    let drc = (!drcs.is_empty()).then(|| drcs.iter().sum::<f64>() / drcs.len() as f64);
    (mmap, drc)
}

/// Mean of the finite values present (`None` when there are none).
pub fn mean_some(v: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let f: Vec<f64> = v.flatten().filter(|x| x.is_finite()).collect();
    (!f.is_empty()).then(|| f.iter().sum::<f64>() / f.len() as f64)
}

/// Mean of the finite values (NaN when there are none).
pub fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let f: Vec<f64> = v.filter(|x| x.is_finite()).collect();
    if f.is_empty() {
        f64::NAN
    } else {
        f.iter().sum::<f64>() / f.len() as f64
    }
}

/// The paper's row name for the run (e.g. "Gaussian Flow + Indirect Scene Motion (MotionGS)",
/// `train::method::row_name`), with α when it is not the paper's 0.1 and the normalisation
/// gradient when it is not the default.
pub fn method_name(cfg: &TrainConfig) -> String {
    let mut name = crate::train::method::row_name(cfg);
    let moving = cfg.deform != DeformMode::Off && cfg.motion_weight > 0.0;
    if moving && cfg.motion_weight != 0.1 {
        name += &format!(", α={}", cfg.motion_weight);
    }
    if moving && cfg.motion_norm_grad == NormGrad::Detached {
        name += ", detached norm stats";
    }
    name
}

const TABLE_HEADERS: [&str; 9] = [
    "Method",
    "Scene",
    "PSNR ↑",
    "dyn PSNR ↑",
    "static PSNR ↑",
    "SSIM ↑",
    "LPIPS ↓",
    "MMAP ↑",
    "DRC ↑",
];

/// The paper-style table (a row per run, metric columns).
pub fn table(reports: &[Report]) -> Table {
    Table {
        headers: TABLE_HEADERS.iter().map(|s| s.to_string()).collect(),
        rows: reports
            .iter()
            .map(|r| {
                vec![
                    format!("{} [{}]", r.method, r.run),
                    r.scene.clone(),
                    report::fmt_metric(Some(r.psnr), 2),
                    report::fmt_metric(r.dynamic_psnr, 2),
                    report::fmt_metric(r.static_psnr, 2),
                    report::fmt_metric(Some(r.ssim), 4),
                    report::fmt_metric(r.lpips, 4),
                    report::fmt_metric(r.mmap, 4),
                    report::fmt_metric(r.drc, 4),
                ]
            })
            .collect(),
    }
}
