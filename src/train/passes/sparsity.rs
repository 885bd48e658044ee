//! The motion probe: splits the model into dynamic and static Gaussians (DESIGN in
//! `model::dynamic`). Runs between steps, at the cadence the plan gives, never inside one.
//!
//! One classification: D at `times` (evenly over the training frames' time range) over every
//! Gaussian, each sample folded into a running maximum of the apparent motion in pixels of
//! the training view where it looks largest; flags = maximum > threshold; the flags' prefix
//! sum and the compaction give the dynamic indices on the GPU; the count is read after the
//! submit (the host sizes the next steps' MLP dispatches with it).

use super::deform::{DeformPass, Slot};
use crate::error::Result;
use crate::kernels::raster::Camera;
use crate::kernels::scan::{Count, PrefixSum, ScanScratch};
use crate::kernels::sparse::{ProbeInputs, ProbeSample, SparseKernels};
use crate::model::gaussians::Section;
use crate::model::state::Model;
use crate::vk::{Buffer, Gpu, Recorder};

/// What a classification measures against.
#[derive(Clone, Debug, PartialEq)]
pub struct ProbeConfig {
    /// A Gaussian is dynamic when D moves it by more than this many pixels.
    pub threshold_px: f32,
    /// Times D is sampled at.
    pub times: Vec<f32>,
}

impl ProbeConfig {
    /// `samples` times evenly over `[t_min, t_max]` (both ends included; one sample: the middle).
    pub fn even(threshold_px: f32, samples: u32, t_min: f32, t_max: f32) -> Self {
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
            times,
        }
    }
}

pub struct Classifier {
    k: SparseKernels,
    scan: PrefixSum,
    scratch: ScanScratch,
    offsets: Buffer,
    extent: Buffer,
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
            extent: rows("motion probe extent")?,
            cams: gpu.buffer_from("probe cameras", &cams)?,
            num_cams: cams.len() as u32,
            near: if near.is_finite() { near.max(1e-6) } else { 1e-6 },
            cfg,
        })
    }

    /// The per-Gaussian apparent motion (pixels) of the last classification, rows `0..n`.
    pub fn extent(&self) -> &Buffer {
        &self.extent
    }

    /// Probes D over every Gaussian and splits `model`; returns the dynamic count.
    pub fn classify(&self, gpu: &Gpu, model: &mut Model, deform: &DeformPass) -> Result<u32> {
        let n = model.gaussians.n;
        if n == 0 {
            model.dynamic.set_split(0);
            return Ok(0);
        }
        // The probe evaluates D over every Gaussian, static ones included: that is how a
        // static Gaussian whose neighbourhood started moving is found again.
        model.dynamic.set_dense();
        let (g, d) = (&model.gaussians, &model.dynamic);
        let mut rec = Recorder::new(gpu)?;
        let last = self.cfg.times.len().saturating_sub(1);
        let (extent, flags) = (self.extent.elems::<f32>(0, n as u64), d.flags.all());
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
                threshold_px: self.cfg.threshold_px,
                near: self.near,
            };
            self.k.probe(&mut rec, n, &x, &s, extent, flags);
        }
        let offsets = self.offsets.all();
        self.scan
            .record(&mut rec, &self.scratch, flags, offsets, Count::Host(n));
        let (idx, row_of, count) = (d.idx(), d.row_of(), d.count.elems::<u32>(0, 1));
        self.k
            .compact(&mut rec, n, flags, offsets, idx, row_of, count);
        rec.finish()?;
        let c = gpu.read::<u32>(count)?[0];
        model.dynamic.set_split(c);
        Ok(c)
    }
}

/// A camera as the probe reads it: centre and the larger focal length (pixels).
pub fn camera_row(c: &Camera) -> [f32; 4] {
    let o = c.centre();
    [o[0] as f32, o[1] as f32, o[2] as f32, c.fx.max(c.fy)]
}
