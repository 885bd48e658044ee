#version 460
// RGB [0,1] → grey levels [0, 255] of both images into level 0 of the pyramid.
// Reads: width, height, off0 (I0 plane), off1 (I1 plane).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "flow.glsl"

layout(local_size_x = 16, local_size_y = 16) in;

layout(push_constant) uniform Push { FlowParams pc; };
layout(std430, binding = 0) readonly buffer ImgA { vec4 img_a[]; };
layout(std430, binding = 1) readonly buffer ImgB { vec4 img_b[]; };
layout(std430, binding = 2) buffer Pyr { float pyr[]; };

void main() {
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y;
    if (x >= pc.width || y >= pc.height) return;
    uint o = y * pc.width + x;
    const vec3 luma = vec3(0.299, 0.587, 0.114);
    pyr[pc.off0 + o] = FLOW_GREY_SCALE * dot(img_a[o].rgb, luma);
    pyr[pc.off1 + o] = FLOW_GREY_SCALE * dot(img_b[o].rgb, luma);
}
