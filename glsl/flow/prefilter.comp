#version 460
// One 5×5 binomial blur pass ([1 4 6 4 1]/16 separable, clamped border; variance +1 px²) of a
// full-resolution grey plane, for the flow's prefilters: mix = 0 writes dst = blur(src) (the
// photo's blur, matched to a blurry render), mix = β writes dst = dst − β·blur(src) (the
// texture part of a structure–texture split whose structure is the blurred image).
// src and dst are different buffers: a pass reads its neighbours while others write.
// Reads: width, height, off0 (src plane), off2 (dst plane), mix.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "flow.glsl"

layout(local_size_x = 16, local_size_y = 16) in;

layout(push_constant) uniform Push { FlowParams pc; };
layout(std430, binding = 0) readonly buffer Src { float src[]; };
layout(std430, binding = 1) buffer Dst { float dst[]; };

void main() {
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y;
    if (x >= pc.width || y >= pc.height) return;
    const float k[5] = float[5](1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0);
    int w = int(pc.width), h = int(pc.height);
    float acc = 0.0;
    for (int j = 0; j < 5; ++j) {
        int yy = clamp(int(y) + j - 2, 0, h - 1);
        float row = 0.0;
        for (int i = 0; i < 5; ++i) {
            int xx = clamp(int(x) + i - 2, 0, w - 1);
            row += k[i] * src[pc.off0 + uint(yy * w + xx)];
        }
        acc += k[j] * row;
    }
    uint o = pc.off2 + y * pc.width + x;
    dst[o] = pc.mix == 0.0 ? acc : dst[o] - pc.mix * acc;
}
