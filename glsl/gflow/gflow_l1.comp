#version 460
// Gaussian-flow loss α · (1/N) Σ_p c_p · (|e_x| + |e_y|), e = (F_gauss(p) − F_scene(p)) / s,
// with F_gauss(p) = G(p)·p + B(p) composed from the six blended channels at the pixel centre
// p, and its gradient wrt those channels. L1 on the vectors as GaussianFlow/MotionGS; the one
// scale s is the denominator the scene motion's normalisation divides its magnitudes by
// (max − min for min-max), read from its statistics on the GPU, so α weighs both motion
// representations on the same footing. A degenerate scene map skips the term (zero value and
// gradient), as in motion_l1. Per-workgroup partial sums of c·(|e_x| + |e_y|).
// Twin: reference::gflow::l1.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "gflow.glsl"

// Statistics words (mirror glsl/motion/motion.glsl).
#define NS_FLAG 0
#define NS_EXP 1
#define NS_DENOM 3

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { GFlowParams pc; };
layout(std430, binding = 0) readonly buffer Feat { float feat[]; };     // [H·W, 6] blended
layout(std430, binding = 1) readonly buffer Scene { vec2 scene[]; };    // [H·W]
layout(std430, binding = 2) readonly buffer Stats { uint stats[]; };    // the scene's norm stats
layout(std430, binding = 3) writeonly buffer DFeat { float d_feat[]; }; // [H·W, 6]
layout(std430, binding = 4) writeonly buffer Sums { float sums[]; };    // [groups]
layout(std430, binding = 5) readonly buffer Conf { float conf[]; };     // [H·W] when pc.conf

shared float s_sum[256];

void main() {
    uint p = gl_GlobalInvocationID.x;
    float s = ldexp(uintBitsToFloat(stats[NS_DENOM]), int(stats[NS_EXP]));
    bool skip = stats[NS_FLAG] != 0u || !(s > 0.0) || isinf(s);
    float v = 0.0;
    if (p < pc.n) {
        vec2 px = vec2(float(p % pc.width), float(p / pc.width)) + 0.5;
        uint o = GF_FEAT * p;
        vec2 f = vec2(feat[o] * px.x + feat[o + 1] * px.y + feat[o + 4],
                      feat[o + 2] * px.x + feat[o + 3] * px.y + feat[o + 5]);
        float c = pc.conf != 0u ? conf[p] : 1.0;
        vec2 e = (f - scene[p]) / s;
        vec2 g = skip ? vec2(0.0) : pc.weight * c * sign(e) / (s * float(pc.n));
        d_feat[o] = g.x * px.x;
        d_feat[o + 1] = g.x * px.y;
        d_feat[o + 2] = g.y * px.x;
        d_feat[o + 3] = g.y * px.y;
        d_feat[o + 4] = g.x;
        d_feat[o + 5] = g.y;
        v = skip ? 0.0 : c * (abs(e.x) + abs(e.y));
    }
    uint tid = gl_LocalInvocationIndex;
    s_sum[tid] = v;
    barrier();
    for (uint off = 128u; off > 0u; off >>= 1) {
        if (tid < off) s_sum[tid] += s_sum[tid + off];
        barrier();
    }
    if (tid == 0u) sums[gl_WorkGroupID.x] = s_sum[0];
}
