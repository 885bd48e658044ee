//! The MLP's register path (`glsl/mlp/linear_rows.comp`, `transpose_w.comp`): Linears for
//! CPU-like devices, selected per device by [`MlpKernels`]. Same maths and row-major buffers
//! as the tiled GEMMs of [`super::mlp`], so the two paths are interchangeable per Linear.
//!
//! Why a second path: on lavapipe every storage-buffer or shared-memory load is a per-lane
//! loop, while a uniform-buffer load at a uniform index is one scalar load and a broadcast
//! (cheaper, but still about 20 cycles measured: the weight gradient reuses each for 4 FMAs).
//! The kernel keeps each row's input in a private array and reads weights from a uniform
//! buffer, so the matrix is bound in windows of whole rows of at most
//! `maxUniformBufferRange` bytes (one dispatch per window).

use bytemuck::{Pod, Zeroable};

pub use super::shape::{Access, DeviceShape};
use crate::error::Result;
use crate::shaders;
use crate::vk::{BufSlice, ComputePipeline, Gpu, Recorder};

/// Mirrors `MlpRowsParams` in glsl/include/params.glsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct MlpRowsParams {
    pub n: u32,
    pub fan_in: u32,
    pub ka: u32,
    pub a_stride: u32,
    pub b_stride: u32,
    pub out_stride: u32,
    pub out_col: u32,
    pub count: u32,
    pub m_res: u32,
    pub b_res: u32,
    pub has_bias: u32,
    pub relu: u32,
    pub mask_stride: u32,
    pub mask_col: u32,
    pub accumulate: u32,
    pub pad: u32,
}

/// Mirrors `MlpTransposeParams` in glsl/include/params.glsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct MlpTransposeParams {
    pub fan_in: u32,
    pub fan_out: u32,
    pub w_off: u32,
    pub pad: u32,
}

/// Mirrors `MlpRowsWeightParams` in glsl/include/params.glsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct MlpRowsWeightParams {
    pub r0: u32,
    pub rows: u32,
    pub fan_in: u32,
    pub fan_out: u32,
    pub ka: u32,
    pub a_stride: u32,
    pub b_stride: u32,
    pub dz_stride: u32,
    pub dz_res: u32,
    pub accumulate: u32,
    pub pad0: u32,
    pub pad1: u32,
}

/// Which kernels run the MLP's Linears.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, clap::ValueEnum)]
pub enum MlpKernels {
    /// 64×64 shared-memory tiles per workgroup (GPUs).
    Tiled,
    /// Rows per invocation, weights from uniform buffers (CPU devices such as lavapipe).
    Rows,
}

/// `DISPFLOW_MLP_KERNELS=tiled|rows` when set, else by device type: the register path on
/// CPU devices (measured 6–10× faster there, see `cargo bench --bench mlp`), tiles on GPUs.
impl DeviceShape for MlpKernels {
    const ENV: &'static str = "DISPFLOW_MLP_KERNELS";
    const ALL: &'static [Self] = &[MlpKernels::Tiled, MlpKernels::Rows];
    const CPU: Self = MlpKernels::Rows;
    const GPU: Self = MlpKernels::Tiled;

    fn name(self) -> &'static str {
        match self {
            MlpKernels::Tiled => "tiled",
            MlpKernels::Rows => "rows",
        }
    }
}

/// Rows per invocation × invocations per workgroup (mirrors R and local_size_x).
const ROWS_PER_GROUP: u32 = 8 * 32;
/// Largest fan-in the kernel's private array holds (mirrors KMAX); wider Linears use tiles.
pub const KMAX: usize = 512;
/// The uniform-buffer block's declared size (4096 vec4).
const UBO_BLOCK: u64 = 65536;

