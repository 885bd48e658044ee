#version 460
// Backward, stage 1: per-workgroup G = Σ g and H = Σ g·m̂ (g = ∂L/∂m̂), the two sums through
// which every pixel's gradient reaches the offset and the denominator. Fixed-order tree sums.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "motion.glsl"

layout(local_size_x = MOTION_WG) in;

layout(push_constant) uniform Push { MotionNormParams pc; };
layout(std430, binding = 0) readonly buffer DMHat { float d_m_hat[]; };
layout(std430, binding = 1) readonly buffer MHat { float m_hat[]; };
layout(std430, binding = 2) writeonly buffer Sums { vec2 sums[]; };

shared vec2 s_sum[MOTION_WG];

void main() {
    uint wg = motion_group(pc.groups_x);
    uint tid = gl_LocalInvocationIndex;
    uint p = wg * MOTION_WG + tid;
    vec2 x = vec2(0.0);
    if (p < pc.n) {
        float g = d_m_hat[p];
        x = vec2(g, g * m_hat[p]);
    }
    s_sum[tid] = x;
    barrier();
    for (uint off = MOTION_WG / 2u; off > 0u; off >>= 1) {
        if (tid < off) s_sum[tid] += s_sum[tid + off];
        barrier();
    }
    if (tid == 0u) sums[wg] = s_sum[0];
}
