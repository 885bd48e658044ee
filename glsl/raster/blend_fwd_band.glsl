// Blend forward, pixels in registers, one subgroup per band of the tile: the same maths as
// blend_fwd_tile.glsl (and so blend_fwd.glsl: read its header), but each subgroup owns a band
// of S·PX consecutive pixels of the tile (S = its lanes: 4 rows of 16 at lavapipe's 8) and
// walks the tile's list on its own, stepping over the splats that cannot reach its rows in a
// short loop of its own before blending the next one that can.
//
// Why on lavapipe: an `if` there is an execution mask, not a branch, so the tile kernel pays
// the whole tile's PX bodies for every splat of its list, however few rows the splat reaches
// (the row skip of blend_fwd_tile.glsl saves no time). A loop's exit is a real branch: the
// step-over loop leaves as soon as the band is reached, and a splat that misses the band costs
// its three record loads and one compare, not PX evaluations of exp. Per pixel the splats
// blended and their order are blend_fwd_tile.glsl's (a skipped splat has α < 1/255 at every
// row of the band, which the blend skips anyway), so the outputs are the same bits.
// Subgroup layout is a matter of speed only: every subgroup operation below is correct for
// any grouping of the invocations (the band is `gl_LocalInvocationIndex / S`).
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_vote : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"

#define WG (TILE * TILE / PX)
layout(local_size_x = WG) in;

#include "blend_fwd_io.glsl"

void main() {
    uint t = gl_LocalInvocationIndex;
    uint tile = gl_WorkGroupID.y * pc.tiles_x + gl_WorkGroupID.x;
    uvec2 range = ranges[tile];
    // The other kernel of the pass draws this tile (BlendParams.list_min/list_max).
    uint listed = range.y - range.x;
    if (listed < pc.list_min || listed > pc.list_max) return;
    uvec2 origin = gl_WorkGroupID.xy * TILE;
    // Lanes per band: the subgroup's, at most the workgroup (a power of two dividing WG).
    uint S = min(gl_SubgroupSize, uint(WG));
    uint band = t / S, lane = t % S;
    uint first = band * S * PX; // the band's first pixel (row-major in the tile)
    // Pixel-centre rows of the band, for the reach test.
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

    uint j = range.x;
    for (; j < range.y; ++j) {
        if (subgroupAll(live == 0u)) break;
        // Step over the splats that reach no row of the band (α < 1/255 there).
        uint gid = 0u;
        vec4 a = vec4(0.0), c4 = vec4(0.0);
        bool found = false;
        for (; j < range.y; ++j) {
            gid = ids[j];
            a = splats[SPLAT_STRIDE * gid];
            c4 = splats[SPLAT_STRIDE * gid + 2];
            if (a.y + c4.w >= row_lo && a.y - c4.w <= row_hi) {
                found = true;
                break;
            }
        }
        if (!found) break;
        vec3 con = splats[SPLAT_STRIDE * gid + 1].xyz;
        vec3 col = c4.rgb;
#if FEAT > 0
        float f[FEAT];
        for (int c = 0; c < FEAT; ++c) f[c] = feat[gid * FEAT + c];
#endif
        uint seen = j - range.x + 1u;
        for (int i = 0; i < PX; ++i) {
            if ((live & (1u << uint(i))) == 0u) continue;
            uint q = first + lane + S * uint(i);
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

    // As blend_fwd_tile.glsl: a walk that ends early with a live pixel was cut by the device.
    if (j < range.y && live != 0u) atomicOr(overflow_word, OVERFLOW_WALK_CUT);

    for (int i = 0; i < PX; ++i) {
        uint q = first + lane + S * uint(i);
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
