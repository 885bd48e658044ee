#version 460
// Which CPU-shaped kernel draws each tile of the picked blend backward (BlendBwdVariant::
// TilePicked, twin reference::raster::bin::band_pick): the bands (blend_bwd_band_f*.comp) or
// the whole tile (blend_bwd_tile_f*.comp), from the forward's own stopping points, which the
// forward's cover sample (blend_pick.glsl) cannot see. Per 4-row band b of the tile (lavapipe's
// band, whatever the device's subgroup size) the backward walks the list up to end_b, the
// band's furthest last contributor (n_contrib), and evaluates and folds only the splats that
// reach its rows (reached_b); the whole tile walks to the furthest end of all and evaluates
// all 256 pixels of every splat. In eighths of one pixel evaluation per lane:
//   bands  Σ_b reached_b · pick_band_splat + end_b · pick_band_step
//   whole  max_b end_b · pick_whole_splat
// and the cheaper goes (bands on a tie). The pixels a splat covers cost both kernels alike, so
// they cancel from the comparison (PICK_COSTS in src/kernels/raster.rs is fitted to the
// difference of the two kernels' times). A list longer than band_list_max goes whole (the
// band kernels' loop budget). One invocation per tile; a speed choice only: either kernel
// gives the same gradients up to the order of float sums.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"

layout(local_size_x = 16) in;
layout(push_constant) uniform Push { BlendParams pc; };
layout(std430, binding = 0) readonly buffer Ranges { uvec2 ranges[]; };
layout(std430, binding = 1) readonly buffer Ids { uint ids[]; };
layout(std430, binding = 2) readonly buffer Splats { vec4 splats[]; };
layout(std430, binding = 3) readonly buffer NContrib { uint n_contrib[]; };
layout(std430, binding = 4) writeonly buffer BandPick { uint band_pick[]; }; // 1 bands, 0 whole

void main() {
    uint tile = gl_GlobalInvocationID.x;
    if (tile >= pc.tiles_x * pc.tiles_y) return;
    uvec2 range = ranges[tile];
    if (range.y - range.x > pc.band_list_max) {
        band_pick[tile] = 0u;
        return;
    }
    uvec2 origin = uvec2(tile % pc.tiles_x, tile / pc.tiles_x) * TILE;
    // Each band's walk: its furthest last contributor (1-based; 0 = nothing to walk).
    uvec4 end = uvec4(0u);
    for (uint r = 0u; r < TILE; ++r) {
        uint y = origin.y + r;
        if (y >= pc.height) break;
        uint m = 0u;
        for (uint c = 0u; c < TILE && origin.x + c < pc.width; ++c)
            m = max(m, n_contrib[y * pc.width + origin.x + c]);
        end[r / 4u] = max(end[r / 4u], m);
    }
    uint longest = max(max(end.x, end.y), max(end.z, end.w));
    // Splats each band evaluates: those of its walk whose reach meets its rows (the band
    // kernels' step-over test, the same f32 comparisons).
    uvec4 reached = uvec4(0u);
    vec4 lo = vec4(float(origin.y)) + vec4(0.5, 4.5, 8.5, 12.5);
    vec4 hi = lo + 3.0;
    for (uint j = 0u; j < longest; ++j) {
        uint gid = ids[range.x + j];
        float y = splats[SPLAT_STRIDE * gid].y;
        float reach = splats[SPLAT_STRIDE * gid + 2].w;
        bvec4 meets = bvec4(uvec4(greaterThanEqual(vec4(y + reach), lo)) &
                            uvec4(lessThanEqual(vec4(y - reach), hi)) &
                            uvec4(lessThan(uvec4(j), end)));
        reached += uvec4(meets);
    }
    uint bands = (reached.x + reached.y + reached.z + reached.w) * pc.pick_band_splat +
                 (end.x + end.y + end.z + end.w) * pc.pick_band_step;
    uint whole = longest * pc.pick_whole_splat;
    band_pick[tile] = bands <= whole ? 1u : 0u;
}
