#version 460
// Transients at time pc.t: the drawn mean μ + v·(t − c), scale exp(min(s, LOG_SCALE_MAX)) and
// rotation normalize(q) of rows [first, n) (as deform_apply with D ≡ 0, plus the motion), and
// the opacity factor w of every row (1 for the canonical rows, whose drawn geometry the
// deformation wrote and this stage leaves alone).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "temporal.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { TemporalParams pc; };
layout(std430, binding = 0) readonly buffer Means { float means[]; };          // [N,3]
layout(std430, binding = 1) readonly buffer LogScales { float log_scales[]; }; // [N,3]
layout(std430, binding = 2) readonly buffer Quats { vec4 quats[]; };           // [N]
layout(std430, binding = 3) readonly buffer Centre { float centre[]; };        // [N]
layout(std430, binding = 4) readonly buffer LogWidth { float log_width[]; };   // [N]
layout(std430, binding = 5) readonly buffer Velocity { float velocity[]; };    // [N,3]
layout(std430, binding = 6) buffer OutMeans { float out_means[]; };            // [N,3]
layout(std430, binding = 7) buffer OutScales { float out_scales[]; };          // [N,3]
layout(std430, binding = 8) buffer OutQuats { vec4 out_quats[]; };             // [N]
layout(std430, binding = 9) writeonly buffer OpacityScale { float op_scale[]; }; // [N]

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n) return;
    if (i < pc.first) {
        op_scale[i] = 1.0;
        return;
    }
    Weight r = temporal_weight(centre[i], log_width[i], pc.t, pc);
    op_scale[i] = r.w;
    // A culled transient's geometry is still written finite (nothing reads it: w = 0 culls
    // it before projection), so no stale row of another time remains.
    float d = r.w > 0.0 ? r.d : 0.0;
    for (uint a = 0; a < 3u; ++a) {
        out_means[3 * i + a] = means[3 * i + a] + velocity[3 * i + a] * d;
        float ls = log_scales[3 * i + a];
        out_scales[3 * i + a] = exp(ls > LOG_SCALE_MAX ? LOG_SCALE_MAX : ls);
    }
    vec4 q = quats[i];
    float len = length(q);
    out_quats[i] = len > 1e-12 ? q / len : vec4(1.0, 0.0, 0.0, 0.0);
}
