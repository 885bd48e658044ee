//! Motion metrics of the paper on the GPU (`glsl/metrics/*.comp`): per-frame average precision
//! of a motion score against a ground-truth motion mask (MMAP = its mean over frames) and
//! Deformation-Rendering Consistency (DRC). CPU twin: `reference::metrics`.
//!
//! **AP** (one frame): `AP = Σ_n (R_n − R_{n−1})·P_n` over one threshold per *distinct* score
//! (a run of equal scores is admitted at once, like sklearn's `average_precision_score`),
//! scores taken in descending order. Stages: `mmap_keys` (key = bit-inverted order-preserving
//! transform of the score, value = label) → stable radix sort (32 bits) → exclusive scan of the
//! sorted labels (true positives before each index) → `mmap_ap` (at the last index e of each
//! run: `(TP_e − TP_{start−1})·TP_e/(e + 1)`, the run start by binary search on the sorted keys;
//! per-workgroup partial sums, and P). The host sums the partials in f64 and divides by P; an
//! empty mask (P = 0) gives `None` ("undefined"), which [`mmap`] skips.
//!
//! **DRC** (one frame): `DRC = Σ_p F̂(p)·[ΔE(p) > 0] / (Σ_p F̂(p) + ε)`, ε = [`DRC_EPS`] = 1e-8
//! (the sums are of F̂ ∈ [0, 1]: ε only keeps an all-zero F̂ finite — DRC = 0 — and is far below
//! one pixel's weight at any score resolution that matters), `ΔE(p) = mean_c |I_frozen − I_gt| −
//! mean_c |I_full − I_gt|` over RGB. `drc` writes per-workgroup partial sums; the host finishes
//! in f64.
//!
//! Shapes: `score` [H·W] f32 (F̂, normally the min-max normalised displacement-flow magnitude
//! `MotionNorm`'s `m_hat()`; not NaN), `mask` [H·W] u32 (non-zero = moving), images [H·W] vec4
//! (alpha ignored). Results are read after the command buffer finished.

use bytemuck::{Pod, Zeroable};

use super::motion::grid;
use super::radix_sort::{KeyWidth, RadixSort, SortBuffers};
use super::scan::{Count, PrefixSum, ScanScratch};
use crate::error::{Error, Result};
use crate::shaders;
use crate::vk::{BufSlice, Buffer, ComputePipeline, Gpu, Recorder};

/// ε of the DRC denominator.
pub const DRC_EPS: f64 = 1e-8;

/// Mirrors `MetricsParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct MetricsParams {
    pub n: u32,
    pub groups_x: u32,
    pub groups: u32,
    pub pad: u32,
}

/// MMAP over frames: the mean of the per-frame APs that are defined (non-empty mask); `None`
/// when no frame has a moving pixel.
pub fn mmap<I: IntoIterator<Item = Option<f64>>>(aps: I) -> Option<f64> {
    let (mut sum, mut count) = (0.0f64, 0usize);
    for ap in aps.into_iter().flatten() {
        sum += ap;
        count += 1;
    }
    (count > 0).then(|| sum / count as f64)
}

pub struct MotionMetrics {
    keys: ComputePipeline,
    ap: ComputePipeline,
    drc: ComputePipeline,
    sort: RadixSort,
    scan: PrefixSum,
}

/// Scratch and results for one image size, allocated once; holds the last AP and DRC recorded.
pub struct MetricBuffers {
    pub width: u32,
    pub height: u32,
    groups_x: u32,
    groups: u32,
    sort: SortBuffers,
    scan: ScanScratch,
    tp: Buffer,
    ap_sums: Buffer,
    total: Buffer,
    drc_sums: Buffer,
}

impl MetricBuffers {
    pub fn pixels(&self) -> u32 {
        self.width * self.height
    }

    /// Every buffer it owns except the sort/scan internals (tests fill them with noise first).
    #[doc(hidden)]
    pub fn all_buffers(&self) -> Vec<&Buffer> {
        let mut v = vec![&self.tp, &self.ap_sums, &self.total, &self.drc_sums];
        v.extend(self.sort.keys.iter().chain(&self.sort.vals));
        v
    }

    fn params(&self) -> MetricsParams {
        MetricsParams {
            n: self.pixels(),
            groups_x: self.groups_x,
            groups: self.groups,
            pad: 0,
        }
    }

    fn grid(&self) -> [u32; 3] {
        [self.groups_x, self.groups / self.groups_x, 1]
    }

