#version 460
// Depth-first binning (CPU shape), step 2: Gaussians per tile. One invocation per band of
// tile rows walks every tile rectangle and counts the tiles of its band: each tile belongs to
// one band, so plain increments (no atomics, which lavapipe runs as per-lane loops).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 1) in;

layout(push_constant) uniform Push { BinParams pc; };
layout(std430, binding = 0) readonly buffer Rects { uvec4 rects[]; };
layout(std430, binding = 1) buffer TileNext { uint tile_next[]; };
layout(std430, binding = 2) writeonly buffer BandSums { uint band_sums[]; };

void main() {
    uint band = gl_WorkGroupID.x;
    uint y0 = band * pc.band_rows;
    uint y1 = min(y0 + pc.band_rows, pc.tiles_y);
    for (uint t = y0 * pc.tiles_x; t < y1 * pc.tiles_x; ++t) tile_next[t] = 0u;
    uint total = 0u;
    for (uint i = 0u; i < pc.num_gaussians; ++i) {
        uvec4 r = rects[i];
        uint ya = max(r.y, y0);
        uint yb = min(r.w, y1);
        for (uint ty = ya; ty < yb; ++ty) {
            for (uint tx = r.x; tx < r.z; ++tx) tile_next[ty * pc.tiles_x + tx] += 1u;
            total += r.z - r.x;
        }
    }
    band_sums[band] = total;
}
