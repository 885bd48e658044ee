#version 460
// The dynamic flag from the probe's apparent motion (column 20 of the range rows): 1 where
// it exceeds the threshold the host chose from the probe's distribution (see
// train::passes::sparsity). A separate stage so the threshold can depend on all Gaussians.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { FlagParams pc; };
layout(std430, binding = 0) readonly buffer Range { float range[]; }; // [N,21]
layout(std430, binding = 1) writeonly buffer Flags { uint flags[]; }; // [N]

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n) return;
    flags[i] = range[21 * i + 20] > pc.threshold_px ? 1u : 0u;
}
