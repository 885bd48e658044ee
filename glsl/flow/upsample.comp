#version 460
// Coarse → fine level: bilinear, fine pixel x at coarse x/2 (the pyramid keeps even pixels);
// the flow is scaled by 2, the dual variables are not.
// Reads: width, height (fine), src_width, src_height (coarse).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "flow.glsl"

layout(local_size_x = 16, local_size_y = 16) in;

layout(push_constant) uniform Push { FlowParams pc; };
layout(std430, binding = 0) readonly buffer UIn { vec2 u_in[]; };
layout(std430, binding = 1) readonly buffer PIn { vec4 p_in[]; };
layout(std430, binding = 2) writeonly buffer UOut { vec2 u_out[]; };
layout(std430, binding = 3) writeonly buffer POut { vec4 p_out[]; };

void main() {
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y;
    if (x >= pc.width || y >= pc.height) return;
    vec2 f;
    uvec4 c = flow_bilinear(0.5 * vec2(float(x), float(y)), pc.src_width, pc.src_height, f);
    uint o = y * pc.width + x;
    u_out[o] = 2.0 * FLOW_LERP2(u_in[c.x], u_in[c.y], u_in[c.z], u_in[c.w], f);
    p_out[o] = FLOW_LERP2(p_in[c.x], p_in[c.y], p_in[c.z], p_in[c.w], f);
}
