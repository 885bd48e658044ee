//! Magnitude of a per-pixel vector field and its normalisation over the image, forward and
//! backward (`glsl/motion/*.comp`): steps 6–7 of the DispFlow-GS step (`m̂_disp`, `m̂_scene`)
//! and the `F̂` the motion metrics score. CPU twin: `reference::motion`.
//!
//! Shapes: the field is interleaved `[H·W, C]` f32 with C = 2 (the flow estimator's `[H·W]`
//! vec2) or C = 3 (the rasteriser's displacement-flow feature output); `m`, `m̂` and `∂L/∂m̂`
//! are `[H·W]` f32; `∂L/∂v` has the field's shape.
//!
//! Modes (`m̂ = (m − offset) / denom`): min-max (default; `(m − min)/(max − min)`), max-abs
//! (`m / max`), z-score (`(m − mean)/std`, population std), IQR (`(m − median)/(q75 − q25)`,
//! quantiles by linear interpolation between order statistics at `q·(N − 1)`, as torch.quantile
//! and numpy by default).
//!
//! Everything stays on the GPU: `norm_mag` (magnitudes, per-workgroup min/max with the first
//! pixel among ties) → `norm_minmax` (one workgroup) → [z-score: `norm_moments`, exact
//! per-workgroup centred moments] → [IQR: radix sort of the float bits — magnitudes are ≥ 0,
//! so bits order like values — with the pixel as value] → `norm_finalize` (offset, denominator,
//! flag) → `norm_apply`. No float atomics: every sum has a fixed order, so results are
//! bit-reproducible on one device.
//!
//! The statistics are taken on `u = m·2^-e` (e: the binary exponent of the max): an exact
//! power-of-two rescaling into [0, 1), so sums of squares cannot overflow and no reciprocal is
//! denormal, for any finite map.
//!
//! **Degenerate maps**: the flag word (`NormBuffers::stats`, word [`stat::FLAG`]) is
//! [`NormFlag::Flat`] when the denominator is below `eps` (magnitude units) or below
//! [`REL_FLAT`]·2^e (IQR: `REL_FLAT·q75`; the f32 map cannot resolve the spread), [`NormFlag::NonFinite`] when a
//! magnitude is ∞/NaN (an input component is, or |v| overflows f32). Then `m̂ = 0` and the
//! gradient is 0: a later kernel reads the flag to skip the motion term for the step, on the
//! GPU, without a readback. Nothing is divided by ~0.
//!
//! **Backward** (autograd semantics, statistics included): with `G = Σ g`, `H = Σ g·m̂`
//! (`g = ∂L/∂m̂`): `∂L/∂offset = −G/d`, `∂L/∂denom = −H/d`; they reach the argmin/argmax pixel
//! (min-max, max-abs; first index among ties), every pixel (z-score: `∂mean/∂m = 1/N`,
//! `∂std/∂m_q = m̂_q/N`), or the two order-statistic pixels of each quantile with weights
//! `(1 − frac, frac)` (IQR; among equal magnitudes the stable sort's order, lower pixel first).
//! Then `∂L/∂v = ∂L/∂m · v/|v|`, 0 where `|v| = 0`.

use bytemuck::{Pod, Zeroable};

use super::radix_sort::{KeyWidth, RadixSort, SortBuffers};
use super::scan::Count;
use super::shape::DeviceShape;
use crate::error::{Error, Result};
use crate::shaders;
use crate::vk::{BufSlice, Buffer, ComputePipeline, Gpu, Recorder};

/// Workgroup size of the per-pixel passes (mirrors `MOTION_WG` in glsl/motion/motion.glsl).
pub const MOTION_WG: u32 = 256;

/// Relative flatness threshold (mirrors `REL_FLAT` in glsl/motion/motion.glsl): a denominator
/// below `REL_FLAT · 2^e`, `max = f·2^e` (IQR: below `REL_FLAT · q75`), counts as flat.
pub const REL_FLAT: f32 = 1.0 / 1_048_576.0;

/// Default absolute flatness threshold on the denominator, in magnitude units.
pub const DEFAULT_EPS: f32 = 1e-6;

