// Blend forward, pixels in registers: the same maths as blend_fwd.glsl (read its header), one
// workgroup per 16×16 tile with TILE²/PX invocations, each owning PX pixels of the tile (pixel
// q = invocation + WG·i) with their blend state in registers. Each subgroup walks the tile's
// depth-sorted splats front to back on its own (no barrier, no shared memory): the splat
// record is a uniform (broadcast) load, then the PX pixels are blended in order, exactly as
// blend_fwd.glsl blends its one pixel, so per pixel the float operations and their order are
// the same. The walk stops once every pixel of the subgroup is saturated (a uniform break), and
// skips the pixel rows a splat cannot reach (its record's `reach`, from alpha_extent: α < 1/255
// there, so the skip changes nothing but the time).
//
// Why on lavapipe: a workgroup is ceil(WG/8) coroutines of 8 SIMD lanes, and every barrier()
// suspends and resumes each of them; shared-memory accesses are per-lane scalar loops. The
// shared-memory kernel pays 4 barriers and 256 per-lane staging loads per batch of 256 splats
// and reads every splat from shared memory per lane; with PX = 32 the workgroup is one
// coroutine and a splat is one broadcast load. On a GPU the 8-invocation workgroup leaves most
// of a warp idle: the host keeps the shared-memory kernel there.
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_vote : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"

#define WG (TILE * TILE / PX)
#if (TILE % WG) != 0
#error "a pixel's row q / TILE must be uniform: WG must divide TILE"
#endif
layout(local_size_x = WG) in;

#include "blend_fwd_io.glsl"

void main() {
    uint t = gl_LocalInvocationID.x;
    uint tile = gl_WorkGroupID.y * pc.tiles_x + gl_WorkGroupID.x;
    uvec2 range = ranges[tile];
    // The other kernel of the pass draws this tile (BlendParams.list_min/list_max).
    uint listed = range.y - range.x;
    if (listed < pc.list_min || listed > pc.list_max) return;
    uvec2 origin = gl_WorkGroupID.xy * TILE;

    // Per pixel: transmittance, colour, depth, features, last contributor (1-based, 0: none).
    float T[PX], D[PX];
    vec3 C[PX];
    uint last[PX];
#if FEAT > 0
    float F[PX * FEAT];
#endif
    uint live = 0u; // bit i: pixel i is inside the image and not yet saturated
    for (int i = 0; i < PX; ++i) {
        uint q = t + WG * uint(i);
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

    uint j = range.x;
    for (; j < range.y; ++j) {
        if (subgroupAll(live == 0u)) break;
        uint gid = ids[j]; // uniform: broadcast loads below
        vec4 a = splats[SPLAT_STRIDE * gid];
        vec3 con = splats[SPLAT_STRIDE * gid + 1].xyz;
        vec4 c4 = splats[SPLAT_STRIDE * gid + 2];
        vec3 col = c4.rgb;
        float reach = c4.w; // |dy| past which α < 1/255 (alpha_extent)
#if FEAT > 0
        float f[FEAT];
        for (int c = 0; c < FEAT; ++c) f[c] = feat[gid * FEAT + c];
#endif
        uint seen = j - range.x + 1u;
        for (int i = 0; i < PX; ++i) {
            // A row the splat cannot reach is skipped whole (uniform: q / TILE = WG·i / TILE);
            // dy is the d.y below, so a skipped pixel is one with α < 1/255.
            if (abs(a.y - (float(origin.y + (WG * uint(i)) / TILE) + 0.5)) > reach) continue;
            if ((live & (1u << uint(i))) == 0u) continue;
            uint q = t + WG * uint(i);
            vec2 centre = vec2(origin + uvec2(q % TILE, q / TILE)) + 0.5;
            vec2 d = a.xy - centre;
            float sigma = splat_sigma(con, d);
            float alpha = min(pc.alpha_max, a.w * exp(-sigma));
            if (alpha < ALPHA_MIN) continue;
            float test_t = T[i] * (1.0 - alpha);
            if (test_t < T_STOP) {
                live &= ~(1u << uint(i));
                continue;
            }
            float w = alpha * T[i];
            C[i] += w * col;
            D[i] += w * a.z;
#if FEAT > 0
            for (int c = 0; c < FEAT; ++c) F[i * FEAT + c] += w * f[c];
#endif
            T[i] = test_t;
            last[i] = seen;
        }
    }

    // The walk ends at the list's end or once every pixel is saturated. Ending elsewhere with a
    // live pixel means the device cut the loop (llvmpipe ends an invocation's loops after
    // 65 535 iterations in all, silently): the image is wrong, so say so.
    if (j < range.y && live != 0u) atomicOr(overflow_word, OVERFLOW_WALK_CUT);

    for (int i = 0; i < PX; ++i) {
        uint q = t + WG * uint(i);
        uvec2 pix = origin + uvec2(q % TILE, q / TILE);
        if (pix.x >= pc.width || pix.y >= pc.height) continue;
        uint p = pix.y * pc.width + pix.x;
        out_rgba[p] = vec4(C[i] + T[i] * pc.background.rgb, 1.0 - T[i]);
        out_depth[p] = D[i];
        final_t[p] = T[i];
        n_contrib[p] = last[i];
#if FEAT > 0
        for (int c = 0; c < FEAT; ++c) out_feat[p * FEAT + c] = F[i * FEAT + c];
#endif
    }
}
