// α-blends the depth-sorted splats of one 16×16 tile per workgroup, front to back, one pixel
// per invocation. Also blends depth and FEAT extra per-Gaussian channels with the same weights
// w_i = α_i T_i (FEAT = 3: displacement flow; 2: Gaussian flow). FEAT = 0 compiles the
// feature path away entirely.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"

layout(local_size_x = TILE, local_size_y = TILE) in;

layout(push_constant) uniform Push { BlendParams pc; };
layout(std430, binding = 0) readonly buffer Ranges { uvec2 ranges[]; };
layout(std430, binding = 1) readonly buffer Ids { uint ids[]; };         // sorted Gaussian ids
layout(std430, binding = 2) readonly buffer Splats { vec4 splats[]; };
layout(std430, binding = 3) writeonly buffer OutRgba { vec4 out_rgba[]; }; // rgb + alpha
layout(std430, binding = 4) writeonly buffer OutDepth { float out_depth[]; }; // Σ w z
layout(std430, binding = 5) writeonly buffer FinalT { float final_t[]; };
layout(std430, binding = 6) writeonly buffer NContrib { uint n_contrib[]; };
#if FEAT > 0
layout(std430, binding = 7) readonly buffer Feat { float feat[]; };         // [N,FEAT]
layout(std430, binding = 8) writeonly buffer OutFeat { float out_feat[]; }; // [H·W,FEAT]
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
