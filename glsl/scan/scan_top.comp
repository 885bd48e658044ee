#version 460
// Top of the scan pyramid: one workgroup scans the (at most 2048) block sums of the level below,
// or the whole input when it fits in one block.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "block_scan.glsl"

layout(local_size_x = SCAN_WG) in;

layout(push_constant) uniform Push { ScanParams pc; };
layout(std430, binding = 0) readonly buffer Meta { uint meta[]; };
layout(std430, binding = 1) readonly buffer Src { uint src[]; };
layout(std430, binding = 2) writeonly buffer Dst { uint dst[]; };

void main() {
    uint n = meta[4 * pc.level];
    BLOCK_SCAN(src, dst, 0u, n, 0u)
}
