#version 460
// z-score only: per-workgroup (count, Σu, Σ(u − ū_wg)²) of u = m·2^-e ∈ [0, 1) — the
// workgroup's own centred second moment, merged exactly (Chan et al.) by norm_finalize.
// Deterministic: fixed-order tree sums, no float atomics.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "motion.glsl"

layout(local_size_x = MOTION_WG) in;

layout(push_constant) uniform Push { MotionNormParams pc; };
layout(std430, binding = 0) readonly buffer M { float m[]; };
layout(std430, binding = 1) readonly buffer Stats { uint stats[]; };
layout(std430, binding = 2) writeonly buffer Moments { vec4 moments[]; };

shared float s_sum[MOTION_WG];

float wg_sum(float x) {
    uint tid = gl_LocalInvocationIndex;
    s_sum[tid] = x;
    barrier();
    for (uint off = MOTION_WG / 2u; off > 0u; off >>= 1) {
        if (tid < off) s_sum[tid] += s_sum[tid + off];
        barrier();
    }
    float total = s_sum[0];
    barrier();
    return total;
}

void main() {
    uint wg = motion_group(pc.groups_x);
    uint p = wg * MOTION_WG + gl_LocalInvocationIndex;
    int e = int(stats[NS_EXP]);
    bool valid = p < pc.n;
    float u = valid ? ldexp(m[p], -e) : 0.0;
    float cnt = wg_sum(valid ? 1.0 : 0.0);
    float s = wg_sum(u);
    float mu = cnt > 0.0 ? s / cnt : 0.0;
    float d = valid ? u - mu : 0.0;
    float m2 = wg_sum(d * d);
    if (gl_LocalInvocationIndex == 0u) moments[wg] = vec4(cnt, s, m2, 0.0);
}