/// Word indices of the statistics buffer (mirrors `NS_*` in glsl/motion/motion.glsl).
pub mod stat {
    pub const FLAG: usize = 0;
    pub const EXP: usize = 1;
    pub const OFFSET: usize = 2;
    pub const DENOM: usize = 3;
    pub const MIN: usize = 4;
    pub const MAX: usize = 5;
    pub const ARGMIN: usize = 6;
    pub const ARGMAX: usize = 7;
    pub const MEAN: usize = 8;
    pub const STD: usize = 9;
    pub const Q: usize = 10;
    pub const QPIX: usize = 13;
    pub const WORDS: usize = 19;
}

/// Words of the backward coefficient buffer (mirrors `NB_WORDS`).
const COEF_WORDS: u64 = 16;

/// Normalisation of the magnitude map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum NormMode {
    /// `(m − min)/(max − min)` (the paper's choice).
    #[default]
    MinMax,
    /// `m / max`.
    MaxAbs,
    /// `(m − mean)/std`, population std.
    ZScore,
    /// `(m − median)/(q75 − q25)`.
    Iqr,
}

impl NormMode {
    pub const ALL: [NormMode; 4] = [
        NormMode::MinMax,
        NormMode::MaxAbs,
        NormMode::ZScore,
        NormMode::Iqr,
    ];

    /// The `mode` push constant.
    pub fn code(self) -> u32 {
        self as u32
    }

    pub fn name(self) -> &'static str {
        match self {
            NormMode::MinMax => "min-max",
            NormMode::MaxAbs => "max-abs",
            NormMode::ZScore => "z-score",
            NormMode::Iqr => "iqr",
        }
    }
}

impl std::str::FromStr for NormMode {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        NormMode::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                Error::Invalid(format!(
                    "normalisation {s:?}: expected one of min-max, max-abs, z-score, iqr"
                ))
            })
    }
}

/// What the flag word of the statistics buffer says about the last forward pass.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum NormFlag {
    /// Normalised; the motion term may be used.
    #[default]
    Ok,
    /// Denominator below eps (or not resolvable in f32): `m̂ = 0`, gradient 0.
    Flat,
    /// A magnitude is ∞ or NaN: `m̂ = 0`, gradient 0.
    NonFinite,
}

impl NormFlag {
    /// Decodes the flag word (`FLAG_*` in glsl/motion/motion.glsl).
    pub fn from_word(w: u32) -> NormFlag {
        match w {
            0 => NormFlag::Ok,
            1 => NormFlag::Flat,
            _ => NormFlag::NonFinite,
        }
    }

    pub fn is_degenerate(self) -> bool {
        self != NormFlag::Ok
    }
}

/// Mode and absolute flatness threshold of one normalisation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NormConfig {
    pub mode: NormMode,
    pub eps: f32,
    /// Backward holds the statistics (min/max, mean/std, quantiles) constant: ∂m̂/∂m = 1/d
    /// per pixel. With them (autograd semantics) min-max puts the whole image's gradient sum
    /// on the argmax pixel, which a training loop can exploit by inflating one pixel.
    pub detach_stats: bool,
}

impl Default for NormConfig {
    fn default() -> Self {
        NormConfig {
            mode: NormMode::MinMax,
            eps: DEFAULT_EPS,
            detach_stats: false,
        }
    }
}

impl NormConfig {
    /// Checks `eps` (finite, ≥ 0).
    pub fn new(mode: NormMode, eps: f32) -> Result<Self> {
        if !(eps.is_finite() && eps >= 0.0) {
            return Err(Error::Invalid(format!(
                "normalisation eps {eps}: expected a finite number >= 0"
            )));
        }
        Ok(NormConfig {
            mode,
            eps,
            detach_stats: false,
        })
    }
}

/// Sorted position of quantile `q` among `n ≥ 1` values: `(floor(q·(n − 1)), frac)`. For
/// q ∈ {0.25, 0.5, 0.75} the fraction is a multiple of 1/4, exact in f32.
pub fn quantile_position(n: u32, q: f64) -> (u32, f32) {
    let pos = q * (n.max(1) - 1) as f64;
    let lo = pos.floor();
    (lo as u32, (pos - lo) as f32)
}

/// Mirrors `MotionNormParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct MotionNormParams {
    pub n: u32,
    pub channels: u32,
    pub mode: u32,
    pub groups: u32,
    pub groups_x: u32,
    pub eps: f32,
    pub q25_lo: u32,
    pub q50_lo: u32,
    pub q75_lo: u32,
    pub q25_frac: f32,
    pub q50_frac: f32,
    pub q75_frac: f32,
    pub detach: u32,
}

