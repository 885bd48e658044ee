#version 460
// Level l of the scan pyramid, down-sweep: scans each block and adds its block's offset
// (the already scanned sums of level l + 1).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "block_scan.glsl"

layout(local_size_x = SCAN_WG) in;

layout(push_constant) uniform Push { ScanParams pc; };
layout(std430, binding = 0) readonly buffer Meta { uint meta[]; };
layout(std430, binding = 1) readonly buffer Src { uint src[]; };
layout(std430, binding = 2) readonly buffer Offsets { uint offsets[]; };
layout(std430, binding = 3) writeonly buffer Dst { uint dst[]; };

void main() {
    uint n = meta[4 * pc.level];
    uint b = gl_WorkGroupID.x;
    BLOCK_SCAN(src, dst, b * SCAN_BLOCK, n, offsets[b])
}
