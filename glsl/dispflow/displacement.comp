#version 460
// Per-Gaussian displacement δ_i = dx_i(t2) − dx_i(t1) from the two MLP outputs ([N,10]: dx
// first), the feature the rasteriser splats into the displacement flow F_disp.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { DispFlowParams pc; };
layout(std430, binding = 0) readonly buffer D1 { float d1[]; };
layout(std430, binding = 1) readonly buffer D2 { float d2[]; };
layout(std430, binding = 2) writeonly buffer Delta { float delta[]; };  // [N,3]

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n) return;
    for (uint a = 0; a < 3u; ++a) delta[3 * i + a] = d2[10 * i + a] - d1[10 * i + a];
}
