//! Stable key-value radix sort, u32 or u64 keys (`glsl/sort/*.comp`). CPU twin:
//! `reference::radix_sort`.
//!
//! 4-bit digits, least significant first, `ceil(bits / 4)` passes over the low `bits` bits of
//! the key (the rasteriser sorts only `tile_bits + depth_bits`). Per pass: `radix_hist` (digit
//! histogram per block of keys, digit-major) → exclusive scan of the histogram → `radix_scatter`
//! (stable rank within the block). The key count may live on the GPU; every per-pass dispatch is
//! indirect on the block count computed by `sort_setup`. Two shapes of `radix_hist` and
//! `radix_scatter` ([`SortShape`]) give the same output.

use bytemuck::{Pod, Zeroable};

use super::scan::{Count, PrefixSum, ScanScratch};
pub use super::shape::DeviceShape;
use crate::error::{Error, Result};
use crate::shaders;
use crate::vk::{Buffer, ComputePipeline, Gpu, Recorder};

/// Keys per block of the block shape (mirrors `SORT_BLOCK` in glsl/include/common.glsl).
pub const SORT_BLOCK: u32 = 2048;
/// Keys per block of the serial shape, and its blocks per workgroup (mirror
/// `SORT_SERIAL_BLOCK` and `SORT_SERIAL_LANES`).
pub const SORT_SERIAL_BLOCK: u32 = 256;
pub const SORT_SERIAL_LANES: u32 = 8;
/// Bits per pass (16 digits).
pub const RADIX_BITS: u32 = 4;

/// Mirrors `SortParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct SortParams {
    pub capacity: u32,
    pub shift: u32,
    pub digit_mask: u32,
    /// Keys per block ([`SortShape::block_keys`]).
    pub block_keys: u32,
    /// Blocks per workgroup ([`SortShape::group_blocks`]).
    pub group_blocks: u32,
    pub pad: u32,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KeyWidth {
    U32,
    U64,
}

impl KeyWidth {
    pub fn bytes(self) -> u64 {
        match self {
            KeyWidth::U32 => 4,
            KeyWidth::U64 => 8,
        }
    }
    pub fn bits(self) -> u32 {
        self.bytes() as u32 * 8
    }
}

/// The digit passes' shape. Both write the same histogram and the same stable order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SortShape {
    /// 256 invocations per block: shared-memory atomics for the histogram, a shared-memory scan
    /// of a 16 × 256 count table for the ranks (GPUs).
    Block,
    /// One invocation per block, a plain loop over its 2048 keys with 16 counters in a private
    /// array (CPU devices: lavapipe runs the block shape's barriers and shared arrays per lane).
    Serial,
}

/// Serial on CPU devices, blocks elsewhere (`DISPFLOW_SORT=block|serial` overrides).
impl SortShape {
    /// Keys per block: a workgroup's 256 invocations share a 2048-key block, or one invocation
    /// walks a 256-key block alone.
    pub fn block_keys(self) -> u32 {
        match self {
            SortShape::Block => SORT_BLOCK,
            SortShape::Serial => SORT_SERIAL_BLOCK,
        }
    }

    /// Blocks per workgroup.
    pub fn group_blocks(self) -> u32 {
        match self {
            SortShape::Block => 1,
            SortShape::Serial => SORT_SERIAL_LANES,
        }
    }
}

impl DeviceShape for SortShape {
    const ENV: &'static str = "DISPFLOW_SORT";
    const ALL: &'static [Self] = &[SortShape::Block, SortShape::Serial];
    const CPU: Self = SortShape::Serial;
    const GPU: Self = SortShape::Block;

    fn name(self) -> &'static str {
        match self {
            SortShape::Block => "block",
            SortShape::Serial => "serial",
        }
    }
}

pub struct RadixSort {
    /// Which shape `hist` and `scatter` are.
    pub shape: SortShape,
    setup: ComputePipeline,
    hist: [ComputePipeline; 2],
    scatter: [ComputePipeline; 2],
    scan: PrefixSum,
}

/// Ping-pong key/value buffers and scratch for one capacity, allocated once.
/// Callers write the input into `keys[0]`/`vals[0]`; `record` says which pair holds the output.
pub struct SortBuffers {
    pub keys: [Buffer; 2],
    pub vals: [Buffer; 2],
    pub width: KeyWidth,
    capacity: u32,
    hist: Buffer,
    meta: Buffer,
    count: Buffer,
    scan: ScanScratch,
}

impl SortBuffers {
    pub fn capacity(&self) -> u32 {
        self.capacity
    }
}

/// Byte offset of the histogram length in the sort meta buffer; 256 keeps it aligned for a
/// storage-buffer binding on every device.
const META_HIST_LEN: u64 = 256;

/// Passes needed for `bits` significant key bits.
pub fn passes(bits: u32) -> u32 {
    bits.div_ceil(RADIX_BITS)
}

impl RadixSort {
    /// The shape [`SortShape::for_device`] picks.
    pub fn new(gpu: &Gpu) -> Result<Self> {
        Self::with_shape(gpu, SortShape::for_device(&gpu.info))
    }

