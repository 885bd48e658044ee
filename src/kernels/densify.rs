//! 3DGS adaptive density control on the GPU (`glsl/densify/*.comp`). CPU twin:
//! `reference::densify`.
//!
//! - `record_stats` after every backward pass: per visible Gaussian, ‖∂L/∂mean_ndc‖ (or, with
//!   `abs_grad`, the norm of Σ|∂L/∂mean_ndc| per component, the official Deformable-3DGS
//!   rasteriser's statistic) into `grad_accum`, +1 into `denom`, the largest screen radius into
//!   `max_radii`.
//! - `record_densify` (3DGS: every 100 iterations from 500 to 15000): `densify_grow` (demanded
//!   clone/split per original) → scan of growth (budget) → `densify_mark` (budget, prune bits,
//!   rows per original) → scan of rows (output offsets) → `densify_count` (new count, GPU u32)
//!   → `densify_write` once per parameter section, into the `dst` ("next") buffers: params and
//!   Adam m, v in the same [`GaussianLayout`]. The host reads the new count after the submit
//!   ([`DensifyBuffers::read_count`]) and swaps `src` and `dst`. Statistics are zeroed at the
//!   end of the step.
//! - `record_opacity_reset` (every 3000 iterations): opacity ← min(opacity, 0.01), opacity m, v ← 0.
//!
//! Output row order: originals in index order, each contributing its surviving rows
//! (keep: [original]; clone: [original, copy]; split: [child 0, child 1]).
//!
//! Screen-size prune: an original row is tested with its accumulated `max_radii`, new rows
//! (copies, children) with 0. (The official 3DGS code zeroes `max_radii2D` for every point in
//! `densification_postfix` before its prune, which makes that test a no-op there; here it acts
//! as the paper describes when `max_screen_size > 0`. The paper preset has 0: the official
//! behaviour, docs/parity.md.) The world-size prune has its own switch (`max_world_size`).
//!
//! Budget rule (exact, deterministic): originals are processed in index order with a running
//! row total starting at N; an original whose growth (+1 for clone or split) would push the
//! total past `capacity` is downgraded to keep (its prune test still applies). Pruning only
//! removes rows, so the new count never exceeds `capacity`.

use bytemuck::{Pod, Zeroable};

use super::raster::RasterBuffers;
use super::scan::{Count, PrefixSum, ScanScratch};
use crate::error::{Error, Result};
use crate::model::gaussians::{GaussianLayout, Section};
use crate::shaders;
use crate::vk::{BufSlice, Buffer, ComputePipeline, Gpu, Recorder};

/// Mirrors `DensifyStatsParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct DensifyStatsParams {
    pub num_gaussians: u32,
    pub width: u32,
    pub height: u32,
    pub skip_flags: u32,
    /// 1: the statistic reads `grad2d`'s slots 10-11 (Σ|∂L/∂mean2d|), else 0-1.
    pub abs_grad: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

/// Mirrors `DensifyParams` in glsl/include/params.glsl (checked by tests/layout.rs). Built by
/// [`DensifySettings::params`]; the twin decides with the same f32 values.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct DensifyParams {
    pub num_gaussians: u32,
    pub capacity: u32,
    pub row_len: u32,
    pub section: u32,
    pub seed: u32,
    pub iteration: u32,
    pub screen_prune: u32,
    pub pad0: u32,
    pub grad_threshold: f32,
    pub log_dense_scale: f32,
    pub min_opacity_logit: f32,
    pub max_screen_size: f32,
    pub log_max_world_size: f32,
    pub pad1: f32,
    pub pad2: f32,
    pub pad3: f32,
}

/// Mirrors `OpacityResetParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct OpacityResetParams {
    pub num_gaussians: u32,
    pub reset_logit: f32,
    pub pad0: u32,
    pub pad1: u32,
}

/// `section` codes of `densify_write` (mirrors `SECTION_*` in glsl/densify/densify.glsl).
const SECTION_COPY: u32 = 0;
const SECTION_MEANS: u32 = 1;
const SECTION_LOG_SCALES: u32 = 2;

/// Opacity the reset lowers every Gaussian to (at most), as 3DGS.
pub const OPACITY_RESET: f64 = 0.01;

