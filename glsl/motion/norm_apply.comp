#version 460
// m̂(p) = (m(p)·2^-e − offset) / denom, or 0 for every pixel when the map is degenerate.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "motion.glsl"

layout(local_size_x = MOTION_WG) in;

layout(push_constant) uniform Push { MotionNormParams pc; };
layout(std430, binding = 0) readonly buffer M { float m[]; };
layout(std430, binding = 1) readonly buffer Stats { uint stats[]; };
layout(std430, binding = 2) writeonly buffer MHat { float m_hat[]; };

void main() {
    uint p = motion_group(pc.groups_x) * MOTION_WG + gl_LocalInvocationIndex;
    if (p >= pc.n) return;
    float r = 0.0;
    if (stats[NS_FLAG] == FLAG_OK) {
        float u = ldexp(m[p], -int(stats[NS_EXP]));
        r = (u - uintBitsToFloat(stats[NS_OFFSET])) / uintBitsToFloat(stats[NS_DENOM]);
    }
    m_hat[p] = r;
}
