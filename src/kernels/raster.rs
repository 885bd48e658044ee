//! The differentiable tile rasteriser (`glsl/raster/*.comp`). CPU twin: `reference::raster`.
//! Over 600 lines: forward, backward and the overflow re-run share one buffer set and its
//! capacity contract; split, each part would restate which pass fills which buffer.
//!
//! Forward: `project` → binning, one of `Binning` (radix: scan of tiles touched → `bin_total`
//! → `bin_emit` ((tile | depth) keys) → radix sort (only `32 + tile_bits` bits); depth first:
//! depth sort of the Gaussians → `bin_depth_counts` → scan → `bin_total` → `bin_emit_depth` →
//! radix sort of the tile bits; both → `bin_ranges`) → `blend_fwd` (one of `BlendFwdVariant`).
//! Backward: `blend_bwd` (accumulates per-splat 2D gradients; one of `BlendBwdVariant`) →
//! `project_bwd`.
//! Nothing is read back inside a pass; the intersection count drives the sort and the range
//! pass on the GPU. Overflow of the intersection capacity is detected after the submit
//! (`RasterBuffers::intersections`) and `render_checked` re-runs with grown buffers, so a splat
//! is never dropped silently.
//!
//! Over 600 lines: one wrapper for the whole rasteriser family (sizes, buffers, forward,
//! backward, the grow policy), because the passes share buffers and sort layout.

use bytemuck::{Pod, Zeroable};

pub use super::binning::Binning;
use super::binning::{BinParams, DepthFirst, DepthFirstBuffers};
use super::radix_sort::{passes, KeyWidth, RadixSort, SortBuffers};
use super::scan::{Count, PrefixSum, ScanScratch};
pub use super::shape::{Access, DeviceShape};
use crate::error::{Error, Result};
use crate::shaders;
use crate::vk::{BufSlice, Buffer, ComputePipeline, Gpu, Recorder};

/// Tile edge in pixels (mirrors `TILE` in glsl/include/raster.glsl).
pub const TILE: u32 = 16;
/// vec4s per splat record (mirrors `SPLAT_STRIDE`).
pub const SPLAT_STRIDE: u64 = 3;
/// Floats per 2D gradient record (mirrors `G2D_STRIDE`): mean2d 2, conic 3, opacity 1,
/// colour 3, depth 1, Σ|∂L/∂mean2d| 2 (`RenderOpts::abs_grad`), the feature channels' share of
/// the opacity gradient 1 (`RenderOpts::detach_feature_weights`).
pub const G2D_STRIDE: u64 = 13;
/// Feature-channel counts with a compiled blend variant (0: none, 2: a 2D field, 3:
/// displacement flow, 6: Gaussian flow's affine channels, see `kernels::gflow`).
pub const FEATURE_DIMS: [u32; 4] = [0, 2, 3, 6];

/// Pinhole camera with principal point; world-to-camera `p_cam = rot · p + trans`, OpenCV axes
/// (x right, y down, z forward). Pixel centres at (x + 0.5, y + 0.5).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub rot: [[f32; 3]; 3],
    pub trans: [f32; 3],
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub width: u32,
    pub height: u32,
    pub near: f32,
}

impl Camera {
    /// Tiles per row and per column, `ceil(W/16)`, `ceil(H/16)`.
    pub fn tiles(&self) -> (u32, u32) {
        (self.width.div_ceil(TILE), self.height.div_ceil(TILE))
    }

    /// Camera centre in world coordinates, `−rotᵀ · trans`.
    pub fn centre(&self) -> [f64; 3] {
        let mut c = [0.0; 3];
        for (j, cj) in c.iter_mut().enumerate() {
            for i in 0..3 {
                *cj -= self.rot[i][j] as f64 * self.trans[i] as f64;
            }
        }
        c
    }
}

/// Splits SH coefficients stored as [N, K, 3] into the DC band [N, 3] and the rest
/// [N, K − 1, 3], the layout the rasteriser reads.
pub fn split_sh(sh: &[f32], coeffs: usize) -> (Vec<f32>, Vec<f32>) {
    let (mut dc, mut rest) = (Vec::new(), Vec::new());
    for g in sh.chunks_exact(3 * coeffs) {
        dc.extend_from_slice(&g[..3]);
        rest.extend_from_slice(&g[3..]);
    }
    (dc, rest)
}

/// Inverse of [`split_sh`].
pub fn join_sh(dc: &[f32], rest: &[f32], coeffs: usize) -> Vec<f32> {
    let r = 3 * (coeffs - 1);
    dc.chunks_exact(3)
        .enumerate()
        .flat_map(|(i, d)| {
            d.iter()
                .chain(&rest[i * r..(i + 1) * r])
                .copied()
                .collect::<Vec<_>>()
        })
        .collect()
}

/// Mirrors `ProjectParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct ProjectParams {
    pub rot0: [f32; 4],
    pub rot1: [f32; 4],
    pub rot2: [f32; 4],
    pub trans_near: [f32; 4],
    pub intrinsics: [f32; 4],
    pub width: u32,
    pub height: u32,
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub num_gaussians: u32,
    pub sh_coeffs: u32,
    pub sh_degree: u32,
    pub isect_capacity: u32,
    /// 1: each opacity is multiplied by `SplatInputs::opacity_scale` (bound at 9 / 13).
    pub opacity_scale: u32,
    /// 1: `d_op_scale` leaves out the feature channels' share of the opacity gradient.
    pub feat_detach: u32,
    /// `SplatExtent` as a number: 0 the 3σ square, 1 the opacity-aware box.
    pub splat_extent: u32,
    pub pad2: u32,
}

/// Mirrors `BlendParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct BlendParams {
    pub background: [f32; 4],
    pub width: u32,
    pub height: u32,
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub alpha_max: f32,
    pub num_gaussians: u32,
    pub abs_grad: u32,
    /// 1: the backward also accumulates the feature channels' share of slot 5 into slot 12.
    pub feat_op: u32,
    /// Which tiles a CPU-shaped blend kernel draws (`blend_pick.glsl`): 0 every tile, 1 those
    /// the band kernel takes, 2 the others (the whole-tile kernel of the same pass).
    pub pick: u32,
    /// The longest list the band kernels walk ([`BAND_LIST_MAX`]).
    pub band_list_max: u32,
    /// The bands take a tile when its sampled splats reach at most this many eighths of a
    /// 4-row band each on average ([`BAND_COVER_MAX`]; 32: every short list).
    pub band_cover_max: u32,
    /// The picked backward's cost model ([`PickCosts`]), in eighths of one pixel evaluation.
    pub pick_band_splat: u32,
    pub pick_band_step: u32,
    pub pick_whole_splat: u32,
    pub pad0: u32,
    pub pad1: u32,
}

