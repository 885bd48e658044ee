#version 460
// Compacts the dynamic set after the exclusive scan of its flags: the dynamic Gaussians'
// indices in ascending order (`idx`), each Gaussian's row in that list or NO_ROW
// (`row_of`), and the count (written by the last Gaussian; n >= 1).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { RowsParams pc; };
layout(std430, binding = 0) readonly buffer Flags { uint flags[]; };     // [N] 0/1
layout(std430, binding = 1) readonly buffer Offsets { uint offsets[]; }; // [N] exclusive scan
layout(std430, binding = 2) writeonly buffer Idx { uint idx[]; };        // [count]
layout(std430, binding = 3) writeonly buffer RowOf { uint row_of[]; };   // [N]
layout(std430, binding = 4) writeonly buffer Count { uint count[]; };    // [1]

const uint NO_ROW = 0xffffffffu;

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n) return;
    uint f = flags[i] != 0u ? 1u : 0u;
    uint o = offsets[i];
    if (f != 0u) idx[o] = i;
    row_of[i] = f != 0u ? o : NO_ROW;
    if (i == pc.n - 1u) count[0] = o + f;
}
