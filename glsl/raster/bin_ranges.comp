#version 460
// Per tile, the [start, end) range of its entries in the sorted intersection list (ranges of
// tiles without entries stay as cleared, (0, 0)).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { ProjectParams pc; };
layout(std430, binding = 0) readonly buffer Meta { uint meta[]; };
layout(std430, binding = 1) readonly buffer Keys { uvec2 keys[]; };
layout(std430, binding = 2) buffer Ranges { uvec2 ranges[]; };

void main() {
    uint n = meta[0];
    uint j = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (j >= n) return;
    uint tile = keys[j].y;
    if (j == 0u || keys[j - 1u].y != tile) ranges[tile].x = j;
    if (j + 1u == n || keys[j + 1u].y != tile) ranges[tile].y = j + 1u;
}
