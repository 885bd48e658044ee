//! The dynamic/static split (`glsl/sparse/*.comp`); CPU twin: `reference::sparse`.
//!
//! A Gaussian is *static* when its deformation varies by less than a threshold in pixels over
//! the probed times; a static Gaussian is drawn with its time-constant deformation (the
//! midrange of the probed D), so only the dynamic ones go through the MLP. `motion_probe`
//! folds D at one time into running per-component ranges (pixels and midrange on the last
//! sample), `dyn_flag` thresholds the pixels, the prefix sum of the flags and `dyn_compact`
//! list the dynamic indices,
//! `rows_gather` feeds the MLP their rows and `rows_expand` puts its output back in Gaussian
//! order, with the static Gaussians' constant rows in between.

use bytemuck::{Pod, Zeroable};

use crate::error::Result;
use crate::shaders;
use crate::vk::{BufSlice, ComputePipeline, Gpu, Recorder};

/// `row_of` of a static Gaussian (mirrors `NO_ROW` in glsl/sparse/*.comp).
pub const NO_ROW: u32 = u32::MAX;

/// Floats per Gaussian of the probe's range buffer: minimum (10), maximum (10), pixels (1).
pub const RANGE_ROW: usize = 21;

/// Mirrors `ProbeParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct ProbeParams {
    pub n: u32,
    pub num_cams: u32,
    pub first: u32,
    pub last: u32,
    pub near: f32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

/// Mirrors `FlagParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct FlagParams {
    pub n: u32,
    pub threshold_px: f32,
    pub pad0: u32,
    pub pad1: u32,
}

/// Mirrors `RowsParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct RowsParams {
    pub n: u32,
    pub width: u32,
    pub pad0: u32,
    pub pad1: u32,
}

/// One probe sample's inputs: `deform` [N,10] = D(x, t_k), `log_scales` and `means` [N,3]
/// (canonical), `cams` [C] vec4 (camera centre, focal length in pixels).
#[derive(Clone, Copy, Debug)]
pub struct ProbeInputs<'a> {
    pub deform: BufSlice<'a>,
    pub log_scales: BufSlice<'a>,
    pub means: BufSlice<'a>,
    pub cams: BufSlice<'a>,
    pub num_cams: u32,
}

/// Which sample of a probe this is.
#[derive(Clone, Copy, Debug)]
pub struct ProbeSample {
    pub first: bool,
    pub last: bool,
    /// Smallest camera distance used (scene units), so a Gaussian on a camera stays finite.
    pub near: f32,
}

pub struct SparseKernels {
    probe: ComputePipeline,
    flag: ComputePipeline,
    compact: ComputePipeline,
    gather: ComputePipeline,
    expand: ComputePipeline,
}

impl SparseKernels {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        use shaders::sparse as s;
        Ok(SparseKernels {
            probe: gpu.pipeline(&s::MOTION_PROBE)?,
            flag: gpu.pipeline(&s::DYN_FLAG)?,
            compact: gpu.pipeline(&s::DYN_COMPACT)?,
            gather: gpu.pipeline(&s::ROWS_GATHER)?,
            expand: gpu.pipeline(&s::ROWS_EXPAND)?,
        })
    }

    /// One probe sample over `n` Gaussians: `range` [N,21] holds the running per-component
    /// minimum (0..10) and maximum (10..20) of D (restarted on the first sample); on the last,
    /// column 20 = the apparent motion in pixels and `mid` [N,10] = the midrange of D.
    pub fn probe(
        &self,
        rec: &mut Recorder<'_>,
        n: u32,
        x: &ProbeInputs<'_>,
        s: &ProbeSample,
        range: BufSlice<'_>,
        mid: BufSlice<'_>,
    ) {
        assert!(x.num_cams >= 1, "the motion probe needs a training camera");
        let pc = ProbeParams {
            n,
            num_cams: x.num_cams,
            first: s.first as u32,
            last: s.last as u32,
            near: s.near,
            ..Default::default()
        };
        let binds = [x.deform, x.log_scales, x.means, x.cams, range, mid];
        rec.dispatch_rows(&self.probe, &pc, &binds, n);
    }

    /// `flags` [N] = pixels (column 20 of `range`) > `threshold_px`.
    pub fn flag(
        &self,
        rec: &mut Recorder<'_>,
        n: u32,
        threshold_px: f32,
        range: BufSlice<'_>,
        flags: BufSlice<'_>,
    ) {
        let pc = FlagParams {
            n,
            threshold_px,
            ..Default::default()
        };
        rec.dispatch_rows(&self.flag, &pc, &[range, flags], n);
    }

    /// From `flags` [N] and their exclusive prefix sum `offsets` [N]: the dynamic indices
    /// `idx` [count], `row_of` [N] (a row or [`NO_ROW`]) and `count` [1]. `n` >= 1.
    #[allow(clippy::too_many_arguments)] // the stage's bindings, each one named
    pub fn compact(
        &self,
        rec: &mut Recorder<'_>,
        n: u32,
        flags: BufSlice<'_>,
        offsets: BufSlice<'_>,
        idx: BufSlice<'_>,
        row_of: BufSlice<'_>,
        count: BufSlice<'_>,
    ) {
        assert!(n >= 1, "compaction of an empty set");
        let pc = RowsParams {
            n,
            ..Default::default()
        };
        let binds = [flags, offsets, idx, row_of, count];
        rec.dispatch_rows(&self.compact, &pc, &binds, n);
    }

    /// `dst[j] = src[idx[j]]` for `rows` rows of `width` floats (nothing for 0 rows).
    pub fn gather(
        &self,
        rec: &mut Recorder<'_>,
        rows: u32,
        width: u32,
        idx: BufSlice<'_>,
        src: BufSlice<'_>,
        dst: BufSlice<'_>,
    ) {
        if rows == 0 {
            return;
        }
        debug_assert!(dst.size >= rows as u64 * width as u64 * 4);
        let pc = RowsParams {
            n: rows,
            width,
            ..Default::default()
        };
        rec.dispatch_rows(&self.gather, &pc, &[idx, src, dst], rows);
    }

    /// `dst[i] = src[row_of[i]]`, or `fixed[i]` where `row_of[i]` = [`NO_ROW`], for `n`
    /// Gaussians.
    #[allow(clippy::too_many_arguments)] // the stage's bindings, each one named
    pub fn expand(
        &self,
        rec: &mut Recorder<'_>,
        n: u32,
        width: u32,
        row_of: BufSlice<'_>,
        src: BufSlice<'_>,
        fixed: BufSlice<'_>,
        dst: BufSlice<'_>,
    ) {
        debug_assert!(dst.size >= n as u64 * width as u64 * 4);
        let pc = RowsParams {
            n,
            width,
            ..Default::default()
        };
        rec.dispatch_rows(&self.expand, &pc, &[row_of, src, fixed, dst], n);
    }
}
