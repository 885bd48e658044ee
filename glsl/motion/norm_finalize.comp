#version 460
// One workgroup: finishes the statistics the mode needs and the affine map m̂ = (u − offset) /
// denom in the u = m·2^-e domain, then the flag: non-finite input, or a flat map (denominator
// below eps in magnitude units, or below REL_FLAT relative to 2^e — to q75 for IQR — where f32
// cannot resolve the spread) — the caller then skips the motion term; nothing is ever divided
// by ~0.
// z-score: exact merge of the per-workgroup moments: mean = Σs / N,
// M2 = Σ [M2_w + n_w·(s_w/n_w − mean)²], std = sqrt(M2 / N) (population).
// IQR: linear interpolation between the order statistics at the host-computed positions of the
// stably sorted magnitudes (keys = float bits, values = pixels).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "motion.glsl"

layout(local_size_x = MOTION_WG) in;

layout(push_constant) uniform Push { MotionNormParams pc; };
layout(std430, binding = 0) readonly buffer Moments { vec4 moments[]; };
layout(std430, binding = 1) readonly buffer Keys { uint keys[]; };  // sorted ascending
layout(std430, binding = 2) readonly buffer Vals { uint vals[]; };  // pixel of each key
layout(std430, binding = 3) buffer Stats { uint stats[]; };

shared vec2 s_sum[MOTION_WG];

vec2 wg_sum2(vec2 x) {
    uint tid = gl_LocalInvocationIndex;
    s_sum[tid] = x;
    barrier();
    for (uint off = MOTION_WG / 2u; off > 0u; off >>= 1) {
        if (tid < off) s_sum[tid] += s_sum[tid + off];
        barrier();
    }
    vec2 total = s_sum[0];
    barrier();
    return total;
}

float quantile(uint lo, float frac, int e, uint k) {
    uint hi = min(lo + 1u, pc.n - 1u);
    float a = ldexp(uintBitsToFloat(keys[lo]), -e);
    float b = ldexp(uintBitsToFloat(keys[hi]), -e);
    if (gl_LocalInvocationIndex == 0u) {
        stats[NS_QPIX + 2u * k] = vals[lo];
        stats[NS_QPIX + 2u * k + 1u] = vals[hi];
    }
    return a + frac * (b - a);
}

void main() {
    uint tid = gl_LocalInvocationIndex;
    uint flag = stats[NS_FLAG];
    int e = int(stats[NS_EXP]);
    float min_u = ldexp(uintBitsToFloat(stats[NS_MIN]), -e);
    float max_u = ldexp(uintBitsToFloat(stats[NS_MAX]), -e);
    float offset = 0.0, denom = 0.0, rel = 1.0;
    if (pc.mode == MODE_MINMAX) {
        offset = min_u;
        denom = max_u - min_u;
    } else if (pc.mode == MODE_MAXABS) {
        denom = max_u;
    } else if (pc.mode == MODE_ZSCORE) {
        vec2 acc = vec2(0.0);
        for (uint i = tid; i < pc.groups; i += MOTION_WG) acc += moments[i].xy;
        vec2 tot = wg_sum2(acc);  // (N, Σu)
        float mean = tot.y / max(tot.x, 1.0);
        float m2 = 0.0;
        for (uint i = tid; i < pc.groups; i += MOTION_WG) {
            vec4 w = moments[i];
            if (w.x > 0.0) {
                float d = w.y / w.x - mean;
                m2 += w.z + w.x * d * d;
            }
        }
        float var = wg_sum2(vec2(m2, 0.0)).x / max(tot.x, 1.0);
        offset = mean;
        denom = sqrt(max(var, 0.0));
        if (tid == 0u) {
            stats[NS_MEAN] = floatBitsToUint(mean);
            stats[NS_STD] = floatBitsToUint(denom);
        }
    } else {
        float q25 = quantile(pc.q25_lo, pc.q25_frac, e, 0u);
        float q50 = quantile(pc.q50_lo, pc.q50_frac, e, 1u);
        float q75 = quantile(pc.q75_lo, pc.q75_frac, e, 2u);
        offset = q50;
        denom = q75 - q25;
        rel = q75;
        if (tid == 0u) {
            stats[NS_Q] = floatBitsToUint(q25);
            stats[NS_Q + 1u] = floatBitsToUint(q50);
            stats[NS_Q + 2u] = floatBitsToUint(q75);
        }
    }
    if (tid == 0u) {
        // Third test: a denominator that is not a normal f32 in the u domain (possible only for
        // IQR with quartiles ~2^-126 below the max, or eps = 0) would make 1/denom overflow.
        bool is_flat = !(ldexp(denom, e) >= pc.eps) || !(denom >= REL_FLAT * rel) || !(denom >= FLT_MIN);
        if (flag == FLAG_OK && is_flat) flag = FLAG_FLAT;
        stats[NS_FLAG] = flag;
        stats[NS_OFFSET] = floatBitsToUint(offset);
        stats[NS_DENOM] = floatBitsToUint(denom);
    }
}
