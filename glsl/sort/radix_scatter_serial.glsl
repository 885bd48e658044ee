// Pass 2 of a radix-sort digit pass, CPU shape: one invocation per SORT_SERIAL_BLOCK-key block
// (SORT_SERIAL_LANES per workgroup, as radix_hist_serial.glsl) walks its
// keys in order and writes each at its digit's next slot (the block's scanned offset plus the
// keys of that digit already written), which is the stable order radix_scatter.glsl computes
// with a shared-memory scan. No shared memory, no barriers.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "radix_common.glsl"

layout(local_size_x = SORT_SERIAL_LANES) in;

layout(push_constant) uniform Push { SortParams pc; };
layout(std430, binding = 0) readonly buffer Meta { uint meta[]; };
layout(std430, binding = 1) readonly buffer KeysIn { KEY_T keys_in[]; };
layout(std430, binding = 2) readonly buffer ValsIn { uint vals_in[]; };
layout(std430, binding = 3) readonly buffer Offsets { uint offsets[]; }; // scanned histogram
layout(std430, binding = 4) writeonly buffer KeysOut { KEY_T keys_out[]; };
layout(std430, binding = 5) writeonly buffer ValsOut { uint vals_out[]; };

void main() {
    uint n = meta[0];
    uint blocks = meta[1];
    uint b = gl_GlobalInvocationID.x;
    if (b >= blocks) return;
    uint next[SORT_RADIX];
    for (uint d = 0; d < SORT_RADIX; ++d) next[d] = offsets[d * blocks + b];
    uint end = min(n, (b + 1) * SORT_SERIAL_BLOCK);
    for (uint idx = b * SORT_SERIAL_BLOCK; idx < end; ++idx) {
        KEY_T k = keys_in[idx];
        uint d = key_digit(k, pc.shift, pc.digit_mask);
        uint dst = next[d];
        next[d] = dst + 1;
        keys_out[dst] = k;
        vals_out[dst] = vals_in[idx];
    }
}
