//! How the rasteriser turns tile rectangles into the per-tile lists of Gaussian ids the blends
//! read (`ranges` and the id list), in one of two shapes ([`Binning`]) that write the same
//! lists bit for bit (tests/raster_binning.rs).
//!
//! The radix path (in `raster.rs`): one (tile | depth) key per intersection, emitted in
//! Gaussian order, radix-sorted over `32 + tile_bits` bits, then `bin_ranges`. The depth-first
//! path (here, `glsl/raster/bin_depth_keys.comp`, `bin_tile_count.comp`,
//! `bin_tile_scatter.comp`): the N Gaussians sorted by depth alone (a u32 stable radix sort,
//! so equal depths stay in index order), Gaussians per tile, and a serial per-tile scatter in
//! depth order (a stable counting sort by tile). N ≪ intersections, and 8 digit passes over N
//! replace 11–12 over all intersections. No CPU twin of its own: it is tested to equal the
//! radix path, whose stages have theirs.

use bytemuck::{Pod, Zeroable};

use super::radix_sort::{KeyWidth, RadixSort, SortBuffers};
use super::scan::Count;
use super::shape::DeviceShape;
use crate::error::Result;
use crate::shaders;
use crate::vk::{BufSlice, Buffer, ComputePipeline, Gpu, Recorder};

/// Mirrors `BinParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct BinParams {
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub num_gaussians: u32,
    pub isect_capacity: u32,
    /// Tile rows per band (one serial invocation each).
    pub band_rows: u32,
    pub bands: u32,
    pub pad0: u32,
    pub pad1: u32,
}

/// Most bands: the serial passes' parallelism. Each band walks every tile rectangle, so more
/// bands cost more reads; 8 keeps two lavapipe threads busy despite uneven bands.
pub const MAX_BANDS: u32 = 8;

/// The rasteriser's binning shape. Both write the same ranges and the same id list.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Binning {
    /// (tile | depth) keys per intersection, one radix sort of them (GPU-shaped: wide, no
    /// serial pass).
    Radix,
    /// Depth sort of the Gaussians, per-tile counts, a serial scatter per band of tile rows
    /// (CPU-shaped).
    DepthFirst,
}

impl Binning {
    pub const ALL: [Binning; 2] = [Binning::Radix, Binning::DepthFirst];
}

/// Depth first on CPU devices (the tile sort was ≈40 % of a lavapipe forward, issue 60), the
/// radix path on GPUs. `DISPFLOW_BINNING=radix|depth-first` overrides the choice.
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

/// The depth-first path's pipelines.
pub struct DepthFirst {
    keys: ComputePipeline,
    count: ComputePipeline,
    scatter: ComputePipeline,
}

/// The depth-first path's scratch for `max_gaussians` Gaussians and `tiles` tiles.
pub struct DepthFirstBuffers {
    /// Depth keys and Gaussian ids, u32, capacity `max_gaussians`.
    sort: SortBuffers,
    /// [tiles] counts, then each tile's next free slot.
    tile_next: Buffer,
    /// [MAX_BANDS] intersections per band.
    band_sums: Buffer,
}

/// What the depth-first path reads and writes of the rasteriser's buffers: `splats` [N, 3]
/// vec4 and `rects` [N] uvec4 (from `project`), `ranges` [T] uvec2, `ids` [capacity] and
/// `meta` (`bin_total`'s layout).
pub struct BinIo<'a> {
    pub splats: BufSlice<'a>,
    pub rects: BufSlice<'a>,
    pub ranges: BufSlice<'a>,
    pub ids: BufSlice<'a>,
    pub meta: BufSlice<'a>,
}

impl DepthFirst {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        use shaders::raster as r;
        Ok(DepthFirst {
            keys: gpu.pipeline(&r::BIN_DEPTH_KEYS)?,
            count: gpu.pipeline(&r::BIN_TILE_COUNT)?,
            scatter: gpu.pipeline(&r::BIN_TILE_SCATTER)?,
        })
    }

    pub fn buffers(
        &self,
        gpu: &Gpu,
        sort: &RadixSort,
        max_gaussians: u32,
        tiles: u64,
    ) -> Result<DepthFirstBuffers> {
        Ok(DepthFirstBuffers {
            sort: sort.buffers(
                gpu,
                "raster depth order",
                max_gaussians.max(1),
                KeyWidth::U32,
            )?,
            tile_next: gpu.buffer("raster tile cursors", tiles.max(1) * 4)?,
            band_sums: gpu.buffer("raster band sums", MAX_BANDS as u64 * 4)?,
        })
    }

    /// The parameters for `n` Gaussians on a `tiles_x`×`tiles_y` grid.
    pub fn params(tiles_x: u32, tiles_y: u32, n: u32, isect_capacity: u32) -> BinParams {
        let band_rows = tiles_y.div_ceil(MAX_BANDS).max(1);
        BinParams {
            tiles_x,
            tiles_y,
            num_gaussians: n,
            isect_capacity,
            band_rows,
            bands: tiles_y.div_ceil(band_rows).max(1),
            ..Default::default()
        }
    }

    /// Records the binning of `p.num_gaussians` projected Gaussians into `io.ranges` and
    /// `io.ids` (and the totals into `io.meta`), sorting with `sort`.
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        sort: &RadixSort,
        b: &DepthFirstBuffers,
        p: &BinParams,
        io: &BinIo<'_>,
    ) {
        debug_assert!(p.bands <= MAX_BANDS && p.bands * p.band_rows >= p.tiles_y);
        debug_assert!(p.num_gaussians <= b.sort.capacity());
        rec.dispatch_rows(
            &self.keys,
            p,
            &[io.splats, b.sort.keys[0].all(), b.sort.vals[0].all()],
            p.num_gaussians,
        );
        let out = sort.record(rec, &b.sort, Count::Host(p.num_gaussians), 32);
        rec.dispatch(
            &self.count,
            p,
            &[io.rects, b.tile_next.all(), b.band_sums.all()],
            [p.bands, 1, 1],
        );
        rec.dispatch(
            &self.scatter,
            p,
            &[
                io.rects,
                b.sort.vals[out].all(),
                b.band_sums.all(),
                b.tile_next.all(),
                io.ranges,
                io.ids,
                io.meta,
            ],
            [p.bands, 1, 1],
        );
    }
}
