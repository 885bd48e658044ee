#version 460
// The opacity logit densification prunes by: a canonical row's own; a transient's the logit of
// σ(o)·max_{t ∈ [t_lo, t_hi]} w(t), its largest opacity over the sequence (1 where its centre
// lies inside the range), so a transient is judged where it lives, not at one time.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "temporal.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { TemporalParams pc; };
layout(std430, binding = 0) readonly buffer Opacity { float logits[]; };      // [N]
layout(std430, binding = 1) readonly buffer Centre { float centre[]; };       // [N]
layout(std430, binding = 2) readonly buffer LogWidth { float log_width[]; };  // [N]
layout(std430, binding = 3) writeonly buffer Peak { float peak[]; };          // [N]

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n) return;
    float l = logits[i];
    if (i < pc.first) {
        peak[i] = l;
        return;
    }
    float c = centre[i];
    float t = clamp(c, pc.t_lo, pc.t_hi); // the time of the largest weight in the range
    if (isnan(t)) t = pc.t_lo;
    Weight r = temporal_weight(c, log_width[i], t, pc);
    float p = r.w / (1.0 + exp(-l));       // σ(o)·w_max
    peak[i] = log(p) - log(max(1.0 - p, 1e-30)); // logit; −∞ for a transient never alive
}
