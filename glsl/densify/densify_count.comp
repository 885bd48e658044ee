#version 460
// Densify step 3/4: the new Gaussian count, offsets[N−1] + rows[N−1] (0 when N = 0), into a
// GPU u32 the host reads after the submit.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 1) in;

layout(push_constant) uniform Push { DensifyParams pc; };
layout(std430, binding = 0) readonly buffer Offsets { uint offsets[]; };  // [N] exclusive scan of rows
layout(std430, binding = 1) readonly buffer Rows { uint rows[]; };        // [N]
layout(std430, binding = 2) writeonly buffer Count { uint count[]; };

void main() {
    uint n = pc.num_gaussians;
    count[0] = n == 0u ? 0u : offsets[n - 1u] + rows[n - 1u];
}