    pub fn with_shape(gpu: &Gpu, shape: SortShape) -> Result<Self> {
        use shaders::sort as s;
        let (hist, scatter) = match shape {
            SortShape::Block => (
                [&s::RADIX_HIST_U32, &s::RADIX_HIST_U64],
                [&s::RADIX_SCATTER_U32, &s::RADIX_SCATTER_U64],
            ),
            SortShape::Serial => (
                [&s::RADIX_HIST_SERIAL_U32, &s::RADIX_HIST_SERIAL_U64],
                [&s::RADIX_SCATTER_SERIAL_U32, &s::RADIX_SCATTER_SERIAL_U64],
            ),
        };
        Ok(RadixSort {
            shape,
            setup: gpu.pipeline(&s::SORT_SETUP)?,
            hist: [gpu.pipeline(hist[0])?, gpu.pipeline(hist[1])?],
            scatter: [gpu.pipeline(scatter[0])?, gpu.pipeline(scatter[1])?],
            scan: PrefixSum::new(gpu)?,
        })
    }

    pub fn buffers(
        &self,
        gpu: &Gpu,
        name: &str,
        capacity: u32,
        width: KeyWidth,
    ) -> Result<SortBuffers> {
        let max_groups = gpu.info.max_workgroup_count[0] as u64;
        let blocks = capacity.div_ceil(self.shape.block_keys());
        let per_group = (self.shape.block_keys() * self.shape.group_blocks()) as u64;
        if blocks.div_ceil(self.shape.group_blocks()) as u64 > max_groups {
            return Err(Error::Capacity {
                what: "radix sort (blocks of keys per workgroup)",
                capacity: max_groups * per_group,
                asked: capacity as u64,
            });
        }
        let kb = capacity as u64 * width.bytes();
        let range = gpu.info.max_storage_buffer_range as u64;
        if kb > range {
            return Err(Error::Capacity {
                what: "radix sort keys (maxStorageBufferRange of one binding)",
                capacity: range / width.bytes(),
                asked: capacity as u64,
            });
        }
        let vb = capacity as u64 * 4;
        let hist_len = 16 * blocks.max(1);
        Ok(SortBuffers {
            keys: [
                gpu.buffer(&format!("{name} keys A"), kb)?,
                gpu.buffer(&format!("{name} keys B"), kb)?,
            ],
            vals: [
                gpu.buffer(&format!("{name} values A"), vb)?,
                gpu.buffer(&format!("{name} values B"), vb)?,
            ],
            width,
            capacity,
            hist: gpu.buffer(&format!("{name} digit histogram"), hist_len as u64 * 4)?,
            meta: gpu.buffer(&format!("{name} meta"), META_HIST_LEN + 16)?,
            count: gpu.buffer(&format!("{name} count"), 16)?,
            scan: self.scan.scratch(gpu, hist_len)?,
        })
    }

    /// Sorts the first `count` pairs of (`b.keys[0]`, `b.vals[0]`) by the low `bits` bits of the
    /// key, stably (higher key bits are ignored). Returns the index (0 or 1) of the pair of
    /// buffers that holds the result: `passes(bits)` is odd → 1.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        b: &SortBuffers,
        count: Count<'_>,
        bits: u32,
    ) -> usize {
        self.record_bits(rec, b, count, 0, bits)
    }

    /// As [`record`](Self::record) over the key bits `[lo, bits)` only (`lo` a multiple of
    /// `RADIX_BITS`): for pairs already in order by the bits below `lo` (the depth-first
    /// binning sorts only the tile bits of keys emitted in depth order). `passes(bits - lo)`
    /// odd → 1.
    pub fn record_bits(
        &self,
        rec: &mut Recorder<'_>,
        b: &SortBuffers,
        count: Count<'_>,
        lo: u32,
        bits: u32,
    ) -> usize {
        assert!(
            lo % RADIX_BITS == 0 && lo <= bits,
            "sort of bits [{lo}, {bits})"
        );
        assert!(
            bits <= b.width.bits(),
            "sort of {bits} bits with {:?} keys",
            b.width
        );
        if let Count::Host(n) = count {
            assert!(
                n <= b.capacity,
                "sort of {n} keys exceeds the capacity {}",
                b.capacity
            );
        }
        let count = count.to_gpu(rec, b.count.slice(0, 4));
        let w = (b.width == KeyWidth::U64) as usize;
        let pc = |shift: u32| {
            let left = bits - shift;
            let digit_mask = if left >= RADIX_BITS {
                15
            } else {
                (1 << left) - 1
            };
            SortParams {
                capacity: b.capacity,
                shift,
                digit_mask,
                block_keys: self.shape.block_keys(),
                group_blocks: self.shape.group_blocks(),
                pad: 0,
            }
        };
        rec.dispatch(&self.setup, &pc(0), &[count, b.meta.all()], [1, 1, 1]);
        let args = b.meta.slice(16, 12);
        let hist_len = b.meta.slice(META_HIST_LEN, 4);
        for p in 0..passes(bits - lo) {
            let (src, dst) = ((p % 2) as usize, ((p + 1) % 2) as usize);
            let pc = pc(lo + p * RADIX_BITS);
            rec.dispatch_indirect(
                &self.hist[w],
                &pc,
                &[b.meta.all(), b.keys[src].all(), b.hist.all()],
                args,
            );
            self.scan.record(
                rec,
                &b.scan,
                b.hist.all(),
                b.hist.all(),
                Count::Gpu(hist_len),
            );
            rec.dispatch_indirect(
                &self.scatter[w],
                &pc,
                &[
                    b.meta.all(),
                    b.keys[src].all(),
                    b.vals[src].all(),
                    b.hist.all(),
                    b.keys[dst].all(),
                    b.vals[dst].all(),
                ],
                args,
            );
        }
        (passes(bits - lo) % 2) as usize
    }
}
