#version 460
// Level l of the scan pyramid, up-sweep: one partial sum per 2048-element block.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "wg_scan.glsl"

layout(local_size_x = SCAN_WG) in;

layout(push_constant) uniform Push { ScanParams pc; };
layout(std430, binding = 0) readonly buffer Meta { uint meta[]; };
layout(std430, binding = 1) readonly buffer Src { uint src[]; };
layout(std430, binding = 2) writeonly buffer Sums { uint sums[]; };

void main() {
    uint n = meta[4 * pc.level];
    uint base = gl_WorkGroupID.x * SCAN_BLOCK;
    uint tid = gl_LocalInvocationIndex;
    uint acc = 0;
    // Strided so neighbouring invocations read neighbouring words.
    for (uint i = 0; i < SCAN_ITEMS; ++i) {
        uint idx = base + i * SCAN_WG + tid;
        if (idx < n) acc += src[idx];
    }
    uint total;
    wg_exclusive_scan(acc, total);
    if (tid == 0) sums[gl_WorkGroupID.x] = total;
}
