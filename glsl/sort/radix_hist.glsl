// Pass 1 of a radix-sort digit pass: per-block digit histogram, stored digit-major
// (hist[d · blocks + b]) so one exclusive scan of the whole array yields each block's stable
// output offset per digit.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "radix_common.glsl"

layout(local_size_x = SORT_WG) in;

layout(push_constant) uniform Push { SortParams pc; };
layout(std430, binding = 0) readonly buffer Meta { uint meta[]; };
layout(std430, binding = 1) readonly buffer Keys { KEY_T keys[]; };
layout(std430, binding = 2) writeonly buffer Hist { uint hist[]; };

shared uint s_hist[SORT_RADIX];

void main() {
    uint n = meta[0];
    uint blocks = meta[1];
    uint b = gl_WorkGroupID.x;
    uint tid = gl_LocalInvocationIndex;
    if (tid < SORT_RADIX) s_hist[tid] = 0;
    barrier();
    // Counting order does not matter here, so read coalesced and count with shared atomics.
    for (uint i = 0; i < SORT_ITEMS; ++i) {
        uint idx = b * SORT_BLOCK + i * SORT_WG + tid;
        if (idx < n) atomicAdd(s_hist[key_digit(keys[idx], pc.shift, pc.digit_mask)], 1u);
    }
    barrier();
    if (tid < SORT_RADIX) hist[tid * blocks + b] = s_hist[tid];
}