/// The cost model of the picked blend backward ([`BlendBwdVariant::TilePicked`],
/// `blend_bwd_pick.comp`), in eighths of one pixel evaluation per lane: a band kernel pays
/// `band_splat` for each splat that reaches its rows (8 pixels per lane and one fold) and
/// `band_step` for each splat it walks; the whole-tile kernel pays `whole_splat` for each
/// splat of its walk (32 pixels per lane and one fold). A tile goes to the cheaper.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PickCosts {
    pub band_splat: u32,
    pub band_step: u32,
    pub whole_splat: u32,
}

/// The default, fitted on lavapipe to the difference between the two kernels' times over
/// 14 measured scene states (docs/measurements.md, "The blend backward picks per tile"): a
/// splat of a band's walk costs about a sixth of one it evaluates, one of the whole tile's
/// about 2.4 of them.
pub const PICK_COSTS: PickCosts = PickCosts {
    band_splat: 88,
    band_step: 14,
    whole_splat: 213,
};

/// The longest tile list the band blends walk: each splat of a list costs them up to two loop
/// iterations (the step-over loop's and the walk's), and lavapipe ends an invocation's loops
/// after 65 535 iterations in all; a longer list goes to the whole-tile kernel of the same
/// pass (`blend_*_tile.glsl`, one iteration per splat), dispatched after it.
pub const BAND_LIST_MAX: u32 = 32_000;

/// The default of `BlendParams::band_cover_max`: 32, every list of at most [`BAND_LIST_MAX`]
/// splats stays in bands. A lower value sends the tiles whose splats reach more than that many
/// eighths of the tile's four bands each, on average, to the whole-tile kernel (there the bands
/// walk the list four times and, backward, fold most splats four times). Measured on lavapipe
/// (docs/measurements.md, "Bands or whole tiles, per tile"): 16 wins back the whole tiles'
/// speed on the initial points but loses 10–20 % on trained models, whose bands stop early
/// where their own pixels saturate, which the cover does not see; so the pick is a knob,
/// `DISPFLOW_BAND_COVER` (0–32).
pub const BAND_COVER_MAX: u32 = 32;

/// `DISPFLOW_BAND_COVER`'s value, else [`BAND_COVER_MAX`]. A value that is not a number in
/// 0–32 is reported on stderr (a typo must not pass as a measurement of the pick it meant), as
/// the shape variables are (`shape::for_device`), and the default stands.
fn band_cover_max() -> u32 {
    let Ok(v) = std::env::var("DISPFLOW_BAND_COVER") else {
        return BAND_COVER_MAX;
    };
    match v.trim().parse::<u32>() {
        Ok(c) if c <= 32 => c,
        _ => {
            eprintln!(
                "warning: DISPFLOW_BAND_COVER={v} is not a number in 0-32; using {BAND_COVER_MAX}"
            );
            BAND_COVER_MAX
        }
    }
}

/// Blend options.
#[derive(Clone, Copy, Debug)]
pub struct RenderOpts {
    pub background: [f32; 3],
    /// α clamp: 0.99 as in 3DGS; gsplat uses 0.999.
    pub alpha_max: f32,
    /// The backward also accumulates Σ_pixels |∂L/∂mean2d| per component into `grad2d`'s
    /// slots 10-11 (the official Deformable-3DGS rasteriser's densification statistic).
    pub abs_grad: bool,
    /// The opacity factors (`SplatInputs::opacity_scale`) are held constant in the blend of the
    /// feature channels: `d_op_scale` gets only the rgb, alpha and depth outputs' gradient,
    /// while the logits and the 2D geometry keep every output's. The transients' temporal
    /// weights detached in the motion pass (`[transient] motion_weights`). Costs one more
    /// atomic per splat and tile in the blend backward.
    pub detach_feature_weights: bool,
}

impl Default for RenderOpts {
    fn default() -> Self {
        RenderOpts {
            background: [0.0; 3],
            alpha_max: 0.99,
            abs_grad: false,
            detach_feature_weights: false,
        }
    }
}

/// The Gaussians to render, already deformed: `means` [N,3], `scales` [N,3] (linear),
/// `quats` [N,4] (w, x, y, z; unnormalised), `opacity_logits` [N], SH coefficients split in
/// `sh_dc` [N,3] and `sh_rest` [N, sh_coeffs − 1, 3] (separate learning rates; `sh_rest` is
/// not read when `sh_coeffs` is 1), and optionally `features` ([N, K] with its K, one of
/// `FEATURE_DIMS` up to the buffers' `feature_dims`) blended with the same weights. Without
/// features the plain blend variant runs: the extra channels cost nothing.
#[derive(Clone, Copy, Debug)]
pub struct SplatInputs<'a> {
    pub n: u32,
    pub means: BufSlice<'a>,
    pub scales: BufSlice<'a>,
    pub quats: BufSlice<'a>,
    pub opacity_logits: BufSlice<'a>,
    pub sh_dc: BufSlice<'a>,
    pub sh_rest: BufSlice<'a>,
    pub sh_coeffs: u32,
    pub sh_degree: u32,
    pub features: Option<(BufSlice<'a>, u32)>,
    /// [N] factors each opacity is multiplied by (0 culls the Gaussian before projection):
    /// the transients' temporal weights. `None`: 1.
    pub opacity_scale: Option<BufSlice<'a>>,
}

impl SplatInputs<'_> {
    /// Feature channels blended by this pass (0 without features).
    pub fn feature_dims(&self) -> u32 {
        self.features.map_or(0, |f| f.1)
    }
}

/// Upstream gradients of the forward outputs: `rgba` [H·W,4], `depth` [H·W] (`None`: the
/// loss does not read depth), `features` [H·W, feature_dims].
#[derive(Clone, Copy, Debug)]
pub struct OutputGrads<'a> {
    pub rgba: BufSlice<'a>,
    pub depth: Option<BufSlice<'a>>,
    pub features: Option<BufSlice<'a>>,
}

/// What `RasterBuffers` are sized for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RasterSize {
    pub max_gaussians: u32,
    pub width: u32,
    pub height: u32,
    /// SH coefficients stored per Gaussian: 1, 4, 9 or 16.
    pub sh_coeffs: u32,
    /// Extra blended channels: one of `FEATURE_DIMS`.
    pub feature_dims: u32,
    /// Tile intersections (first guess; grown on overflow).
    pub isect_capacity: u32,
}

