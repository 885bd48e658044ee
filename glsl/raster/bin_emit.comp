#version 460
// One (tile | depth) key per tile a Gaussian overlaps, at the offset the prefix sum of the
// tile counts gave it. Keys are u64 as (low = depth bits, high = tile id): depth > near > 0,
// so its float bits order like the value. Writes past the capacity are dropped here but the
// total is still counted (bin_total), so the host sees the overflow and re-runs; never a
// silently missing splat.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { ProjectParams pc; };
layout(std430, binding = 0) readonly buffer Splats { vec4 splats[]; };
layout(std430, binding = 1) readonly buffer Rects { uvec4 rects[]; };
layout(std430, binding = 2) readonly buffer Offsets { uint offsets[]; };
layout(std430, binding = 3) writeonly buffer Keys { uvec2 keys[]; };
layout(std430, binding = 4) writeonly buffer Vals { uint vals[]; };

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.num_gaussians) return;
    uvec4 r = rects[i];
    uint depth_bits = floatBitsToUint(splats[SPLAT_STRIDE * i].z);
    uint o = offsets[i];
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
