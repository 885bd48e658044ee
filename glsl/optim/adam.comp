#version 460
// Fused Adam (PyTorch semantics, bias-corrected) on floats [first, first + count) of one
// buffer: one dispatch per parameter group. With use_mask, rows of row_len floats whose mask
// word is 0 are skipped entirely (p, m, v unchanged).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { AdamParams pc; };
layout(std430, binding = 0) buffer P { float p[]; };
layout(std430, binding = 1) readonly buffer G { float g[]; };
layout(std430, binding = 2) buffer M { float m[]; };
layout(std430, binding = 3) buffer V { float v[]; };
layout(std430, binding = 4) readonly buffer Mask { uint mask[]; };
// skip holds pc.skip_flags (flag, needed) pairs as the rasteriser writes its overflow: any
// non-zero flag turns the whole update into a no-op, so a training step one of whose renders
// overflowed is discarded on the GPU (and re-run by the host) without a mid-step readback.
layout(std430, binding = 5) readonly buffer Skip { uint skip[]; };

void main() {
    uint j = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    bool skipped = false;
    for (uint k = 0u; k < pc.skip_flags; ++k) skipped = skipped || skip[2u * k] != 0u;
    if (j >= pc.count || skipped) return;
    if (pc.use_mask != 0 && mask[j / pc.row_len] == 0u) return;
    uint i = pc.first + j;
    float gi = g[i];
    float mi = pc.beta1 * m[i] + (1.0 - pc.beta1) * gi;
    float vi = pc.beta2 * v[i] + (1.0 - pc.beta2) * gi * gi;
    m[i] = mi;
    v[i] = vi;
    p[i] -= pc.lr * (mi / pc.bc1) / (sqrt(vi / pc.bc2) + pc.eps);
}