/// Every buffer the rasteriser needs for `max_gaussians` splats at one image size, allocated
/// once. Outputs (`out_*`) and gradients (`d_*`) are public for the caller to read or chain.
pub struct RasterBuffers {
    pub max_gaussians: u32,
    pub width: u32,
    pub height: u32,
    pub feature_dims: u32,
    pub sh_coeffs: u32,
    isect_capacity: u32,
    pub splats: Buffer,
    rects: Buffer,
    counts: Buffer,
    offsets: Buffer,
    meta: Buffer,
    scan: ScanScratch,
    sort: SortBuffers,
    depth_first: DepthFirstBuffers,
    ranges: Buffer,
    /// [tiles] u32: 1 where the picked blend backward gives the tile to the bands.
    band_pick: Buffer,
    /// [H·W] vec4: rgb (background included) and alpha = 1 − T.
    pub out_rgba: Buffer,
    /// [H·W] Σ w_i z_i (not normalised by alpha).
    pub out_depth: Buffer,
    pub final_t: Buffer,
    pub n_contrib: Buffer,
    /// [H·W, feature_dims]
    pub out_features: Buffer,
    /// [N, G2D_STRIDE] per-splat 2D gradients (see `G2D_STRIDE`), accumulated by blend_bwd.
    pub grad2d: Buffer,
    /// [N, feature_dims]
    pub d_features: Buffer,
    pub d_means: Buffer,
    pub d_scales: Buffer,
    pub d_quats: Buffer,
    pub d_opacity_logits: Buffer,
    /// [N] ∂L/∂(opacity factor) when the splats had `opacity_scale`.
    pub d_op_scale: Buffer,
    pub d_sh_dc: Buffer,
    /// [N, sh_coeffs − 1, 3]
    pub d_sh_rest: Buffer,
    /// Zeros [H·W], bound as the depth gradient when the caller has none. (A blend_bwd variant
    /// without the depth term would let the compiler drop it and re-associate the α gradient:
    /// kept as a zero input so every caller runs the same arithmetic.)
    no_depth_grad: Buffer,
}

impl RasterBuffers {
    pub fn isect_capacity(&self) -> u32 {
        self.isect_capacity
    }

    pub fn size(&self) -> RasterSize {
        RasterSize {
            max_gaussians: self.max_gaussians,
            width: self.width,
            height: self.height,
            sh_coeffs: self.sh_coeffs,
            feature_dims: self.feature_dims,
            isect_capacity: self.isect_capacity,
        }
    }

    /// Tile intersections the last forward pass needed (read after its submit). Larger than
    /// `isect_capacity()` means the pass overflowed and must be re-run with grown buffers.
    pub fn intersections(&self, gpu: &Gpu) -> Result<u32> {
        Ok(gpu.read::<u32>(self.meta.elems::<u32>(1, 1))?[0])
    }

    /// The tile rectangles `[x0, y0, x1, y1)` of the last forward's first `n` splats (tests).
    pub fn tile_rects(&self, gpu: &Gpu, n: u32) -> Result<Vec<[u32; 4]>> {
        gpu.read(self.rects.elems::<[u32; 4]>(0, n as u64))
    }

    /// Per tile `[start, end)` in the intersection list of the last forward ((0, 0) for a tile
    /// without entries; tests).
    pub fn tile_ranges(&self, gpu: &Gpu) -> Result<Vec<[u32; 2]>> {
        let (tx, ty) = (self.width.div_ceil(TILE), self.height.div_ceil(TILE));
        gpu.read(self.ranges.elems::<[u32; 2]>(0, tx as u64 * ty as u64))
    }

    /// The Gaussian id of every tile intersection of the last forward, tile by tile, front to
    /// back (what the blends walk; tests). Read after its submit; at most the capacity.
    pub fn intersection_ids(&self, gpu: &Gpu) -> Result<Vec<u32>> {
        let m = self.intersections(gpu)?.min(self.isect_capacity);
        let out = isect_out(self.width, self.height);
        gpu.read(self.sort.vals[out].elems::<u32>(0, m as u64))
    }

    /// Per tile, whether the last picked blend backward gave it to the bands (1) or the whole
    /// tile (0) (tests).
    pub fn band_picks(&self, gpu: &Gpu) -> Result<Vec<u32>> {
        let (tx, ty) = (self.width.div_ceil(TILE), self.height.div_ceil(TILE));
        gpu.read(self.band_pick.elems::<u32>(0, tx as u64 * ty as u64))
    }

    /// The overflow word of the last forward (bits `OVERFLOW_*`: non-zero when its render must
    /// not be used), followed by the intersections needed: bind it as an optimiser's skip
    /// flag, or copy it out.
    pub fn overflow_flag(&self) -> BufSlice<'_> {
        self.meta.slice(256, 8)
    }

    /// The overflow pair of the last forward, read after its submit.
    pub fn overflow(&self, gpu: &Gpu) -> Result<Overflow> {
        let w = gpu.read::<u32>(self.meta.elems::<u32>(64, 2))?;
        Overflow::from_words(w[0], w[1], "render")
    }
}

/// Bits of the overflow word (`meta[64]`; glsl/include/raster.glsl): the tile intersections
/// overflowed their capacity (grow and re-run), and a blend's walk of a tile was cut by the
/// device's loop budget (an error: nothing to grow).
pub const OVERFLOW_CAPACITY: u32 = 1;
pub const OVERFLOW_WALK_CUT: u32 = 2;

/// One render's overflow after a submit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Overflow {
    /// The intersections overflowed: grow to `needed` and re-run.
    pub overflowed: bool,
    pub needed: u32,
}

impl Overflow {
    /// From the overflow word and the needed count; a cut walk is [`Error::TileWalkCut`]
    /// naming `what` rendered.
    pub fn from_words(word: u32, needed: u32, what: &str) -> Result<Overflow> {
        if word & OVERFLOW_WALK_CUT != 0 {
            return Err(Error::TileWalkCut {
                what: what.to_string(),
            });
        }
        Ok(Overflow {
            overflowed: word & OVERFLOW_CAPACITY != 0,
            needed,
        })
    }
}

fn sort_bits(width: u32, height: u32) -> u32 {
    let tiles = (width.div_ceil(TILE) * height.div_ceil(TILE)).max(2);
    32 + (32 - (tiles - 1).leading_zeros())
}

/// Which of `sort.keys`/`sort.vals` holds the sorted intersections the blends read: both
/// binnings end in the same buffer (the depth-first tile sort runs a whole number of digit
/// passes fewer), so the backward needs no binning choice.
fn isect_out(width: u32, height: u32) -> usize {
    (passes(sort_bits(width, height)) % 2) as usize
}

/// How `blend_bwd` folds per-pixel gradient terms into per-splat sums. All variants compute
/// the same sums (up to float summation order; tests compare every variant with the twin);
/// they differ in speed per device. Discriminants index `Rasterizer::blend_bwd`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BlendBwdVariant {
    /// 16×16 invocations per tile, splats staged in shared memory; per splat, one subgroupAdd
    /// and one float atomic per subgroup and component (`blend_bwd.glsl`). GPU-shaped.
    SubgroupAtomic,
    /// 8 invocations per tile, 32 pixels each; per splat, the terms are summed over the whole
    /// tile and added with one atomic per component (`blend_bwd_tile.glsl`). CPU-shaped.
    TileAccum,
    /// 32 invocations per tile, 8 pixels each, one subgroup per band of rows stepping over the
    /// splats that miss its rows; per splat, the terms are summed over the band
    /// (`blend_bwd_band_f*.comp`: `blend_bwd_tile.glsl` with `STEP_OVER`). CPU-shaped.
    TileBands,
    /// `TileBands` and `TileAccum` sharing the tiles by a pass that reads the forward's
    /// stopping points (`blend_bwd_pick.comp`, [`PickCosts`]): a tile goes to the bands when
    /// their walks and folds cost less than the whole tile's. CPU-shaped.
    TilePicked,
}