/// ln(1.6) rounded to f32 (mirrors `LN_1_6`): a split child's log-scale is `log_scale − LN_1_6`.
pub const LN_1_6: f32 = 0.470_003_63;

/// One densify step's knobs (3DGS defaults from [`DensifySettings::new`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DensifySettings {
    /// Threshold on the average ‖∂L/∂mean_ndc‖ (3DGS: 0.0002).
    pub grad_threshold: f32,
    /// Clone if max scale <= percent_dense · extent, else split (3DGS: 0.01).
    pub percent_dense: f32,
    /// Camera extent (radius of the camera centres around their mean, × 1.1 in 3DGS).
    pub scene_extent: f32,
    /// Prune rows with sigmoid(opacity) below (3DGS: 0.005).
    pub min_opacity: f32,
    /// Prune rows whose largest screen radius (pixels) exceeds this; 0 disables it (3DGS asks
    /// for 20 once the first opacity reset has happened; the official code's test never fires).
    pub max_screen_size: f32,
    /// Prune rows whose largest scale exceeds this (world units); 0 disables it, independently
    /// of `max_screen_size` (3DGS: 0.1 · extent once the first opacity reset has happened).
    pub max_world_size: f32,
    /// Seed of the split sampler (with `iteration`: see `glsl/densify/densify.glsl`).
    pub seed: u32,
    pub iteration: u32,
    /// Row budget: the new count never exceeds it (<= the buffers' capacity).
    pub capacity: u32,
}

impl DensifySettings {
    /// 3DGS defaults for a scene of camera extent `scene_extent`, screen-size prune on.
    pub fn new(scene_extent: f32, capacity: u32) -> Self {
        DensifySettings {
            grad_threshold: 0.0002,
            percent_dense: 0.01,
            scene_extent,
            min_opacity: 0.005,
            max_screen_size: 20.0,
            max_world_size: 0.1 * scene_extent,
            seed: 0,
            iteration: 0,
            capacity,
        }
    }

    /// Checks the knobs (finite, in range; `n <= capacity`).
    pub fn validate(&self, n: u32) -> Result<()> {
        let bad = |what: &str, v: f32, want: &str| {
            Err(Error::Invalid(format!(
                "densify: {what} = {v}: expected {want}"
            )))
        };
        if !(self.grad_threshold.is_finite() && self.grad_threshold >= 0.0) {
            return bad("grad_threshold", self.grad_threshold, "a finite value >= 0");
        }
        if !(self.percent_dense.is_finite() && self.percent_dense > 0.0) {
            return bad("percent_dense", self.percent_dense, "a finite value > 0");
        }
        if !(self.scene_extent.is_finite() && self.scene_extent > 0.0) {
            return bad("scene_extent", self.scene_extent, "a finite value > 0");
        }
        if !(0.0..=1.0).contains(&self.min_opacity) {
            return bad("min_opacity", self.min_opacity, "a value in [0, 1]");
        }
        if !(self.max_screen_size.is_finite() && self.max_screen_size >= 0.0) {
            return bad(
                "max_screen_size",
                self.max_screen_size,
                "a finite value >= 0 (0 disables)",
            );
        }
        if self.max_world_size.is_nan() || self.max_world_size < 0.0 {
            return bad(
                "max_world_size",
                self.max_world_size,
                "a value >= 0 (0 disables)",
            );
        }
        if n > self.capacity {
            return Err(Error::Capacity {
                what: "densify budget (Gaussians before the step)",
                capacity: self.capacity as u64,
                asked: n as u64,
            });
        }
        Ok(())
    }

    /// The push constants for `n` originals: thresholds moved to log / logit space in f64 on
    /// the host and rounded to f32, so the kernels (and the twin) only compare f32 values —
    /// neither the GPU's inexact `exp` nor a division ever decides a Gaussian's fate.
    pub fn params(&self, n: u32) -> DensifyParams {
        let p = self.min_opacity as f64;
        DensifyParams {
            num_gaussians: n,
            capacity: self.capacity,
            seed: self.seed,
            iteration: self.iteration,
            screen_prune: (self.max_screen_size > 0.0) as u32
                | ((self.max_world_size > 0.0) as u32) << 1,
            grad_threshold: self.grad_threshold,
            log_dense_scale: (self.percent_dense as f64 * self.scene_extent as f64).ln() as f32,
            min_opacity_logit: (p / (1.0 - p)).ln() as f32,
            max_screen_size: self.max_screen_size,
            // ln(0) = −∞ is never compared (bit 1 off); +∞ never prunes.
            log_max_world_size: (self.max_world_size as f64).ln() as f32,
            ..Default::default()
        }
    }
}

