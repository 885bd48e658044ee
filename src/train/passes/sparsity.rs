//! The motion probe: splits the model into dynamic and static Gaussians (DESIGN in
//! `model::dynamic`). Runs between steps, at the cadence the plan gives, never inside one.
//!
//! One classification: D at `times` (evenly over the training frames' time range) over every
//! Gaussian, each sample folded into per-component ranges; the apparent motion in pixels of
//! the training view where it looks largest follows from the ranges, each Gaussian's constant
//! deformation = the midrange. The threshold is max(threshold_px, noise_k · median motion):
//! the MLP moves *every* Gaussian a little (measured on the built-in scene after 600
//! iterations: median 0.53 px on the moving scene, 0.54 px on its static variant, p99 1.1 and
//! 1.2 px), and motion the MLP learnt for a moving object stands out from that floor. Flags =
//! motion > threshold; the flags' prefix sum and the compaction give the dynamic indices on
//! the GPU; the count is read after the submit (the host sizes the next steps' MLP dispatches
//! with it).

use super::deform::{DeformPass, Slot};
use crate::error::Result;
use crate::kernels::raster::Camera;
use crate::kernels::scan::{Count, PrefixSum, ScanScratch};
use crate::kernels::sparse::{ProbeInputs, ProbeSample, SparseKernels, RANGE_ROW};
use crate::model::gaussians::Section;
use crate::model::state::Model;
use crate::vk::{Buffer, Gpu, Recorder};

/// What a classification measures against.
#[derive(Clone, Debug, PartialEq)]
pub struct ProbeConfig {
    /// A Gaussian is dynamic when D moves it by more than this many pixels ...
    pub threshold_px: f32,
    /// ... and by more than this multiple of the median Gaussian's motion (0: off).
    pub noise_k: f32,
    /// Times D is sampled at.
    pub times: Vec<f32>,
}

impl ProbeConfig {
    /// `samples` times evenly over `[t_min, t_max]` (both ends included; one sample: the middle).
    pub fn even(threshold_px: f32, noise_k: f32, samples: u32, t_min: f32, t_max: f32) -> Self {
        let k = samples.max(1);
        let times = (0..k)
            .map(|i| {
                if k == 1 {
                    0.5 * (t_min + t_max)
                } else {
                    t_min + (t_max - t_min) * i as f32 / (k - 1) as f32
                }
            })
            .collect();
        ProbeConfig {
            threshold_px,
            noise_k,
            times,
        }
    }
}

/// What one classification found.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SplitStats {
    pub dynamic: u32,
    pub n: u32,
    /// Quantiles (50 %, 90 %, 99 %) of the probed apparent motion, pixels.
    pub motion_px: [f32; 3],
    /// The threshold used: max(threshold_px, noise_k · median).
    pub threshold_px: f32,
}

impl std::fmt::Display for SplitStats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [a, b, c] = self.motion_px;
        write!(
            f,
            "{} of {} Gaussians dynamic ({:.1} %) above {:.3} px; probed motion p50 {a:.3} px, \
             p90 {b:.3} px, p99 {c:.3} px",
            self.dynamic,
            self.n,
            100.0 * self.dynamic as f64 / self.n.max(1) as f64,
            self.threshold_px
        )
    }
}

pub struct Classifier {
    k: SparseKernels,
    scan: PrefixSum,
    scratch: ScanScratch,
    offsets: Buffer,
    /// [capacity, 21]: the probe's per-component range of D and the pixels (RANGE_ROW).
    range: Buffer,
    cams: Buffer,
    num_cams: u32,
    near: f32,
    cfg: ProbeConfig,
}