impl BlendBwdVariant {
    pub const ALL: [BlendBwdVariant; 4] = [
        BlendBwdVariant::SubgroupAtomic,
        BlendBwdVariant::TileAccum,
        BlendBwdVariant::TileBands,
        BlendBwdVariant::TilePicked,
    ];

    /// The pipelines (indices of `Rasterizer::blend_bwd`) and picks a pass dispatches: the
    /// variant's kernel over every tile, or the band kernel and the whole-tile kernel over the
    /// tiles each takes (`blend_pick.glsl`: `BlendParams::pick`).
    fn dispatches(self) -> &'static [(usize, u32)] {
        match self {
            BlendBwdVariant::SubgroupAtomic => &[(0, 0)],
            BlendBwdVariant::TileAccum => &[(1, 0)],
            BlendBwdVariant::TileBands => &[(2, 1), (1, 2)],
            BlendBwdVariant::TilePicked => &[(2, 3), (1, 4)],
        }
    }
}

/// The default for a device: the per-tile accumulation on CPU devices since its walk loads
/// its splats in batches (stop 74: 2.1× the picked bands on `bench --suite raster`'s
/// D-NeRF-like scene, docs/measurements.md, "Batched splat loads"; before that the bands
/// and the per-tile pick led, "Blends in bands", "The backward picks per tile"); the subgroup
/// kernel on GPUs, where a few invocations per tile leave most of a warp idle (the whole
/// CPU-shaped step measured 6.8–7.9× slower on an H200, docs/gpu_h200.md).
/// `DISPFLOW_BLEND_BWD=subgroup-atomic|tile-accum|tile-bands|tile-picked` overrides the choice
/// (benches, tests).
impl DeviceShape for BlendBwdVariant {
    const ENV: &'static str = "DISPFLOW_BLEND_BWD";
    const ALL: &'static [Self] = &BlendBwdVariant::ALL;
    const CPU: Self = BlendBwdVariant::TileAccum;
    const GPU: Self = BlendBwdVariant::SubgroupAtomic;

    fn name(self) -> &'static str {
        match self {
            BlendBwdVariant::SubgroupAtomic => "subgroup-atomic",
            BlendBwdVariant::TileAccum => "tile-accum",
            BlendBwdVariant::TileBands => "tile-bands",
            BlendBwdVariant::TilePicked => "tile-picked",
        }
    }
}

/// How `blend_fwd` walks a tile. Both variants blend each pixel with the same float
/// operations in the same order (tests compare every variant with the twin, and either
/// variant's `final_t`/`n_contrib` feed every `BlendBwdVariant`); they differ in speed per
/// device. Discriminants index `Rasterizer::blend_fwd`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BlendFwdVariant {
    /// 16×16 invocations per tile, one pixel each, splats staged in shared memory in batches
    /// of 256 behind barriers (`blend_fwd.glsl`). GPU-shaped.
    Shared,
    /// 8 invocations per tile, 32 pixels each in registers; splats loaded 8 at a time, one per
    /// lane, and shuffled to the tile; no barriers, no shared memory (`blend_fwd_tile.glsl`).
    /// CPU-shaped.
    TileRegs,
    /// 32 invocations per tile, 8 pixels each in registers, one subgroup per band of rows
    /// stepping over the splats that miss its rows (`blend_fwd_tile.glsl` with `STEP_OVER`).
    /// CPU-shaped.
    TileBands,
}

impl BlendFwdVariant {
    pub const ALL: [BlendFwdVariant; 3] = [
        BlendFwdVariant::Shared,
        BlendFwdVariant::TileRegs,
        BlendFwdVariant::TileBands,
    ];

    /// As [`BlendBwdVariant::dispatches`], for `Rasterizer::blend_fwd`.
    fn dispatches(self) -> &'static [(usize, u32)] {
        match self {
            BlendFwdVariant::Shared => &[(0, 0)],
            BlendFwdVariant::TileRegs => &[(1, 0)],
            BlendFwdVariant::TileBands => &[(2, 1), (1, 2)],
        }
    }
}

/// The default for a device: pixels in registers, whole tiles, on CPU devices since that walk
/// loads its splats in batches (stop 74, lavapipe, `bench --suite raster`: 3.3–3.6× the
/// bands, which load theirs one at a time; docs/measurements.md, "Batched splat loads");
/// the shared-memory kernel on GPUs, where a few invocations per tile
/// leave most of a warp idle (measured on an H200 with the backward: docs/gpu_h200.md).
/// `DISPFLOW_BLEND_FWD=shared|tile-regs|tile-bands` overrides the choice (benches, tests).
impl DeviceShape for BlendFwdVariant {
    const ENV: &'static str = "DISPFLOW_BLEND_FWD";
    const ALL: &'static [Self] = &BlendFwdVariant::ALL;
    const CPU: Self = BlendFwdVariant::TileRegs;
    const GPU: Self = BlendFwdVariant::Shared;

    fn name(self) -> &'static str {
        match self {
            BlendFwdVariant::Shared => "shared",
            BlendFwdVariant::TileRegs => "tile-regs",
            BlendFwdVariant::TileBands => "tile-bands",
        }
    }
}

/// Which tiles `project` bins a splat to, and which bands of a tile the band blends
/// (`TileBands`) evaluate it at. Both give the same images and gradients (the blend
/// draws no pixel outside the opacity-aware box; tests/raster_extent.rs compares them bit for
/// bit); the box gives fewer tile intersections, so less binning, sorting and blending.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SplatExtent {
    /// The square of the 3σ radius around the mean (3DGS); every band of a tile.
    Radius,
    /// The bounding box of the ellipse where α = opacity·exp(−σ) reaches 1/255, capped by the
    /// 3σ square; none for opacity < 1/255 (`opacity_rect` in glsl/include/raster.glsl). The
    /// band blends step over a splat whose box (the splat record's `reach`) misses their rows.
    OpacityBox,
}

impl SplatExtent {
    pub const ALL: [SplatExtent; 2] = [SplatExtent::Radius, SplatExtent::OpacityBox];
}

/// The opacity-aware box on every device (fewer intersections, the same outputs);
/// `DISPFLOW_SPLAT_EXTENT=radius|opacity-box` overrides it (`bench step` runs both).
impl DeviceShape for SplatExtent {
    const ENV: &'static str = "DISPFLOW_SPLAT_EXTENT";
    const ALL: &'static [Self] = &SplatExtent::ALL;
    const CPU: Self = SplatExtent::OpacityBox;
    const GPU: Self = SplatExtent::OpacityBox;

