#version 460
// dst[j] = src[idx[j]] for whole rows of `width` floats, j < n (the dynamic rows): feeds the
// MLP the dynamic Gaussians' means, and its backward their output gradients.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { RowsParams pc; };
layout(std430, binding = 0) readonly buffer Idx { uint idx[]; };   // [n]
layout(std430, binding = 1) readonly buffer Src { float src[]; };  // [N, width]
layout(std430, binding = 2) writeonly buffer Dst { float dst[]; }; // [n, width]

void main() {
    uint j = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (j >= pc.n) return;
    uint s = idx[j] * pc.width, o = j * pc.width;
    for (uint c = 0; c < pc.width; ++c) dst[o + c] = src[s + c];
}
