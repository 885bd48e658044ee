//! Rendering and the photometric loss: a [`RenderPass`] owns one set of raster buffers (grown on
//! overflow by the rasteriser's one policy), [`PhotoLoss`] the loss scratch and ∂L/∂render, and
//! [`OverflowWatch`] carries every render's overflow flag out of a submit.

use std::rc::Rc;

use super::StepSizes;
use crate::error::Result;
use crate::kernels::deform::Drawn;
use crate::kernels::loss::{LossBuffers, LossValues, PhotometricLoss};
use crate::kernels::raster::{
    Camera, OutputGrads, Overflow, RasterBuffers, Rasterizer, RenderOpts, SplatInputs,
};
use crate::model::gaussians::Section;
use crate::model::state::GaussianState;
use crate::vk::{BufSlice, Buffer, Gpu, Recorder};

/// One render target with its backward buffers. The rasteriser's pipelines are shared.
pub struct RenderPass {
    raster: Rc<Rasterizer>,
    pub bufs: RasterBuffers,
}

impl RenderPass {
    /// Buffers for `s` blending `feature_dims` extra channels.
    pub fn new(
        raster: Rc<Rasterizer>,
        gpu: &Gpu,
        s: &StepSizes,
        feature_dims: u32,
    ) -> Result<Self> {
        let bufs = raster.buffers(gpu, &s.raster(feature_dims))?;
        Ok(RenderPass { raster, bufs })
    }

    pub fn forward(
        &self,
        rec: &mut Recorder<'_>,
        cam: &Camera,
        g: &SplatInputs<'_>,
        o: &RenderOpts,
    ) {
        self.raster.forward(rec, &self.bufs, cam, g, o);
    }

    /// Backward of the last forward (same inputs) into the raster gradient buffers.
    pub fn backward(
        &self,
        rec: &mut Recorder<'_>,
        cam: &Camera,
        g: &SplatInputs<'_>,
        o: &RenderOpts,
        d: &OutputGrads<'_>,
    ) {
        self.raster.backward(rec, &self.bufs, cam, g, o, d);
    }

    /// The projection of [`RenderPass::forward`] alone (its splat records).
    pub fn project(&self, rec: &mut Recorder<'_>, cam: &Camera, g: &SplatInputs<'_>) {
        self.raster.forward_project(rec, &self.bufs, cam, g);
    }

    /// The rest of [`RenderPass::forward`] after [`RenderPass::project`].
    pub fn blend(&self, rec: &mut Recorder<'_>, cam: &Camera, g: &SplatInputs<'_>, o: &RenderOpts) {
        self.raster.forward_blend(rec, &self.bufs, cam, g, o);
    }

    /// The blend half of [`RenderPass::backward`]: the 2D gradient records and feature grads.
    pub fn backward_blend(
        &self,
        rec: &mut Recorder<'_>,
        cam: &Camera,
        g: &SplatInputs<'_>,
        o: &RenderOpts,
        d: &OutputGrads<'_>,
    ) {
        self.raster.backward_blend(rec, &self.bufs, cam, g, o, d);
    }

    /// The projection half of [`RenderPass::backward`], from the 2D gradient records as they
    /// stand.
    pub fn backward_project(
        &self,
        rec: &mut Recorder<'_>,
        cam: &Camera,
        g: &SplatInputs<'_>,
        o: &RenderOpts,
    ) {
        self.raster.backward_project(rec, &self.bufs, cam, g, o);
    }

    /// The splat records ([N,3] vec4) of the last projection.
    pub fn splats(&self) -> BufSlice<'_> {
        self.bufs.splats.all()
    }

    /// The per-splat 2D gradient records ([N, G2D_STRIDE]).
    pub fn grad2d(&self) -> BufSlice<'_> {
        self.bufs.grad2d.all()
    }

    /// [H·W] Σ w·z of the last forward (not normalised by alpha).
    pub fn depth(&self) -> BufSlice<'_> {
        self.bufs.out_depth.all()
    }

    pub fn rgba(&self) -> BufSlice<'_> {
        self.bufs.out_rgba.all()
    }

    pub fn features(&self) -> BufSlice<'_> {
        self.bufs.out_features.all()
    }

    /// ∂L/∂(blended features) per splat of the last backward.
    pub fn feature_grads(&self) -> BufSlice<'_> {
        self.bufs.d_features.all()
    }

    /// Gradients wrt the drawn geometry of the last backward.
    pub fn drawn_grads(&self) -> Drawn<'_> {
        let b = &self.bufs;
        Drawn {
            means: b.d_means.all(),
            scales: b.d_scales.all(),
            quats: b.d_quats.all(),
        }
    }

    /// Opacity and SH gradients of the last backward go into their Adam sections.
    pub fn copy_appearance_grads(&self, rec: &mut Recorder<'_>, g: &GaussianState) {
        if g.n == 0 {
            return;
        }
        let (b, n) = (&self.bufs, g.n as u64);
        rec.copy(b.d_opacity_logits.slice(0, n * 4), g.grad(Section::Opacity));
        rec.copy(b.d_sh_dc.slice(0, n * 12), g.grad(Section::ShDc));
        if g.layout.sh_coeffs > 1 {
            let bytes = n * 4 * g.layout.row_len(Section::ShRest) as u64;
            rec.copy(b.d_sh_rest.slice(0, bytes), g.grad(Section::ShRest));
        }
    }

    /// The u32 pair (overflowed, intersections needed) of the last forward.
    pub fn overflow_flag(&self) -> BufSlice<'_> {
        self.bufs.overflow_flag()
    }

    /// Grows the buffers for `needed` intersections (after an overflow; the caller re-runs).
    pub fn grow(&mut self, gpu: &Gpu, needed: u32) -> Result<()> {
        self.raster.grow(gpu, &mut self.bufs, needed)
    }
}

