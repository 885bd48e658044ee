// Per pixel and colour channel c: planes x, y, x², y², x·y (x = render, y = target), each
// [3][H·W], stacked as plane (5 · c + j) — the inputs of the SSIM window statistics.
// Body of ssim_products.comp (storage buffers) and ssim_products_texel.comp (texel buffers, glsl/include/access.glsl).
#ifndef SSIM_PRODUCTS_GLSL
#define SSIM_PRODUCTS_GLSL
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "loss.glsl"
#include "access.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { LossParams pc; };
ARR_RO(0, vec4, rgba32f, Render, render)  // [H·W] rgb(a)
ARR_RO(1, vec4, rgba32f, Target, target)  // [H·W] rgb(a)
ARR_WO(2, float, r32f, Planes, planes)

void main() {
    uint p = gl_GlobalInvocationID.x;
    uint hw = pc.width * pc.height;
    if (p >= hw) return;
    vec3 x = LD4(render, p).rgb, y = LD4(target, p).rgb;
    for (uint c = 0; c < 3u; ++c) {
        uint b = 5u * c * hw + p;
        ST1(planes, b, x[c]);
        ST1(planes, b + hw, y[c]);
        ST1(planes, b + 2u * hw, x[c] * x[c]);
        ST1(planes, b + 3u * hw, y[c] * y[c]);
        ST1(planes, b + 4u * hw, x[c] * y[c]);
    }
}

#endif
