#version 460
// Second stage of the weight-gradient reduction: sums the chunk partials in chunk order
// (deterministic) into the flat gradient buffer: [o][c < fan_in] → W, [o][fan_in] → b.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { MlpReduceParams pc; };
layout(std430, binding = 0) readonly buffer Partial { float partial[]; };
layout(std430, binding = 1) buffer Grad { float grad[]; };

void main() {
    uint e = gl_GlobalInvocationID.x;
    if (e >= pc.count) return;
    float s = 0.0;
    for (uint c = 0; c < pc.chunks; ++c) s += partial[c * pc.count + e];
    uint cols = pc.fan_in + 1;
    uint o = e / cols, k = e % cols;
    uint dst = k < pc.fan_in ? pc.w_off + o * pc.fan_in + k : pc.b_off + o;
    grad[dst] = pc.accumulate != 0 ? grad[dst] + s : s;
}
