//! LPIPS with the AlexNet backbone (`glsl/lpips/*.comp`), as the reference `lpips` package
//! (v0.1) computes it. CPU twin: `reference::lpips`.
//!
//! Stages: `lpips_input` (two RGBA images → planar [2][3][H][W], [0, 1] → [−1, 1], then the
//! package's ScalingLayer) → five `conv` (+ bias + ReLU; `max_pool` 3×3/2 before conv2 and
//! conv3) whose outputs relu1…relu5 are the feature stages → `lpips_diff` per stage (channel
//! unit normalisation, squared difference, learned 1×1 weights, spatial mean) into
//! per-workgroup partial sums that the host adds in f64 (no float atomics: bit-reproducible).
//! Both images go through every stage as one batch of two.

use bytemuck::{Pod, Zeroable};

use crate::error::{Error, Result};
use crate::shaders;
use crate::vk::{BufSlice, Buffer, ComputePipeline, Gpu, Recorder};

/// Mirrors `LpipsInputParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct LpipsInputParams {
    pub width: u32,
    pub height: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub shift: [f32; 4],
    pub scale: [f32; 4],
}

/// Mirrors `LpipsConvParams` in glsl/include/params.glsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct LpipsConvParams {
    pub in_w: u32,
    pub in_h: u32,
    pub out_w: u32,
    pub out_h: u32,
    pub cin: u32,
    pub cout: u32,
    pub ksize: u32,
    pub stride: u32,
    pub pad: u32,
    pub w_off: u32,
    pub b_off: u32,
    pub pad0: u32,
}

/// Mirrors `LpipsPoolParams` in glsl/include/params.glsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct LpipsPoolParams {
    pub in_w: u32,
    pub in_h: u32,
    pub out_w: u32,
    pub out_h: u32,
    pub planes: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

/// Mirrors `LpipsDiffParams` in glsl/include/params.glsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct LpipsDiffParams {
    pub width: u32,
    pub height: u32,
    pub channels: u32,
    pub lin_off: u32,
    pub inv_count: f32,
    pub sum_off: u32,
    pub pad0: u32,
    pub pad1: u32,
}

/// The reference package's ScalingLayer: `x' = (x − SHIFT) / SCALE` on x ∈ [−1, 1].
pub const SHIFT: [f32; 3] = [-0.030, -0.088, -0.188];
pub const SCALE: [f32; 3] = [0.458, 0.448, 0.450];

/// One convolution of the backbone (ReLU after it; `pool_before`: max-pool 3×3/2 before it).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ConvSpec {
    pub cin: u32,
    pub cout: u32,
    pub ksize: u32,
    pub stride: u32,
    pub pad: u32,
    pub pool_before: bool,
}

/// torchvision's AlexNet `features` (indices 0, 3, 6, 8, 10); LPIPS taps relu1…relu5.
pub const ALEXNET: [ConvSpec; 5] = [
    conv(3, 64, 11, 4, 2, false),
    conv(64, 192, 5, 1, 2, true),
    conv(192, 384, 3, 1, 1, true),
    conv(384, 256, 3, 1, 1, false),
    conv(256, 256, 3, 1, 1, false),
];

const fn conv(cin: u32, cout: u32, ksize: u32, stride: u32, pad: u32, pool: bool) -> ConvSpec {
    ConvSpec {
        cin,
        cout,
        ksize,
        stride,
        pad,
        pool_before: pool,
    }
}

/// The smallest image side AlexNet accepts: 31 px gives relu1 7 px, pool1 3, pool2 1 (30 px
/// would leave pool2 nothing to pool).
pub const MIN_SIDE: u32 = 31;

/// Spatial sizes of one image through the backbone: the input of each conv and its output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Plan {
    pub width: u32,
    pub height: u32,
    pub conv_in: [(u32, u32); 5],
    pub conv_out: [(u32, u32); 5],
}