/// logit(0.01) as f32: the opacity reset's ceiling.
pub fn reset_logit() -> f32 {
    (OPACITY_RESET / (1.0 - OPACITY_RESET)).ln() as f32
}

/// Parameters and Adam moments of the canonical Gaussians: three buffers laid out by `layout`.
#[derive(Clone, Copy)]
pub struct GaussianBuffers<'a> {
    pub layout: &'a GaussianLayout,
    pub params: &'a Buffer,
    pub m: &'a Buffer,
    pub v: &'a Buffer,
}

/// Statistics and scratch of the densify stages for `capacity` Gaussians, allocated once.
/// `grad_accum`, `denom`, `max_radii`: [capacity] f32 (zero after allocation and after every
/// densify step).
pub struct DensifyBuffers {
    capacity: u32,
    pub grad_accum: Buffer,
    pub denom: Buffer,
    pub max_radii: Buffer,
    action: Buffer,
    growth: Buffer,
    rows: Buffer,
    offsets: Buffer,
    count: Buffer,
    scan: ScanScratch,
    /// A cleared (flag, needed) pair: statistics without a guard.
    no_skip: Buffer,
}

impl DensifyBuffers {
    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// Gaussians after the last recorded densify step (read after its submit).
    pub fn read_count(&self, gpu: &Gpu) -> Result<u32> {
        Ok(gpu.read::<u32>(self.count.elems::<u32>(0, 1))?[0])
    }

    /// Output rows of the last densify step's originals `0..i` of its `n` (read after its
    /// submit): rows keep their originals' order, so this is where original `i`'s rows begin.
    pub fn read_rows_before(&self, gpu: &Gpu, i: u32, n: u32) -> Result<u32> {
        if i >= n {
            return self.read_count(gpu);
        }
        Ok(gpu.read::<u32>(self.offsets.elems::<u32>(i as u64, 1))?[0])
    }

    /// The internal scratch buffers (action, growth, rows, offsets, count), so tests can fill
    /// them with noise first.
    #[doc(hidden)]
    pub fn scratch_for_tests(&self) -> [&Buffer; 5] {
        [
            &self.action,
            &self.growth,
            &self.rows,
            &self.offsets,
            &self.count,
        ]
    }

    /// Per original of the last densify step (after its submit): `code | keep0 << 2 |
    /// keep1 << 3` with code 0 keep, 1 clone, 2 split (after the budget).
    pub fn read_actions(&self, gpu: &Gpu, n: u32) -> Result<Vec<u32>> {
        if n == 0 {
            return Ok(Vec::new());
        }
        gpu.read::<u32>(self.action.elems::<u32>(0, n as u64))
    }
}

/// The densify pipelines (stats, step, opacity reset).
pub struct Densifier {
    stats: ComputePipeline,
    grow: ComputePipeline,
    mark: ComputePipeline,
    count: ComputePipeline,
    write: ComputePipeline,
    reset: ComputePipeline,
    scan: PrefixSum,
}

