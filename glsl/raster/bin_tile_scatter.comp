#version 460
// Depth-first binning (CPU shape), step 3: per tile, its [start, end) range (an exclusive scan
// of the counts over tile ids), then every Gaussian in depth order writes its id into the next
// slot of each of its tiles. A stable counting sort by tile of the depth-sorted list: within a
// tile, depth ascending and equal depths by index, the order of the (tile | depth) radix sort.
// One invocation per band of tile rows (each tile's cursor belongs to one band). Band 0 also
// writes the totals bin_total writes on the radix path (the same meta layout: the overflow
// flag and the count the host reads). Slots past the capacity are dropped and the ranges
// clamped to it, so an overflowed pass reads in bounds until the host re-runs it.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 1) in;

layout(push_constant) uniform Push { BinParams pc; };
layout(std430, binding = 0) readonly buffer Rects { uvec4 rects[]; };
layout(std430, binding = 1) readonly buffer Order { uint order[]; }; // Gaussians by depth
layout(std430, binding = 2) readonly buffer BandSums { uint band_sums[]; };
layout(std430, binding = 3) buffer TileNext { uint tile_next[]; };
layout(std430, binding = 4) writeonly buffer Ranges { uvec2 ranges[]; };
layout(std430, binding = 5) writeonly buffer Ids { uint ids[]; };
layout(std430, binding = 6) writeonly buffer Meta { uint meta[]; };

void main() {
    uint band = gl_WorkGroupID.x;
    uint cap = pc.isect_capacity;
    uint start = 0u;
    for (uint b = 0u; b < band; ++b) start += band_sums[b];
    if (band == 0u) {
        uint total = 0u;
        for (uint b = 0u; b < pc.bands; ++b) total += band_sums[b];
        uint clamped = min(total, cap);
        meta[0] = clamped;
        meta[1] = total;
        uint groups = (clamped + 255u) / 256u;
        uint gx = min(groups, 32768u);
        meta[4] = gx;
        meta[5] = gx == 0u ? 0u : (groups + gx - 1u) / gx;
        meta[6] = 1u;
        meta[64] = total > cap ? 1u : 0u;
        meta[65] = total;
    }
    uint y0 = band * pc.band_rows;
    uint y1 = min(y0 + pc.band_rows, pc.tiles_y);
    for (uint t = y0 * pc.tiles_x; t < y1 * pc.tiles_x; ++t) {
        uint c = tile_next[t];
        // (0, 0) for a tile without entries, as bin_ranges leaves it.
        ranges[t] = c == 0u || start >= cap ? uvec2(0u) : uvec2(start, min(start + c, cap));
        tile_next[t] = start;
        start += c;
    }
    for (uint j = 0u; j < pc.num_gaussians; ++j) {
        uint i = order[j];
        uvec4 r = rects[i];
        uint ya = max(r.y, y0);
        uint yb = min(r.w, y1);
        for (uint ty = ya; ty < yb; ++ty) {
            for (uint tx = r.x; tx < r.z; ++tx) {
                uint t = ty * pc.tiles_x + tx;
                uint s = tile_next[t];
                tile_next[t] = s + 1u;
                if (s < cap) ids[s] = i;
            }
        }
    }
}