impl Plan {
    /// The sizes for a `width`×`height` image, or an error naming the minimum.
    pub fn new(width: u32, height: u32) -> Result<Plan> {
        let too_small = || {
            Error::Invalid(format!(
                "LPIPS (AlexNet) needs images of at least {MIN_SIDE}×{MIN_SIDE} pixels; got \
                 {width}×{height}"
            ))
        };
        let mut cur = (width, height);
        let mut conv_in = [(0, 0); 5];
        let mut conv_out = [(0, 0); 5];
        for (i, s) in ALEXNET.iter().enumerate() {
            if s.pool_before {
                cur = (
                    pool_out(cur.0).ok_or_else(too_small)?,
                    pool_out(cur.1).ok_or_else(too_small)?,
                );
            }
            conv_in[i] = cur;
            let o = |n: u32| {
                (n + 2 * s.pad)
                    .checked_sub(s.ksize)
                    .map(|d| d / s.stride + 1)
            };
            cur = (
                o(cur.0).ok_or_else(too_small)?,
                o(cur.1).ok_or_else(too_small)?,
            );
            conv_out[i] = cur;
        }
        Ok(Plan {
            width,
            height,
            conv_in,
            conv_out,
        })
    }

    /// Pixels of feature stage `i` (relu i+1).
    pub fn stage_pixels(&self, i: usize) -> u32 {
        self.conv_out[i].0 * self.conv_out[i].1
    }
}

/// MaxPool2d(3, 2) output side (floor), `None` below 3.
pub fn pool_out(n: u32) -> Option<u32> {
    n.checked_sub(3).map(|d| d / 2 + 1)
}

/// The network's weights packed as the GPU binds them: one f32 array, conv weights in the
/// reference layout [cout][cin][k][k], then their biases, then the 1×1 linear weights [C].
#[derive(Clone, Debug, PartialEq)]
pub struct LpipsWeights {
    pub data: Vec<f32>,
    pub conv_w: [u32; 5],
    pub conv_b: [u32; 5],
    pub lin: [u32; 5],
}

impl LpipsWeights {
    /// Packs per-stage tensors (shapes as in [`ALEXNET`]; caller validated them).
    pub fn pack(conv_w: [&[f32]; 5], conv_b: [&[f32]; 5], lin: [&[f32]; 5]) -> Self {
        let mut data = Vec::new();
        let mut put = |t: &[f32]| {
            let off = data.len() as u32;
            data.extend_from_slice(t);
            off
        };
        let conv_w = conv_w.map(&mut put);
        let conv_b = conv_b.map(&mut put);
        let lin = lin.map(&mut put);
        LpipsWeights {
            data,
            conv_w,
            conv_b,
            lin,
        }
    }

    pub fn conv_weight(&self, i: usize) -> &[f32] {
        let s = ALEXNET[i];
        let n = (s.cout * s.cin * s.ksize * s.ksize) as usize;
        &self.data[self.conv_w[i] as usize..][..n]
    }

    pub fn conv_bias(&self, i: usize) -> &[f32] {
        &self.data[self.conv_b[i] as usize..][..ALEXNET[i].cout as usize]
    }

    pub fn lin_weight(&self, i: usize) -> &[f32] {
        &self.data[self.lin[i] as usize..][..ALEXNET[i].cout as usize]
    }
}

/// The LPIPS pipelines.
pub struct Lpips {
    input: ComputePipeline,
    conv: ComputePipeline,
    pool: ComputePipeline,
    diff: ComputePipeline,
}

/// Scratch for one image size, allocated once. Shapes per image pair: `input` [2][3][H][W],
/// `acts[i]` relu(i+1) [2][C_i][h_i][w_i], `pooled[j]` the pool before conv j+2, `sums` the
/// partial sums of the five stages (`slots[i]` from `slot0[i]`).
pub struct LpipsBuffers {
    pub plan: Plan,
    input: Buffer,
    acts: Vec<Buffer>,
    pooled: Vec<Buffer>,
    sums: Buffer,
    slot0: [u32; 5],
    slots: [u32; 5],
}

/// Output pixels and channels per `conv` invocation (`CONV_PX`, `CONV_CO` in
/// glsl/lpips/conv.comp).
const CONV_PX: u32 = 8;
const CONV_CO: u32 = 32;

