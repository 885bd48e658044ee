#version 460
// Backward of δ = dx(t2) − dx(t1): ∂L/∂dx(t1) −= ∂L/∂δ (added to the gradient the drawn
// Gaussians already gave dx(t1)); ∂L/∂out(t2) = (∂L/∂δ, 0, …) for the second MLP backward.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { DispFlowParams pc; };
layout(std430, binding = 0) readonly buffer DDelta { float d_delta[]; };  // [N,3]
layout(std430, binding = 1) buffer DOut1 { float d_out1[]; };             // [N,10], updated
layout(std430, binding = 2) writeonly buffer DOut2 { float d_out2[]; };   // [N,10]

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n) return;
    for (uint a = 0; a < 3u; ++a) {
        float g = d_delta[3 * i + a];
        d_out1[10 * i + a] -= g;
        d_out2[10 * i + a] = g;
    }
    for (uint a = 3; a < 10u; ++a) d_out2[10 * i + a] = 0.0;
}
