//! CPU twin of the rasteriser's binning (`glsl/raster/bin_*.comp`, `kernels::binning`): the
//! ordered list of tile intersections and the per-tile ranges the blends walk. Keys are
//! `(tile << 32) | depth bits`, as the GPU's `uvec2(depth, tile)`; depth bits are the f32 view
//! depth's bits (`floatBitsToUint`), which order as the depths for the positive depths a
//! Gaussian with a tile has. Stage functions carry the GLSL stage's name and read their inputs
//! in its binding order; [`bin`] is the whole list, [`bin_depth_first`] the same list built
//! the depth-first way, stage by stage.

/// A tile intersection's key: tile in the high word, depth bits in the low one.
pub fn key(tile: u32, depth_bits: u32) -> u64 {
    ((tile as u64) << 32) | depth_bits as u64
}

/// `bin_emit`: each Gaussian's intersections at its exclusive-scan offset, in row-major tile
/// order of its rectangle `[x0, y0, x1, y1)`; entries past `capacity` dropped.
pub fn bin_emit(
    depth_bits: &[u32],
    rects: &[[u32; 4]],
    offsets: &[u32],
    tiles_x: u32,
    capacity: u32,
) -> (Vec<u64>, Vec<u32>) {
    let total = (0..rects.len()).map(|i| offsets[i] + area(rects[i])).max();
    let len = total.unwrap_or(0).min(capacity) as usize;
    let (mut keys, mut vals) = (vec![0u64; len], vec![0u32; len]);
    for i in 0..rects.len() {
        emit(
            i,
            depth_bits[i],
            rects[i],
            offsets[i],
            tiles_x,
            &mut keys,
            &mut vals,
        );
    }
    (keys, vals)
}

/// `bin_depth_keys`: one (depth bits, index) pair per Gaussian.
pub fn bin_depth_keys(depth_bits: &[u32]) -> (Vec<u32>, Vec<u32>) {
    (depth_bits.to_vec(), (0..depth_bits.len() as u32).collect())
}

/// `bin_depth_counts`: the tile counts in depth order.
pub fn bin_depth_counts(order: &[u32], counts: &[u32]) -> Vec<u32> {
    order.iter().map(|&i| counts[i as usize]).collect()
}

/// `bin_emit_depth`: [`bin_emit`]'s keys with the j-th nearest Gaussian at offset `offsets[j]`.
pub fn bin_emit_depth(
    depth_bits: &[u32],
    rects: &[[u32; 4]],
    order: &[u32],
    offsets: &[u32],
    tiles_x: u32,
    capacity: u32,
) -> (Vec<u64>, Vec<u32>) {
    let total = (0..order.len())
        .map(|j| offsets[j] + area(rects[order[j] as usize]))
        .max();
    let len = total.unwrap_or(0).min(capacity) as usize;
    let (mut keys, mut vals) = (vec![0u64; len], vec![0u32; len]);
    for (j, &i) in order.iter().enumerate() {
        let i = i as usize;
        emit(
            i,
            depth_bits[i],
            rects[i],
            offsets[j],
            tiles_x,
            &mut keys,
            &mut vals,
        );
    }
    (keys, vals)
}

/// `bin_ranges`: per tile `[start, end)` in the sorted `keys` ((0, 0) for a tile without any).
pub fn bin_ranges(keys: &[u64], tiles: u32) -> Vec<[u32; 2]> {
    let mut r = vec![[0u32; 2]; tiles as usize];
    for (j, k) in keys.iter().enumerate() {
        let t = (k >> 32) as usize;
        if j == 0 || (keys[j - 1] >> 32) as usize != t {
            r[t][0] = j as u32;
        }
        r[t][1] = j as u32 + 1;
    }
    r
}

/// The binned list: Gaussian ids tile by tile, front to back, equal depths in index order, and
/// the per-tile ranges (the radix path: emit, then one stable sort of the whole keys).
pub struct Binned {
    pub ids: Vec<u32>,
    pub ranges: Vec<[u32; 2]>,
}

