#version 460
// Wᵀ of one Linear into the same offsets of a second buffer, so the input gradient reads
// windows of whole Wᵀ rows (contiguous) from a uniform buffer like the forward reads W.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 64) in;

layout(push_constant) uniform Push { MlpTransposeParams pc; };
layout(std430, binding = 0) readonly buffer Params { float params[]; };
layout(std430, binding = 1) writeonly buffer Wt { float wt[]; };

void main() {
    uint e = gl_GlobalInvocationID.x;
    if (e >= pc.fan_in * pc.fan_out) return;
    uint o = e / pc.fan_in, c = e % pc.fan_in;
    wt[pc.w_off + c * pc.fan_out + o] = params[pc.w_off + e];
}
