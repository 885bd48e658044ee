#version 460
// Depth-first binning, step 2: the tile counts in depth order (counts_sorted[j] = tiles of the
// j-th nearest Gaussian), for the prefix sum that places each Gaussian's intersections.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { BinParams pc; };
layout(std430, binding = 0) readonly buffer Order { uint order[]; }; // Gaussians by depth
layout(std430, binding = 1) readonly buffer Counts { uint counts[]; };
layout(std430, binding = 2) writeonly buffer CountsSorted { uint counts_sorted[]; };

void main() {
    uint j = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (j >= pc.num_gaussians) return;
    counts_sorted[j] = counts[order[j]];
}
