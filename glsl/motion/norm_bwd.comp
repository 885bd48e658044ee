#version 460
// Backward, stage 3: ∂L/∂v(p) = ∂L/∂m(p) · v(p)/|v(p)| (0 where |v| = 0, or everywhere when the
// map is degenerate), with ∂L/∂m = 2^-e · ∂L/∂u from the coefficients of norm_bwd_finalize.
// The direction is computed from the largest component, like the forward magnitude.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "motion.glsl"

layout(local_size_x = MOTION_WG) in;

layout(push_constant) uniform Push { MotionNormParams pc; };
layout(std430, binding = 0) readonly buffer V { float v[]; };
layout(std430, binding = 1) readonly buffer MHat { float m_hat[]; };
layout(std430, binding = 2) readonly buffer DMHat { float d_m_hat[]; };
layout(std430, binding = 3) readonly buffer Stats { uint stats[]; };
layout(std430, binding = 4) readonly buffer Coef { uint coef[]; };
layout(std430, binding = 5) writeonly buffer DV { float dv[]; };

void main() {
    uint p = motion_group(pc.groups_x) * MOTION_WG + gl_LocalInvocationIndex;
    if (p >= pc.n) return;
    uint b = p * pc.channels;
    vec3 x = vec3(v[b], v[b + 1u], pc.channels == 3u ? v[b + 2u] : 0.0);
    vec3 g = vec3(0.0);
    if (stats[NS_FLAG] == FLAG_OK) {
        float du = d_m_hat[p] * uintBitsToFloat(coef[NB_CG]) + uintBitsToFloat(coef[NB_C0])
                 + uintBitsToFloat(coef[NB_C1]) * m_hat[p];
        for (uint k = 0u; k < 6u; ++k) {
            if (coef[NB_SPECIAL + 2u * k] == p) du += uintBitsToFloat(coef[NB_SPECIAL + 2u * k + 1u]);
        }
        float dm = ldexp(du, -int(stats[NS_EXP]));
        float s = max(max(abs(x.x), abs(x.y)), abs(x.z));
        if (s > 0.0) {
            vec3 a = x / s;
            g = dm * a / sqrt(dot(a, a));
        }
    }
    dv[b] = g.x;
    dv[b + 1u] = g.y;
    if (pc.channels == 3u) dv[b + 2u] = g.z;
}
