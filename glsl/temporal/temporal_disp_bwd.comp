#version 460
// Backward of temporal_disp: ∂L/∂v += ∂L/∂δ · (t2 − t1) for rows [first, n), added to the
// velocity gradient temporal_bwd wrote for the same step.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { TemporalParams pc; };
layout(std430, binding = 0) readonly buffer DDelta { float d_delta[]; };  // [N,3]
layout(std430, binding = 1) buffer GVelocity { float g_velocity[]; };     // [N,3]

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n || i < pc.first) return;
    float dt = pc.t2 - pc.t;
    for (uint a = 0; a < 3u; ++a) g_velocity[3 * i + a] += d_delta[3 * i + a] * dt;
}
