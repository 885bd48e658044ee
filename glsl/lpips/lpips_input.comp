#version 460
// Two RGBA images in [0, 1] → planar [2][3][H][W] network input: clamped to [0, 1] (scored as
// they would be saved), mapped to [−1, 1], then the reference package's ScalingLayer
// (x − shift) / scale.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(push_constant) uniform Push { LpipsInputParams pc; };
layout(std430, binding = 0) readonly buffer Img0 { vec4 img0[]; };  // [H·W]
layout(std430, binding = 1) readonly buffer Img1 { vec4 img1[]; };  // [H·W]
layout(std430, binding = 2) writeonly buffer Dst { float dst[]; };  // [2][3][H·W]

void main() {
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y;
    if (x >= pc.width || y >= pc.height) return;
    uint hw = pc.width * pc.height, p = y * pc.width + x;
    vec3 a = clamp(img0[p].rgb, 0.0, 1.0) * 2.0 - 1.0;
    vec3 b = clamp(img1[p].rgb, 0.0, 1.0) * 2.0 - 1.0;
    for (uint c = 0; c < 3u; ++c) {
        dst[c * hw + p] = (a[c] - pc.shift[c]) / pc.scale[c];
        dst[(3u + c) * hw + p] = (b[c] - pc.shift[c]) / pc.scale[c];
    }
}
