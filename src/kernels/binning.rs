//! How the rasteriser orders tile intersections ([`Binning`]): two shapes that write the same
//! (tile | depth) keys, the same Gaussian-id list and the same per-tile ranges, bit for bit
//! (tests/raster_binning.rs). Both live in `raster.rs` (they share its buffers and end in the
//! same `bin_ranges`); this file holds the choice and the depth-first path's stages.
//!
//! Radix: `bin_emit` writes one key per intersection in Gaussian order, and one stable radix
//! sort orders all `32 + tile_bits` bits (8 + `tile_bits / 4` digit passes over every
//! intersection). Depth first: the N Gaussians are sorted by their depth bits alone (u32 keys,
//! 8 passes over N; stable, so equal depths keep index order), `bin_depth_counts` and a prefix
//! sum place each Gaussian's intersections in depth order, `bin_emit_depth` writes the same
//! keys there, and a stable sort of the tile bits alone (`tile_bits / 4` passes over the
//! intersections) finishes the order the radix path reaches: by tile, then depth, then index.
//! Cheaper where the digit passes over every intersection dominate (CPU devices).
//!
//! Every serial loop stays bounded by a block (lavapipe's compiled loops stop after 65 535
//! iterations per invocation: a per-band walk over all N Gaussians, tried first, dropped
//! entries beyond that silently).

use bytemuck::{Pod, Zeroable};

use super::radix_sort::{KeyWidth, RadixSort, SortBuffers};
use super::shape::DeviceShape;
use crate::error::Result;
use crate::shaders;
use crate::vk::{Buffer, ComputePipeline, Gpu};

/// Mirrors `BinParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct BinParams {
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub num_gaussians: u32,
    pub isect_capacity: u32,
}

/// The rasteriser's binning shape. Both write the same keys, ids and ranges.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Binning {
    /// One radix sort of every intersection's (tile | depth) key.
    Radix,
    /// A depth sort of the Gaussians, then a sort of the intersections' tile bits only.
    DepthFirst,
}

impl Binning {
    pub const ALL: [Binning; 2] = [Binning::Radix, Binning::DepthFirst];
}

/// Depth first on CPU devices (the tile sort was ≈40 % of a lavapipe forward, issue 60), the
/// radix path on GPUs (not measured there). `DISPFLOW_BINNING=radix|depth-first` overrides it.
impl DeviceShape for Binning {
    const ENV: &'static str = "DISPFLOW_BINNING";
    const ALL: &'static [Self] = &Binning::ALL;
    const CPU: Self = Binning::DepthFirst;
    const GPU: Self = Binning::Radix;

    fn name(self) -> &'static str {
        match self {
            Binning::Radix => "radix",
            Binning::DepthFirst => "depth-first",
        }
    }
}

/// The depth-first path's own stages.
pub struct DepthFirst {
    /// Depth bits and index per Gaussian (`bin_depth_keys`).
    pub(crate) keys: ComputePipeline,
    /// Tile counts gathered into depth order (`bin_depth_counts`).
    pub(crate) counts: ComputePipeline,
    /// `bin_emit` in depth order (`bin_emit_depth`).
    pub(crate) emit: ComputePipeline,
}

/// The depth-first path's scratch for `max_gaussians` Gaussians (the intersections use the
/// radix path's buffers).
pub struct DepthFirstBuffers {
    /// Depth keys and Gaussian ids, u32, capacity `max_gaussians`.
    pub(crate) sort: SortBuffers,
    /// [N] tile counts in depth order.
    pub(crate) counts: Buffer,
}

impl DepthFirst {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        use shaders::raster as r;
        Ok(DepthFirst {
            keys: gpu.pipeline(&r::BIN_DEPTH_KEYS)?,
            counts: gpu.pipeline(&r::BIN_DEPTH_COUNTS)?,
            emit: gpu.pipeline(&r::BIN_EMIT_DEPTH)?,
        })
    }

    pub fn buffers(
        &self,
        gpu: &Gpu,
        sort: &RadixSort,
        max_gaussians: u32,
    ) -> Result<DepthFirstBuffers> {
        let n = max_gaussians.max(1);
        Ok(DepthFirstBuffers {
            sort: sort.buffers(gpu, "raster depth order", n, KeyWidth::U32)?,
            counts: gpu.buffer("raster tile counts by depth", n as u64 * 4)?,
        })
    }
}
