#version 460
// Counts the non-finite floats (NaN, ±Inf) of x[first, first + count) into counts[slot] and
// keeps the smallest offending index (relative to first) in counts[slots + slot]; the host
// fills the counts with 0 and the indices with 0xFFFFFFFF first. The collapse guard runs it
// over the model's parameters at every probe render: a Gaussian with a NaN mean is culled by
// the projection, so it never shows in a loss or a render, only in the saved model.
// The test is on the exponent bits, so no compiler's float assumptions can drop it.
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_ballot : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { CheckParams pc; };
layout(std430, binding = 0) readonly buffer X { float x[]; };   // [first + count]
layout(std430, binding = 1) buffer Counts { uint counts[]; };    // [2 · slots]

void main() {
    uint j = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    // No early return: every lane takes part in the subgroup reductions.
    bool bad = j < pc.count && (floatBitsToUint(x[pc.first + min(j, pc.count - 1u)]) & 0x7f800000u) == 0x7f800000u;
    uint n = subgroupAdd(bad ? 1u : 0u);
    uint lo = subgroupMin(bad ? j : 0xFFFFFFFFu);
    if (n > 0u && subgroupElect()) {
        atomicAdd(counts[pc.slot], n);
        atomicMin(counts[pc.slots + pc.slot], lo);
    }
}
