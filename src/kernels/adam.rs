//! Fused Adam (`glsl/optim/adam.comp`), one dispatch per parameter group. CPU twin:
//! `reference::adam`. Works on any f32 buffer (MLP weights, Gaussian parameters): a group is a
//! float range of one buffer with its own learning rate (from `model::optim::ExpLr` on the host)
//! and an optional visibility mask.

use bytemuck::{Pod, Zeroable};

use crate::error::Result;
use crate::kernels::shape::{Access, DeviceShape};
use crate::model::optim::AdamHyper;
use crate::shaders;
use crate::vk::{BufSlice, Buffer, ComputePipeline, Gpu, Recorder};

/// Mirrors `AdamParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct AdamParams {
    pub first: u32,
    pub count: u32,
    pub row_len: u32,
    pub use_mask: u32,
    pub lr: f32,
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
    pub bc1: f32,
    pub bc2: f32,
    pub skip_flags: u32,
    pub pad1: u32,
}

/// The four buffers Adam updates or reads, all bound whole and indexed by the group's range:
/// parameters, gradients, first and second moments (same length, f32).
#[derive(Clone, Copy, Debug)]
pub struct AdamBuffers<'a> {
    pub params: BufSlice<'a>,
    pub grads: BufSlice<'a>,
    pub m: BufSlice<'a>,
    pub v: BufSlice<'a>,
}

/// One parameter group: floats `first .. first + count`, learning rate, optional mask
/// (one u32 per row of `row_len` floats counted from `first`; 0 = skip the row).
#[derive(Clone, Copy, Debug)]
pub struct AdamGroup<'a> {
    pub first: u32,
    pub count: u32,
    pub lr: f32,
    pub mask: Option<(BufSlice<'a>, u32)>,
}

pub struct Adam {
    pipe: ComputePipeline,
    /// A zero word: "do not skip", bound when the caller has no guard.
    no_skip: Buffer,
}

impl Adam {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        Self::with_access(gpu, Access::for_device(&gpu.info))
    }

    /// Adam reaching its arrays through `access` (tests run both).
    pub fn with_access(gpu: &Gpu, access: Access) -> Result<Self> {
        use shaders::optim as o;
        Ok(Adam {
            pipe: gpu.pipeline(access.pick(&o::ADAM, &o::ADAM_TEXEL))?,
            no_skip: gpu.buffer_from("adam no-skip", &[0u32; 4])?,
        })
    }

    /// Records one Adam step (1-based `step`) for each group, one dispatch each.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        b: AdamBuffers<'_>,
        groups: &[AdamGroup<'_>],
        h: &AdamHyper,
        step: u32,
    ) {
        self.record_guarded(rec, b, groups, h, step, self.no_skip.slice(0, 8));
    }

    /// As [`Adam::record`], but every update is a no-op when any flag in `skip` is non-zero:
    /// `skip` holds (flag, needed) u32 pairs as the rasteriser writes its overflow
    /// ([`crate::kernels::raster::RasterBuffers::overflow_flag`]), written earlier on the GPU.
    pub fn record_guarded(
        &self,
        rec: &mut Recorder<'_>,
        b: AdamBuffers<'_>,
        groups: &[AdamGroup<'_>],
        h: &AdamHyper,
        step: u32,
        skip: BufSlice<'_>,
    ) {
        assert!(
            skip.size >= 8 && skip.size % 8 == 0,
            "adam skip {skip:?}: (flag, needed) pairs expected"
        );
        let (bc1, bc2) = h.bias_corrections(step);
        let outer = rec.set_zone("adam");
        for g in groups {
            let end = (g.first as u64 + g.count as u64) * 4;
            for s in [b.params, b.grads, b.m, b.v] {
                assert!(s.size >= end, "adam group {g:?}: buffer {s:?} too small");
            }
            if let Some((m, row_len)) = g.mask {
                assert!(row_len > 0 && m.size >= g.count.div_ceil(row_len) as u64 * 4);
            }
            let pc = AdamParams {
                first: g.first,
                count: g.count,
                row_len: g.mask.map_or(1, |m| m.1),
                use_mask: g.mask.is_some() as u32,
                lr: g.lr,
                beta1: h.beta1,
                beta2: h.beta2,
                eps: h.eps,
                bc1,
                bc2,
                skip_flags: (skip.size / 8) as u32,
                ..Default::default()
            };
            let mask = g.mask.map_or(b.grads, |m| m.0);
            rec.dispatch_rows(
                &self.pipe,
                &pc,
                &[b.params, b.grads, b.m, b.v, mask, skip],
                g.count,
            );
        }
        rec.set_zone(&outer);
    }
}