/// The statistics buffer decoded on the host (for tests, logs and reports), in magnitude units.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GpuNormStats {
    pub flag: NormFlag,
    /// `max = f·2^exponent`, f ∈ [0.5, 1).
    pub exponent: i32,
    pub offset: f64,
    pub denom: f64,
    pub min: f32,
    pub max: f32,
    pub argmin: u32,
    pub argmax: u32,
    /// z-score only.
    pub mean: f64,
    pub std: f64,
    /// IQR only: q25, q50, q75 and their (lo, hi) pixels.
    pub quantiles: [f64; 3],
    pub quantile_pixels: [[u32; 2]; 3],
}

/// Per-pixel grid: (workgroups along x, partial-result slots) for `n` pixels; 2D beyond the
/// device's x limit.
pub(crate) fn grid(gpu: &Gpu, n: u32) -> (u32, u32) {
    let groups = n.div_ceil(MOTION_WG).max(1);
    let gx = groups.min(gpu.info.max_workgroup_count[0]);
    (gx, gx * groups.div_ceil(gx))
}

/// The magnitude pass's shape (`norm_mag`); both write the same bits (min and max by
/// (value, pixel) do not depend on the fold order).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NormMagShape {
    /// 256 invocations per workgroup, one pixel each, a shared-memory tree (`norm_mag`).
    Tree,
    /// 8 invocations per workgroup, 32 pixels each folded in registers, one barrier
    /// (`norm_mag_runs`): lavapipe runs a 256-wide workgroup's barriers as 32 coroutine
    /// switches each.
    Runs,
}

/// Runs on CPU devices, the tree elsewhere (override: `DISPFLOW_MOTION_NORM=tree|runs`).
impl DeviceShape for NormMagShape {
    const ENV: &'static str = "DISPFLOW_MOTION_NORM";
    const ALL: &'static [Self] = &[NormMagShape::Tree, NormMagShape::Runs];
    const CPU: Self = NormMagShape::Runs;
    const GPU: Self = NormMagShape::Tree;

    fn name(self) -> &'static str {
        match self {
            NormMagShape::Tree => "tree",
            NormMagShape::Runs => "runs",
        }
    }
}

pub struct MotionNorm {
    mag: ComputePipeline,
    mag_shape: NormMagShape,
    minmax: ComputePipeline,
    moments: ComputePipeline,
    finalize: ComputePipeline,
    apply: ComputePipeline,
    bwd_sums: ComputePipeline,
    bwd_finalize: ComputePipeline,
    bwd: ComputePipeline,
    sort: RadixSort,
}

/// Scratch and outputs for one image size and channel count, allocated once.
pub struct NormBuffers {
    pub width: u32,
    pub height: u32,
    pub channels: u32,
    groups_x: u32,
    groups: u32,
    m: Buffer,
    m_hat: Buffer,
    parts: Buffer,
    moments: Buffer,
    stats: Buffer,
    bwd_sums: Buffer,
    coef: Buffer,
    sort: SortBuffers,
    /// Configuration of the last recorded forward pass (the backward pass reuses it).
    cfg: NormConfig,
    /// Which sort buffer pair holds the sorted magnitudes.
    sorted: usize,
}

impl NormBuffers {
    pub fn pixels(&self) -> u32 {
        self.width * self.height
    }

