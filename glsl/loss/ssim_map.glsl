// From the window statistics (blurred x, y, x², y², x·y per channel) to the SSIM map and its
// partial derivatives wrt μx, E[x²] and E[x·y] (the render's only paths into SSIM), pre-scaled
// by ∂L/∂SSIM(p) = −lambda_ssim / (3·H·W). Writes planes A, B, C per channel as plane
// (3 · c + j), and per-workgroup partial sums of SSIM (deterministic: no float atomics).
// Body of ssim_map.comp (storage buffers) and ssim_map_texel.comp (texel buffers, glsl/include/access.glsl).
#ifndef SSIM_MAP_GLSL
#define SSIM_MAP_GLSL
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "loss.glsl"
#include "wg_scan.glsl"
#include "access.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { LossParams pc; };
ARR_RO(0, float, r32f, Stats, stats)     // [15][H·W]
ARR_WO(1, float, r32f, Partials, dmaps)  // [9][H·W]
layout(std430, binding = 2) buffer Sums { vec4 sums[]; };                // [groups]

shared float s_sum[256];

void main() {
    uint p = gl_GlobalInvocationID.x;
    uint hw = pc.width * pc.height;
    float ssim_sum = 0.0;
    if (p < hw) {
        float scale = -pc.lambda_ssim * pc.inv_count;
        for (uint c = 0; c < 3u; ++c) {
            uint b = 5u * c * hw + p;
            float mx = LD1(stats, b), my = LD1(stats, b + hw);
            float exx = LD1(stats, b + 2u * hw), eyy = LD1(stats, b + 3u * hw);
            float exy = LD1(stats, b + 4u * hw);
            float sxx = exx - mx * mx, syy = eyy - my * my, sxy = exy - mx * my;
            float n1 = 2.0 * mx * my + SSIM_C1, n2 = 2.0 * sxy + SSIM_C2;
            float d1 = mx * mx + my * my + SSIM_C1, d2 = sxx + syy + SSIM_C2;
            float s = (n1 * n2) / (d1 * d2);
            ssim_sum += s;
            uint o = 3u * c * hw + p;
            ST1(dmaps, o, scale * s * (2.0 * my / n1 - 2.0 * my / n2 - 2.0 * mx / d1 + 2.0 * mx / d2));
            ST1(dmaps, o + hw, scale * (-s / d2));
            ST1(dmaps, o + 2u * hw, scale * (2.0 * s / n2));
        }
    }
    uint tid = gl_LocalInvocationIndex;
    s_sum[tid] = ssim_sum;
    barrier();
    for (uint off = 128u; off > 0u; off >>= 1) {
        if (tid < off) s_sum[tid] += s_sum[tid + off];
        barrier();
    }
    if (tid == 0u) sums[gl_WorkGroupID.x].z = s_sum[0];
}

#endif
