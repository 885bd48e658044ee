#version 460
// Weight and bias gradients of one Linear, first stage of a deterministic two-stage reduction:
//   partial[s][o][c] = Σ_{r in chunk s} dz[r][o] · in[r][c],  in = [A | B | 1]
// (column fan_in is the constant 1, so it yields the bias gradient). Each workgroup owns a
// 64 (o) × 64 (c) tile of one chunk and walks its rows 16 at a time; `mlp/reduce_grad` sums
// the chunks in a fixed order. Grid: x = column tiles, y = output tiles, z = chunks.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "gemm.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { MlpBwdWeightParams pc; };
layout(std430, binding = 0) readonly buffer Dz { float dz[]; };
layout(std430, binding = 1) readonly buffer InA { float in_a[]; };
layout(std430, binding = 2) readonly buffer InB { float in_b[]; };
layout(std430, binding = 3) writeonly buffer Partial { float partial[]; };

float load_in(uint r, uint k) {
    if (r >= pc.n || k > pc.fan_in) return 0.0;
    if (k == pc.fan_in) return 1.0;
    return k < pc.ka ? in_a[r * pc.a_stride + k] : in_b[r * pc.b_stride + (k - pc.ka)];
}

void main() {
    uint lid = gl_LocalInvocationIndex;
    uint tx = lid % 16, ty = lid / 16;
    uint c0 = gl_WorkGroupID.x * GEMM_BN;
    uint o0 = gl_WorkGroupID.y * GEMM_BM;
    uint chunk = gl_WorkGroupID.z;
    uint r_begin = chunk * pc.chunk_rows;
    uint r_end = min(r_begin + pc.chunk_rows, pc.n);
    float acc[4][4];
    for (uint i = 0; i < 4; ++i)
        for (uint j = 0; j < 4; ++j) acc[i][j] = 0.0;
    for (uint r0 = r_begin; r0 < r_end; r0 += GEMM_BK) {
        for (uint e = lid; e < GEMM_BM * GEMM_BK; e += 256) {
            uint k = e / GEMM_BM, x = e % GEMM_BM;
            uint r = r0 + k;
            bool ok = r < r_end;
            s_a[k][x] = (ok && o0 + x < pc.fan_out) ? dz[r * pc.dz_stride + o0 + x] : 0.0;
            s_b[k][x] = ok ? load_in(r, c0 + x) : 0.0;
        }
        barrier();
        GEMM_TILE_FMA(acc, tx, ty)
        barrier();
    }
    uint cols = pc.fan_in + 1;
    uint base = chunk * pc.fan_out * cols;
    for (uint i = 0; i < 4; ++i) {
        uint o = o0 + ty + 16 * i;
        if (o >= pc.fan_out) continue;
        for (uint j = 0; j < 4; ++j) {
            uint c = c0 + tx + 16 * j;
            if (c < cols) partial[base + o * cols + c] = acc[i][j];
        }
    }
}
