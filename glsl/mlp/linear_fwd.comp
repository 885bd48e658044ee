#version 460
// One Linear over all rows: out[r][out_col + o] = act(b[o] + Σ_k W[o][k] · in[r][k]) with
// in = [A[r][0..ka] | B[r][0..fan_in−ka]] (the skip concatenation without a copy).
// Tiled GEMM with a fused bias + ReLU epilogue. Grid: x = output tiles, y·z = row tiles.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "gemm.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { MlpLinearParams pc; };
layout(std430, binding = 0) readonly buffer Params { float params[]; };
layout(std430, binding = 1) readonly buffer InA { float in_a[]; };
layout(std430, binding = 2) readonly buffer InB { float in_b[]; };
layout(std430, binding = 3) writeonly buffer Out { float out_[]; };

float load_in(uint r, uint k) {
    if (r >= pc.n || k >= pc.fan_in) return 0.0;
    return k < pc.ka ? in_a[r * pc.a_stride + k] : in_b[r * pc.b_stride + (k - pc.ka)];
}

void main() {
    uint lid = gl_LocalInvocationIndex;
    uint tx = lid % 16, ty = lid / 16;
    uint row0 = gemm_row_tile() * GEMM_BM;
    uint o0 = gl_WorkGroupID.x * GEMM_BN;
    float acc[4][4];
    for (uint i = 0; i < 4; ++i)
        for (uint j = 0; j < 4; ++j) acc[i][j] = 0.0;
    for (uint k0 = 0; k0 < pc.fan_in; k0 += GEMM_BK) {
        for (uint e = lid; e < GEMM_BM * GEMM_BK; e += 256) {
            uint r = e / GEMM_BK, k = e % GEMM_BK;
            s_a[k][r] = load_in(row0 + r, k0 + k);
            uint o = o0 + r;
            s_b[k][r] = (o < pc.fan_out && k0 + k < pc.fan_in)
                ? params[pc.w_off + o * pc.fan_in + k0 + k] : 0.0;
        }
        barrier();
        GEMM_TILE_FMA(acc, tx, ty)
        barrier();
    }
    for (uint j = 0; j < 4; ++j) {
        uint o = o0 + tx + 16 * j;
        if (o >= pc.fan_out) continue;
        float bias = params[pc.b_off + o];
        for (uint i = 0; i < 4; ++i) {
            uint r = row0 + ty + 16 * i;
            if (r >= pc.n) continue;
            float v = acc[i][j] + bias;
            out_[r * pc.out_stride + pc.out_col + o] = pc.relu != 0 ? max(v, 0.0) : v;
        }
    }
}
