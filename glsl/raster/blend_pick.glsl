// Which of the two CPU-shaped kernels of a blend pass draws a tile (BlendParams.pick), the
// same answer in both: the band kernel (blend_*_tile.glsl with STEP_OVER) or the whole-tile
// one. Bands pay one walk of the list per band and, in the backward, one fold per band that a
// splat reaches; the whole tile pays every pixel of the tile for every splat. So, below
// band_cover_max = 32 (the default, where every list of at most BAND_LIST_MAX stays in bands:
// the cover cannot see that a trained tile's bands stop early, docs/measurements.md), a tile
// whose splats mostly span the whole tile goes whole, one with small splats to the bands. The
// cover is sampled at BAND_SAMPLE evenly spaced list
// entries, in bands of 4 rows (lavapipe's shape, whatever the device's subgroup size): a speed
// choice only, the image is the same either way (forward bit for bit; backward up to the
// order of float sums). Needs the bindings `ids`, `splats` and the push constants `pc` (and
// `band_pick` where BAND_PICK_BUFFER is defined).
#define BAND_SAMPLE 32u

bool band_tile(uint tile_y, uvec2 range) {
    uint n = range.y - range.x;
    if (n > pc.band_list_max) return false; // lavapipe's loop budget (BAND_LIST_MAX)
    if (pc.band_cover_max >= 32u) return true; // every short list (the default): no sample
    uint s = min(n, BAND_SAMPLE);
    float y0 = float(tile_y * TILE);
    uint cover = 0u; // bands reached, summed over the sample
    for (uint k = 0u; k < s; ++k) {
        uint gid = LDU1(ids, range.x + (k * n) / s);
        float y = LD4(splats, SPLAT_STRIDE * gid).y;
        float reach = LD4(splats, SPLAT_STRIDE * gid + 2).w;
        for (uint b = 0u; b < 4u; ++b) {
            float lo = y0 + float(4u * b) + 0.5, hi = lo + 3.0;
            cover += (y + reach >= lo && y - reach <= hi) ? 1u : 0u;
        }
    }
    return cover * 8u <= pc.band_cover_max * s; // band_cover_max: bands per splat, in eighths
}

// pick: 0 every tile; 1 / 2 the bands' / the whole tile's share by the cover above; 3 / 4 the
// same by band_pick (the picked backward's pass, blend_bwd_pick.comp, which binds it).
bool drawn_here(uint tile, uint tile_y, uvec2 range) {
    if (pc.pick == 0u) return true;
#ifdef BAND_PICK_BUFFER
    if (pc.pick >= 3u) return (band_pick[tile] != 0u) == (pc.pick == 3u);
#endif
    return band_tile(tile_y, range) == (pc.pick == 1u);
}
