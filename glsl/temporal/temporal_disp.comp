#version 460
// The displacement flow's feature of rows [first, n): a transient moves by δ = v·(t2 − t1)
// between the rendered time pc.t (t1) and the pair's pc.t2 (the canonical rows' δ is the
// deformation's, written before by the displacement stage).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { TemporalParams pc; };
layout(std430, binding = 0) readonly buffer Velocity { float velocity[]; }; // [N,3]
layout(std430, binding = 1) buffer Delta { float delta[]; };                // [N,3]

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n || i < pc.first) return;
    float dt = pc.t2 - pc.t;
    for (uint a = 0; a < 3u; ++a) delta[3 * i + a] = velocity[3 * i + a] * dt;
}
