#version 460
// Densify step 1/4, per original Gaussian: the demanded action (3DGS densify_and_clone /
// densify_and_split) and its growth in rows (clone +1, split +1: two children replace it).
//   dense  = denom > 0 && grad_accum >= grad_threshold · denom   (avg grad >= thr; NaN → false)
//   clone  = dense && max log-scale <= ln(percent_dense · extent)
//   split  = dense && max log-scale >  ln(percent_dense · extent)
// Comparing in this form keeps the decision exact f32 arithmetic (no division, no exp), so the
// GPU and the twin decide identically.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "densify.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { DensifyParams pc; };
layout(std430, binding = 0) readonly buffer GradAccum { float grad_accum[]; };  // [N]
layout(std430, binding = 1) readonly buffer Denom { float denom[]; };           // [N]
layout(std430, binding = 2) readonly buffer LogScales { float log_scales[]; };  // [N,3]
layout(std430, binding = 3) writeonly buffer Action { uint action[]; };         // [N] demanded code
layout(std430, binding = 4) writeonly buffer Growth { uint growth[]; };         // [N] 0 or 1

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.num_gaussians) return;
    float d = denom[i];
    bool dense = d > 0.0 && grad_accum[i] >= pc.grad_threshold * d;
    float ls = max_log_scale(log_scales[3u * i], log_scales[3u * i + 1u], log_scales[3u * i + 2u]);
    uint code = ACT_KEEP;
    if (dense && ls <= pc.log_dense_scale) code = ACT_CLONE;
    if (dense && ls > pc.log_dense_scale) code = ACT_SPLIT;
    action[i] = code;
    growth[i] = code == ACT_KEEP ? 0u : 1u;
}