impl Classifier {
    /// Scratch for `capacity` Gaussians; `cameras`: the training views (their centres and
    /// focal lengths convert scene units to pixels).
    pub fn new(gpu: &Gpu, capacity: u32, cameras: &[Camera], cfg: ProbeConfig) -> Result<Self> {
        let cams: Vec<[f32; 4]> = cameras.iter().map(camera_row).collect();
        let near = cameras.iter().map(|c| c.near).fold(f32::INFINITY, f32::min);
        let scan = PrefixSum::new(gpu)?;
        let rows = |name: &str| gpu.buffer(name, capacity.max(1) as u64 * 4);
        Ok(Classifier {
            k: SparseKernels::new(gpu)?,
            scratch: scan.scratch(gpu, capacity.max(1))?,
            scan,
            offsets: rows("dynamic offsets")?,
            range: gpu.buffer(
                "motion probe range",
                capacity.max(1) as u64 * 4 * RANGE_ROW as u64,
            )?,
            cams: gpu.buffer_from("probe cameras", &cams)?,
            num_cams: cams.len() as u32,
            near: if near.is_finite() {
                near.max(1e-6)
            } else {
                1e-6
            },
            cfg,
        })
    }

    /// Probes D over every canonical Gaussian and splits them (transients move by their own
    /// velocity, never through D, and stay outside the split).
    pub fn classify(
        &self,
        gpu: &Gpu,
        model: &mut Model,
        deform: &DeformPass,
    ) -> Result<SplitStats> {
        let n = model.gaussians.canonical_rows().len();
        if n == 0 {
            model.dynamic.set_split(0);
            return Ok(SplitStats::default());
        }
        // The probe evaluates D over every Gaussian, static ones included: that is how a
        // static Gaussian whose neighbourhood started moving is found again.
        model.dynamic.set_dense();
        let (g, d) = (&model.gaussians, &model.dynamic);
        let mut rec = Recorder::new(gpu)?;
        let last = self.cfg.times.len().saturating_sub(1);
        let range = self.range.elems::<f32>(0, RANGE_ROW as u64 * n as u64);
        for (k, &t) in self.cfg.times.iter().enumerate() {
            deform.mlp_forward(&mut rec, model, Slot::T1, t);
            let x = ProbeInputs {
                deform: deform.output(Slot::T1),
                log_scales: g.param(Section::LogScales),
                means: g.param(Section::Means),
                cams: self.cams.all(),
                num_cams: self.num_cams,
            };
            let s = ProbeSample {
                first: k == 0,
                last: k == last,
                near: self.near,
            };
            self.k.probe(&mut rec, n, &x, &s, range, d.fixed());
        }
        rec.finish()?;
        // The threshold depends on every Gaussian's motion: read it (this is between steps).
        let r: Vec<f32> = gpu.read(range)?;
        let mut e: Vec<f32> = r.chunks_exact(RANGE_ROW).map(|row| row[20]).collect();
        e.sort_unstable_by(f32::total_cmp);
        let q = |f: f64| e[((e.len() - 1) as f64 * f).round() as usize];
        let threshold_px = self.cfg.threshold_px.max(self.cfg.noise_k * q(0.5));
        let mut rec = Recorder::new(gpu)?;
        let (flags, offsets) = (d.flags.all(), self.offsets.all());
        self.k.flag(&mut rec, n, threshold_px, range, flags);
        self.scan
            .record(&mut rec, &self.scratch, flags, offsets, Count::Host(n));
        let (idx, row_of, count) = (d.idx(), d.row_of(), d.count.elems::<u32>(0, 1));
        self.k
            .compact(&mut rec, n, flags, offsets, idx, row_of, count);
        rec.finish()?;
        let c = gpu.read::<u32>(count)?[0];
        model.dynamic.set_split(c);
        Ok(SplitStats {
            dynamic: c,
            n,
            motion_px: [q(0.5), q(0.9), q(0.99)],
            threshold_px,
        })
    }
}

/// A camera as the probe reads it: centre and the larger focal length (pixels).
pub fn camera_row(c: &Camera) -> [f32; 4] {
    let o = c.centre();
    [o[0] as f32, o[1] as f32, o[2] as f32, c.fx.max(c.fy)]
}