/// Workgroup width of `lpips_diff` (one partial sum per workgroup).
const DIFF_WG: u32 = 64;

impl LpipsBuffers {
    /// Per-stage values (each the spatial mean of that stage's weighted distance) of the last
    /// `record` (after its submit); LPIPS is their sum.
    pub fn stage_values(&self, gpu: &Gpu) -> Result<[f64; 5]> {
        let total = self.slot0[4] + self.slots[4];
        let sums: Vec<f32> = gpu.read(self.sums.elems::<f32>(0, total as u64))?;
        Ok(std::array::from_fn(|i| {
            let r = self.slot0[i] as usize..(self.slot0[i] + self.slots[i]) as usize;
            sums[r].iter().map(|&v| v as f64).sum()
        }))
    }

    /// LPIPS of the last `record`.
    pub fn value(&self, gpu: &Gpu) -> Result<f64> {
        Ok(self.stage_values(gpu)?.iter().sum())
    }

    /// relu(i+1) features [2][C][h][w] (tests).
    pub fn features(&self, i: usize) -> BufSlice<'_> {
        self.acts[i].all()
    }

    /// The max-pool output before conv `j + 2` [2][C][h][w] (tests).
    pub fn pooled(&self, j: usize) -> BufSlice<'_> {
        self.pooled[j].all()
    }

    /// The scaled network input [2][3][H][W] (tests).
    pub fn input(&self) -> BufSlice<'_> {
        self.input.all()
    }
}

