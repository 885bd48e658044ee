// Backward of deform_apply: from the rasteriser's gradients wrt the drawn mean, scale and rot
// to the canonical parameters (written into their gradient sections) and to the MLP outputs
// (dx, dr, ds), which get exactly the drawn gradients. Body of deform_apply_bwd.comp
// (USE_DEFORM 1) and deform_static_bwd.comp (USE_DEFORM 0: no MLP-output gradient binding);
// deform_apply_bwd_acc.comp (ACCUM 1) adds instead of writing: a second render of the same
// step (the Gaussians at t2, or the reverse order's intermediate) adds its gradients. The
// drawn geometry is the canonical one plus the MLP output, so the canonical Jacobian does not
// depend on the slot and sums of the drawn gradients map to sums of these.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { DeformParams pc; };
layout(std430, binding = 0) readonly buffer LogScales { float log_scales[]; };
layout(std430, binding = 1) readonly buffer Quats { vec4 quats[]; };
layout(std430, binding = 2) readonly buffer DMeans { float d_means[]; };     // ∂L/∂ drawn mean
layout(std430, binding = 3) readonly buffer DScales { float d_scales[]; };   // ∂L/∂ drawn scale
layout(std430, binding = 4) readonly buffer DQuats { vec4 d_quats[]; };      // ∂L/∂ drawn rot
#ifndef ACCUM
#define ACCUM 0
#endif
#if ACCUM
#define OUTBUF buffer
#define PUT(x, v) x += (v)
#else
#define OUTBUF writeonly buffer
#define PUT(x, v) x = (v)
#endif
layout(std430, binding = 5) OUTBUF GMeans { float g_means[]; };    // ∂L/∂x
layout(std430, binding = 6) OUTBUF GLogScales { float g_log_scales[]; };
layout(std430, binding = 7) OUTBUF GQuats { vec4 g_quats[]; };
#if USE_DEFORM
layout(std430, binding = 8) OUTBUF DDeform { float d_deform[]; };  // [N,10]
#endif

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n) return;
    vec4 dq = d_quats[i];
    for (uint a = 0; a < 3u; ++a) {
        float dm = d_means[3 * i + a], dsc = d_scales[3 * i + a];
        PUT(g_means[3 * i + a], dm);
        float ls = log_scales[3 * i + a];
        PUT(g_log_scales[3 * i + a], ls <= LOG_SCALE_MAX ? dsc * exp(ls) : 0.0); // 0 above the clamp
#if USE_DEFORM
        PUT(d_deform[10 * i + a], dm);
        PUT(d_deform[10 * i + 7 + a], dsc);
#endif
    }
#if USE_DEFORM
    for (uint a = 0; a < 4u; ++a) PUT(d_deform[10 * i + 3 + a], dq[a]);
#endif
    // normalize(q): ∂/∂q = (I − q̂q̂ᵀ) / |q|; a degenerate q was replaced by a constant.
    vec4 q = quats[i];
    float len = length(q);
    vec4 qn = q / max(len, 1e-30);
    PUT(g_quats[i], len > 1e-12 ? (dq - qn * dot(qn, dq)) / len : vec4(0.0));
}
