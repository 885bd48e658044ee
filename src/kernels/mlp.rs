//! The deformation MLP, layer-wise implementation (`glsl/mlp/{encode,linear_fwd,
//! linear_bwd_data,linear_bwd_weight,reduce_grad}.comp`). CPU twin: `reference::mlp`.
//! (Over 600 lines: the forward, both backward halves, the gradient reduction and the row
//! chunking share one scratch layout, its per-Linear offsets and which activation each backward
//! stage reads; split, each file would restate them.)
//!
//! One dispatch per Linear, dims and offsets in push constants, so depth, width, skip and the
//! time encoding are runtime configuration ([`MlpConfig`]). On GPUs every Linear is a 64×64-tiled
//! GEMM with a fused bias + ReLU epilogue; on CPU devices the register path
//! ([`super::mlp_rows`], same buffers and maths) runs them. The skip concatenation
//! `[γ(x), t_feat, h]` is read from two buffers without a copy. Batches whose rows exceed one
//! storage-buffer binding run in chunks of rows ([`MlpBuffers::chunk_rows`]).
//!
//! Backward stores activations (no recomputation): the forward keeps the encoded input, the
//! time-net hidden layer and every trunk layer's post-ReLU output, which also serve as the ReLU
//! masks. Weight gradients are reduced over Gaussians deterministically: per-chunk partial tiles
//! (at most [`MAX_CHUNKS`] chunks) then a fixed-order sum into the flat gradient buffer.
//! Memory per Gaussian: [`MlpBuffers::bytes_per_gaussian`] (8×256 synthetic: 11.8 KB).

use bytemuck::{Pod, Zeroable};

use super::mlp_rows::{Access, DeviceShape, Gemv, MlpKernels, RowsPath};
use crate::error::{Error, Result};
use crate::model::deform::{LinearSpec, MlpConfig, MlpLayout, OUT_DIMS};
use crate::shaders;
use crate::vk::{BufSlice, Buffer, ComputePipeline, Gpu, Recorder};

/// Mirrors `MlpEncodeParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct MlpEncodeParams {
    pub n: u32,
    pub x_freqs: u32,
    pub t_freqs: u32,
    pub x0_stride: u32,
    pub t_to_x0: u32,
    pub t_stride: u32,
    pub per_gaussian_time: u32,
    pub time: f32,
}

/// Mirrors `MlpLinearParams` in glsl/include/params.glsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct MlpLinearParams {
    pub n: u32,
    pub fan_in: u32,
    pub fan_out: u32,
    pub ka: u32,
    pub a_stride: u32,
    pub b_stride: u32,
    pub out_stride: u32,
    pub out_col: u32,
    pub w_off: u32,
    pub b_off: u32,
    pub relu: u32,
    pub pad: u32,
}

/// Mirrors `MlpBwdDataParams` in glsl/include/params.glsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct MlpBwdDataParams {
    pub n: u32,
    pub fan_in: u32,
    pub fan_out: u32,
    pub cols: u32,
    pub col0: u32,
    pub dz_stride: u32,
    pub out_stride: u32,
    pub out_col: u32,
    pub mask_stride: u32,
    pub mask_col: u32,
    pub w_off: u32,
    pub accumulate: u32,
}

/// Mirrors `MlpBwdWeightParams` in glsl/include/params.glsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct MlpBwdWeightParams {
    pub n: u32,
    pub fan_in: u32,
    pub fan_out: u32,
    pub ka: u32,
    pub a_stride: u32,
    pub b_stride: u32,
    pub dz_stride: u32,
    pub chunk_rows: u32,
}

/// Mirrors `MlpReduceParams` in glsl/include/params.glsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct MlpReduceParams {
    pub count: u32,
    pub chunks: u32,
    pub fan_in: u32,
    pub w_off: u32,
    pub b_off: u32,
    pub accumulate: u32,
    pub pad0: u32,
    pub pad1: u32,
}

/// Most partial-gradient chunks per Linear (bounds the partials buffer: 64 × 256 × 350 floats
/// = 23 MB at 8×256).
pub const MAX_CHUNKS: u32 = 64;
/// Fewest rows per chunk (below that a chunk's tile setup dominates).
const MIN_CHUNK_ROWS: u32 = 256;
/// Output tile of the GEMM kernels (mirrors GEMM_BM/GEMM_BN in glsl/mlp/gemm.glsl).
const TILE: u32 = 64;

