#version 460
// Backward of temporal_fwd for rows [first, n), from the rasteriser's gradients wrt the drawn
// mean, scale and rotation and wrt the opacity factor (project_bwd's d_op_scale):
//   ∂L/∂μ = g_m,  ∂L/∂s = g_s·exp(s) (0 above the clamp),  ∂L/∂q through normalize,
//   ∂L/∂v = g_m·(t − c),  ∂L/∂c = g_w·w·(t − c)/σ² − g_m·v,  ∂L/∂τ = g_w·w·(t − c)²/σ²
// (0 while τ is at the floor). A culled transient (w = 0) gets zeros. Written, not added: the
// canonical rows' gradients are the deformation backward's, these rows are this stage's alone.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "temporal.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { TemporalParams pc; };
layout(std430, binding = 0) readonly buffer LogScales { float log_scales[]; };  // [N,3]
layout(std430, binding = 1) readonly buffer Quats { vec4 quats[]; };            // [N]
layout(std430, binding = 2) readonly buffer Centre { float centre[]; };         // [N]
layout(std430, binding = 3) readonly buffer LogWidth { float log_width[]; };    // [N]
layout(std430, binding = 4) readonly buffer Velocity { float velocity[]; };     // [N,3]
layout(std430, binding = 5) readonly buffer DMeans { float d_means[]; };        // [N,3] drawn
layout(std430, binding = 6) readonly buffer DScales { float d_scales[]; };      // [N,3] drawn
layout(std430, binding = 7) readonly buffer DQuats { vec4 d_quats[]; };         // [N] drawn
layout(std430, binding = 8) readonly buffer DOpScale { float d_op_scale[]; };   // [N]
layout(std430, binding = 9) buffer GMeans { float g_means[]; };                 // [N,3]
layout(std430, binding = 10) buffer GLogScales { float g_log_scales[]; };       // [N,3]
layout(std430, binding = 11) buffer GQuats { vec4 g_quats[]; };                 // [N]
layout(std430, binding = 12) buffer GCentre { float g_centre[]; };              // [N]
layout(std430, binding = 13) buffer GLogWidth { float g_log_width[]; };         // [N]
layout(std430, binding = 14) buffer GVelocity { float g_velocity[]; };          // [N,3]

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n || i < pc.first) return;
    Weight r = temporal_weight(centre[i], log_width[i], pc.t, pc);
    if (r.w == 0.0) {
        for (uint a = 0; a < 3u; ++a) {
            g_means[3 * i + a] = 0.0;
            g_log_scales[3 * i + a] = 0.0;
            g_velocity[3 * i + a] = 0.0;
        }
        g_quats[i] = vec4(0.0);
        g_centre[i] = 0.0;
        g_log_width[i] = 0.0;
        return;
    }
    vec3 gm = vec3(d_means[3 * i], d_means[3 * i + 1], d_means[3 * i + 2]);
    vec3 v = vec3(velocity[3 * i], velocity[3 * i + 1], velocity[3 * i + 2]);
    float gw = d_op_scale[i];
    for (uint a = 0; a < 3u; ++a) {
        g_means[3 * i + a] = gm[a];
        float ls = log_scales[3 * i + a];
        g_log_scales[3 * i + a] = ls <= LOG_SCALE_MAX ? d_scales[3 * i + a] * exp(ls) : 0.0;
        g_velocity[3 * i + a] = gm[a] * r.d;
    }
    vec4 q = quats[i], dq = d_quats[i];
    float len = length(q);
    vec4 qn = q / max(len, 1e-30);
    g_quats[i] = len > 1e-12 ? (dq - qn * dot(qn, dq)) / len : vec4(0.0);
    float k = gw * r.w * r.inv_s2;
    g_centre[i] = k * r.d - dot(gm, v);
    g_log_width[i] = r.floored ? 0.0 : k * r.d * r.d;
}
