#version 460
// γ(x) (and γ(t)) per Gaussian into the trunk input rows x0 (layer-wise path).
// Row layout (NeRF embedder): x0 x1 x2, sin(x)·3, cos(x)·3 per frequency 2^0..2^(L−1), then
// γ(t) = t, sin(t), cos(t), … either after γ(x) in x0 (Direct) or in enc_t (time net input).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "posenc.glsl"

layout(local_size_x = 64) in;

layout(push_constant) uniform Push { MlpEncodeParams pc; };
layout(std430, binding = 0) readonly buffer Xyz { float xyz[]; };
layout(std430, binding = 1) readonly buffer Times { float times[]; };
layout(std430, binding = 2) writeonly buffer X0 { float x0[]; };
layout(std430, binding = 3) writeonly buffer EncT { float enc_t[]; };

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n) return;
    uint r = i * pc.x0_stride;
    vec3 x = vec3(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
    x0[r] = x.x;
    x0[r + 1] = x.y;
    x0[r + 2] = x.z;
    for (uint j = 0; j < pc.x_freqs; ++j) {
        vec2 a = sincos_pow2(x.x, int(j));
        vec2 b = sincos_pow2(x.y, int(j));
        vec2 c = sincos_pow2(x.z, int(j));
        uint o = r + 3 + 6 * j;
        x0[o] = a.x;
        x0[o + 1] = b.x;
        x0[o + 2] = c.x;
        x0[o + 3] = a.y;
        x0[o + 4] = b.y;
        x0[o + 5] = c.y;
    }
    float t = pc.per_gaussian_time != 0 ? times[i] : pc.time;
    if (pc.t_to_x0 != 0) {
        uint o = r + 3 + 6 * pc.x_freqs;
        x0[o] = t;
        for (uint j = 0; j < pc.t_freqs; ++j) {
            vec2 s = sincos_pow2(t, int(j));
            x0[o + 1 + 2 * j] = s.x;
            x0[o + 2 + 2 * j] = s.y;
        }
    } else {
        uint o = i * pc.t_stride;
        enc_t[o] = t;
        for (uint j = 0; j < pc.t_freqs; ++j) {
            vec2 s = sincos_pow2(t, int(j));
            enc_t[o + 1 + 2 * j] = s.x;
            enc_t[o + 2 + 2 * j] = s.y;
        }
    }
}
