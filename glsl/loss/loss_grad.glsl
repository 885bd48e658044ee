// ∂L/∂render for L = (1 − λ)·mean|x − y| + λ·(1 − SSIM): the L1 sign term plus the SSIM term
// Σ_p G(p − q)·(A(p) + 2·x(q)·B(p) + y(q)·C(p)) = (G∗A)(q) + 2x(q)(G∗B)(q) + y(q)(G∗C)(q),
// with G∗ the blurred partial maps. Alpha gets no gradient. Also per-workgroup partial sums
// of |x − y| and (x − y)² for the L1 value and PSNR.
// Body of loss_grad.comp (storage buffers) and loss_grad_texel.comp (texel buffers, glsl/include/access.glsl).
#ifndef LOSS_GRAD_GLSL
#define LOSS_GRAD_GLSL
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "loss.glsl"
#include "access.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { LossParams pc; };
ARR_RO(0, vec4, rgba32f, Render, render)
ARR_RO(1, vec4, rgba32f, Target, target)
ARR_RO(2, float, r32f, Blurred, gmaps)  // [9][H·W] G∗(A,B,C)
ARR_WO(3, vec4, rgba32f, DRender, d_render)
layout(std430, binding = 4) buffer Sums { vec4 sums[]; };

shared vec2 s_sum[256];

void main() {
    uint p = gl_GlobalInvocationID.x;
    uint hw = pc.width * pc.height;
    vec2 acc = vec2(0.0);
    if (p < hw) {
        vec3 x = LD4(render, p).rgb, y = LD4(target, p).rgb;
        vec3 g;
        for (uint c = 0; c < 3u; ++c) {
            uint o = 3u * c * hw + p;
            float l1 = (1.0 - pc.lambda_ssim) * pc.inv_count * sign(x[c] - y[c]);
            g[c] = l1 + LD1(gmaps, o) + 2.0 * x[c] * LD1(gmaps, o + hw) + y[c] * LD1(gmaps, o + 2u * hw);
            float e = x[c] - y[c];
            acc += vec2(abs(e), e * e);
        }
        ST4(d_render, p, vec4(g, 0.0));
    }
    uint tid = gl_LocalInvocationIndex;
    s_sum[tid] = acc;
    barrier();
    for (uint off = 128u; off > 0u; off >>= 1) {
        if (tid < off) s_sum[tid] += s_sum[tid + off];
        barrier();
    }
    if (tid == 0u) {
        sums[gl_WorkGroupID.x].xy = s_sum[0];
    }
}

#endif
