#version 460
// Opacity reset (3DGS reset_opacity, every 3000 iterations): opacity ← min(opacity, 0.01), done
// on logits as logit ← min(logit, logit(0.01)) (sigmoid is monotone: the same value without a
// sigmoid/logit round trip; a NaN logit becomes logit(0.01)), and the opacity's Adam m, v
// zeroed as 3DGS replaces that optimizer state.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { OpacityResetParams pc; };
layout(std430, binding = 0) buffer Opacity { float logits[]; };      // [N]
layout(std430, binding = 1) writeonly buffer M { float m[]; };       // [N] opacity section of Adam m
layout(std430, binding = 2) writeonly buffer V { float v[]; };       // [N] opacity section of Adam v

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.num_gaussians) return;
    float x = logits[i];
    logits[i] = x < pc.reset_logit ? x : pc.reset_logit;
    m[i] = 0.0;
    v[i] = 0.0;
}