impl Lpips {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        use shaders::lpips as l;
        Ok(Lpips {
            input: gpu.pipeline(&l::LPIPS_INPUT)?,
            conv: gpu.pipeline(&l::CONV)?,
            pool: gpu.pipeline(&l::MAX_POOL)?,
            diff: gpu.pipeline(&l::LPIPS_DIFF)?,
        })
    }

    /// Scratch for `width`×`height` pairs: an error for images under [`MIN_SIDE`] or whose
    /// largest activation exceeds the device's storage-buffer range (one binding each).
    pub fn buffers(&self, gpu: &Gpu, width: u32, height: u32) -> Result<LpipsBuffers> {
        let plan = Plan::new(width, height)?;
        let limit = gpu.info.max_storage_buffer_range as u64;
        let alloc = |name: &str, floats: u64| -> Result<Buffer> {
            if floats * 4 > limit {
                return Err(Error::Invalid(format!(
                    "LPIPS of {width}×{height} images: {name} needs {} MiB, over this device's \
                     storage-buffer range of {} MiB; score smaller images",
                    (floats * 4) >> 20,
                    limit >> 20
                )));
            }
            gpu.buffer(name, floats.max(1) * 4)
        };
        let hw = |d: (u32, u32)| d.0 as u64 * d.1 as u64;
        let input = alloc("lpips input", 2 * 3 * hw((width, height)))?;
        let mut acts = Vec::new();
        let mut pooled = Vec::new();
        for (i, s) in ALEXNET.iter().enumerate() {
            if s.pool_before {
                pooled.push(alloc(
                    "lpips pooled",
                    2 * s.cin as u64 * hw(plan.conv_in[i]),
                )?);
            }
            acts.push(alloc(
                "lpips features",
                2 * s.cout as u64 * hw(plan.conv_out[i]),
            )?);
        }
        let slots: [u32; 5] = std::array::from_fn(|i| plan.stage_pixels(i).div_ceil(DIFF_WG));
        let mut slot0 = [0; 5];
        for i in 1..5 {
            slot0[i] = slot0[i - 1] + slots[i - 1];
        }
        let sums = gpu.buffer("lpips partial sums", (slot0[4] + slots[4]) as u64 * 4)?;
        Ok(LpipsBuffers {
            plan,
            input,
            acts,
            pooled,
            sums,
            slot0,
            slots,
        })
    }

    /// Records one convolution + bias + ReLU of `batch` planar images `src`
    /// [batch][cin][in_h][in_w] into `dst` [batch][cout][out_h][out_w].
    pub fn record_conv(
        &self,
        rec: &mut Recorder<'_>,
        p: &LpipsConvParams,
        batch: u32,
        src: BufSlice<'_>,
        weights: BufSlice<'_>,
        dst: BufSlice<'_>,
    ) {
        let (in_px, out_px) = (
            p.in_w as u64 * p.in_h as u64,
            p.out_w as u64 * p.out_h as u64,
        );
        assert!(src.size >= batch as u64 * p.cin as u64 * in_px * 4);
        assert!(dst.size >= batch as u64 * p.cout as u64 * out_px * 4);
        assert!(
            (p.out_w - 1) * p.stride + p.ksize <= p.in_w + 2 * p.pad
                && (p.out_h - 1) * p.stride + p.ksize <= p.in_h + 2 * p.pad
        );
        // One thread per CONV_PX pixels of a row × CONV_CO channels.
        let blocks = p.out_w.div_ceil(CONV_PX) * p.out_h;
        rec.dispatch_threads(
            &self.conv,
            p,
            &[src, weights, dst],
            [blocks, p.cout.div_ceil(CONV_CO), batch],
        );
    }

    /// Records LPIPS of `img0` against `img1` (both [H·W] vec4 RGBA in [0, 1], alpha ignored)
    /// with `weights` (an [`LpipsWeights::data`] upload); read it with [`LpipsBuffers::value`].
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        b: &LpipsBuffers,
        weights: BufSlice<'_>,
        w: &LpipsWeights,
        img0: BufSlice<'_>,
        img1: BufSlice<'_>,
    ) {
        let p = &b.plan;
        let px = p.width as u64 * p.height as u64;
        assert!(img0.size >= px * 16 && img1.size >= px * 16);
        assert!(weights.size >= w.data.len() as u64 * 4);
        let ip = LpipsInputParams {
            width: p.width,
            height: p.height,
            shift: [SHIFT[0], SHIFT[1], SHIFT[2], 0.0],
            scale: [SCALE[0], SCALE[1], SCALE[2], 1.0],
            ..Default::default()
        };
        rec.dispatch_threads(
            &self.input,
            &ip,
            &[img0, img1, b.input.all()],
            [p.width, p.height, 1],
        );
        let mut src = b.input.all();
        let mut pool_i = 0;
        for (i, s) in ALEXNET.iter().enumerate() {
            let (in_w, in_h) = p.conv_in[i];
            if s.pool_before {
                let (pw, ph) = if pool_i == 0 {
                    p.conv_out[0]
                } else {
                    p.conv_out[1]
                };
                let pp = LpipsPoolParams {
                    in_w: pw,
                    in_h: ph,
                    out_w: in_w,
                    out_h: in_h,
                    planes: 2 * s.cin,
                    ..Default::default()
                };
                let dst = b.pooled[pool_i].all();
                rec.dispatch_threads(&self.pool, &pp, &[src, dst], [in_w, in_h, 2 * s.cin]);
                src = dst;
                pool_i += 1;
            }
            let (out_w, out_h) = p.conv_out[i];
            let cp = LpipsConvParams {
                in_w,
                in_h,
                out_w,
                out_h,
                cin: s.cin,
                cout: s.cout,
                ksize: s.ksize,
                stride: s.stride,
                pad: s.pad,
                w_off: w.conv_w[i],
                b_off: w.conv_b[i],
                pad0: 0,
            };
            let dst = b.acts[i].all();
            self.record_conv(rec, &cp, 2, src, weights, dst);
            src = dst;
        }
        for (i, s) in ALEXNET.iter().enumerate() {
            let (sw, sh) = p.conv_out[i];
            let dp = LpipsDiffParams {
                width: sw,
                height: sh,
                channels: s.cout,
                lin_off: w.lin[i],
                inv_count: 1.0 / (sw * sh) as f32,
                sum_off: b.slot0[i],
                ..Default::default()
            };
            rec.dispatch_threads(
                &self.diff,
                &dp,
                &[b.acts[i].all(), weights, b.sums.all()],
                [sw * sh, 1, 1],
            );
        }
    }
}