/// The overflow flags of a step's renders: gathered on the GPU as (flag, needed) pairs, which
/// guard the optimiser and the densification statistics (an overflowed step changes nothing),
/// then published to host memory so the host learns after the submit which renders must grow
/// before it re-runs the step. No mid-step read.
pub struct OverflowWatch {
    flags: Buffer,
    host: Buffer,
    slots: u64,
}

impl OverflowWatch {
    pub fn new(gpu: &Gpu, name: &str, slots: u64) -> Result<Self> {
        Ok(OverflowWatch {
            flags: gpu.buffer(name, slots * 8)?,
            host: gpu.host_buffer(&format!("{name} (host)"), slots * 8)?,
            slots,
        })
    }

    /// Records the copy of `pass`'s flag (after its forward) into slot `k`.
    pub fn record(&self, rec: &mut Recorder<'_>, k: u64, pass: &RenderPass) {
        assert!(k < self.slots);
        rec.copy(pass.overflow_flag(), self.flags.slice(8 * k, 8));
    }

    /// Slots `0..count` as a skip guard (see `Adam::record_guarded`).
    pub fn guard(&self, count: u64) -> BufSlice<'_> {
        assert!((1..=self.slots).contains(&count));
        self.flags.slice(0, 8 * count)
    }

    /// Copies every slot to host memory (the last command of a submit).
    pub fn publish(&self, rec: &mut Recorder<'_>) {
        rec.copy(self.flags.all(), self.host.all());
    }

    /// Slot `k` as of the last finished submit that recorded and published it; an error when
    /// its render's tile walk was cut ([`Error::TileWalkCut`], naming `what`).
    pub fn read(&self, k: u64, what: &str) -> Result<Overflow> {
        let w: Vec<u32> = self.host.read_mapped();
        Overflow::from_words(w[2 * k as usize], w[2 * k as usize + 1], what)
    }
}

/// The photometric loss `(1 − λ)·L1 + λ·(1 − SSIM)` of a render and its gradient.
pub struct PhotoLoss {
    loss: PhotometricLoss,
    bufs: LossBuffers,
    d_render: Buffer,
    /// Host copy of the partial sums, written by every record: the host reads each step's
    /// values after the submit without another submit (the worst-view check reads them all).
    host: Buffer,
}

impl PhotoLoss {
    pub fn new(gpu: &Gpu, s: &StepSizes) -> Result<Self> {
        let loss = PhotometricLoss::new(gpu)?;
        let bufs = loss.buffers(gpu, s.width, s.height)?;
        Ok(PhotoLoss {
            host: gpu.host_buffer("loss partial sums (host)", bufs.sums().size)?,
            bufs,
            d_render: gpu.buffer("d render", s.pixels() * 16)?,
            loss,
        })
    }

    /// Loss of `render`'s colour against `target` ([H·W] vec4) and ∂L/∂render.
    pub fn record(
        &mut self,
        rec: &mut Recorder<'_>,
        render: &RenderPass,
        target: BufSlice<'_>,
        lambda_ssim: f32,
    ) {
        let d = self.d_render.all();
        self.loss
            .record(rec, &mut self.bufs, render.rgba(), target, d, lambda_ssim);
        let sums = self.bufs.sums();
        rec.copy(sums, self.host.slice(0, sums.size));
    }

    /// ∂L/∂render of the last record.
    pub fn d_render(&self) -> BufSlice<'_> {
        self.d_render.all()
    }

    /// Values of the last record (after its submit; read from host memory).
    pub fn values(&self) -> LossValues {
        self.bufs.values_of(&self.host.read_mapped())
    }
}
