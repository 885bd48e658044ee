#version 460
// Central differences of I1 at one level, clamped at the border.
// Reads: width, height, off1 (I1 plane).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "flow.glsl"

layout(local_size_x = 16, local_size_y = 16) in;

layout(push_constant) uniform Push { FlowParams pc; };
layout(std430, binding = 0) readonly buffer Pyr { float pyr[]; };
layout(std430, binding = 1) writeonly buffer Grad { vec2 grad[]; };

float i1(int x, int y) {
    x = clamp(x, 0, int(pc.width) - 1);
    y = clamp(y, 0, int(pc.height) - 1);
    return pyr[pc.off1 + uint(y) * pc.width + uint(x)];
}

void main() {
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y;
    if (x >= pc.width || y >= pc.height) return;
    int xi = int(x), yi = int(y);
    grad[y * pc.width + x] = vec2(0.5 * (i1(xi + 1, yi) - i1(xi - 1, yi)),
                                  0.5 * (i1(xi, yi + 1) - i1(xi, yi - 1)));
}
