// Warps I1 and its gradient by the current flow u0 (bilinear, border-clamped) and writes the
// linearised data term per pixel: (ρ_c, I1x, I1y, |∇I1|²), ρ(u) = ρ_c + (I1x, I1y)·u,
// ρ_c = I1(x + u0) − ∇I1(x + u0)·u0 − I0(x).
// Reads: width, height, off0 (I0), off1 (I1).
// Body of warp.comp (storage buffers) and warp_texel.comp (texel buffers, glsl/include/access.glsl).
#ifndef WARP_GLSL
#define WARP_GLSL
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "flow.glsl"
#include "access.glsl"

layout(local_size_x = 16, local_size_y = 16) in;

layout(push_constant) uniform Push { FlowParams pc; };
ARR_RO(0, float, r32f, Pyr, pyr)
ARR_RO(1, vec2, rg32f, Grad, grad)
ARR_RO(2, vec2, rg32f, U, u)
ARR_WO(3, vec4, rgba32f, Warp, warp)

void main() {
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y;
    if (x >= pc.width || y >= pc.height) return;
    uint o = y * pc.width + x;
    vec2 u0 = LD2(u, o);
    vec2 f;
    uvec4 c = flow_bilinear(vec2(float(x), float(y)) + u0, pc.width, pc.height, f);
    uint b = pc.off1;
    float i1w = FLOW_LERP2(LD1(pyr, b + c.x), LD1(pyr, b + c.y), LD1(pyr, b + c.z), LD1(pyr, b + c.w), f);
    vec2 g = FLOW_LERP2(LD2(grad, c.x), LD2(grad, c.y), LD2(grad, c.z), LD2(grad, c.w), f);
    float rho_c = i1w - g.x * u0.x - g.y * u0.y - LD1(pyr, pc.off0 + o);
    ST4(warp, o, vec4(rho_c, g.x, g.y, g.x * g.x + g.y * g.y));
}

#endif