    fn name(self) -> &'static str {
        match self {
            SplatExtent::Radius => "radius",
            SplatExtent::OpacityBox => "opacity-box",
        }
    }
}

/// The whole-tile row of the blend pipelines (`dispatches`' kernel 1) and its texel twin's.
const WHOLE_TILE: usize = 1;
const WHOLE_TILE_TEXEL: usize = 3;

pub struct Rasterizer {
    project: ComputePipeline,
    bin_total: ComputePipeline,
    bin_emit: ComputePipeline,
    bin_ranges: ComputePipeline,
    /// Per variant (its discriminant), per feature count; row 3 is the whole tile (row 1)
    /// reading and writing through texel buffers ([`WHOLE_TILE_TEXEL`]).
    blend_fwd: [[ComputePipeline; 4]; 4],
    blend_fwd_variant: BlendFwdVariant,
    /// Per kernel (`BlendBwdVariant::dispatches`), per feature count; row 3 as in `blend_fwd`.
    blend_bwd: [[ComputePipeline; 4]; 4],
    blend_bwd_variant: BlendBwdVariant,
    /// How the whole-tile blends reach their arrays.
    access: Access,
    blend_bwd_pick: ComputePipeline,
    pick_costs: PickCosts,
    project_bwd: ComputePipeline,
    splat_extent: SplatExtent,
    binning: Binning,
    /// `BlendParams::band_cover_max`, read once.
    band_cover_max: u32,
    depth_first: DepthFirst,
    scan: PrefixSum,
    sort: RadixSort,
}

fn variant(feature_dims: u32) -> Result<usize> {
    FEATURE_DIMS.iter().position(|&k| k == feature_dims).ok_or_else(|| {
        Error::Invalid(format!("feature_dims = {feature_dims}: the blend kernels are compiled for {FEATURE_DIMS:?}"))
    })
}

