#version 460
// Separable 11-tap Gaussian blur (h pass) of pc.planes planar images with zero padding, like
// 3DGS's conv2d(padding = 5). The window is symmetric, so the same pass is also its own
// transpose (used by the SSIM backward).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "loss.glsl"

layout(local_size_x = 16, local_size_y = 16) in;

layout(push_constant) uniform Push { LossParams pc; };
layout(std430, binding = 0) readonly buffer Src { float src[]; };
layout(std430, binding = 1) writeonly buffer Dst { float dst[]; };

void main() {
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y, plane = gl_GlobalInvocationID.z;
    if (x >= pc.width || y >= pc.height || plane >= pc.planes) return;
    uint base = plane * pc.width * pc.height;
    float acc = 0.0;
    for (int d = -SSIM_RADIUS; d <= SSIM_RADIUS; ++d) {
        ivec2 q = ivec2(int(x) + d, int(y));
        int xx = q.x, yy = q.y;
        if (xx >= 0 && xx < int(pc.width)) acc += gauss_tap(d) * src[base + uint(xx) + y * pc.width];
    }
    dst[base + x + y * pc.width] = acc;
}
