#version 460
// The (node, pair) keys and pair ids the radix sort turns into each node's list of
// (Gaussian, slot) pairs for the gradient gather; rebuilt whenever the KNN changes.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { NodesParams pc; };
layout(std430, binding = 0) readonly buffer Knn { uint knn[]; };   // [pairs]
layout(std430, binding = 1) writeonly buffer Keys { uint keys[]; }; // [pairs]
layout(std430, binding = 2) writeonly buffer Vals { uint vals[]; }; // [pairs]

void main() {
    uint p = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (p >= pc.n) return;
    keys[p] = knn[p];
    vals[p] = p;
}
