#version 460
// Warps I1 and its gradient by the current flow u0 (bilinear, border-clamped) and writes the
// linearised data term per pixel: (ρ_c, I1x, I1y, |∇I1|²), ρ(u) = ρ_c + (I1x, I1y)·u,
// ρ_c = I1(x + u0) − ∇I1(x + u0)·u0 − I0(x).
// Reads: width, height, off0 (I0), off1 (I1).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "flow.glsl"

layout(local_size_x = 16, local_size_y = 16) in;

layout(push_constant) uniform Push { FlowParams pc; };
layout(std430, binding = 0) readonly buffer Pyr { float pyr[]; };
layout(std430, binding = 1) readonly buffer Grad { vec2 grad[]; };
layout(std430, binding = 2) readonly buffer U { vec2 u[]; };
layout(std430, binding = 3) writeonly buffer Warp { vec4 warp[]; };

void main() {
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y;
    if (x >= pc.width || y >= pc.height) return;
    uint o = y * pc.width + x;
    vec2 u0 = u[o];
    vec2 f;
    uvec4 c = flow_bilinear(vec2(float(x), float(y)) + u0, pc.width, pc.height, f);
    uint b = pc.off1;
    float i1w = FLOW_LERP2(pyr[b + c.x], pyr[b + c.y], pyr[b + c.z], pyr[b + c.w], f);
    vec2 g = FLOW_LERP2(grad[c.x], grad[c.y], grad[c.z], grad[c.w], f);
    float rho_c = i1w - g.x * u0.x - g.y * u0.y - pyr[pc.off0 + o];
    warp[o] = vec4(rho_c, g.x, g.y, g.x * g.x + g.y * g.y);
}