    /// The AP of the last `record_ap` (after its submit); `None` for an empty mask.
    pub fn ap(&self, gpu: &Gpu) -> Result<Option<f64>> {
        let p: Vec<u32> = gpu.read(self.total.slice(0, 4))?;
        if p[0] == 0 {
            return Ok(None);
        }
        let sums: Vec<f32> = gpu.read(self.ap_sums.elems::<f32>(0, self.groups as u64))?;
        let s: f64 = sums.iter().map(|&x| x as f64).sum();
        Ok(Some(s / p[0] as f64))
    }

    /// The DRC of the last `record_drc` (after its submit).
    pub fn drc(&self, gpu: &Gpu) -> Result<f64> {
        let sums: Vec<[f32; 2]> =
            gpu.read(self.drc_sums.elems::<[f32; 2]>(0, self.groups as u64))?;
        let (num, den) = sums.iter().fold((0.0f64, 0.0f64), |(a, b), s| {
            (a + s[0] as f64, b + s[1] as f64)
        });
        Ok(num / (den + DRC_EPS))
    }
}

impl MotionMetrics {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        use shaders::metrics as s;
        Ok(MotionMetrics {
            keys: gpu.pipeline(&s::MMAP_KEYS)?,
            ap: gpu.pipeline(&s::MMAP_AP)?,
            drc: gpu.pipeline(&s::DRC)?,
            sort: RadixSort::new(gpu)?,
            scan: PrefixSum::new(gpu)?,
        })
    }

    pub fn buffers(&self, gpu: &Gpu, width: u32, height: u32) -> Result<MetricBuffers> {
        let n = width as u64 * height as u64;
        if n == 0 || n > u32::MAX as u64 / 4 {
            return Err(Error::Invalid(format!(
                "motion metrics: image {width}×{height}, expected 1 to 2^30 pixels"
            )));
        }
        let n = n as u32;
        let (groups_x, groups) = grid(gpu, n);
        Ok(MetricBuffers {
            width,
            height,
            groups_x,
            groups,
            sort: self.sort.buffers(gpu, "mmap sort", n, KeyWidth::U32)?,
            scan: self.scan.scratch(gpu, n)?,
            tp: gpu.buffer("mmap true positives", n as u64 * 4)?,
            ap_sums: gpu.buffer("mmap partial sums", groups as u64 * 4)?,
            total: gpu.buffer("mmap positives", 16)?,
            drc_sums: gpu.buffer("drc partial sums", groups as u64 * 8)?,
        })
    }

    /// Records the AP of `score` ([H·W] f32) against `mask` ([H·W] u32, non-zero = moving).
    pub fn record_ap(
        &self,
        rec: &mut Recorder<'_>,
        b: &MetricBuffers,
        score: BufSlice<'_>,
        mask: BufSlice<'_>,
    ) {
        let n = b.pixels();
        assert!(
            score.size >= n as u64 * 4 && mask.size >= n as u64 * 4,
            "mmap: score {score:?} or mask {mask:?} smaller than {n} words"
        );
        let pc = b.params();
        let outer = rec.set_zone("mmap");
        rec.dispatch(
            &self.keys,
            &pc,
            &[score, mask, b.sort.keys[0].all(), b.sort.vals[0].all()],
            b.grid(),
        );
        let o = self.sort.record(rec, &b.sort, Count::Host(n), 32);
        self.scan.record(
            rec,
            &b.scan,
            b.sort.vals[o].elems::<u32>(0, n as u64),
            b.tp.all(),
            Count::Host(n),
        );
        rec.dispatch(
            &self.ap,
            &pc,
            &[
                b.sort.keys[o].all(),
                b.sort.vals[o].all(),
                b.tp.all(),
                b.ap_sums.all(),
                b.total.all(),
            ],
            b.grid(),
        );
        rec.set_zone(&outer);
    }

    /// Records the DRC partial sums of `score` ([H·W] f32, F̂ ∈ [0, 1]) with the renders
    /// `frozen` (deformation of t−1), `full` (of t) and the ground truth `gt` ([H·W] vec4).
    pub fn record_drc(
        &self,
        rec: &mut Recorder<'_>,
        b: &MetricBuffers,
        score: BufSlice<'_>,
        frozen: BufSlice<'_>,
        full: BufSlice<'_>,
        gt: BufSlice<'_>,
    ) {
        let n = b.pixels() as u64;
        assert!(
            score.size >= n * 4
                && frozen.size >= n * 16
                && full.size >= n * 16
                && gt.size >= n * 16,
            "drc: inputs smaller than {n} pixels"
        );
        let outer = rec.set_zone("drc");
        rec.dispatch(
            &self.drc,
            &b.params(),
            &[score, frozen, full, gt, b.drc_sums.all()],
            b.grid(),
        );
        rec.set_zone(&outer);
    }
}
