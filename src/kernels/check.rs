//! Non-finite counts (`glsl/check/count_nonfinite.comp`); CPU twin: `reference::check`.
//! A [`NonFiniteCheck`] owns one small counts buffer of `slots` (count, first index) pairs:
//! [`NonFiniteCheck::reset`], then one [`NonFiniteCheck::count`] per buffer range (each into its
//! own slot, or several into one), then [`NonFiniteCheck::read`] after the command buffer
//! finished. The collapse guard checks the model's parameters with it at every probe render,
//! where a read-back already happens: never in the middle of a step.

use bytemuck::{Pod, Zeroable};

use crate::error::Result;
use crate::shaders;
use crate::vk::{BufSlice, Buffer, ComputePipeline, Gpu, Recorder};

/// Mirrors `CheckParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct CheckParams {
    pub first: u32,
    pub count: u32,
    pub slot: u32,
    pub slots: u32,
}

/// What one slot found: how many floats were not finite and the smallest index among them
/// (relative to the start of the range counted into the slot).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NonFinite {
    pub count: u32,
    pub first: Option<u32>,
}

pub struct NonFiniteCheck {
    pipeline: ComputePipeline,
    counts: Buffer,
    slots: u32,
}

impl NonFiniteCheck {
    pub fn new(gpu: &Gpu, slots: u32) -> Result<Self> {
        let slots = slots.max(1);
        Ok(NonFiniteCheck {
            pipeline: gpu.pipeline(&shaders::check::COUNT_NONFINITE)?,
            counts: gpu.buffer("non-finite counts", 8 * slots as u64)?,
            slots,
        })
    }

    pub fn slots(&self) -> u32 {
        self.slots
    }

    /// Zeroes every count and sets every first index to "none".
    pub fn reset(&self, rec: &mut Recorder<'_>) {
        let half = 4 * self.slots as u64;
        rec.fill(self.counts.slice(0, half), 0);
        rec.fill(self.counts.slice(half, half), u32::MAX);
    }

    /// Adds the non-finite floats of `x`'s floats `[first, first + count)` to `slot`.
    pub fn count(
        &self,
        rec: &mut Recorder<'_>,
        x: BufSlice<'_>,
        first: u32,
        count: u32,
        slot: u32,
    ) {
        assert!(
            slot < self.slots,
            "non-finite check: slot {slot} of {}",
            self.slots
        );
        assert!(
            x.size >= (first as u64 + count as u64) * 4,
            "non-finite check: a binding of {} bytes for floats {first}..{}",
            x.size,
            first as u64 + count as u64
        );
        if count == 0 {
            return;
        }
        let p = CheckParams {
            first,
            count,
            slot,
            slots: self.slots,
        };
        rec.dispatch_rows(&self.pipeline, &p, &[x, self.counts.all()], count);
    }

    /// Every slot's result (after the recorder that counted has finished).
    pub fn read(&self, gpu: &Gpu) -> Result<Vec<NonFinite>> {
        let v: Vec<u32> = gpu.read(self.counts.all())?;
        let n = self.slots as usize;
        Ok((0..n)
            .map(|s| NonFinite {
                count: v[s],
                first: (v[n + s] != u32::MAX).then_some(v[n + s]),
            })
            .collect())
    }
}