impl Densifier {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        use shaders::densify as d;
        Ok(Densifier {
            stats: gpu.pipeline(&d::DENSIFY_STATS)?,
            grow: gpu.pipeline(&d::DENSIFY_GROW)?,
            mark: gpu.pipeline(&d::DENSIFY_MARK)?,
            count: gpu.pipeline(&d::DENSIFY_COUNT)?,
            write: gpu.pipeline(&d::DENSIFY_WRITE)?,
            reset: gpu.pipeline(&d::DENSIFY_RESET_OPACITY)?,
            scan: PrefixSum::new(gpu)?,
        })
    }

    /// Buffers for up to `capacity` Gaussians, statistics zeroed.
    pub fn buffers(&self, gpu: &Gpu, capacity: u32) -> Result<DensifyBuffers> {
        let c = capacity.max(1) as u64;
        let b = DensifyBuffers {
            capacity,
            grad_accum: gpu.buffer("densify grad accum", c * 4)?,
            denom: gpu.buffer("densify denom", c * 4)?,
            max_radii: gpu.buffer("densify max radii", c * 4)?,
            action: gpu.buffer("densify action", c * 4)?,
            growth: gpu.buffer("densify growth", c * 4)?,
            rows: gpu.buffer("densify rows", c * 4)?,
            offsets: gpu.buffer("densify offsets", c * 4)?,
            count: gpu.buffer("densify count", 256)?,
            scan: self.scan.scratch(gpu, capacity.max(1))?,
            no_skip: gpu.buffer_from("densify no-skip", &[0u32; 2])?,
        };
        let mut rec = Recorder::new(gpu)?;
        self.record_clear_stats(&mut rec, &b);
        rec.finish()?;
        Ok(b)
    }

    /// Zeroes the statistics (done at allocation and at the end of every densify step).
    pub fn record_clear_stats(&self, rec: &mut Recorder<'_>, b: &DensifyBuffers) {
        rec.fill(b.grad_accum.all(), 0);
        rec.fill(b.denom.all(), 0);
        rec.fill(b.max_radii.all(), 0);
    }

    /// Accumulates the statistics of the last rasteriser backward pass over `n` Gaussians
    /// (`raster.grad2d` [N, G2D_STRIDE], `raster.splats` [N,3] vec4, image size from `raster`). Adds
    /// nothing when a flag in `skip` ((flag, needed) u32 pairs, e.g. the step's render
    /// overflows) is set; `None`: always add.
    pub fn record_stats(
        &self,
        rec: &mut Recorder<'_>,
        b: &DensifyBuffers,
        raster: &RasterBuffers,
        n: u32,
        skip: Option<BufSlice<'_>>,
        abs_grad: bool,
    ) {
        let skip = skip.unwrap_or(b.no_skip.slice(0, 8));
        assert!(
            skip.size >= 8 && skip.size % 8 == 0,
            "densify stats skip {skip:?}: (flag, needed) pairs expected"
        );
        assert!(
            n <= b.capacity && n <= raster.max_gaussians,
            "densify stats: {n} Gaussians exceed the buffers ({} stats, {} raster)",
            b.capacity,
            raster.max_gaussians
        );
        let p = DensifyStatsParams {
            num_gaussians: n,
            width: raster.width,
            height: raster.height,
            skip_flags: (skip.size / 8) as u32,
            abs_grad: abs_grad as u32,
            ..Default::default()
        };
        rec.dispatch_rows(
            &self.stats,
            &p,
            &[
                raster.grad2d.all(),
                raster.splats.all(),
                b.grad_accum.all(),
                b.denom.all(),
                b.max_radii.all(),
                skip,
            ],
            n,
        );
    }

    /// Records one densify step over the `n` Gaussians of `src` into `dst` (distinct buffers
    /// of one layout), then zeroes the statistics. The new count is in
    /// [`DensifyBuffers::read_count`] after the submit; rows past it in `dst` are unspecified.
    pub fn record_densify(
        &self,
        rec: &mut Recorder<'_>,
        b: &DensifyBuffers,
        src: GaussianBuffers<'_>,
        dst: GaussianBuffers<'_>,
        n: u32,
        s: &DensifySettings,
    ) -> Result<()> {
        self.record_densify_pruning(rec, b, src, dst, n, s, None)
    }

    /// [`Self::record_densify`] with the opacity the prune compares given per Gaussian as a
    /// logit (`prune_logits` [N]; `None`: the parameters' own). Transients are pruned by their
    /// largest opacity over the sequence (`kernels::temporal`'s `peak`); only the decision
    /// changes, the rows written are the parameters as they are.
    #[allow(clippy::too_many_arguments)] // the densify step's own arguments plus the override
    pub fn record_densify_pruning(
        &self,
        rec: &mut Recorder<'_>,
        b: &DensifyBuffers,
        src: GaussianBuffers<'_>,
        dst: GaussianBuffers<'_>,
        n: u32,
        s: &DensifySettings,
        prune_logits: Option<BufSlice<'_>>,
    ) -> Result<()> {
        s.validate(n)?;
        assert_eq!(
            src.layout, dst.layout,
            "densify: src and dst must share one layout"
        );
        let layout = src.layout;
        if s.capacity > layout.capacity || s.capacity > b.capacity {
            return Err(Error::Capacity {
                what: "densify budget vs. buffer capacity (Gaussian layout, densify buffers)",
                capacity: layout.capacity.min(b.capacity) as u64,
                asked: s.capacity as u64,
            });
        }
        let bytes = layout.total_floats() * 4;
        for (what, buf) in [
            ("src params", src.params),
            ("src m", src.m),
            ("src v", src.v),
            ("dst params", dst.params),
            ("dst m", dst.m),
            ("dst v", dst.v),
        ] {
            assert!(
                buf.size() >= bytes,
                "densify: {what} {:?} holds {} bytes, the layout needs {bytes}",
                buf.name(),
                buf.size()
            );
        }
        for (a, z) in [(src.params, dst), (src.m, dst), (src.v, dst)] {
            assert!(
                !std::ptr::eq(a, z.params) && !std::ptr::eq(a, z.m) && !std::ptr::eq(a, z.v),
                "densify: src and dst must be distinct buffers (double buffering)"
            );
        }
        let p = s.params(n);
        fn first(buf: &Buffer, n: u32) -> BufSlice<'_> {
            buf.slice(0, n.max(1) as u64 * 4)
        }
        let u32s = |buf| first(buf, n);
        let f = |buf| layout.slice(buf, Section::LogScales, n);
        rec.dispatch_rows(
            &self.grow,
            &p,
            &[
                u32s(&b.grad_accum),
                u32s(&b.denom),
                f(src.params),
                u32s(&b.action),
                u32s(&b.growth),
            ],
            n,
        );
        self.scan
            .record(rec, &b.scan, b.growth.all(), b.growth.all(), Count::Host(n));
        rec.dispatch_rows(
            &self.mark,
            &p,
            &[
                u32s(&b.growth),
                u32s(&b.max_radii),
                f(src.params),
                prune_logits.unwrap_or(layout.slice(src.params, Section::Opacity, n)),
                u32s(&b.action),
                u32s(&b.rows),
            ],
            n,
        );
        self.scan
            .record(rec, &b.scan, b.rows.all(), b.offsets.all(), Count::Host(n));
        rec.dispatch(
            &self.count,
            &p,
            &[u32s(&b.offsets), u32s(&b.rows), b.count.slice(0, 4)],
            [1, 1, 1],
        );
        for sec in Section::ALL {
            let row_len = layout.row_len(sec);
            if row_len == 0 {
                continue;
            }
            let section = match sec {
                Section::Means => SECTION_MEANS,
                Section::LogScales => SECTION_LOG_SCALES,
                _ => SECTION_COPY,
            };
            let pw = DensifyParams {
                row_len,
                section,
                ..p
            };
            rec.dispatch_rows(
                &self.write,
                &pw,
                &[
                    u32s(&b.action),
                    u32s(&b.offsets),
                    layout.slice(src.params, sec, n),
                    layout.slice(src.m, sec, n),
                    layout.slice(src.v, sec, n),
                    layout.slice(src.params, Section::LogScales, n),
                    layout.slice(src.params, Section::Quats, n),
                    layout.slice(dst.params, sec, s.capacity),
                    layout.slice(dst.m, sec, s.capacity),
                    layout.slice(dst.v, sec, s.capacity),
                ],
                n,
            );
        }
        self.record_clear_stats(rec, b);
        Ok(())
    }

    /// Opacity reset over the `n` Gaussians of `g`: logit ← min(logit, logit(0.01)) (a NaN
    /// logit becomes logit(0.01)); the opacity section of Adam m, v ← 0.
    pub fn record_opacity_reset(&self, rec: &mut Recorder<'_>, g: GaussianBuffers<'_>, n: u32) {
        let layout = g.layout;
        assert!(
            n <= layout.capacity,
            "opacity reset: {n} Gaussians exceed the layout's capacity {}",
            layout.capacity
        );
        let p = OpacityResetParams {
            num_gaussians: n,
            reset_logit: reset_logit(),
            pad0: 0,
            pad1: 0,
        };
        rec.dispatch_rows(
            &self.reset,
            &p,
            &[
                layout.slice(g.params, Section::Opacity, n),
                layout.slice(g.m, Section::Opacity, n),
                layout.slice(g.v, Section::Opacity, n),
            ],
            n,
        );
    }
}