/// One Linear-shaped product on the register path.
pub struct Gemv<'a> {
    pub n: u32,
    /// Input: (A, columns from A, A's row stride), optional (B, B's row stride).
    pub a: (BufSlice<'a>, u32, u32),
    pub b: Option<(BufSlice<'a>, u32)>,
    pub fan_in: u32,
    /// The matrix: `count` rows of `fan_in` floats at float `m_off` of `mat`.
    pub mat: BufSlice<'a>,
    pub m_off: u64,
    pub count: u32,
    /// Bias floats at `b_off` of `mat`'s buffer (forward only).
    pub bias: Option<u64>,
    pub relu: bool,
    /// Output (slice, row stride, first column).
    pub out: (BufSlice<'a>, u32, u32),
    /// ReLU mask of the produced columns: (act, row stride).
    pub mask: Option<(BufSlice<'a>, u32)>,
    pub accumulate: bool,
}

/// Outputs per invocation of the weight-gradient kernel (mirrors OB).
const WEIGHT_OB: u32 = 32;
/// Input columns per invocation of the weight-gradient kernel (mirrors C).
const WEIGHT_C: u32 = 4;

pub struct RowsPath {
    rows: ComputePipeline,
    weight: ComputePipeline,
    transpose: ComputePipeline,
    range: u64,
    align: u64,
}

impl RowsPath {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        Self::with_access(gpu, Access::for_device(&gpu.info))
    }

    /// The rows kernels reaching their per-row arrays through `access`.
    pub fn with_access(gpu: &Gpu, access: Access) -> Result<Self> {
        use shaders::mlp as m;
        Ok(RowsPath {
            rows: gpu.pipeline(access.pick(&m::LINEAR_ROWS, &m::LINEAR_ROWS_TEXEL))?,
            weight: gpu.pipeline(
                access.pick(&m::LINEAR_BWD_WEIGHT_ROWS, &m::LINEAR_BWD_WEIGHT_ROWS_TEXEL),
            )?,
            transpose: gpu.pipeline(&shaders::mlp::TRANSPOSE_W)?,
            range: (gpu.info.max_uniform_buffer_range as u64).min(UBO_BLOCK),
            align: gpu.info.min_uniform_buffer_offset_alignment.max(4),
        })
    }

    /// Whether a product with this fan-in runs here (else the caller uses tiles).
    pub fn fits(fan_in: usize) -> bool {
        fan_in <= KMAX
    }

    /// `floats` floats from float `first` of `s` as an aligned uniform window: the slice and
    /// the floats between its start and `first`.
    fn window<'b>(&self, s: BufSlice<'b>, first: u64, floats: u64) -> (BufSlice<'b>, u32) {
        let start = s.offset + first * 4;
        let base = start / self.align * self.align;
        let size = (start - base + floats * 4).min(s.buf.size() - base);
        (s.buf.slice(base, size), ((start - base) / 4) as u32)
    }

    /// Records `g` as one dispatch per window of matrix rows.
    pub fn gemv(&self, rec: &mut Recorder<'_>, g: &Gemv<'_>) {
        assert!(
            Self::fits(g.fan_in as usize),
            "fan-in {} > {KMAX}",
            g.fan_in
        );
        // Rows per window, leaving room for the alignment residue.
        let per = ((self.range - self.align) / 4 / g.fan_in as u64).max(1) as u32;
        let groups = g.n.div_ceil(ROWS_PER_GROUP);
        let grid = if groups <= 65535 {
            [groups.max(1), 1, 1]
        } else {
            [65535, groups.div_ceil(65535), 1]
        };
        if g.n == 0 {
            return;
        }
        let mut j = 0;
        while j < g.count {
            let cnt = per.min(g.count - j);
            let (mw, m_res) = self.window(
                g.mat,
                g.m_off + j as u64 * g.fan_in as u64,
                cnt as u64 * g.fan_in as u64,
            );
            let (bw, b_res) = match g.bias {
                Some(b) => self.window(g.mat, b + j as u64, cnt as u64),
                None => (mw, 0),
            };
            let pc = MlpRowsParams {
                n: g.n,
                fan_in: g.fan_in,
                ka: g.a.1,
                a_stride: g.a.2,
                b_stride: g.b.map_or(0, |x| x.1),
                out_stride: g.out.1,
                out_col: g.out.2 + j,
                count: cnt,
                m_res,
                b_res,
                has_bias: g.bias.is_some() as u32,
                relu: g.relu as u32,
                mask_stride: g.mask.map_or(0, |m| m.1),
                mask_col: j,
                accumulate: g.accumulate as u32,
                pad: 0,
            };
            let binb = g.b.map_or(g.a.0, |x| x.0);
            let act = g.mask.map_or(g.a.0, |m| m.0);
            rec.dispatch(&self.rows, &pc, &[mw, bw, g.a.0, binb, act, g.out.0], grid);
            j += cnt;
        }
    }

    /// `partial[o][c] = Σ_r dz[r][o] · [a | bb | 1][r][c]` over `n` rows (`fan_out` ×
    /// (`fan_in` + 1) floats), one dispatch per uniform window of dz rows, in row order.
    #[allow(clippy::too_many_arguments)]
    pub fn weight_grad(
        &self,
        rec: &mut Recorder<'_>,
        n: u32,
        dz: (BufSlice<'_>, u32),
        a: (BufSlice<'_>, u32, u32),
        bb: Option<(BufSlice<'_>, u32)>,
        fan_in: u32,
        fan_out: u32,
        partial: BufSlice<'_>,
    ) {
        let per = ((self.range - self.align) / 4 / dz.1 as u64).max(1) as u32;
        let grid = [
            (fan_in + 1).div_ceil(64 * WEIGHT_C),
            fan_out.div_ceil(WEIGHT_OB),
            1,
        ];
        let binb = bb.map_or(a.0, |x| x.0);
        let mut r0 = 0;
        while r0 < n.max(1) {
            let rows = per.min(n - r0);
            // n = 0 still runs one (empty) window, which zeroes the partial.
            let floats = if rows == 0 {
                1
            } else {
                ((rows - 1) * dz.1 + fan_out) as u64
            };
            let (w, dz_res) = self.window(dz.0, r0 as u64 * dz.1 as u64, floats);
            let pc = MlpRowsWeightParams {
                r0,
                rows,
                fan_in,
                fan_out,
                ka: a.1,
                a_stride: a.2,
                b_stride: bb.map_or(0, |x| x.1),
                dz_stride: dz.1,
                dz_res,
                accumulate: (r0 > 0) as u32,
                pad0: 0,
                pad1: 0,
            };
            rec.dispatch(&self.weight, &pc, &[w, a.0, binb, partial], grid);
            r0 += rows.max(1);
        }
    }

    /// Wᵀ of the Linear at `w_off` (`fan_out` × `fan_in`) into the same offsets of `wt`.
    pub fn transpose(
        &self,
        rec: &mut Recorder<'_>,
        params: BufSlice<'_>,
        wt: BufSlice<'_>,
        fan_in: u32,
        fan_out: u32,
        w_off: u32,
    ) {
        let pc = MlpTransposeParams {
            fan_in,
            fan_out,
            w_off,
            pad: 0,
        };
        rec.dispatch_threads(
            &self.transpose,
            &pc,
            &[params, wt],
            [fan_in * fan_out, 1, 1],
        );
    }
}
