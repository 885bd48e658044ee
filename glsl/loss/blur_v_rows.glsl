// blur_v for CPU devices: one invocation blurs a run of BLUR_RUN pixels of one column (lanes
// take neighbouring columns), from a private array of the run and its neighbours; the same
// floats as blur_v (see blur_h_rows).
// Body of blur_v_rows.comp (storage buffers) and blur_v_rows_texel.comp (texel buffers, glsl/include/access.glsl).
#ifndef BLUR_V_ROWS_GLSL
#define BLUR_V_ROWS_GLSL
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
    uint runs = (pc.height + uint(BLUR_RUN) - 1u) / uint(BLUR_RUN);
    if (id >= pc.width * runs * pc.planes) return;
    uint x = id % pc.width;
    uint rest = id / pc.width;
    int y0 = int(rest % runs) * BLUR_RUN;
    uint base = (rest / runs) * pc.width * pc.height + x;
    float v[BLUR_RUN + 2 * SSIM_RADIUS];
    for (int i = 0; i < BLUR_RUN + 2 * SSIM_RADIUS; ++i) {
        int yy = y0 - SSIM_RADIUS + i;
        bool inside = yy >= 0 && yy < int(pc.height);
        v[i] = inside ? LD1(src, base + uint(clamp(yy, 0, int(pc.height) - 1)) * pc.width) : 0.0;
    }
    for (int o = 0; o < BLUR_RUN; ++o) {
        float acc = 0.0;
        for (int d = -SSIM_RADIUS; d <= SSIM_RADIUS; ++d) acc += gauss_tap(d) * v[o + SSIM_RADIUS + d];
        if (y0 + o < int(pc.height)) ST1(dst, base + uint(y0 + o) * pc.width, acc);
    }
}

#endif
