// Blend forward, pixels in registers: the same maths as blend_fwd.glsl (read its header), one
// workgroup per 16×16 tile with TILE²/PX invocations, each owning PX pixels of the tile with
// their blend state in registers. Each subgroup owns a band of S·PX consecutive pixels of the
// tile (S = its lanes, at most the workgroup) and walks the tile's depth-sorted splats front to
// back on its own (no barrier, no shared memory): the splat record is a uniform load, then its
// PX pixels are blended in order, exactly as blend_fwd.glsl blends its one pixel, so per pixel
// the float operations and their order are the same. The walk stops once every pixel of the
// subgroup is saturated (a uniform break).
//
// Two shapes, both for CPU devices (on a GPU a few invocations per tile leave most of a warp
// idle: the host keeps the shared-memory kernel there):
// - whole tile (PX = 32, blend_fwd_tile_f*.comp): 8 invocations, one lavapipe coroutine of 8
//   lanes per tile; the shared-memory kernel pays 4 barriers and 256 per-lane staging loads
//   per batch of 256 splats. This one loads S list entries at a time, lane l the entry jb + l
//   (id, record, features), and takes each splat's record from its lane with a shuffle at a
//   uniform index: llvmpipe runs any buffer load whose address it cannot prove always uniform
//   as a loop over the lanes, so a load per splat (four loops) was most of the walk's time
//   (stop 74, docs/measurements.md "Batched splat loads"). A batch costs one loop iteration
//   besides its splats': 9 per 8 splats, so an unsaturated walk reaches 58 254 entries.
// - bands (PX = 8 and STEP_OVER, blend_fwd_band_f*.comp): 32 invocations, 4 rows per subgroup
//   at lavapipe's 8 lanes, and a short loop that steps over the splats whose reach (the
//   record's alpha_extent y) misses the band's rows. On lavapipe an `if` is an execution mask,
//   not a branch, so the whole-tile shape pays all PX evaluations of exp for every splat of
//   the list however few rows it reaches; a loop's exit is a real branch, so a splat that
//   misses the band costs one loop iteration. A skipped splat has α < 1/255 at every row of
//   the band, which the blend skips anyway: the outputs are the whole-tile shape's bits. Each
//   splat costs up to two loop iterations of lavapipe's 65 535 per invocation.
// A pass on a CPU device dispatches both shapes, and each draws the tiles blend_pick.glsl gives
// it (BlendParams.pick): the whole tile takes the lists longer than BAND_LIST_MAX (the loop
// budget) and, below the default threshold, those whose splats mostly span every band.
// The band is gl_LocalInvocationIndex / S and its lane the index % S; the whole tile's
// shuffles take that lane to be gl_SubgroupInvocationID's (subgroups of consecutive
// invocations, as lavapipe makes them: these kernels are for CPU devices).
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_shuffle : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"

#define WG (TILE * TILE / PX)
layout(local_size_x = WG) in;

#include "blend_fwd_io.glsl"
#include "blend_pick.glsl"

