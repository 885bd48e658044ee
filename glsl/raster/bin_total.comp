#version 460
// Total tile intersections = last exclusive offset + last count. meta[0] = total clamped to the
// capacity (the sort's count), meta[1] = unclamped total (the host compares it with the capacity
// after the step and re-runs with grown buffers on overflow), meta[4..7] = the indirect dispatch
// size of bin_ranges (2D beyond 32768 workgroups), meta[64] = OVERFLOW_CAPACITY on overflow (at byte 256, so it
// can be bound alone as the optimiser's skip flag), meta[65] = total again (read with the flag).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"

layout(local_size_x = 1) in;

layout(push_constant) uniform Push { ProjectParams pc; };
layout(std430, binding = 0) readonly buffer Offsets { uint offsets[]; };
layout(std430, binding = 1) readonly buffer Counts { uint counts[]; };
layout(std430, binding = 2) writeonly buffer Meta { uint meta[]; };

void main() {
    uint n = pc.num_gaussians;
    uint total = n == 0u ? 0u : offsets[n - 1u] + counts[n - 1u];
    uint clamped = min(total, pc.isect_capacity);
    meta[0] = clamped;
    meta[1] = total;
    uint groups = (clamped + 255u) / 256u;
    uint gx = min(groups, 32768u);
    meta[4] = gx;
    meta[5] = gx == 0u ? 0u : (groups + gx - 1u) / gx;
    meta[6] = 1u;
    meta[64] = total > pc.isect_capacity ? OVERFLOW_CAPACITY : 0u;
    meta[65] = total;
}
