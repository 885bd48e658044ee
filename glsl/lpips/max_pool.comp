#version 460
// Max-pool 3×3, stride 2, no padding, floor size (torchvision AlexNet's MaxPool2d(3, 2)) of
// planar images. Grid: x, y = output pixel, z = plane (image · channel).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 8, local_size_y = 8) in;

layout(push_constant) uniform Push { LpipsPoolParams pc; };
layout(std430, binding = 0) readonly buffer Src { float src[]; };   // [planes][in_h][in_w]
layout(std430, binding = 1) writeonly buffer Dst { float dst[]; };  // [planes][out_h][out_w]

void main() {
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y, z = gl_GlobalInvocationID.z;
    if (x >= pc.out_w || y >= pc.out_h || z >= pc.planes) return;
    uint base = z * pc.in_w * pc.in_h + 2u * y * pc.in_w + 2u * x;
    float m = src[base];
    for (uint dy = 0; dy < 3u; ++dy)
        for (uint dx = 0; dx < 3u; ++dx) m = max(m, src[base + dy * pc.in_w + dx]);
    dst[(z * pc.out_h + y) * pc.out_w + x] = m;
}
