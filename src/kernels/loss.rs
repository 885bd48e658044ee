//! Photometric loss `(1 − λ)·L1 + λ·(1 − SSIM)` (λ = 0.2 in 3DGS) and its gradient wrt the
//! render, plus the values for logging (L1, MSE → PSNR, SSIM) (`glsl/loss/*.comp`).
//! CPU twin: `reference::loss`.
//!
//! SSIM uses the 11×11 Gaussian window (σ = 1.5) with zero padding, per colour channel, like
//! 3DGS. Stages: `ssim_products` (x, y, x², y², xy) → separable blur → `ssim_map` (SSIM and its
//! partials wrt μx, E[x²], E[xy]) → separable blur (the window is symmetric, so this is the
//! transposed convolution) → `loss_grad`. Values are per-workgroup partial sums, summed on the
//! host in f64 only when asked (no float atomics: bit-reproducible).

use bytemuck::{Pod, Zeroable};

pub use super::shape::{Access, DeviceShape};
use crate::error::Result;
use crate::shaders;
use crate::vk::{BufSlice, Buffer, ComputePipeline, Gpu, Recorder};

/// Mirrors `LossParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct LossParams {
    pub width: u32,
    pub height: u32,
    pub planes: u32,
    pub pad0: u32,
    pub lambda_ssim: f32,
    pub inv_count: f32,
    pub pad1: u32,
    pub pad2: u32,
}

/// Loss values of one image pair (means over pixels and the 3 colour channels).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LossValues {
    pub l1: f64,
    pub mse: f64,
    pub ssim: f64,
    /// `(1 − λ)·l1 + λ·(1 − ssim)`
    pub loss: f64,
    /// `10·log10(1 / mse)` on [0, 1] images.
    pub psnr: f64,
}

impl LossValues {
    pub fn new(l1: f64, mse: f64, ssim: f64, lambda_ssim: f64) -> Self {
        LossValues {
            l1,
            mse,
            ssim,
            loss: (1.0 - lambda_ssim) * l1 + lambda_ssim * (1.0 - ssim),
            psnr: psnr(mse),
        }
    }
}

/// PSNR of a mean squared error on [0, 1] images (∞ for a perfect match).
pub fn psnr(mse: f64) -> f64 {
    -10.0 * mse.log10()
}

pub struct PhotometricLoss {
    products: ComputePipeline,
    blur_h: ComputePipeline,
    blur_v: ComputePipeline,
    ssim_map: ComputePipeline,
    grad: ComputePipeline,
    /// Which blur shape `blur_h` and `blur_v` are.
    pub blur: BlurShape,
}

/// The separable blur's shape: both sum the same taps in the same order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlurShape {
    /// One pixel per invocation (`blur_h`, `blur_v`): coalesced loads on GPUs.
    Pixel,
    /// A run of 16 pixels per invocation from a private array (`blur_h_rows`, `blur_v_rows`):
    /// on lavapipe each storage load is a per-lane loop, and this shape loads 26 values per
    /// 16 outputs instead of 11 per output.
    Rows,
}

/// Rows on CPU devices, pixels elsewhere (override: `DISPFLOW_LOSS_BLUR=pixel|rows`).
impl DeviceShape for BlurShape {
    const ENV: &'static str = "DISPFLOW_LOSS_BLUR";
    const ALL: &'static [Self] = &[BlurShape::Pixel, BlurShape::Rows];
    const CPU: Self = BlurShape::Rows;
    const GPU: Self = BlurShape::Pixel;

    fn name(self) -> &'static str {
        match self {
            BlurShape::Pixel => "pixel",
            BlurShape::Rows => "rows",
        }
    }
}

/// Pixels per invocation of the rows blurs (mirrors `BLUR_RUN` in glsl/include/loss.glsl).
const BLUR_RUN: u32 = 16;

/// Scratch for one image size, allocated once.
pub struct LossBuffers {
    pub width: u32,
    pub height: u32,
    planes: Buffer,
    tmp: Buffer,
    stats: Buffer,
    /// Per-workgroup partial sums [groups] × (L1, squared error, SSIM, −).
    sums: Buffer,
    lambda_ssim: f32,
}

impl LossBuffers {
    fn groups(&self) -> u32 {
        (self.width * self.height).div_ceil(256)
    }

    /// Reads the partial sums of the last `record` (after its submit) and finishes the values.
    pub fn values(&self, gpu: &Gpu) -> Result<LossValues> {
        Ok(self.values_of(&gpu.read(self.sums())?))
    }

    /// The per-workgroup partial sums of the last `record` (to copy to host memory).
    pub fn sums(&self) -> BufSlice<'_> {
        self.sums.elems::<[f32; 4]>(0, self.groups() as u64)
    }

    /// Finishes the values from partial sums read back from [`Self::sums`].
    pub fn values_of(&self, sums: &[[f32; 4]]) -> LossValues {
        let (mut l1, mut se, mut ss) = (0f64, 0f64, 0f64);
        for s in &sums[..self.groups() as usize] {
            l1 += s[0] as f64;
            se += s[1] as f64;
            ss += s[2] as f64;
        }
        let n = 3.0 * (self.width * self.height) as f64;
        LossValues::new(l1 / n, se / n, ss / n, self.lambda_ssim as f64)
    }
}