/// The whole binning of Gaussians with view-depth bits `depth_bits` and tile rectangles
/// `rects` on a `tiles_x × tiles_y` grid (capacity unbounded).
pub fn bin(depth_bits: &[u32], rects: &[[u32; 4]], tiles_x: u32, tiles_y: u32) -> Binned {
    let offsets = exclusive_scan(&rects.iter().map(|&r| area(r)).collect::<Vec<_>>());
    let (keys, vals) = bin_emit(depth_bits, rects, &offsets, tiles_x, u32::MAX);
    sorted(keys, vals, tiles_x * tiles_y)
}

/// [`bin`] the depth-first way: the Gaussians stably sorted by depth, their counts in that
/// order, scanned, the keys emitted in depth order, then stably sorted by tile alone.
pub fn bin_depth_first(
    depth_bits: &[u32],
    rects: &[[u32; 4]],
    tiles_x: u32,
    tiles_y: u32,
) -> Binned {
    let (keys, vals) = bin_depth_keys(depth_bits);
    let mut order: Vec<(u32, u32)> = keys.into_iter().zip(vals).collect();
    order.sort_by_key(|&(k, _)| k); // stable: equal depths in index order
    let order: Vec<u32> = order.into_iter().map(|(_, i)| i).collect();
    let counts: Vec<u32> = rects.iter().map(|&r| area(r)).collect();
    let offsets = exclusive_scan(&bin_depth_counts(&order, &counts));
    let (keys, vals) = bin_emit_depth(depth_bits, rects, &order, &offsets, tiles_x, u32::MAX);
    let mut e: Vec<(u64, u32)> = keys.into_iter().zip(vals).collect();
    e.sort_by_key(|&(k, _)| k >> 32); // stable: the depth order within a tile stays
    let keys: Vec<u64> = e.iter().map(|x| x.0).collect();
    Binned {
        ranges: bin_ranges(&keys, tiles_x * tiles_y),
        ids: e.into_iter().map(|x| x.1).collect(),
    }
}

fn sorted(keys: Vec<u64>, vals: Vec<u32>, tiles: u32) -> Binned {
    let mut e: Vec<(u64, u32)> = keys.into_iter().zip(vals).collect();
    e.sort_by_key(|&(k, _)| k); // stable: equal keys keep emit order, which is index order
    let keys: Vec<u64> = e.iter().map(|x| x.0).collect();
    Binned {
        ranges: bin_ranges(&keys, tiles),
        ids: e.into_iter().map(|x| x.1).collect(),
    }
}

fn area(r: [u32; 4]) -> u32 {
    r[2].saturating_sub(r[0]) * r[3].saturating_sub(r[1])
}

fn exclusive_scan(v: &[u32]) -> Vec<u32> {
    let mut s = 0u32;
    v.iter()
        .map(|&c| {
            let o = s;
            s += c;
            o
        })
        .collect()
}

fn emit(
    i: usize,
    depth_bits: u32,
    r: [u32; 4],
    mut o: u32,
    tiles_x: u32,
    keys: &mut [u64],
    vals: &mut [u32],
) {
    for ty in r[1]..r[3] {
        for tx in r[0]..r[2] {
            if (o as usize) < keys.len() {
                keys[o as usize] = key(ty * tiles_x + tx, depth_bits);
                vals[o as usize] = i as u32;
            }
            o += 1;
        }
    }
}

/// `blend_pick.glsl`'s `band_tile`: whether the band blends (rather than the whole-tile ones)
/// draw tile row `tile_y`'s tile with list `ids` (front to back), from the splat records
/// `splats` (`[N·3]` vec4: mean2d.y in `[3i].y`, the y reach in `[3i + 2].w`): no longer than
/// `band_list_max`, and its `BAND_SAMPLE` evenly spaced entries reaching at most
/// `band_cover_max`/8 of the tile's four 4-row bands each, on average. Exact: the same f32
/// comparisons and integer sums.
pub fn band_tile(
    tile_y: u32,
    ids: &[u32],
    splats: &[[f32; 4]],
    band_list_max: u32,
    band_cover_max: u32,
) -> bool {
    const BAND_SAMPLE: u32 = 32;
    let n = ids.len() as u32;
    if n > band_list_max {
        return false;
    }
    if band_cover_max >= 32 {
        return true;
    }
    let s = n.min(BAND_SAMPLE);
    let y0 = (tile_y * super::TILE) as f32;
    let mut cover = 0u32;
    for k in 0..s {
        let gid = ids[(k * n / s) as usize] as usize;
        let (y, reach) = (splats[3 * gid][1], splats[3 * gid + 2][3]);
        for b in 0..4u32 {
            let lo = y0 + (4 * b) as f32 + 0.5;
            let hi = lo + 3.0;
            cover += (y + reach >= lo && y - reach <= hi) as u32;
        }
    }
    cover * 8 <= band_cover_max * s
}

