#version 460
// Motion term α · (1/N) Σ_p c_p · |m̂_scene(p) − m̂_disp(p)| and its gradient wrt m̂_disp, with
// c_p the scene motion's confidence in [0, 1] (c ≡ 1 without one). The normalisation is the
// pixel count N, not Σ c: a render that does not match its photo anywhere gives a weaker term
// instead of one whose few confident pixels are scaled up. When either normalised map was
// degenerate (flat, flagged by the normalisation), the term is skipped for this step: zero
// value and zero gradient, never a division by ~0. Per-workgroup partial sums of c·|·|.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { DispFlowParams pc; };
layout(std430, binding = 0) readonly buffer Disp { float m_disp[]; };
layout(std430, binding = 1) readonly buffer Scene { float m_scene[]; };
layout(std430, binding = 2) readonly buffer Flags { uint degenerate[]; };  // [2]: disp, scene
layout(std430, binding = 3) writeonly buffer DDisp { float d_disp[]; };
layout(std430, binding = 4) writeonly buffer Sums { float sums[]; };      // [groups]
layout(std430, binding = 5) readonly buffer Conf { float conf[]; };       // [N] when pc.conf

shared float s_sum[256];

void main() {
    uint p = gl_GlobalInvocationID.x;
    bool skip = degenerate[0] != 0u || degenerate[1] != 0u;
    float v = 0.0;
    if (p < pc.n) {
        float c = pc.conf != 0u ? conf[p] : 1.0;
        float e = m_disp[p] - m_scene[p];
        d_disp[p] = skip ? 0.0 : pc.weight * c * sign(e) / float(pc.n);
        v = skip ? 0.0 : c * abs(e);
    }
    uint tid = gl_LocalInvocationIndex;
    s_sum[tid] = v;
    barrier();
    for (uint off = 128u; off > 0u; off >>= 1) {
        if (tid < off) s_sum[tid] += s_sum[tid + off];
        barrier();
    }
    if (tid == 0u) sums[gl_WorkGroupID.x] = s_sum[0];
}