/// The time input of a batch: one value, or one f32 per Gaussian (time noise).
#[derive(Clone, Copy, Debug)]
pub enum MlpTime<'a> {
    Batch(f32),
    PerGaussian(BufSlice<'a>),
}

/// Layer-wise deformation MLP: owns its pipelines and the parameter layout.
pub struct Mlp {
    pub layout: MlpLayout,
    encode: ComputePipeline,
    fwd: ComputePipeline,
    bwd_data: ComputePipeline,
    bwd_weight: ComputePipeline,
    reduce: ComputePipeline,
    /// The register path, when [`MlpKernels::Rows`] runs the forward and input gradients.
    rows: Option<RowsPath>,
}

/// Activations and scratch for up to `capacity` Gaussians, allocated once. Shapes (row-major,
/// f32): `x0` [N][in_dims], `enc_t` [N][t_enc_dims] (time net), `ht` [N][hidden] (time net),
/// `h[i]` [N][width], `dz` 2 × [N][max(width, hidden)], `dtf` [N][t_feat] (time net),
/// `partials` [MAX_CHUNKS][max fan_out·(fan_in + 1)].
pub struct MlpBuffers {
    pub capacity: u32,
    /// Most rows one dispatch binds (the storage-buffer range over the widest row).
    pub chunk_rows: u32,
    /// Floats per row of x0, enc_t, ht, h[i], dz, dtf (0: unused placeholder).
    row_floats: [u32; 6],
    pub x0: Buffer,
    pub enc_t: Buffer,
    pub ht: Buffer,
    pub h: Vec<Buffer>,
    dz: [Buffer; 2],
    dtf: Buffer,
    partials: Buffer,
    /// Wᵀ per Linear at the layout's offsets (register path's input gradients).
    wt: Buffer,
    dummy: Buffer,
}

impl MlpBuffers {
    /// Bytes of activations and backward scratch per Gaussian (the partials are per network,
    /// not per Gaussian, and excluded).
    pub fn bytes_per_gaussian(cfg: &MlpConfig) -> u64 {
        let (w, tn) = (cfg.width as u64, cfg.time_net());
        let hid = match cfg.time {
            crate::model::deform::TimeEncoding::TimeNet { hidden, .. } => hidden as u64,
            _ => 0,
        };
        let floats = cfg.in_dims() as u64
            + if tn {
                cfg.t_enc_dims() as u64 + hid + cfg.t_feat_dims() as u64
            } else {
                0
            }
            + cfg.depth as u64 * w
            + 2 * w.max(hid);
        floats * 4
    }

    pub fn total_bytes(&self) -> u64 {
        let mut b = self.x0.size() + self.enc_t.size() + self.ht.size() + self.dtf.size();
        b += self.h.iter().map(|x| x.size()).sum::<u64>();
        b + self.dz[0].size() + self.dz[1].size() + self.partials.size()
    }
}

/// The rows `[r0, r0 + rows)` of every per-Gaussian tensor of [`MlpBuffers`], as bound by one
/// chunk's dispatches.
struct Acts<'a> {
    x0: BufSlice<'a>,
    enc_t: BufSlice<'a>,
    ht: BufSlice<'a>,
    h: Vec<BufSlice<'a>>,
    dz: [BufSlice<'a>; 2],
    dtf: BufSlice<'a>,
}

impl MlpBuffers {
    fn rows(&self, r0: u32, rows: u32) -> Acts<'_> {
        let [x0, enc_t, ht, h, dz, dtf] = self.row_floats;
        fn view(b: &Buffer, floats: u32, r0: u32, rows: u32) -> BufSlice<'_> {
            if floats == 0 {
                return b.all(); // an unused placeholder
            }
            let f = floats as u64 * 4;
            b.slice(r0 as u64 * f, rows.max(1) as u64 * f)
        }
        let v = |b, floats| view(b, floats, r0, rows);
        Acts {
            x0: v(&self.x0, x0),
            enc_t: v(&self.enc_t, enc_t),
            ht: v(&self.ht, ht),
            h: self.h.iter().map(|b| v(b, h)).collect(),
            dz: [v(&self.dz[0], dz), v(&self.dz[1], dz)],
            dtf: v(&self.dtf, dtf),
        }
    }

    /// `(first row, rows)` of each chunk of an `n`-row batch; one empty chunk when `n` = 0.
    fn chunks(&self, n: u32) -> Vec<(u32, u32)> {
        if n == 0 {
            return vec![(0, 0)];
        }
        (0..n)
            .step_by(self.chunk_rows as usize)
            .map(|r0| (r0, self.chunk_rows.min(n - r0)))
            .collect()
    }
}