/// `blend_bwd_pick.comp`: whether the picked blend backward gives the tile at `origin` (its
/// top-left pixel) with list `ids` (front to back) to the band kernels (rather than the
/// whole-tile one), from the forward's `n_contrib` (`[H·W]`, 1-based last contributor) on a
/// `width`×`height` image, the splat records `splats` (as [`band_tile`]) and the cost model
/// `costs` (`[band_splat, band_step, whole_splat]`, eighths of a pixel evaluation): per 4-row
/// band, the walk to its furthest last contributor and the splats of that walk that reach its
/// rows, against the whole tile's walk to the furthest of all. Exact: the same f32
/// comparisons and integer sums.
#[allow(clippy::too_many_arguments)]
pub fn band_pick(
    origin: [u32; 2],
    ids: &[u32],
    splats: &[[f32; 4]],
    n_contrib: &[u32],
    width: u32,
    height: u32,
    band_list_max: u32,
    costs: [u32; 3],
) -> bool {
    let tile = super::TILE;
    if ids.len() as u32 > band_list_max {
        return false;
    }
    let mut end = [0u32; 4];
    for r in 0..tile {
        let y = origin[1] + r;
        if y >= height {
            break;
        }
        for c in (0..tile).take_while(|c| origin[0] + c < width) {
            let p = (y * width + origin[0] + c) as usize;
            end[(r / 4) as usize] = end[(r / 4) as usize].max(n_contrib[p]);
        }
    }
    let longest = *end.iter().max().unwrap();
    let mut reached = [0u32; 4];
    for (j, &gid) in ids.iter().enumerate().take(longest as usize) {
        let (y, reach) = (splats[3 * gid as usize][1], splats[3 * gid as usize + 2][3]);
        for b in 0..4 {
            let lo = origin[1] as f32 + (4 * b) as f32 + 0.5;
            let hi = lo + 3.0;
            reached[b] += (y + reach >= lo && y - reach <= hi && (j as u32) < end[b]) as u32;
        }
    }
    let bands = reached.iter().sum::<u32>() * costs[0] + end.iter().sum::<u32>() * costs[1];
    bands <= longest * costs[2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_ways_bin_alike_with_ties_broken_by_index() {
        // Four Gaussians on a 2×2 grid; 1 and 3 share a depth, 2 is nearest.
        let depth = [2.0f32, 3.0, 1.0, 3.0].map(f32::to_bits);
        let rects = [[0, 0, 2, 1], [1, 0, 2, 2], [0, 0, 2, 2], [1, 1, 2, 2]];
        let b = bin(&depth, &rects, 2, 2);
        // Tile 0: 2 (1.0), 0 (2.0); tile 1: 2, 0, 1; tile 2: 2; tile 3: 2, 1, 3 (1 before 3).
        assert_eq!(b.ids, [2, 0, 2, 0, 1, 2, 2, 1, 3]);
        assert_eq!(b.ranges, [[0, 2], [2, 5], [5, 6], [6, 9]]);
        let d = bin_depth_first(&depth, &rects, 2, 2);
        assert_eq!((d.ids, d.ranges), (b.ids, b.ranges));
        // A capacity cuts the emitted list, not the offsets.
        let (k, v) = bin_emit(&depth, &rects, &[0, 2, 4, 8], 2, 5);
        assert_eq!(v, [0, 0, 1, 1, 2]);
        assert_eq!(k[4], key(0, depth[2]));
        assert!(bin(&[], &[], 3, 2).ranges.iter().all(|r| r == &[0, 0]));
    }
}