void main() {
    uint t = gl_LocalInvocationIndex;
    uint tile = gl_WorkGroupID.y * pc.tiles_x + gl_WorkGroupID.x;
    uvec2 range = ranges[tile];
    // The other kernel of the pass draws this tile (BlendParams.pick).
    if (!drawn_here(tile, gl_WorkGroupID.y, range)) return;
    uvec2 origin = gl_WorkGroupID.xy * TILE;
    // Lanes per band: the subgroup's, at most the workgroup (a power of two dividing WG).
    uint S = min(gl_SubgroupSize, uint(WG));
    uint band = t / S, lane = t % S;
    uint first = band * S * PX; // the band's first pixel (row-major in the tile)
    // Pixel-centre rows of the band, for the step-over test.
    float row_lo = float(origin.y + first / TILE) + 0.5;
    float row_hi = float(origin.y + (first + S * PX - 1u) / TILE) + 0.5;

    float T[PX], D[PX];
    vec3 C[PX];
    uint last[PX];
#if FEAT > 0
    float F[PX * FEAT];
#endif
    uint live = 0u; // bit i: pixel i is inside the image and not yet saturated
    for (int i = 0; i < PX; ++i) {
        uint q = first + lane + S * uint(i);
        uvec2 pix = origin + uvec2(q % TILE, q / TILE);
        if (pix.x < pc.width && pix.y < pc.height) live |= 1u << uint(i);
        T[i] = 1.0;
        C[i] = vec3(0.0);
        D[i] = 0.0;
        last[i] = 0u;
#if FEAT > 0
        for (int c = 0; c < FEAT; ++c) F[i * FEAT + c] = 0.0;
#endif
    }

#ifdef STEP_OVER
    uint j = range.x;
    for (; j < range.y; ++j) {
        if (subgroupAll(live == 0u)) break;
        // Step over the splats that reach no row of the band (α < 1/255 there).
        uint gid = 0u;
        vec4 a = vec4(0.0), c4 = vec4(0.0);
        bool found = false;
        for (; j < range.y; ++j) {
            gid = LDU1(ids, j);
            a = LD4(splats, SPLAT_STRIDE * gid);
            c4 = LD4(splats, SPLAT_STRIDE * gid + 2);
            if (a.y + c4.w >= row_lo && a.y - c4.w <= row_hi) {
                found = true;
                break;
            }
        }
        if (!found) break;
        vec3 con = LD4(splats, SPLAT_STRIDE * gid + 1).xyz;
        vec3 col = c4.rgb;
#if FEAT > 0
        float f[FEAT];
        for (int c = 0; c < FEAT; ++c) f[c] = LD1(feat, gid * FEAT + c);
#endif
        uint seen = j - range.x + 1u;
#include "blend_fwd_splat.glsl"
    }

    bool walked = j >= range.y;
#else
    // The walk in batches of S entries: lane l loads entry jb + l (its id, record and
    // features: one per-lane load loop per batch, where a load per splat cost llvmpipe one
    // such loop per splat, most of a walk's time), then the batch's splats are blended in
    // order, each record taken from its lane with a uniform-index shuffle.
    uint jb = range.x;
    for (; jb < range.y; jb += S) {
        if (subgroupAll(live == 0u)) break;
        uint nb = min(S, range.y - jb);
        uint g_l = LDU1(ids, jb + min(lane, nb - 1u));
        vec4 a_l = LD4(splats, SPLAT_STRIDE * g_l);
        vec4 n_l = LD4(splats, SPLAT_STRIDE * g_l + 1);
        vec4 c_l = LD4(splats, SPLAT_STRIDE * g_l + 2);
#if FEAT > 0
        float f_l[FEAT];
        for (int c = 0; c < FEAT; ++c) f_l[c] = LD1(feat, g_l * FEAT + c);
#endif
        // A loop that tests at its end: lavapipe's loop budget counts one iteration per splat,
        // where a loop that tests first would count one more per batch.
        uint k = 0u;
        do {
            if (subgroupAll(live == 0u)) break;
#include "blend_tile_take.glsl"
            uint seen = jb + k - range.x + 1u;
#include "blend_fwd_splat.glsl"
        } while (++k < nb);
    }

    bool walked = jb >= range.y;
#endif

    // The walk ends at the list's end or once every pixel is saturated. Ending elsewhere with a
    // live pixel means the device cut the loop (llvmpipe ends an invocation's loops after
    // 65 535 iterations in all, silently): the image is wrong, so say so.
    if (!walked && live != 0u) atomicOr(overflow_word, OVERFLOW_WALK_CUT);

    for (int i = 0; i < PX; ++i) {
        uint q = first + lane + S * uint(i);
        uvec2 pix = origin + uvec2(q % TILE, q / TILE);
        if (pix.x >= pc.width || pix.y >= pc.height) continue;
        uint p = pix.y * pc.width + pix.x;
        ST4(out_rgba, p, vec4(C[i] + T[i] * pc.background.rgb, 1.0 - T[i]));
        ST1(out_depth, p, D[i]);
        ST1(final_t, p, T[i]);
        STU1(n_contrib, p, last[i]);
#if FEAT > 0
        for (int c = 0; c < FEAT; ++c) ST1(out_feat, p * FEAT + c, F[i * FEAT + c]);
#endif
    }
}
