// Coarse → fine level: bilinear, fine pixel x at coarse x/2 (the pyramid keeps even pixels);
// the flow is scaled by 2, the dual variables are not.
// Reads: width, height (fine), src_width, src_height (coarse).
// Body of upsample.comp (storage buffers) and upsample_texel.comp (texel buffers, glsl/include/access.glsl).
#ifndef UPSAMPLE_GLSL
#define UPSAMPLE_GLSL
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "flow.glsl"
#include "access.glsl"

layout(local_size_x = 16, local_size_y = 16) in;

layout(push_constant) uniform Push { FlowParams pc; };
ARR_RO(0, vec2, rg32f, UIn, u_in)
ARR_RO(1, vec4, rgba32f, PIn, p_in)
ARR_WO(2, vec2, rg32f, UOut, u_out)
ARR_WO(3, vec4, rgba32f, POut, p_out)

void main() {
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y;
    if (x >= pc.width || y >= pc.height) return;
    vec2 f;
    uvec4 c = flow_bilinear(0.5 * vec2(float(x), float(y)), pc.src_width, pc.src_height, f);
    uint o = y * pc.width + x;
    ST2(u_out, o, 2.0 * FLOW_LERP2(LD2(u_in, c.x), LD2(u_in, c.y), LD2(u_in, c.z), LD2(u_in, c.w), f));
    ST4(p_out, o, FLOW_LERP2(LD4(p_in, c.x), LD4(p_in, c.y), LD4(p_in, c.z), LD4(p_in, c.w), f));
}

#endif
