// blur_h for CPU devices: one invocation blurs a run of BLUR_RUN pixels of one row, from the
// run and its 2·SSIM_RADIUS neighbours held in a private array: 26 loads per 16 outputs
// instead of 11 per output (on lavapipe each storage load is a per-lane loop). The taps are
// summed in blur_h's order, so both shapes give the same floats. GPUs keep blur_h (one pixel
// per invocation, coalesced).
// Body of blur_h_rows.comp (storage buffers) and blur_h_rows_texel.comp (texel buffers, glsl/include/access.glsl).
#ifndef BLUR_H_ROWS_GLSL
#define BLUR_H_ROWS_GLSL
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "loss.glsl"
#include "access.glsl"

layout(local_size_x = 64) in;

layout(push_constant) uniform Push { LossParams pc; };
ARR_RO(0, float, r32f, Src, src)
ARR_WO(1, float, r32f, Dst, dst)

void main() {
    uint id = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    uint runs = (pc.width + uint(BLUR_RUN) - 1u) / uint(BLUR_RUN);
    if (id >= runs * pc.height * pc.planes) return;
    uint row = id / runs; // plane · height + y
    int x0 = int(id % runs) * BLUR_RUN;
    uint base = row * pc.width;
    float v[BLUR_RUN + 2 * SSIM_RADIUS];
    for (int i = 0; i < BLUR_RUN + 2 * SSIM_RADIUS; ++i) {
        int xx = x0 - SSIM_RADIUS + i;
        bool inside = xx >= 0 && xx < int(pc.width);
        v[i] = inside ? LD1(src, base + uint(clamp(xx, 0, int(pc.width) - 1))) : 0.0;
    }
    for (int o = 0; o < BLUR_RUN; ++o) {
        float acc = 0.0;
        for (int d = -SSIM_RADIUS; d <= SSIM_RADIUS; ++d) {
            // blur_h skips a zero tap outside the image; adding 0 changes no float.
            acc += gauss_tap(d) * v[o + SSIM_RADIUS + d];
        }
        if (x0 + o < int(pc.width)) ST1(dst, base + uint(x0 + o), acc);
    }
}

#endif
