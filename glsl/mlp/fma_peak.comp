#version 460
// FMA-throughput probe: 8 independent register-only FMA chains per invocation, `iters`
// rounds: 16 FMA = 32 FLOP per round per invocation. The result is written so nothing is optimised away.
// Gives the device's ALU ceiling next to the tiled GEMM's achievable rate.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { FmaPeakParams pc; };
layout(std430, binding = 0) writeonly buffer Out { float out_[]; };

void main() {
    uint i = gl_GlobalInvocationID.x;
    float x[8];
    for (uint c = 0; c < 8; ++c) x[c] = float(i + c) * 1e-7;
    for (uint k = 0; k < pc.iters; ++k) {
        for (uint c = 0; c < 8; ++c) x[c] = fma(x[c], pc.a, pc.b);
        for (uint c = 0; c < 8; ++c) x[c] = fma(x[c], pc.b, pc.a);
    }
    float s = 0.0;
    for (uint c = 0; c < 8; ++c) s += x[c];
    out_[i] = s;
}
