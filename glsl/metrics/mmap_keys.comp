#version 460
// MMAP, stage 1: sort input for a descending order of the scores. key = ~ordered(score), where
// ordered() maps float bits to a u32 that orders like the float (negative: all bits flipped;
// non-negative: sign bit set); −0 is first turned into +0 so both are one score. value = the
// label (mask != 0 → 1). Scores must not be NaN.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "metrics.glsl"

layout(local_size_x = METRICS_WG) in;

layout(push_constant) uniform Push { MetricsParams pc; };
layout(std430, binding = 0) readonly buffer Score { float score[]; };
layout(std430, binding = 1) readonly buffer Mask { uint mask[]; };
layout(std430, binding = 2) writeonly buffer Keys { uint keys[]; };
layout(std430, binding = 3) writeonly buffer Labels { uint labels[]; };

void main() {
    uint p = metrics_group(pc.groups_x) * METRICS_WG + gl_LocalInvocationIndex;
    if (p >= pc.n) return;
    uint bits = floatBitsToUint(score[p]);
    if ((bits & 0x7FFFFFFFu) == 0u) bits = 0u;  // −0 → +0
    uint ordered = (bits & 0x80000000u) != 0u ? ~bits : bits | 0x80000000u;
    keys[p] = ~ordered;
    labels[p] = mask[p] != 0u ? 1u : 0u;
}