    /// `m = |v|`, [H·W] f32.
    pub fn m(&self) -> BufSlice<'_> {
        self.m.elems::<f32>(0, self.pixels() as u64)
    }

    /// `m̂`, [H·W] f32 (zeros when degenerate).
    pub fn m_hat(&self) -> BufSlice<'_> {
        self.m_hat.elems::<f32>(0, self.pixels() as u64)
    }

    /// The statistics words ([`stat`]); word 0 is the flag (0 = ok) for GPU consumers.
    pub fn stats(&self) -> BufSlice<'_> {
        self.stats.all()
    }

    /// Every buffer it owns (tests fill them with noise first).
    #[doc(hidden)]
    pub fn all_buffers(&self) -> Vec<&Buffer> {
        let mut v = vec![
            &self.m,
            &self.m_hat,
            &self.parts,
            &self.moments,
            &self.stats,
            &self.bwd_sums,
            &self.coef,
        ];
        v.extend(self.sort.keys.iter().chain(&self.sort.vals));
        v
    }

    /// The configuration of the last recorded forward pass.
    pub fn config(&self) -> NormConfig {
        self.cfg
    }

    /// Reads the flag of the last forward pass (after its submit).
    pub fn flag(&self, gpu: &Gpu) -> Result<NormFlag> {
        let w: Vec<u32> = gpu.read(self.stats.slice(0, 4))?;
        Ok(NormFlag::from_word(w[0]))
    }

    /// Reads and decodes the statistics of the last forward pass (after its submit).
    pub fn read_stats(&self, gpu: &Gpu) -> Result<GpuNormStats> {
        let w: Vec<u32> = gpu.read(self.stats.elems::<u32>(0, stat::WORDS as u64))?;
        let e = w[stat::EXP] as i32;
        let f = |i: usize| f32::from_bits(w[i]);
        let m_units = |i: usize| f(i) as f64 * 2f64.powi(e);
        Ok(GpuNormStats {
            flag: NormFlag::from_word(w[stat::FLAG]),
            exponent: e,
            offset: m_units(stat::OFFSET),
            denom: m_units(stat::DENOM),
            min: f(stat::MIN),
            max: f(stat::MAX),
            argmin: w[stat::ARGMIN],
            argmax: w[stat::ARGMAX],
            mean: m_units(stat::MEAN),
            std: m_units(stat::STD),
            quantiles: [0, 1, 2].map(|k| m_units(stat::Q + k)),
            quantile_pixels: [0, 1, 2].map(|k| [w[stat::QPIX + 2 * k], w[stat::QPIX + 2 * k + 1]]),
        })
    }
}

