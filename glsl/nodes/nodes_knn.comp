#version 460
// K nearest control nodes of every Gaussian by squared distance between canonical positions
// (brute force over the M nodes: M is a few hundred and this runs every few hundred steps),
// nearest first, ties to the lower node index; NO_NODE fills the slots when M < K, and every
// slot of a static Gaussian when the model is split (flags 1).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "nodes.glsl"

layout(local_size_x = 128) in;

layout(push_constant) uniform Push { NodesParams pc; };
layout(std430, binding = 0) readonly buffer Means { float means[]; };   // [N,3] canonical
layout(std430, binding = 1) readonly buffer Nodes { float nodes[]; };   // [4M] positions, ρ
layout(std430, binding = 2) readonly buffer RowOf { uint row_of[]; };   // [N] (flags 1)
layout(std430, binding = 3) writeonly buffer Knn { uint knn[]; };       // [N,K]

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n) return;
    float best[NODES_KMAX];
    uint idx[NODES_KMAX];
    for (uint s = 0; s < NODES_KMAX; ++s) {
        best[s] = 1.0 / 0.0;
        idx[s] = NO_NODE;
    }
    bool wanted = (pc.flags & 1u) == 0u || row_of[i] != 0xffffffffu;
    vec3 mu = vec3(means[3 * i], means[3 * i + 1], means[3 * i + 2]);
    for (uint j = 0; wanted && j < pc.m; ++j) {
        // `precise`: no fused multiply-add, so the CPU twin's f32 distances (and ties) match.
        precise float dx = mu.x - nodes[3 * j];
        precise float dy = mu.y - nodes[3 * j + 1];
        precise float dz = mu.z - nodes[3 * j + 2];
        precise float d = dx * dx + dy * dy + dz * dz;
        if (!(d < best[pc.k - 1])) continue; // strict: a tie keeps the lower index (NaN: never)
        uint s = pc.k - 1;
        while (s > 0 && d < best[s - 1]) {
            best[s] = best[s - 1];
            idx[s] = idx[s - 1];
            --s;
        }
        best[s] = d;
        idx[s] = j;
    }
    for (uint s = 0; s < pc.k; ++s) knn[i * pc.k + s] = idx[s];
}
