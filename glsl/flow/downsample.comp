#version 460
// One pyramid level down: 5×5 binomial blur ([1 4 6 4 1]/16 separable, clamped border) of the
// finer level sampled at even pixels. z = 0: I0, z = 1: I1.
// Reads: width, height (coarse), src_width, src_height (fine), off0/off1 (fine I0/I1),
// off2/off3 (coarse I0/I1).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "flow.glsl"

layout(local_size_x = 16, local_size_y = 16) in;

layout(push_constant) uniform Push { FlowParams pc; };
layout(std430, binding = 0) buffer Pyr { float pyr[]; };

void main() {
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y, z = gl_GlobalInvocationID.z;
    if (x >= pc.width || y >= pc.height || z >= 2u) return;
    const float k[5] = float[5](1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0);
    uint src = z == 0u ? pc.off0 : pc.off1;
    uint dst = z == 0u ? pc.off2 : pc.off3;
    int sw = int(pc.src_width), sh = int(pc.src_height);
    float acc = 0.0;
    for (int j = 0; j < 5; ++j) {
        int yy = clamp(2 * int(y) + j - 2, 0, sh - 1);
        float row = 0.0;
        for (int i = 0; i < 5; ++i) {
            int xx = clamp(2 * int(x) + i - 2, 0, sw - 1);
            row += k[i] * pyr[src + uint(yy * sw + xx)];
        }
        acc += k[j] * row;
    }
    pyr[dst + y * pc.width + x] = acc;
}