impl PhotometricLoss {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        Self::with_blur(gpu, BlurShape::for_device(&gpu.info))
    }

    /// The loss with the blur of shape `blur` (tests run both).
    pub fn with_blur(gpu: &Gpu, blur: BlurShape) -> Result<Self> {
        Self::with_shapes(gpu, blur, Access::for_device(&gpu.info))
    }

    /// The loss with the blur of shape `blur`, every stage with a texel twin (all but the pixel
    /// blur) reaching its arrays through `access`.
    pub fn with_shapes(gpu: &Gpu, blur: BlurShape, access: Access) -> Result<Self> {
        use shaders::loss as l;
        let (h, v) = match blur {
            BlurShape::Pixel => (&l::BLUR_H, &l::BLUR_V),
            BlurShape::Rows => (
                access.pick(&l::BLUR_H_ROWS, &l::BLUR_H_ROWS_TEXEL),
                access.pick(&l::BLUR_V_ROWS, &l::BLUR_V_ROWS_TEXEL),
            ),
        };
        Ok(PhotometricLoss {
            products: gpu.pipeline(access.pick(&l::SSIM_PRODUCTS, &l::SSIM_PRODUCTS_TEXEL))?,
            blur_h: gpu.pipeline(h)?,
            blur_v: gpu.pipeline(v)?,
            ssim_map: gpu.pipeline(access.pick(&l::SSIM_MAP, &l::SSIM_MAP_TEXEL))?,
            grad: gpu.pipeline(access.pick(&l::LOSS_GRAD, &l::LOSS_GRAD_TEXEL))?,
            blur,
        })
    }

    /// Records the separable blur of `planes` planes: `src` → `tmp` (h) → `dst` (v).
    fn record_blur(
        &self,
        rec: &mut Recorder<'_>,
        pc: &LossParams,
        src: BufSlice<'_>,
        tmp: BufSlice<'_>,
        dst: BufSlice<'_>,
    ) {
        let (w, h, planes) = (pc.width, pc.height, pc.planes);
        match self.blur {
            BlurShape::Pixel => {
                rec.dispatch_threads(&self.blur_h, pc, &[src, tmp], [w, h, planes]);
                rec.dispatch_threads(&self.blur_v, pc, &[tmp, dst], [w, h, planes]);
            }
            BlurShape::Rows => {
                let rows_h = w.div_ceil(BLUR_RUN) * h * planes;
                let rows_v = w * h.div_ceil(BLUR_RUN) * planes;
                rec.dispatch_rows(&self.blur_h, pc, &[src, tmp], rows_h);
                rec.dispatch_rows(&self.blur_v, pc, &[tmp, dst], rows_v);
            }
        }
    }

    pub fn buffers(&self, gpu: &Gpu, width: u32, height: u32) -> Result<LossBuffers> {
        let hw = (width as u64 * height as u64).max(1);
        Ok(LossBuffers {
            width,
            height,
            planes: gpu.buffer("loss planes", 15 * hw * 4)?,
            tmp: gpu.buffer("loss blur tmp", 15 * hw * 4)?,
            stats: gpu.buffer("loss window stats", 15 * hw * 4)?,
            sums: gpu.buffer("loss partial sums", hw.div_ceil(256) * 16)?,
            lambda_ssim: 0.2,
        })
    }

    /// Records the loss of `render` against `target` (both [H·W] vec4, alpha ignored) and
    /// writes ∂L/∂render into `d_render` ([H·W] vec4, alpha gradient 0).
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        b: &mut LossBuffers,
        render: BufSlice<'_>,
        target: BufSlice<'_>,
        d_render: BufSlice<'_>,
        lambda_ssim: f32,
    ) {
        let (w, h) = (b.width, b.height);
        let hw = w * h;
        assert!(
            render.size >= hw as u64 * 16
                && target.size >= hw as u64 * 16
                && d_render.size >= hw as u64 * 16
        );
        b.lambda_ssim = lambda_ssim;
        let pc = |planes| LossParams {
            width: w,
            height: h,
            planes,
            lambda_ssim,
            inv_count: 1.0 / (3.0 * hw.max(1) as f32),
            ..Default::default()
        };
        rec.dispatch_threads(
            &self.products,
            &pc(15),
            &[render, target, b.planes.all()],
            [hw, 1, 1],
        );
        self.record_blur(rec, &pc(15), b.planes.all(), b.tmp.all(), b.stats.all());
        // The 9 partial maps reuse `planes`; their blurs reuse `tmp` and `stats`.
        rec.dispatch_threads(
            &self.ssim_map,
            &pc(9),
            &[b.stats.all(), b.planes.all(), b.sums.all()],
            [hw, 1, 1],
        );
        self.record_blur(rec, &pc(9), b.planes.all(), b.tmp.all(), b.stats.all());
        rec.dispatch_threads(
            &self.grad,
            &pc(9),
            &[render, target, b.stats.all(), d_render, b.sums.all()],
            [hw, 1, 1],
        );
    }
}
