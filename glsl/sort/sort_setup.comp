#version 460
// Reads the key count (written by an earlier stage or the host) and writes the block count,
// the indirect dispatch size for the per-block passes and the length of the digit histogram
// that the prefix sum scans. Keeps the count on the GPU.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 1) in;

layout(push_constant) uniform Push { SortParams pc; };
layout(std430, binding = 0) readonly buffer Count { uint count[]; };
// meta[0] = keys, meta[1] = blocks of pc.block_keys, meta[4..7] = the per-block passes'
// workgroups (pc.group_blocks blocks each, 1, 1), meta[64] = histogram length (16 · blocks);
// the length sits at byte 256 so it can be bound on its own as the scan count on any device.
layout(std430, binding = 1) writeonly buffer Meta { uint meta[]; };

void main() {
    uint n = min(count[0], pc.capacity);
    uint blocks = (n + pc.block_keys - 1) / pc.block_keys;
    meta[0] = n;
    meta[1] = blocks;
    meta[4] = (blocks + pc.group_blocks - 1) / pc.group_blocks;
    meta[5] = 1;
    meta[6] = 1;
    meta[64] = SORT_RADIX * blocks;
}
