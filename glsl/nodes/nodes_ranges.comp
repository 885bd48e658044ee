#version 460
// Each node's range [start, end) in the pairs sorted by node (ranges zeroed before: a node
// no Gaussian uses keeps an empty range). NO_NODE pairs sort last and are skipped.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "nodes.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { NodesParams pc; };
layout(std430, binding = 0) readonly buffer Keys { uint keys[]; };  // [pairs] sorted
layout(std430, binding = 1) buffer Ranges { uint ranges[]; };      // [M,2]

void main() {
    uint p = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (p >= pc.n) return;
    uint key = keys[p];
    if (key >= pc.m) return;
    if (p == 0 || keys[p - 1] != key) ranges[2 * key] = p;
    if (p + 1 == pc.n || keys[p + 1] != key) ranges[2 * key + 1] = p + 1;
}
