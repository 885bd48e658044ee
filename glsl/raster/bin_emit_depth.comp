#version 460
// Depth-first binning, step 3: bin_emit's (tile | depth) keys, emitted in depth order (the j-th
// nearest Gaussian at the offset the prefix sum of the depth-ordered counts gave it). The list
// is then sorted by depth within any tile already, and a stable sort of the tile bits alone
// gives bin_emit's fully sorted list: equal depths stay in index order, as there. Writes past
// the capacity are dropped; bin_total still counts them (the host re-runs with more room).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { BinParams pc; };
layout(std430, binding = 0) readonly buffer Splats { vec4 splats[]; };
layout(std430, binding = 1) readonly buffer Rects { uvec4 rects[]; };
layout(std430, binding = 2) readonly buffer Order { uint order[]; };
layout(std430, binding = 3) readonly buffer Offsets { uint offsets[]; }; // depth order
layout(std430, binding = 4) writeonly buffer Keys { uvec2 keys[]; };
layout(std430, binding = 5) writeonly buffer Vals { uint vals[]; };

void main() {
    uint j = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (j >= pc.num_gaussians) return;
    uint i = order[j];
    uvec4 r = rects[i];
    uint depth_bits = floatBitsToUint(splats[SPLAT_STRIDE * i].z);
    uint o = offsets[j];
    for (uint ty = r.y; ty < r.w; ++ty) {
        for (uint tx = r.x; tx < r.z; ++tx) {
            if (o < pc.isect_capacity) {
                keys[o] = uvec2(depth_bits, ty * pc.tiles_x + tx);
                vals[o] = i;
            }
            ++o;
        }
    }
}
