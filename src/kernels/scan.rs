//! Exclusive prefix sum of u32 (`glsl/scan/*.comp`). CPU twin: `reference::scan`.
//!
//! A pyramid of 2048-element blocks: `scan_setup` lays the levels out from a count that lives on
//! the GPU, `scan_reduce` sums blocks level by level, `scan_top` scans the top level in one
//! workgroup and `scan_down` scans each block plus its offset on the way down. Every dispatch
//! after the setup is indirect, so the count is never read back.

use bytemuck::{Pod, Zeroable};

use crate::error::Result;
use crate::shaders;
use crate::vk::{BufSlice, Buffer, ComputePipeline, Gpu, Recorder};

/// Elements per workgroup (mirrors `SCAN_BLOCK` in glsl/include/common.glsl).
pub const SCAN_BLOCK: u32 = 2048;

/// Mirrors `ScanParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct ScanParams {
    pub capacity: u32,
    pub level: u32,
    pub num_levels: u32,
    pub pad: u32,
}

/// Where an element count comes from: the host (written inline into the command stream) or a
/// u32 in a GPU buffer written by an earlier dispatch (never read back).
#[derive(Clone, Copy, Debug)]
pub enum Count<'a> {
    Host(u32),
    Gpu(BufSlice<'a>),
}

impl<'a> Count<'a> {
    /// The count as a GPU slice; a host count is first written into `slot`.
    pub(crate) fn to_gpu(self, rec: &mut Recorder<'_>, slot: BufSlice<'a>) -> BufSlice<'a> {
        match self {
            Count::Host(n) => {
                rec.update(slot, &[n]);
                slot
            }
            Count::Gpu(s) => {
                let align = rec.gpu().info.min_storage_buffer_offset_alignment;
                assert!(
                    s.offset % align == 0,
                    "count slice {s:?} is not aligned to {align} bytes"
                );
                s
            }
        }
    }
}

pub struct PrefixSum {
    setup: ComputePipeline,
    reduce: ComputePipeline,
    top: ComputePipeline,
    down: ComputePipeline,
}

/// Scratch for scans of up to `capacity` elements: allocated once, reused every step.
pub struct ScanScratch {
    capacity: u32,
    /// (byte offset in `partials`, element capacity) of pyramid levels 1.. .
    levels: Vec<(u64, u32)>,
    meta: Buffer,
    partials: Buffer,
    count: Buffer,
}

impl ScanScratch {
    pub fn capacity(&self) -> u32 {
        self.capacity
    }
}

impl PrefixSum {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        Ok(PrefixSum {
            setup: gpu.pipeline(&shaders::scan::SCAN_SETUP)?,
            reduce: gpu.pipeline(&shaders::scan::SCAN_REDUCE)?,
            top: gpu.pipeline(&shaders::scan::SCAN_TOP)?,
            down: gpu.pipeline(&shaders::scan::SCAN_DOWN)?,
        })
    }

    pub fn scratch(&self, gpu: &Gpu, capacity: u32) -> Result<ScanScratch> {
        let mut levels = Vec::new();
        let mut off = 0u64;
        let mut s = capacity;
        while s > SCAN_BLOCK {
            s = s.div_ceil(SCAN_BLOCK);
            levels.push((off, s));
            // 256-byte alignment satisfies every device's storage-buffer offset alignment.
            off += (s as u64 * 4).next_multiple_of(256);
        }
        let num_levels = levels.len() + 1;
        Ok(ScanScratch {
            capacity,
            meta: gpu.buffer("scan meta", 16 * num_levels as u64)?,
            partials: gpu.buffer("scan partials", off.max(16))?,
            count: gpu.buffer("scan count", 16)?,
            levels,
        })
    }

    /// Exclusive prefix sum of the first `count` u32s of `input` into `output` (the same slice
    /// is fine). `count` is clamped to the scratch capacity.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        s: &ScanScratch,
        input: BufSlice<'_>,
        output: BufSlice<'_>,
        count: Count<'_>,
    ) {
        // A GPU count is only known to be <= capacity, so the slices must cover the capacity.
        let need = match count {
            Count::Host(n) => {
                assert!(
                    n <= s.capacity,
                    "scan of {n} elements exceeds the scratch capacity {}",
                    s.capacity
                );
                n as u64 * 4
            }
            Count::Gpu(_) => s.capacity as u64 * 4,
        };
        assert!(
            input.size >= need && output.size >= need,
            "scan {input:?} -> {output:?} smaller than {need} bytes"
        );
        let count = count.to_gpu(rec, s.count.slice(0, 4));
        let num_levels = s.levels.len() as u32 + 1;
        let pc = |level| ScanParams {
            capacity: s.capacity,
            level,
            num_levels,
            pad: 0,
        };
        let level_slice = |l: usize| -> BufSlice<'_> {
            let (off, cap) = s.levels[l - 1];
            s.partials.slice(off, cap as u64 * 4)
        };
        let args = |l: u32| s.meta.slice((4 * l as u64 + 1) * 4, 12);
        rec.dispatch(&self.setup, &pc(0), &[count, s.meta.all()], [1, 1, 1]);
        for l in 0..num_levels - 1 {
            let src = if l == 0 {
                input
            } else {
                level_slice(l as usize)
            };
            let dst = level_slice(l as usize + 1);
            rec.dispatch_indirect(&self.reduce, &pc(l), &[s.meta.all(), src, dst], args(l));
        }
        let top = num_levels - 1;
        let (src, dst) = if top == 0 {
            (input, output)
        } else {
            (level_slice(top as usize), level_slice(top as usize))
        };
        rec.dispatch(&self.top, &pc(top), &[s.meta.all(), src, dst], [1, 1, 1]);
        for l in (0..num_levels - 1).rev() {
            let (src, dst) = if l == 0 {
                (input, output)
            } else {
                (level_slice(l as usize), level_slice(l as usize))
            };
            let offsets = level_slice(l as usize + 1);
            rec.dispatch_indirect(
                &self.down,
                &pc(l),
                &[s.meta.all(), src, offsets, dst],
                args(l),
            );
        }
    }
}