/// `rows` rows of `floats` floats from row `r0` of `s`.
fn sub(s: BufSlice<'_>, r0: u32, rows: u32, floats: u64) -> BufSlice<'_> {
    s.buf.slice(
        s.offset + r0 as u64 * floats * 4,
        rows.max(1) as u64 * floats * 4,
    )
}

/// Row-tile grid: y up to 65535, the rest in z.
fn row_grid(rows: u32, x: u32) -> [u32; 3] {
    let tiles = rows.div_ceil(TILE);
    if tiles == 0 {
        return [x, 0, 1];
    }
    let y = tiles.min(65535);
    [x, y, tiles.div_ceil(y)]
}

/// Chunks and rows per chunk of the weight-gradient reduction for `n` rows.
fn chunking(n: u32) -> (u32, u32) {
    if n == 0 {
        return (0, 16);
    }
    let chunks = n.div_ceil(MIN_CHUNK_ROWS).min(MAX_CHUNKS);
    let rows = n.div_ceil(chunks).next_multiple_of(16);
    (n.div_ceil(rows), rows)
}

impl Mlp {
    /// The kernels [`MlpKernels::for_device`] picks.
    pub fn new(gpu: &Gpu, cfg: &MlpConfig) -> Result<Self> {
        Self::with_kernels(gpu, cfg, MlpKernels::for_device(&gpu.info))
    }

    pub fn with_kernels(gpu: &Gpu, cfg: &MlpConfig, kernels: MlpKernels) -> Result<Self> {
        Self::with_shapes(gpu, cfg, kernels, Access::for_device(&gpu.info))
    }

    /// [`Mlp::with_kernels`] with the register path reaching its rows through `access`.
    pub fn with_shapes(
        gpu: &Gpu,
        cfg: &MlpConfig,
        kernels: MlpKernels,
        access: Access,
    ) -> Result<Self> {
        Ok(Mlp {
            rows: match kernels {
                MlpKernels::Rows => Some(RowsPath::with_access(gpu, access)?),
                MlpKernels::Tiled => None,
            },
            layout: MlpLayout::new(cfg)?,
            encode: gpu.pipeline(&shaders::mlp::ENCODE)?,
            fwd: gpu.pipeline(&shaders::mlp::LINEAR_FWD)?,
            bwd_data: gpu.pipeline(&shaders::mlp::LINEAR_BWD_DATA)?,
            bwd_weight: gpu.pipeline(&shaders::mlp::LINEAR_BWD_WEIGHT)?,
            reduce: gpu.pipeline(&shaders::mlp::REDUCE_GRAD)?,
        })
    }

    pub fn kernels(&self) -> MlpKernels {
        if self.rows.is_some() {
            MlpKernels::Rows
        } else {
            MlpKernels::Tiled
        }
    }

    fn cfg(&self) -> &MlpConfig {
        &self.layout.cfg
    }

    fn hidden(&self) -> usize {
        self.layout.time_net().first().map_or(0, |l| l.fan_out)
    }

    /// Allocates activations and scratch for up to `capacity` Gaussians. Each activation
    /// tensor is one buffer; batches whose rows exceed the device's storage-buffer range
    /// (lavapipe 128 MiB: 131 072 Gaussians at width 256) run in chunks of rows.
    pub fn buffers(&self, gpu: &Gpu, capacity: u32) -> Result<MlpBuffers> {
        self.buffers_with_binding_limit(gpu, capacity, gpu.info.max_storage_buffer_range as u64)
    }

    /// [`Mlp::buffers`] with chunks sized for at most `binding` bytes per bound tensor (tests
    /// force many chunks on small batches).
    pub fn buffers_with_binding_limit(
        &self,
        gpu: &Gpu,
        capacity: u32,
        binding: u64,
    ) -> Result<MlpBuffers> {
        let cfg = self.cfg();
        let (w, ind, hid) = (cfg.width as u64, cfg.in_dims() as u64, self.hidden() as u64);
        // The widest per-Gaussian row bound as one storage buffer; chunks start at multiples of
        // 64 rows so every offset is 256-byte aligned.
        let widest = w.max(ind).max(hid).max(OUT_DIMS as u64);
        let chunk_rows = (binding / (widest * 4)) / 64 * 64;
        if chunk_rows == 0 {
            return Err(Error::Capacity {
                what: "MLP activations (64 rows must fit maxStorageBufferRange)",
                capacity: 0,
                asked: capacity as u64,
            });
        }
        let cap = capacity.max(1) as u64;
        let tn = cfg.time_net();
        let f = |name: &str, floats: u64| gpu.buffer(name, floats.max(1) * 4);
        let max_linear = self
            .layout
            .linears
            .iter()
            .map(|l| (l.fan_out * (l.fan_in + 1)) as u64)
            .max()
            .unwrap();
        Ok(MlpBuffers {
            capacity,
            chunk_rows: chunk_rows.min(u32::MAX as u64) as u32,
            row_floats: [
                ind as u32,
                if tn { cfg.t_enc_dims() as u32 } else { 0 },
                if tn { hid as u32 } else { 0 },
                w as u32,
                w.max(hid) as u32,
                if tn { cfg.t_feat_dims() as u32 } else { 0 },
            ],
            x0: f("mlp x0", cap * ind)?,
            enc_t: f(
                "mlp enc_t",
                if tn { cap * cfg.t_enc_dims() as u64 } else { 1 },
            )?,
            ht: f("mlp time hidden", if tn { cap * hid } else { 1 })?,
            h: (0..cfg.depth)
                .map(|i| f(&format!("mlp h{i}"), cap * w))
                .collect::<Result<_>>()?,
            dz: [
                f("mlp dz0", cap * w.max(hid))?,
                f("mlp dz1", cap * w.max(hid))?,
            ],
            dtf: f(
                "mlp d t_feat",
                if tn {
                    cap * cfg.t_feat_dims() as u64
                } else {
                    1
                },
            )?,
            partials: f("mlp grad partials", MAX_CHUNKS as u64 * max_linear)?,
            wt: f(
                "mlp transposed weights",
                if self.rows.is_some() {
                    self.layout.total as u64
                } else {
                    1
                },
            )?,
            dummy: f("mlp no times", 4)?,
        })
    }

    /// Encodes `xyz` [N][3] and time, runs every layer, writes `out` [N][10] (dx, dr, ds) and
    /// keeps the activations in `b` for [`Mlp::backward`]. `params` holds `layout.total` floats.
    #[allow(clippy::too_many_arguments)]
    pub fn forward(
        &self,
        rec: &mut Recorder<'_>,
        b: &MlpBuffers,
        n: u32,
        xyz: BufSlice<'_>,
        time: MlpTime<'_>,
        params: BufSlice<'_>,
        out: BufSlice<'_>,
    ) {
        assert!(
            n <= b.capacity,
            "MLP forward of {n} rows, capacity {}",
            b.capacity
        );
        assert!(xyz.size >= n as u64 * 12 && out.size >= n as u64 * 40);
        assert!(
            params.size >= self.layout.total as u64 * 4,
            "params {params:?} too small"
        );
        let (per_g, t, times) = match time {
            MlpTime::Batch(t) => (0, t, b.dummy.all()),
            MlpTime::PerGaussian(s) => {
                assert!(s.size >= n as u64 * 4, "times {s:?} shorter than {n}");
                (1, 0.0, s)
            }
        };
        for (r0, rows) in b.chunks(n) {
            let v = b.rows(r0, rows);
            let times = if per_g == 1 {
                sub(times, r0, rows, 1)
            } else {
                times
            };
            let io = (sub(xyz, r0, rows, 3), sub(out, r0, rows, OUT_DIMS as u64));
            self.forward_chunk(rec, &v, rows, io.0, (per_g, t, times), params, io.1);
        }
    }

    /// [`Mlp::forward`] of one chunk of rows.
    #[allow(clippy::too_many_arguments)]
    fn forward_chunk(
        &self,
        rec: &mut Recorder<'_>,
        b: &Acts<'_>,
        n: u32,
        xyz: BufSlice<'_>,
        (per_g, t, times): (u32, f32, BufSlice<'_>),
        params: BufSlice<'_>,
        out: BufSlice<'_>,
    ) {
        let cfg = *self.cfg();
        let ind = cfg.in_dims() as u32;
        let pc = MlpEncodeParams {
            n,
            x_freqs: cfg.x_freqs,
            t_freqs: cfg.t_freqs(),
            x0_stride: ind,
            t_to_x0: !cfg.time_net() as u32,
            t_stride: cfg.t_enc_dims() as u32,
            per_gaussian_time: per_g,
            time: t,
        };
        let outer = rec.set_zone("mlp fwd");
        rec.dispatch_rows(&self.encode, &pc, &[xyz, times, b.x0, b.enc_t], n);
        let lin = |rec: &mut Recorder<'_>,
                   l: &LinearSpec,
                   a: (BufSlice<'_>, u32, u32),
                   bb: Option<(BufSlice<'_>, u32)>,
                   o: (BufSlice<'_>, u32, u32),
                   relu: bool| {
            self.linear(rec, n, l, params, a, bb, o, relu);
        };
        if cfg.time_net() {
            let tn = self.layout.time_net();
            let (ted, hid) = (cfg.t_enc_dims() as u32, self.hidden() as u32);
            lin(rec, &tn[0], (b.enc_t, ted, ted), None, (b.ht, hid, 0), true);
            let xd = cfg.x_dims() as u32;
            lin(rec, &tn[1], (b.ht, hid, hid), None, (b.x0, ind, xd), false);
        }
        let w = cfg.width;
        let skip_layer = cfg.skip.map(|s| s + 1);
        for (i, l) in self.layout.trunk().iter().enumerate() {
            let i = i as u32;
            let dst = (b.h[i as usize], w, 0);
            if i == 0 {
                lin(rec, l, (b.x0, ind, ind), None, dst, true);
            } else if skip_layer == Some(i) {
                let prev = Some((b.h[i as usize - 1], w));
                lin(rec, l, (b.x0, ind, ind), prev, dst, true);
            } else {
                lin(rec, l, (b.h[i as usize - 1], w, w), None, dst, true);
            }
        }
        let last = *b.h.last().unwrap();
        lin(
            rec,
            self.layout.head(),
            (last, w, w),
            None,
            (out, OUT_DIMS as u32, 0),
            false,
        );
        rec.set_zone(&outer);
    }

    /// One Linear over `n` rows: `out[r][out_col + o] = act(b[o] + Σ_k W[o][k] · in[r][k])`
    /// with `in = [a[r][0..ka] | bb[r][..]]`; `a` = (slice, ka, row stride), `bb` = (slice, row
    /// stride), `out` = (slice, row stride, first column). Weights and bias at `l`'s offsets in
    /// `params`. The building block of [`Mlp::forward`], public for the GEMM microbenchmark.
    #[allow(clippy::too_many_arguments)]
    pub fn linear(
        &self,
        rec: &mut Recorder<'_>,
        n: u32,
        l: &LinearSpec,
        params: BufSlice<'_>,
        a: (BufSlice<'_>, u32, u32),
        bb: Option<(BufSlice<'_>, u32)>,
        out: (BufSlice<'_>, u32, u32),
        relu: bool,
    ) {
        assert!(
            a.1 as usize == l.fan_in || bb.is_some(),
            "linear: input narrower than fan_in"
        );
        let pc = MlpLinearParams {
            n,
            fan_in: l.fan_in as u32,
            fan_out: l.fan_out as u32,
            ka: a.1,
            a_stride: a.2,
            b_stride: bb.map_or(0, |x| x.1),
            out_stride: out.1,
            out_col: out.2,
            w_off: l.w_off as u32,
            b_off: l.b_off as u32,
            relu: relu as u32,
            pad: 0,
        };
        if let Some(rp) = self.rows.as_ref().filter(|_| RowsPath::fits(l.fan_in)) {
            rp.gemv(
                rec,
                &Gemv {
                    n,
                    a,
                    b: bb,
                    fan_in: l.fan_in as u32,
                    mat: params,
                    m_off: l.w_off as u64,
                    count: l.fan_out as u32,
                    bias: Some(l.b_off as u64),
                    relu,
                    out,
                    mask: None,
                    accumulate: false,
                },
            );
            return;
        }
        let binb = bb.map_or(a.0, |x| x.0);
        let grid = row_grid(n, (l.fan_out as u32).div_ceil(TILE));
        rec.dispatch(&self.fwd, &pc, &[params, a.0, binb, out.0], grid);
    }

    /// Gradients of every weight and bias for `d_out` [N][10] (gradients of dx, dr, ds), from
    /// the activations the last [`Mlp::forward`] on `b` stored (same `n`, same `params`).
    /// Written into `grads` (`layout.total` floats, padding untouched), or added to it when
    /// `accumulate` (e.g. two time instants in one step). x and t get no gradient.
    #[allow(clippy::too_many_arguments)]
    pub fn backward(
        &self,
        rec: &mut Recorder<'_>,
        b: &MlpBuffers,
        n: u32,
        params: BufSlice<'_>,
        d_out: BufSlice<'_>,
        grads: BufSlice<'_>,
        accumulate: bool,
    ) {
        assert!(
            n <= b.capacity,
            "MLP backward of {n} rows, capacity {}",
            b.capacity
        );
        assert!(d_out.size >= n as u64 * 40);
        let total = self.layout.total as u64 * 4;
        assert!(
            grads.size >= total && params.size >= total,
            "grads {grads:?} or params {params:?} smaller than the layout"
        );
        let outer = rec.set_zone("mlp bwd");
        if let Some(rp) = &self.rows {
            for l in &self.layout.linears {
                let (fi, fo) = (l.fan_in as u32, l.fan_out as u32);
                rp.transpose(rec, params, b.wt.all(), fi, fo, l.w_off as u32);
            }
        }
        for (k, (r0, rows)) in b.chunks(n).into_iter().enumerate() {
            let v = b.rows(r0, rows);
            let d = sub(d_out, r0, rows, OUT_DIMS as u64);
            self.backward_chunk(rec, b, &v, rows, params, d, grads, accumulate || k > 0);
        }
        rec.set_zone(&outer);
    }

    /// [`Mlp::backward`] of one chunk of rows (`bufs` for the per-network scratch).
    #[allow(clippy::too_many_arguments)]
    fn backward_chunk(
        &self,
        rec: &mut Recorder<'_>,
        bufs: &MlpBuffers,
        b: &Acts<'_>,
        n: u32,
        params: BufSlice<'_>,
        d_out: BufSlice<'_>,
        grads: BufSlice<'_>,
        accumulate: bool,
    ) {
        let cfg = *self.cfg();
        let (chunks, chunk_rows) = chunking(n);
        // dW, db of one Linear whose input is [a | bb] and output gradient dz.
        let weights = |rec: &mut Recorder<'_>,
                       l: &LinearSpec,
                       dz: (BufSlice<'_>, u32),
                       a: (BufSlice<'_>, u32, u32),
                       bb: Option<(BufSlice<'_>, u32)>| {
            let pc = MlpBwdWeightParams {
                n,
                fan_in: l.fan_in as u32,
                fan_out: l.fan_out as u32,
                ka: a.1,
                a_stride: a.2,
                b_stride: bb.map_or(0, |x| x.1),
                dz_stride: dz.1,
                chunk_rows,
            };
            let binb = bb.map_or(a.0, |x| x.0);
            let (fi, fo) = (l.fan_in as u32, l.fan_out as u32);
            let chunks = if let Some(rp) = &self.rows {
                rp.weight_grad(rec, n, dz, a, bb, fi, fo, bufs.partials.all());
                1
            } else {
                let grid = [(fi + 1).div_ceil(TILE), fo.div_ceil(TILE), chunks];
                rec.dispatch(
                    &self.bwd_weight,
                    &pc,
                    &[dz.0, a.0, binb, bufs.partials.all()],
                    grid,
                );
                chunks
            };
            let count = (l.fan_out * (l.fan_in + 1)) as u32;
            let rp = MlpReduceParams {
                count,
                chunks,
                fan_in: l.fan_in as u32,
                w_off: l.w_off as u32,
                b_off: l.b_off as u32,
                accumulate: accumulate as u32,
                ..Default::default()
            };
            rec.dispatch_threads(
                &self.reduce,
                &rp,
                &[bufs.partials.all(), grads],
                [count, 1, 1],
            );
        };
        // d_in[:, out_col..] (+)= mask ⊙ (dz · W[:, col0..col0+cols]).
        #[allow(clippy::too_many_arguments)]
        let data = |rec: &mut Recorder<'_>,
                    l: &LinearSpec,
                    dz: (BufSlice<'_>, u32),
                    col0: u32,
                    cols: u32,
                    out: (BufSlice<'_>, u32, u32),
                    mask: Option<(BufSlice<'_>, u32)>,
                    acc: bool| {
            let pc = MlpBwdDataParams {
                n,
                fan_in: l.fan_in as u32,
                fan_out: l.fan_out as u32,
                cols,
                col0,
                dz_stride: dz.1,
                out_stride: out.1,
                out_col: out.2,
                mask_stride: mask.map_or(0, |m| m.1),
                mask_col: 0,
                w_off: l.w_off as u32,
                accumulate: acc as u32,
            };
            if let Some(rp) = self.rows.as_ref().filter(|_| RowsPath::fits(l.fan_out)) {
                // Wᵀ rows col0.. are the matrix; dz is the input.
                rp.gemv(
                    rec,
                    &Gemv {
                        n,
                        a: (dz.0, l.fan_out as u32, dz.1),
                        b: None,
                        fan_in: l.fan_out as u32,
                        mat: bufs.wt.all(),
                        m_off: (l.w_off + col0 as usize * l.fan_out) as u64,
                        count: cols,
                        bias: None,
                        relu: false,
                        out,
                        mask,
                        accumulate: acc,
                    },
                );
                return;
            }
            let m = mask.map_or(dz.0, |m| m.0);
            rec.dispatch(
                &self.bwd_data,
                &pc,
                &[params, dz.0, m, out.0],
                row_grid(n, cols.div_ceil(TILE)),
            );
        };
        let (w, ind, xd) = (cfg.width, cfg.in_dims() as u32, cfg.x_dims() as u32);
        let tf = cfg.t_feat_dims() as u32;
        let tn = cfg.time_net();
        let depth = cfg.depth as usize;
        let skip_layer = cfg.skip.map(|s| s as usize + 1);
        let head = self.layout.head();
        let last = b.h[depth - 1];
        weights(rec, head, (d_out, OUT_DIMS as u32), (last, w, w), None);
        data(
            rec,
            head,
            (d_out, OUT_DIMS as u32),
            0,
            w,
            (b.dz[0], w, 0),
            Some((last, w)),
            false,
        );
        let mut cur = 0;
        let mut dtf_written = false;
        for (i, l) in self.layout.trunk().iter().enumerate().rev() {
            let dz = (b.dz[cur], w);
            let nxt = (b.dz[1 - cur], w, 0);
            if i == 0 {
                weights(rec, l, dz, (b.x0, ind, ind), None);
                if tn {
                    data(rec, l, dz, xd, tf, (b.dtf, tf, 0), None, dtf_written);
                    dtf_written = true;
                }
            } else if skip_layer == Some(i) {
                let prev = b.h[i - 1];
                weights(rec, l, dz, (b.x0, ind, ind), Some((prev, w)));
                data(rec, l, dz, ind, w, nxt, Some((prev, w)), false);
                if tn {
                    data(rec, l, dz, xd, tf, (b.dtf, tf, 0), None, false);
                    dtf_written = true;
                }
                cur = 1 - cur;
            } else {
                let prev = b.h[i - 1];
                weights(rec, l, dz, (prev, w, w), None);
                data(rec, l, dz, 0, w, nxt, Some((prev, w)), false);
                cur = 1 - cur;
            }
        }
        if tn {
            let t = self.layout.time_net();
            let (hid, ted) = (self.hidden() as u32, cfg.t_enc_dims() as u32);
            let dtf = (b.dtf, tf);
            weights(rec, &t[1], dtf, (b.ht, hid, hid), None);
            let dh = b.dz[1 - cur];
            data(
                rec,
                &t[1],
                dtf,
                0,
                hid,
                (dh, hid, 0),
                Some((b.ht, hid)),
                false,
            );
            weights(rec, &t[0], (dh, hid), (b.enc_t, ted, ted), None);
        }
    }
}
