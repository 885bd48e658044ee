#version 460
// One LPIPS stage: per pixel, each image's features divided by their channel norm (+1e-10 as
// the reference), squared difference, weighted by the learned 1×1 linear layer, times
// 1 / (H·W); per-workgroup partial sums (deterministic: no float atomics), summed on the host.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 64) in;

layout(push_constant) uniform Push { LpipsDiffParams pc; };
layout(std430, binding = 0) readonly buffer Feats { float feats[]; };      // [2][C][H·W]
layout(std430, binding = 1) readonly buffer Weights { float weights[]; };  // lin at lin_off
layout(std430, binding = 2) writeonly buffer Sums { float sums[]; };       // [slots]

shared float s_sum[64];

void main() {
    uint p = gl_GlobalInvocationID.x;
    uint hw = pc.width * pc.height;
    float v = 0.0;
    if (p < hw) {
        uint other = pc.channels * hw;
        float n0 = 0.0, n1 = 0.0;
        for (uint c = 0; c < pc.channels; ++c) {
            float a = feats[c * hw + p], b = feats[other + c * hw + p];
            n0 += a * a;
            n1 += b * b;
        }
        float d0 = sqrt(n0) + 1e-10, d1 = sqrt(n1) + 1e-10;
        for (uint c = 0; c < pc.channels; ++c) {
            float e = feats[c * hw + p] / d0 - feats[other + c * hw + p] / d1;
            v += weights[pc.lin_off + c] * e * e;
        }
        v *= pc.inv_count;
    }
    uint tid = gl_LocalInvocationIndex;
    s_sum[tid] = v;
    barrier();
    for (uint off = 32u; off > 0u; off >>= 1) {
        if (tid < off) s_sum[tid] += s_sum[tid + off];
        barrier();
    }
    if (tid == 0u) sums[pc.sum_off + gl_WorkGroupID.x] = s_sum[0];
}