impl Rasterizer {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        if !gpu.info.subgroup_arithmetic {
            return Err(Error::MissingFeature {
                device: gpu.info.name.clone(),
                feature: "subgroup arithmetic (VK_SUBGROUP_FEATURE_ARITHMETIC_BIT)",
                why: "blend_bwd folds per-pixel gradients with subgroupAdd before its atomics",
            });
        }
        if !gpu.info.subgroup_vote {
            return Err(Error::MissingFeature {
                device: gpu.info.name.clone(),
                feature: "subgroup vote (VK_SUBGROUP_FEATURE_VOTE_BIT)",
                why:
                    "the blend kernels skip finished splats and tiles with subgroupAny/subgroupAll",
            });
        }
        use shaders::raster as r;
        Ok(Rasterizer {
            project: gpu.pipeline(&r::PROJECT)?,
            bin_total: gpu.pipeline(&r::BIN_TOTAL)?,
            bin_emit: gpu.pipeline(&r::BIN_EMIT)?,
            bin_ranges: gpu.pipeline(&r::BIN_RANGES)?,
            blend_fwd: [
                [
                    gpu.pipeline(&r::BLEND_FWD_F0)?,
                    gpu.pipeline(&r::BLEND_FWD_F2)?,
                    gpu.pipeline(&r::BLEND_FWD_F3)?,
                    gpu.pipeline(&r::BLEND_FWD_F6)?,
                ],
                [
                    gpu.pipeline(&r::BLEND_FWD_TILE_F0)?,
                    gpu.pipeline(&r::BLEND_FWD_TILE_F2)?,
                    gpu.pipeline(&r::BLEND_FWD_TILE_F3)?,
                    gpu.pipeline(&r::BLEND_FWD_TILE_F6)?,
                ],
                [
                    gpu.pipeline(&r::BLEND_FWD_BAND_F0)?,
                    gpu.pipeline(&r::BLEND_FWD_BAND_F2)?,
                    gpu.pipeline(&r::BLEND_FWD_BAND_F3)?,
                    gpu.pipeline(&r::BLEND_FWD_BAND_F6)?,
                ],
                [
                    gpu.pipeline(&r::BLEND_FWD_TILE_TEXEL_F0)?,
                    gpu.pipeline(&r::BLEND_FWD_TILE_TEXEL_F2)?,
                    gpu.pipeline(&r::BLEND_FWD_TILE_TEXEL_F3)?,
                    gpu.pipeline(&r::BLEND_FWD_TILE_TEXEL_F6)?,
                ],
            ],
            blend_fwd_variant: BlendFwdVariant::for_device(&gpu.info),
            blend_bwd: [
                [
                    gpu.pipeline(&r::BLEND_BWD_F0)?,
                    gpu.pipeline(&r::BLEND_BWD_F2)?,
                    gpu.pipeline(&r::BLEND_BWD_F3)?,
                    gpu.pipeline(&r::BLEND_BWD_F6)?,
                ],
                [
                    gpu.pipeline(&r::BLEND_BWD_TILE_F0)?,
                    gpu.pipeline(&r::BLEND_BWD_TILE_F2)?,
                    gpu.pipeline(&r::BLEND_BWD_TILE_F3)?,
                    gpu.pipeline(&r::BLEND_BWD_TILE_F6)?,
                ],
                [
                    gpu.pipeline(&r::BLEND_BWD_BAND_F0)?,
                    gpu.pipeline(&r::BLEND_BWD_BAND_F2)?,
                    gpu.pipeline(&r::BLEND_BWD_BAND_F3)?,
                    gpu.pipeline(&r::BLEND_BWD_BAND_F6)?,
                ],
                [
                    gpu.pipeline(&r::BLEND_BWD_TILE_TEXEL_F0)?,
                    gpu.pipeline(&r::BLEND_BWD_TILE_TEXEL_F2)?,
                    gpu.pipeline(&r::BLEND_BWD_TILE_TEXEL_F3)?,
                    gpu.pipeline(&r::BLEND_BWD_TILE_TEXEL_F6)?,
                ],
            ],
            access: Access::for_device(&gpu.info),
            blend_bwd_variant: BlendBwdVariant::for_device(&gpu.info),
            blend_bwd_pick: gpu.pipeline(&r::BLEND_BWD_PICK)?,
            pick_costs: PICK_COSTS,
            project_bwd: gpu.pipeline(&r::PROJECT_BWD)?,
            splat_extent: SplatExtent::for_device(&gpu.info),
            binning: Binning::for_device(&gpu.info),
            band_cover_max: band_cover_max(),
            depth_first: DepthFirst::new(gpu)?,
            scan: PrefixSum::new(gpu)?,
            sort: RadixSort::new(gpu)?,
        })
    }

    /// The blend-forward variant `forward` records.
    pub fn blend_fwd_variant(&self) -> BlendFwdVariant {
        self.blend_fwd_variant
    }

    /// Chooses the blend-forward variant (benches and tests compare them on one device).
    pub fn set_blend_fwd_variant(&mut self, v: BlendFwdVariant) {
        self.blend_fwd_variant = v;
    }

    /// How the whole-tile blends reach their arrays (storage or texel buffers).
    pub fn access(&self) -> Access {
        self.access
    }

    /// Chooses the whole-tile blends' array access (benches and tests compare them).
    pub fn set_access(&mut self, a: Access) {
        self.access = a;
    }

    /// The pipeline row of kernel row `k` of a variant's dispatches: the whole tile's texel
    /// twin when the access is texel.
    fn row(&self, k: usize) -> usize {
        if k == WHOLE_TILE && self.access == Access::Texel {
            WHOLE_TILE_TEXEL
        } else {
            k
        }
    }

    /// The blend-backward variant `backward` records.
    pub fn blend_bwd_variant(&self) -> BlendBwdVariant {
        self.blend_bwd_variant
    }

    /// Chooses the blend-backward variant (benches and tests compare them on one device).
    pub fn set_blend_bwd_variant(&mut self, v: BlendBwdVariant) {
        self.blend_bwd_variant = v;
    }

    /// The tiles `forward` bins each splat to.
    pub fn splat_extent(&self) -> SplatExtent {
        self.splat_extent
    }

    /// Chooses the splat extent (tests and benches compare them on one device).
    pub fn set_splat_extent(&mut self, e: SplatExtent) {
        self.splat_extent = e;
    }

    /// `BlendParams::band_cover_max` of every render ([`BAND_COVER_MAX`] unless
    /// `DISPFLOW_BAND_COVER` says otherwise).
    pub fn band_cover_max(&self) -> u32 {
        self.band_cover_max
    }

    /// Chooses which tiles the band blends hand to the whole-tile kernels (0: every tile goes
    /// whole; 32: every list of at most [`BAND_LIST_MAX`] splats stays in bands). Tests and
    /// benches compare the picks on one device.
    pub fn set_band_cover_max(&mut self, c: u32) {
        self.band_cover_max = c.min(32);
    }

    /// The picked backward's cost model ([`PICK_COSTS`] unless set).
    pub fn pick_costs(&self) -> PickCosts {
        self.pick_costs
    }

    /// Chooses the picked backward's cost model (tests and benches split tiles with it).
    pub fn set_pick_costs(&mut self, c: PickCosts) {
        self.pick_costs = c;
    }

    /// How `forward` bins splats to tiles.
    pub fn binning(&self) -> Binning {
        self.binning
    }

    /// Chooses the binning (tests and benches compare them on one device; buffers serve both).
    pub fn set_binning(&mut self, b: Binning) {
        self.binning = b;
    }

    /// Buffers for `s.max_gaussians` splats on a `s.width`×`s.height` image (grown by
    /// `render_checked` when the intersection capacity is exceeded).
    pub fn buffers(&self, gpu: &Gpu, s: &RasterSize) -> Result<RasterBuffers> {
        let RasterSize {
            max_gaussians,
            width,
            height,
            sh_coeffs,
            feature_dims,
            isect_capacity,
        } = *s;
        variant(feature_dims)?;
        if !matches!(sh_coeffs, 1 | 4 | 9 | 16) {
            return Err(Error::Invalid(format!(
                "sh_coeffs = {sh_coeffs}: expected 1, 4, 9 or 16 (degree 0–3)"
            )));
        }
        let n = max_gaussians.max(1) as u64;
        let px = (width as u64 * height as u64).max(1);
        let tiles = (width.div_ceil(TILE) as u64 * height.div_ceil(TILE) as u64).max(1);
        let k = feature_dims as u64;
        let f = 4u64;
        Ok(RasterBuffers {
            max_gaussians,
            width,
            height,
            feature_dims,
            sh_coeffs,
            isect_capacity: isect_capacity.max(1),
            splats: gpu.buffer("raster splats", n * SPLAT_STRIDE * 16)?,
            rects: gpu.buffer("raster tile rects", n * 16)?,
            counts: gpu.buffer("raster tile counts", n * 4)?,
            offsets: gpu.buffer("raster tile offsets", n * 4)?,
            meta: gpu.buffer("raster bin meta", 512)?,
            scan: self.scan.scratch(gpu, n as u32)?,
            sort: self.sort.buffers(
                gpu,
                "raster intersections",
                isect_capacity.max(1),
                KeyWidth::U64,
            )?,
            depth_first: self.depth_first.buffers(gpu, &self.sort, max_gaussians)?,
            ranges: gpu.buffer("raster tile ranges", tiles * 8)?,
            band_pick: gpu.buffer("raster band picks", tiles * 4)?,
            out_rgba: gpu.buffer("raster out rgba", px * 16)?,
            out_depth: gpu.buffer("raster out depth", px * f)?,
            final_t: gpu.buffer("raster final T", px * f)?,
            n_contrib: gpu.buffer("raster contributors", px * 4)?,
            out_features: gpu.buffer("raster out features", px * k.max(1) * f)?,
            grad2d: gpu.buffer("raster 2D gradients", n * G2D_STRIDE * f)?,
            d_features: gpu.buffer("raster feature gradients", n * k.max(1) * f)?,
            d_means: gpu.buffer("raster d means", n * 3 * f)?,
            d_scales: gpu.buffer("raster d scales", n * 3 * f)?,
            d_quats: gpu.buffer("raster d quats", n * 4 * f)?,
            d_opacity_logits: gpu.buffer("raster d opacity logits", n * f)?,
            d_op_scale: gpu.buffer("raster d opacity factor", n * f)?,
            d_sh_dc: gpu.buffer("raster d sh dc", n * 3 * f)?,
            d_sh_rest: gpu.buffer(
                "raster d sh rest",
                n * (sh_coeffs as u64 - 1).max(1) * 3 * f,
            )?,
            no_depth_grad: gpu.buffer_from("raster zero depth grads", &vec![0f32; px as usize])?,
        })
    }

    fn check(b: &RasterBuffers, cam: &Camera, g: &SplatInputs<'_>) {
        assert!(
            g.n <= b.max_gaussians,
            "{} Gaussians exceed the buffers' {}",
            g.n,
            b.max_gaussians
        );
        assert_eq!(
            (cam.width, cam.height),
            (b.width, b.height),
            "camera size differs from the buffers'"
        );
        assert_eq!(
            g.sh_coeffs, b.sh_coeffs,
            "sh_coeffs differs from the buffers'"
        );
        assert!(
            g.sh_degree <= 3 && (g.sh_degree + 1).pow(2) <= g.sh_coeffs,
            "sh_degree {}",
            g.sh_degree
        );
        assert!(
            g.feature_dims() <= b.feature_dims && FEATURE_DIMS.contains(&g.feature_dims()),
            "{} feature channels with buffers for {}",
            g.feature_dims(),
            b.feature_dims
        );
    }

    fn project_params(
        &self,
        b: &RasterBuffers,
        cam: &Camera,
        g: &SplatInputs<'_>,
    ) -> ProjectParams {
        let (tiles_x, tiles_y) = cam.tiles();
        let row = |r: [f32; 3]| [r[0], r[1], r[2], 0.0];
        ProjectParams {
            rot0: row(cam.rot[0]),
            rot1: row(cam.rot[1]),
            rot2: row(cam.rot[2]),
            trans_near: [cam.trans[0], cam.trans[1], cam.trans[2], cam.near],
            intrinsics: [cam.fx, cam.fy, cam.cx, cam.cy],
            width: cam.width,
            height: cam.height,
            tiles_x,
            tiles_y,
            num_gaussians: g.n,
            sh_coeffs: g.sh_coeffs,
            sh_degree: g.sh_degree,
            isect_capacity: b.isect_capacity,
            opacity_scale: g.opacity_scale.is_some() as u32,
            splat_extent: (self.splat_extent == SplatExtent::OpacityBox) as u32,
            ..Default::default()
        }
    }

    fn blend_params(&self, cam: &Camera, g: &SplatInputs<'_>, o: &RenderOpts) -> BlendParams {
        let (tiles_x, tiles_y) = cam.tiles();
        BlendParams {
            background: [o.background[0], o.background[1], o.background[2], 0.0],
            width: cam.width,
            height: cam.height,
            tiles_x,
            tiles_y,
            alpha_max: o.alpha_max,
            num_gaussians: g.n,
            abs_grad: o.abs_grad as u32,
            feat_op: (o.detach_feature_weights && g.features.is_some()) as u32,
            pick: 0,
            band_list_max: BAND_LIST_MAX,
            band_cover_max: self.band_cover_max,
            pick_band_splat: self.pick_costs.band_splat,
            pick_band_step: self.pick_costs.band_step,
            pick_whole_splat: self.pick_costs.whole_splat,
            pad0: 0,
            pad1: 0,
        }
    }

    /// Records the forward pass into `b.out_*`.
    pub fn forward(
        &self,
        rec: &mut Recorder<'_>,
        b: &RasterBuffers,
        cam: &Camera,
        g: &SplatInputs<'_>,
        o: &RenderOpts,
    ) {
        self.forward_project(rec, b, cam, g);
        self.forward_blend(rec, b, cam, g, o);
    }

    /// The projection of `forward` alone: the splat records `b.splats` (a Gaussian-flow step
    /// needs the projection at t2 without its image, and the features of the render at t1
    /// between its projection and its blend).
    pub fn forward_project(
        &self,
        rec: &mut Recorder<'_>,
        b: &RasterBuffers,
        cam: &Camera,
        g: &SplatInputs<'_>,
    ) {
        Self::check(b, cam, g);
        let pp = self.project_params(b, cam, g);
        rec.dispatch_rows(
            &self.project,
            &pp,
            &[
                g.means,
                g.scales,
                g.quats,
                g.opacity_logits,
                g.sh_dc,
                g.sh_rest,
                b.splats.all(),
                b.rects.all(),
                b.counts.all(),
                // Not read without the flag; bound to keep the layout.
                g.opacity_scale.unwrap_or(g.opacity_logits),
            ],
            g.n,
        );
    }

    /// The rest of `forward` after `forward_project`: binning, sorting and the blend.
    pub fn forward_blend(
        &self,
        rec: &mut Recorder<'_>,
        b: &RasterBuffers,
        cam: &Camera,
        g: &SplatInputs<'_>,
        o: &RenderOpts,
    ) {
        Self::check(b, cam, g);
        // Timed as its own zone (`bench step` compares the binning shapes).
        let outer = rec.set_zone("");
        rec.set_zone(format!("{outer} binning").trim_start());
        match self.binning {
            Binning::Radix => self.bin_radix(rec, b, cam, g),
            Binning::DepthFirst => self.bin_depth_first(rec, b, cam, g),
        }
        rec.set_zone(&outer);
        let out = isect_out(cam.width, cam.height);
        let bp = self.blend_params(cam, g, o);
        let (tx, ty) = cam.tiles();
        let mut binds = vec![
            b.ranges.all(),
            b.sort.vals[out].all(),
            b.splats.all(),
            b.out_rgba.all(),
            b.out_depth.all(),
            b.final_t.all(),
            b.n_contrib.all(),
        ];
        if let Some((f, _)) = g.features {
            binds.extend([f, b.out_features.all()]);
        }
        binds.push(b.meta.slice(256, 4));
        for &(k, pick) in self.blend_fwd_variant.dispatches() {
            rec.dispatch(
                &self.blend_fwd[self.row(k)][variant(g.feature_dims()).unwrap()],
                &BlendParams { pick, ..bp },
                &binds,
                [tx.max(1), ty.max(1), 1],
            );
        }
    }

    /// The radix binning: (tile | depth) keys per intersection, sorted, then the ranges.
    fn bin_radix(
        &self,
        rec: &mut Recorder<'_>,
        b: &RasterBuffers,
        cam: &Camera,
        g: &SplatInputs<'_>,
    ) {
        let pp = self.project_params(b, cam, g);
        let bits = sort_bits(cam.width, cam.height);
        self.scan.record(
            rec,
            &b.scan,
            b.counts.all(),
            b.offsets.all(),
            Count::Host(g.n),
        );
        rec.dispatch(
            &self.bin_total,
            &pp,
            &[b.offsets.all(), b.counts.all(), b.meta.all()],
            [1, 1, 1],
        );
        rec.dispatch_rows(
            &self.bin_emit,
            &pp,
            &[
                b.splats.all(),
                b.rects.all(),
                b.offsets.all(),
                b.sort.keys[0].all(),
                b.sort.vals[0].all(),
            ],
            g.n,
        );
        let out = self
            .sort
            .record(rec, &b.sort, Count::Gpu(b.meta.slice(0, 4)), bits);
        debug_assert_eq!(out, (passes(bits) % 2) as usize);
        self.bin_ranges(rec, b, &pp, out);
    }

    /// The depth-first binning (`binning.rs`): the Gaussians sorted by depth, their keys
    /// emitted in that order, then sorted by the tile bits only; the same keys, ids and
    /// ranges as `bin_radix`.
    fn bin_depth_first(
        &self,
        rec: &mut Recorder<'_>,
        b: &RasterBuffers,
        cam: &Camera,
        g: &SplatInputs<'_>,
    ) {
        let pp = self.project_params(b, cam, g);
        let (tiles_x, tiles_y) = cam.tiles();
        let p = BinParams {
            tiles_x,
            tiles_y,
            num_gaussians: g.n,
            isect_capacity: b.isect_capacity,
        };
        let (k, d) = (&self.depth_first, &b.depth_first);
        let keys = [b.splats.all(), d.sort.keys[0].all(), d.sort.vals[0].all()];
        rec.dispatch_rows(&k.keys, &p, &keys, g.n);
        let order = d.sort.vals[self.sort.record(rec, &d.sort, Count::Host(g.n), 32)].all();
        let counts = [order, b.counts.all(), d.counts.all()];
        rec.dispatch_rows(&k.counts, &p, &counts, g.n);
        // `offsets` as the radix path uses it, but in depth order.
        let (counts, offsets) = (d.counts.all(), b.offsets.all());
        self.scan
            .record(rec, &b.scan, counts, offsets, Count::Host(g.n));
        let total = [offsets, counts, b.meta.all()];
        rec.dispatch(&self.bin_total, &pp, &total, [1, 1, 1]);
        let emit = [
            b.splats.all(),
            b.rects.all(),
            order,
            offsets,
            b.sort.keys[0].all(),
            b.sort.vals[0].all(),
        ];
        rec.dispatch_rows(&k.emit, &p, &emit, g.n);
        let count = Count::Gpu(b.meta.slice(0, 4));
        let bits = sort_bits(cam.width, cam.height);
        // 32 is a whole number of digits: the output lands where the radix path's does.
        let out = self.sort.record_bits(rec, &b.sort, count, 32, bits);
        debug_assert_eq!(out, isect_out(cam.width, cam.height));
        self.bin_ranges(rec, b, &pp, out);
    }

    /// Per-tile ranges of the sorted keys in `b.sort.keys[out]`.
    fn bin_ranges(
        &self,
        rec: &mut Recorder<'_>,
        b: &RasterBuffers,
        pp: &ProjectParams,
        out: usize,
    ) {
        rec.fill(b.ranges.all(), 0);
        rec.dispatch_indirect(
            &self.bin_ranges,
            pp,
            &[b.meta.all(), b.sort.keys[out].all(), b.ranges.all()],
            b.meta.slice(16, 12),
        );
    }

    /// Records the backward pass of the last `forward` (same inputs): `b.grad2d`,
    /// `b.d_features` and the 3D gradients `b.d_*`.
    pub fn backward(
        &self,
        rec: &mut Recorder<'_>,
        b: &RasterBuffers,
        cam: &Camera,
        g: &SplatInputs<'_>,
        o: &RenderOpts,
        d: &OutputGrads<'_>,
    ) {
        self.backward_blend(rec, b, cam, g, o, d);
        self.backward_project(rec, b, cam, g, o);
    }

    /// The blend backward of `backward` alone: `b.grad2d` and `b.d_features`.
    pub fn backward_blend(
        &self,
        rec: &mut Recorder<'_>,
        b: &RasterBuffers,
        cam: &Camera,
        g: &SplatInputs<'_>,
        o: &RenderOpts,
        d: &OutputGrads<'_>,
    ) {
        Self::check(b, cam, g);
        assert_eq!(
            d.features.is_some(),
            g.features.is_some(),
            "feature gradients given iff features are"
        );
        let out = isect_out(cam.width, cam.height);
        let bp = self.blend_params(cam, g, o);
        let (tx, ty) = cam.tiles();
        rec.fill(b.grad2d.all(), 0);
        let mut binds = vec![
            b.ranges.all(),
            b.sort.vals[out].all(),
            b.splats.all(),
            b.final_t.all(),
            b.n_contrib.all(),
            d.rgba,
            d.depth.unwrap_or(b.no_depth_grad.all()),
            b.grad2d.all(),
        ];
        if let (Some((f, _)), Some(df)) = (g.features, d.features) {
            rec.fill(b.d_features.all(), 0);
            binds.extend([f, df, b.d_features.all()]);
        }
        let v = self.blend_bwd_variant;
        if v != BlendBwdVariant::SubgroupAtomic {
            // The CPU-shaped kernels read which of them draws each tile (blend_pick.glsl).
            binds.push(b.band_pick.all());
        }
        if v == BlendBwdVariant::TilePicked {
            rec.dispatch_threads(
                &self.blend_bwd_pick,
                &bp,
                &[
                    b.ranges.all(),
                    b.sort.vals[out].all(),
                    b.splats.all(),
                    b.n_contrib.all(),
                    b.band_pick.all(),
                ],
                [tx * ty, 1, 1],
            );
        }
        for &(k, pick) in v.dispatches() {
            rec.dispatch(
                &self.blend_bwd[self.row(k)][variant(g.feature_dims()).unwrap()],
                &BlendParams { pick, ..bp },
                &binds,
                [tx.max(1), ty.max(1), 1],
            );
        }
    }

    /// The projection backward of `backward` alone: `b.grad2d` (as the blend left it, plus
    /// whatever the caller added) to the 3D gradients `b.d_*`.
    pub fn backward_project(
        &self,
        rec: &mut Recorder<'_>,
        b: &RasterBuffers,
        cam: &Camera,
        g: &SplatInputs<'_>,
        o: &RenderOpts,
    ) {
        Self::check(b, cam, g);
        let pp = ProjectParams {
            feat_detach: (o.detach_feature_weights && g.features.is_some()) as u32,
            ..self.project_params(b, cam, g)
        };
        rec.dispatch_rows(
            &self.project_bwd,
            &pp,
            &[
                g.means,
                g.scales,
                g.quats,
                g.opacity_logits,
                g.sh_dc,
                g.sh_rest,
                b.grad2d.all(),
                b.d_means.all(),
                b.d_scales.all(),
                b.d_quats.all(),
                b.d_opacity_logits.all(),
                b.d_sh_dc.all(),
                b.d_sh_rest.all(),
                g.opacity_scale.unwrap_or(g.opacity_logits),
                b.d_op_scale.all(),
            ],
            g.n,
        );
    }

    /// The one grow-on-overflow policy: after a forward pass whose tile intersections
    /// overflowed `b` (it needed `needed`), reallocate `b` with a quarter of headroom. The
    /// caller re-runs the pass (nothing is ever dropped silently).
    pub fn grow(&self, gpu: &Gpu, b: &mut RasterBuffers, needed: u32) -> Result<()> {
        let grown = needed.checked_add(needed / 4).ok_or(Error::Capacity {
            what: "tile intersections",
            capacity: u32::MAX as u64,
            asked: needed as u64,
        })?;
        *b = self.buffers(
            gpu,
            &RasterSize {
                isect_capacity: grown,
                ..b.size()
            },
        )?;
        Ok(())
    }

    /// Forward in its own submit, growing `b` and re-running when the intersection capacity
    /// overflowed. For rendering outside the training step (tests, bench).
    pub fn render_checked(
        &self,
        gpu: &Gpu,
        b: &mut RasterBuffers,
        cam: &Camera,
        g: &SplatInputs<'_>,
        o: &RenderOpts,
    ) -> Result<()> {
        loop {
            let mut rec = Recorder::new(gpu)?;
            self.forward(&mut rec, b, cam, g, o);
            rec.finish()?;
            let o = b.overflow(gpu)?;
            if !o.overflowed {
                return Ok(());
            }
            self.grow(gpu, b, o.needed)?;
        }
    }
}
