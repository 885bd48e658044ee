#version 460
// Backward, stage 2 (one workgroup): G, H from the partials, then the coefficients of
// ∂L/∂u_q = g_q/d + c0 + c1·m̂_q + Σ_k [q == pix_k]·w_k, from ∂L/∂offset = −G/d and
// ∂L/∂denom = −H/d:
//   min-max  argmin += (H − G)/d, argmax += −H/d          (offset = min, denom = max − min)
//   max-abs  argmax += −H/d
//   z-score  c0 = −G/(d·N), c1 = −H/(d·N)                 (∂mean/∂u = 1/N, ∂std/∂u_q = m̂_q/N)
//   IQR      median pixels −G/d, q75 pixels −H/d, q25 pixels +H/d, times (1 − frac, frac)
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "motion.glsl"

layout(local_size_x = MOTION_WG) in;

layout(push_constant) uniform Push { MotionNormParams pc; };
layout(std430, binding = 0) readonly buffer Sums { vec2 sums[]; };
layout(std430, binding = 1) readonly buffer Stats { uint stats[]; };
layout(std430, binding = 2) writeonly buffer Coef { uint coef[]; };

shared vec2 s_sum[MOTION_WG];

void special(uint k, uint pixel, float w) {
    coef[NB_SPECIAL + 2u * k] = pixel;
    coef[NB_SPECIAL + 2u * k + 1u] = floatBitsToUint(w);
}

void main() {
    uint tid = gl_LocalInvocationIndex;
    vec2 acc = vec2(0.0);
    for (uint i = tid; i < pc.groups; i += MOTION_WG) acc += sums[i];
    s_sum[tid] = acc;
    barrier();
    for (uint off = MOTION_WG / 2u; off > 0u; off >>= 1) {
        if (tid < off) s_sum[tid] += s_sum[tid + off];
        barrier();
    }
    if (tid != 0u) return;
    float d = uintBitsToFloat(stats[NS_DENOM]);
    bool ok = stats[NS_FLAG] == FLAG_OK;
    float inv_d = ok ? 1.0 / d : 0.0;   // d ∈ [FLT_MIN, 1) when ok: finite
    float dl_do = -s_sum[0].x * inv_d;
    float dl_dd = -s_sum[0].y * inv_d;
    float c0 = 0.0, c1 = 0.0;
    for (uint k = 0u; k < 6u; ++k) special(k, NONE, 0.0);
    if (ok && pc.detach == 0u) {
        if (pc.mode == MODE_MINMAX) {
            special(0u, stats[NS_ARGMIN], dl_do - dl_dd);
            special(1u, stats[NS_ARGMAX], dl_dd);
        } else if (pc.mode == MODE_MAXABS) {
            special(0u, stats[NS_ARGMAX], dl_dd);
        } else if (pc.mode == MODE_ZSCORE) {
            float inv_n = 1.0 / float(pc.n);
            c0 = dl_do * inv_n;
            c1 = dl_dd * inv_n;
        } else {
            float fr[3] = float[3](pc.q25_frac, pc.q50_frac, pc.q75_frac);
            float w[3] = float[3](-dl_dd, dl_do, dl_dd);
            for (uint q = 0u; q < 3u; ++q) {
                special(2u * q, stats[NS_QPIX + 2u * q], w[q] * (1.0 - fr[q]));
                special(2u * q + 1u, stats[NS_QPIX + 2u * q + 1u], w[q] * fr[q]);
            }
        }
    }
    coef[NB_CG] = floatBitsToUint(inv_d);
    coef[NB_C0] = floatBitsToUint(c0);
    coef[NB_C1] = floatBitsToUint(c1);
    coef[3] = 0u;
}
