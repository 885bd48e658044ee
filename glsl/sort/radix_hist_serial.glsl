// Pass 1 of a radix-sort digit pass, CPU shape: one invocation per SORT_SERIAL_BLOCK-key block
// counts its digits in a private array (no shared memory, no atomics, no barriers; on lavapipe
// those are per-lane loops). SORT_SERIAL_LANES blocks per workgroup: lavapipe runs a private
// array's indexed access and a buffer gather lane by lane whatever the mask, so a workgroup of
// one invocation paid for 8 lanes and used 1. Same output as radix_hist.glsl:
// hist[d · blocks + b].
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "radix_common.glsl"

layout(local_size_x = SORT_SERIAL_LANES) in;

layout(push_constant) uniform Push { SortParams pc; };
layout(std430, binding = 0) readonly buffer Meta { uint meta[]; };
layout(std430, binding = 1) readonly buffer Keys { KEY_T keys[]; };
layout(std430, binding = 2) writeonly buffer Hist { uint hist[]; };

void main() {
    uint n = meta[0];
    uint blocks = meta[1];
    uint b = gl_GlobalInvocationID.x;
    if (b >= blocks) return;
    uint cnt[SORT_RADIX];
    for (uint d = 0; d < SORT_RADIX; ++d) cnt[d] = 0;
    uint end = min(n, (b + 1) * SORT_SERIAL_BLOCK);
    for (uint idx = b * SORT_SERIAL_BLOCK; idx < end; ++idx)
        cnt[key_digit(keys[idx], pc.shift, pc.digit_mask)] += 1;
    for (uint d = 0; d < SORT_RADIX; ++d) hist[d * blocks + b] = cnt[d];
}
