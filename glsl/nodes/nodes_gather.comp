#version 460
// Per-node sums of the contribution rows of the pairs sorted by node (one workgroup per
// node; strided partial sums then a fixed tree in shared memory: deterministic, no atomics).
// Writes ∂L/∂node_out [M,10] (the MLP's output gradient) and writes (flags 0) or adds
// (flags 1: a step's second time slot) ∂L/∂p, ∂L/∂ρ into the node-parameter gradients.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "nodes.glsl"

#define WG 64
layout(local_size_x = WG) in;

layout(push_constant) uniform Push { NodesParams pc; };
layout(std430, binding = 0) readonly buffer Ranges { uint ranges[]; };    // [M,2]
layout(std430, binding = 1) readonly buffer Vals { uint vals[]; };        // sorted pair ids
layout(std430, binding = 2) readonly buffer Contrib { vec4 contrib[]; };  // [pairs,4] (CONTRIB_VEC4)
layout(std430, binding = 3) writeonly buffer DNodeOut { float d_out[]; }; // [M,10]
layout(std430, binding = 4) buffer GNodes { float g_nodes[]; };           // [4M]

shared float part[CONTRIB][WG];

void main() {
    uint j = gl_WorkGroupID.x + gl_WorkGroupID.y * gl_NumWorkGroups.x;
    uint t = gl_LocalInvocationID.x;
    if (j >= pc.m) return; // whole workgroup: uniform
    uint start = ranges[2 * j], end = ranges[2 * j + 1];
    vec4 acc4[CONTRIB_VEC4];
    for (uint c = 0; c < CONTRIB_VEC4; ++c) acc4[c] = vec4(0.0);
    for (uint p = start + t; p < end; p += WG) {
        uint o = vals[p] * CONTRIB_VEC4;
        for (uint c = 0; c < CONTRIB_VEC4; ++c) acc4[c] += contrib[o + c];
    }
    float acc[CONTRIB];
    for (uint c = 0; c < CONTRIB; ++c) acc[c] = acc4[c / 4][c % 4];
    for (uint c = 0; c < CONTRIB; ++c) part[c][t] = acc[c];
    barrier();
    for (uint h = WG / 2; h > 0; h >>= 1) {
        if (t < h)
            for (uint c = 0; c < CONTRIB; ++c) part[c][t] += part[c][t + h];
        barrier();
    }
    if (t < 10u) {
        d_out[10 * j + t] = part[t][0];
    } else if (t < CONTRIB) {
        uint o = t < 13u ? 3 * j + (t - 10u) : 3 * pc.m + j;
        float v = part[t][0];
        if ((pc.flags & 1u) != 0u) g_nodes[o] += v; else g_nodes[o] = v;
    }
}
