#version 460
// Per pixel and colour channel c: planes x, y, x², y², x·y (x = render, y = target), each
// [3][H·W], stacked as plane (5 · c + j) — the inputs of the SSIM window statistics.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "loss.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { LossParams pc; };
layout(std430, binding = 0) readonly buffer Render { vec4 render[]; };  // [H·W] rgb(a)
layout(std430, binding = 1) readonly buffer Target { vec4 target[]; };  // [H·W] rgb(a)
layout(std430, binding = 2) writeonly buffer Planes { float planes[]; };

void main() {
    uint p = gl_GlobalInvocationID.x;
    uint hw = pc.width * pc.height;
    if (p >= hw) return;
    vec3 x = render[p].rgb, y = target[p].rgb;
    for (uint c = 0; c < 3u; ++c) {
        uint b = 5u * c * hw + p;
        planes[b] = x[c];
        planes[b + hw] = y[c];
        planes[b + 2u * hw] = x[c] * x[c];
        planes[b + 3u * hw] = y[c] * y[c];
        planes[b + 4u * hw] = x[c] * y[c];
    }
}
