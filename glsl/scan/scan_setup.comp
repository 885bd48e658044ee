#version 460
// Reads the element count written by an earlier stage (or the host) and lays out the scan
// pyramid for it: per level, the element count and the indirect dispatch size. This keeps the
// count on the GPU — no readback between the producer and the scan.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 1) in;

layout(push_constant) uniform Push { ScanParams pc; };
layout(std430, binding = 0) readonly buffer Count { uint count[]; };
// meta[4*l + 0] = elements at level l; meta[4*l + 1..4] = (workgroups, 1, 1) for level l.
layout(std430, binding = 1) writeonly buffer Meta { uint meta[]; };

void main() {
    uint n = min(count[0], pc.capacity);
    for (uint l = 0; l < pc.num_levels; ++l) {
        uint groups = (n + SCAN_BLOCK - 1) / SCAN_BLOCK;
        meta[4 * l + 0] = n;
        meta[4 * l + 1] = groups;
        meta[4 * l + 2] = 1;
        meta[4 * l + 3] = 1;
        n = groups;
    }
}
