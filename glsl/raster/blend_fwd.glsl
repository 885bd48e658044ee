// α-blends the depth-sorted splats of one 16×16 tile per workgroup, front to back, one pixel
// per invocation. Also blends depth and FEAT extra per-Gaussian channels with the same weights
// w_i = α_i T_i (FEAT = 3: displacement flow; 2: Gaussian flow). FEAT = 0 compiles the
// feature path away entirely.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"

layout(local_size_x = TILE, local_size_y = TILE) in;

#include "blend_fwd_io.glsl"
#if FEAT > 0
shared float s_feat[TILE * TILE * FEAT];
#endif

shared vec4 s_a[TILE * TILE]; // mean2d, depth, opacity
shared vec4 s_b[TILE * TILE]; // conic, -
shared vec4 s_c[TILE * TILE]; // colour
shared uint s_done;

void main() {
    uint tid = gl_LocalInvocationIndex;
    uvec2 pix = gl_WorkGroupID.xy * TILE + gl_LocalInvocationID.xy;
    bool inside = pix.x < pc.width && pix.y < pc.height;
    uint tile = gl_WorkGroupID.y * pc.tiles_x + gl_WorkGroupID.x;
    uvec2 range = ranges[tile];
    vec2 centre = vec2(pix) + 0.5;

    bool done = !inside;
    float T = 1.0;
    vec3 C = vec3(0.0);
    float D = 0.0;
#if FEAT > 0
    float F[FEAT];
    for (int c = 0; c < FEAT; ++c) F[c] = 0.0;
#endif
    uint seen = 0, last = 0;

    for (uint start = range.x; start < range.y; start += TILE * TILE) {
        // Stop the tile once every pixel is saturated (the loop bound stays uniform).
        barrier();
        if (tid == 0) s_done = 0;
        barrier();
        if (done) atomicAdd(s_done, 1u);
        barrier();
        if (s_done == TILE * TILE) break;
        uint j = start + tid;
        if (j < range.y) {
            uint g = ids[j];
            s_a[tid] = splats[SPLAT_STRIDE * g];
            s_b[tid] = splats[SPLAT_STRIDE * g + 1];
            s_c[tid] = splats[SPLAT_STRIDE * g + 2];
#if FEAT > 0
            for (int c = 0; c < FEAT; ++c) s_feat[tid * FEAT + c] = feat[g * FEAT + c];
#endif
        }
        barrier();
        uint count = min(TILE * TILE, range.y - start);
        for (uint k = 0; k < count && !done; ++k) {
            ++seen;
            vec4 a = s_a[k];
            vec3 con = s_b[k].xyz;
            vec2 d = a.xy - centre;
            float sigma = splat_sigma(con, d);
            float alpha = min(pc.alpha_max, a.w * exp(-sigma));
            if (alpha < ALPHA_MIN) continue;
            float test_t = T * (1.0 - alpha);
            if (test_t < T_STOP) {
                done = true;
                break;
            }
            float w = alpha * T;
            C += w * s_c[k].rgb;
            D += w * a.z;
#if FEAT > 0
            for (int c = 0; c < FEAT; ++c) F[c] += w * s_feat[k * FEAT + c];
#endif
            T = test_t;
            last = seen;
        }
    }
    // A pixel not saturated has seen every splat of its tile, unless the device cut the loop
    // (llvmpipe ends an invocation's loops after 65 535 iterations in all, silently).
    if (!done && seen < range.y - range.x) atomicOr(overflow_word, OVERFLOW_WALK_CUT);
    if (!inside) return;
    uint p = pix.y * pc.width + pix.x;
    out_rgba[p] = vec4(C + T * pc.background.rgb, 1.0 - T);
    out_depth[p] = D;
    final_t[p] = T;
    n_contrib[p] = last;
#if FEAT > 0
    for (int c = 0; c < FEAT; ++c) out_feat[p * FEAT + c] = F[c];
#endif
}