impl MotionNorm {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        Self::with_shape(gpu, NormMagShape::for_device(&gpu.info))
    }

    /// With the magnitude pass in `shape` whatever the device (tests, benches).
    pub fn with_shape(gpu: &Gpu, shape: NormMagShape) -> Result<Self> {
        use shaders::motion as s;
        Ok(MotionNorm {
            mag: gpu.pipeline(match shape {
                NormMagShape::Tree => &s::NORM_MAG,
                NormMagShape::Runs => &s::NORM_MAG_RUNS,
            })?,
            mag_shape: shape,
            minmax: gpu.pipeline(&s::NORM_MINMAX)?,
            moments: gpu.pipeline(&s::NORM_MOMENTS)?,
            finalize: gpu.pipeline(&s::NORM_FINALIZE)?,
            apply: gpu.pipeline(&s::NORM_APPLY)?,
            bwd_sums: gpu.pipeline(&s::NORM_BWD_SUMS)?,
            bwd_finalize: gpu.pipeline(&s::NORM_BWD_FINALIZE)?,
            bwd: gpu.pipeline(&s::NORM_BWD)?,
            sort: RadixSort::new(gpu)?,
        })
    }

    /// The magnitude pass's shape.
    pub fn mag_shape(&self) -> NormMagShape {
        self.mag_shape
    }

    /// Allocates the scratch for `width × height` maps of `channels` (2 or 3) floats per pixel.
    pub fn buffers(
        &self,
        gpu: &Gpu,
        width: u32,
        height: u32,
        channels: u32,
    ) -> Result<NormBuffers> {
        if !(channels == 2 || channels == 3) {
            return Err(Error::Invalid(format!(
                "motion normalisation: {channels} channels per pixel, expected 2 or 3"
            )));
        }
        let n = width as u64 * height as u64;
        if n == 0 || n > u32::MAX as u64 / 4 {
            return Err(Error::Invalid(format!(
                "motion normalisation: image {width}×{height}, expected 1 to 2^30 pixels"
            )));
        }
        let n = n as u32;
        let (groups_x, groups) = grid(gpu, n);
        let g = groups as u64;
        Ok(NormBuffers {
            width,
            height,
            channels,
            groups_x,
            groups,
            m: gpu.buffer("motion magnitude", n as u64 * 4)?,
            m_hat: gpu.buffer("motion normalised magnitude", n as u64 * 4)?,
            parts: gpu.buffer("motion min/max partials", g * 32)?,
            moments: gpu.buffer("motion moment partials", g * 16)?,
            stats: gpu.buffer("motion statistics", stat::WORDS as u64 * 4)?,
            bwd_sums: gpu.buffer("motion backward partials", g * 8)?,
            coef: gpu.buffer("motion backward coefficients", COEF_WORDS * 4)?,
            sort: self
                .sort
                .buffers(gpu, "motion quantile sort", n, KeyWidth::U32)?,
            cfg: NormConfig::default(),
            sorted: 0,
        })
    }

    fn params(b: &NormBuffers, cfg: NormConfig) -> MotionNormParams {
        let n = b.pixels();
        let (q25_lo, q25_frac) = quantile_position(n, 0.25);
        let (q50_lo, q50_frac) = quantile_position(n, 0.5);
        let (q75_lo, q75_frac) = quantile_position(n, 0.75);
        MotionNormParams {
            n,
            channels: b.channels,
            mode: cfg.mode.code(),
            groups: b.groups,
            groups_x: b.groups_x,
            eps: cfg.eps,
            q25_lo,
            q50_lo,
            q75_lo,
            q25_frac,
            q50_frac,
            q75_frac,
            detach: cfg.detach_stats as u32,
        }
    }

    fn grid_dims(b: &NormBuffers) -> [u32; 3] {
        [b.groups_x, b.groups / b.groups_x, 1]
    }

    /// Records `m = |field|`, the statistics, the flag and `m̂` (in `b.m_hat()`).
    /// `field`: [H·W, C] interleaved f32 (C = `b.channels`).
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        b: &mut NormBuffers,
        field: BufSlice<'_>,
        cfg: NormConfig,
    ) {
        let n = b.pixels();
        assert!(
            field.size >= n as u64 * b.channels as u64 * 4,
            "motion field {field:?} smaller than {n}×{} floats",
            b.channels
        );
        b.cfg = cfg;
        let pc = Self::params(b, cfg);
        let grid = Self::grid_dims(b);
        let outer = rec.set_zone("motion norm");
        rec.dispatch(
            &self.mag,
            &pc,
            &[
                field,
                b.m.all(),
                b.parts.all(),
                b.sort.keys[0].all(),
                b.sort.vals[0].all(),
            ],
            grid,
        );
        rec.dispatch(
            &self.minmax,
            &pc,
            &[b.parts.all(), b.stats.all()],
            [1, 1, 1],
        );
        if cfg.mode == NormMode::ZScore {
            rec.dispatch(
                &self.moments,
                &pc,
                &[b.m.all(), b.stats.all(), b.moments.all()],
                grid,
            );
        }
        b.sorted = 0;
        if cfg.mode == NormMode::Iqr {
            b.sorted = self.sort.record(rec, &b.sort, Count::Host(n), 32);
        }
        rec.dispatch(
            &self.finalize,
            &pc,
            &[
                b.moments.all(),
                b.sort.keys[b.sorted].all(),
                b.sort.vals[b.sorted].all(),
                b.stats.all(),
            ],
            [1, 1, 1],
        );
        rec.dispatch(
            &self.apply,
            &pc,
            &[b.m.all(), b.stats.all(), b.m_hat.all()],
            grid,
        );
        rec.set_zone(&outer);
    }

    /// Records `∂L/∂field` ([H·W, C], written whole) from `∂L/∂m̂` ([H·W]) for the forward pass
    /// last recorded on `b` with the same `field` (its outputs must still be in `b`).
    pub fn record_backward(
        &self,
        rec: &mut Recorder<'_>,
        b: &NormBuffers,
        field: BufSlice<'_>,
        d_m_hat: BufSlice<'_>,
        d_field: BufSlice<'_>,
    ) {
        let n = b.pixels() as u64;
        let c = b.channels as u64;
        assert!(
            field.size >= n * c * 4 && d_field.size >= n * c * 4 && d_m_hat.size >= n * 4,
            "motion backward: field {field:?}, d_field {d_field:?}, d_m_hat {d_m_hat:?} too small"
        );
        let pc = Self::params(b, b.cfg);
        let grid = Self::grid_dims(b);
        let outer = rec.set_zone("motion norm bwd");
        rec.dispatch(
            &self.bwd_sums,
            &pc,
            &[d_m_hat, b.m_hat.all(), b.bwd_sums.all()],
            grid,
        );
        rec.dispatch(
            &self.bwd_finalize,
            &pc,
            &[b.bwd_sums.all(), b.stats.all(), b.coef.all()],
            [1, 1, 1],
        );
        rec.dispatch(
            &self.bwd,
            &pc,
            &[
                field,
                b.m_hat.all(),
                d_m_hat,
                b.stats.all(),
                b.coef.all(),
                d_field,
            ],
            grid,
        );
        rec.set_zone(&outer);
    }
}
