#version 460
// nodes_gather's sums in one invocation per node, a plain loop over its sorted pairs: no
// shared memory, no barriers. The shape for CPU devices (lavapipe), where the one-workgroup-
// per-node tree's barriers and shared arrays cost 15x this (tests/nodes.rs, bench step);
// on a GPU a node with thousands of pairs would serialise, so GPUs keep the tree. Same
// bindings, same outputs, same deterministic order for a given input.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "nodes.glsl"

layout(local_size_x = 64) in;

layout(push_constant) uniform Push { NodesParams pc; };
layout(std430, binding = 0) readonly buffer Ranges { uint ranges[]; };    // [M,2]
layout(std430, binding = 1) readonly buffer Vals { uint vals[]; };        // sorted pair ids
layout(std430, binding = 2) readonly buffer Contrib { vec4 contrib[]; };  // [pairs,4] (CONTRIB_VEC4)
layout(std430, binding = 3) writeonly buffer DNodeOut { vec2 d_out[]; };  // [M,10] as [M,5]
layout(std430, binding = 4) buffer GNodes { float g_nodes[]; };           // [4M]

void main() {
    uint j = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (j >= pc.m) return;
    vec4 acc4[CONTRIB_VEC4];
    for (uint c = 0; c < CONTRIB_VEC4; ++c) acc4[c] = vec4(0.0);
    for (uint p = ranges[2 * j]; p < ranges[2 * j + 1]; ++p) {
        uint o = vals[p] * CONTRIB_VEC4;
        for (uint c = 0; c < CONTRIB_VEC4; ++c) acc4[c] += contrib[o + c];
    }
    float acc[CONTRIB];
    for (uint c = 0; c < CONTRIB; ++c) acc[c] = acc4[c / 4][c % 4];
    for (uint c = 0; c < 5u; ++c) d_out[5 * j + c] = vec2(acc[2 * c], acc[2 * c + 1]);
    for (uint c = 10u; c < CONTRIB; ++c) {
        uint o = c < 13u ? 3 * j + (c - 10u) : 3 * pc.m + j;
        if ((pc.flags & 1u) != 0u) g_nodes[o] += acc[c]; else g_nodes[o] = acc[c];
    }
}
