// Pass 2 of a radix-sort digit pass: stable scatter. Thread t owns the 8 consecutive keys
// [b·2048 + 8t, +8). Its rank among equal digits of the block is
//   (keys of that digit in threads < t) + (earlier keys of that digit in its own run),
// found with one exclusive scan over a digit-major [16 digits][256 threads] count table.
// No subgroup operations, so any subgroup size (lavapipe: 8) gives the same, stable order.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "radix_common.glsl"
#include "wg_scan.glsl"

layout(local_size_x = SORT_WG) in;

layout(push_constant) uniform Push { SortParams pc; };
layout(std430, binding = 0) readonly buffer Meta { uint meta[]; };
layout(std430, binding = 1) readonly buffer KeysIn { KEY_T keys_in[]; };
layout(std430, binding = 2) readonly buffer ValsIn { uint vals_in[]; };
layout(std430, binding = 3) readonly buffer Offsets { uint offsets[]; }; // scanned histogram
layout(std430, binding = 4) writeonly buffer KeysOut { KEY_T keys_out[]; };
layout(std430, binding = 5) writeonly buffer ValsOut { uint vals_out[]; };

// s_cnt[d · 256 + t]: keys of digit d in thread t's run; exclusive-scanned in place.
shared uint s_cnt[SORT_RADIX * SORT_WG];

// Per-digit counters packed as nibbles (a run has at most 8 keys, so 4 bits suffice).
uint nib_get(uvec2 c, uint d) { return ((d < 8u ? c.x : c.y) >> ((d & 7u) * 4u)) & 15u; }
uvec2 nib_inc(uvec2 c, uint d) {
    uint one = 1u << ((d & 7u) * 4u);
    return d < 8u ? uvec2(c.x + one, c.y) : uvec2(c.x, c.y + one);
}

void main() {
    uint n = meta[0];
    uint blocks = meta[1];
    uint b = gl_WorkGroupID.x;
    uint tid = gl_LocalInvocationIndex;
    uint run = b * SORT_BLOCK + tid * SORT_ITEMS;

    uvec2 cnt = uvec2(0);
    for (uint i = 0; i < SORT_ITEMS; ++i) {
        uint idx = run + i;
        if (idx < n) cnt = nib_inc(cnt, key_digit(keys_in[idx], pc.shift, pc.digit_mask));
    }
    for (uint d = 0; d < SORT_RADIX; ++d) s_cnt[d * SORT_WG + tid] = nib_get(cnt, d);
    barrier();

    // Exclusive scan of the 4096-entry table: 16 consecutive entries per thread.
    uint local_vals[SORT_RADIX];
    uint sum = 0;
    for (uint j = 0; j < SORT_RADIX; ++j) {
        local_vals[j] = s_cnt[tid * SORT_RADIX + j];
        sum += local_vals[j];
    }
    uint total;
    uint pre = wg_exclusive_scan(sum, total);
    for (uint j = 0; j < SORT_RADIX; ++j) {
        s_cnt[tid * SORT_RADIX + j] = pre;
        pre += local_vals[j];
    }
    barrier();

    uvec2 seen = uvec2(0);
    for (uint i = 0; i < SORT_ITEMS; ++i) {
        uint idx = run + i;
        if (idx >= n) break;
        KEY_T k = keys_in[idx];
        uint d = key_digit(k, pc.shift, pc.digit_mask);
        uint local_rank = s_cnt[d * SORT_WG + tid] - s_cnt[d * SORT_WG] + nib_get(seen, d);
        uint dst = offsets[d * blocks + b] + local_rank;
        keys_out[dst] = k;
        vals_out[dst] = vals_in[idx];
        seen = nib_inc(seen, d);
    }
}
