// Fused Adam (PyTorch semantics, bias-corrected) on floats [first, first + count) of one
// buffer: one dispatch per parameter group. With use_mask, rows of row_len floats whose mask
// word is 0 are skipped entirely (p, m, v unchanged).
// Body of adam.comp (storage buffers) and adam_texel.comp (texel buffers, glsl/include/access.glsl).
#ifndef ADAM_GLSL
#define ADAM_GLSL
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "access.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { AdamParams pc; };
ARR_RW(0, float, r32f, P, p)
ARR_RO(1, float, r32f, G, g)
ARR_RW(2, float, r32f, M, m)
ARR_RW(3, float, r32f, V, v)
ARR_RO_U(4, uint, r32ui, Mask, mask)
// skip holds pc.skip_flags (flag, needed) pairs as the rasteriser writes its overflow: any
// non-zero flag turns the whole update into a no-op, so a training step one of whose renders
// overflowed is discarded on the GPU (and re-run by the host) without a mid-step readback.
layout(std430, binding = 5) readonly buffer Skip { uint skip[]; };

void main() {
    uint j = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    bool skipped = false;
    for (uint k = 0u; k < pc.skip_flags; ++k) skipped = skipped || skip[2u * k] != 0u;
    if (j >= pc.count || skipped) return;
    if (pc.use_mask != 0 && LDU1(mask, j / pc.row_len) == 0u) return;
    uint i = pc.first + j;
    float gi = LD1(g, i);
    float mi = pc.beta1 * LD1(m, i) + (1.0 - pc.beta1) * gi;
    float vi = pc.beta2 * LD1(v, i) + (1.0 - pc.beta2) * gi * gi;
    ST1(m, i, mi);
    ST1(v, i, vi);
#ifdef TEXEL_ACCESS
    ST1(p, i, LD1(p, i) - pc.lr * (mi / pc.bc1) / (sqrt(vi / pc.bc2) + pc.eps));
#else
    p[i] -= pc.lr * (mi / pc.bc1) / (sqrt(vi / pc.bc2) + pc.eps);
#endif
}

#endif
