#version 460
// Depth-first binning, step 1: one u32 key per Gaussian, the depth bits bin_emit puts in the
// low word of its (tile | depth) keys, with the Gaussian's index as value. A stable sort of
// these orders equal depths by index, as the 64-bit sort orders them by emit order.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { BinParams pc; };
layout(std430, binding = 0) readonly buffer Splats { vec4 splats[]; };
layout(std430, binding = 1) writeonly buffer Keys { uint keys[]; };
layout(std430, binding = 2) writeonly buffer Vals { uint vals[]; };

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.num_gaussians) return;
    keys[i] = floatBitsToUint(splats[SPLAT_STRIDE * i].z);
    vals[i] = i;
}
