#version 460
// Gradient to a Linear's input columns [col0, col0 + cols):
//   d_in[r][out_col + c] (+)= m · Σ_o dz[r][o] · W[o][col0 + c],
// m = (act[r][mask_col + c] > 0) when mask_stride > 0 (the ReLU of the layer that produced
// those inputs), else 1. Tiled GEMM, K = fan_out. Grid: x = column tiles, y·z = row tiles.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "gemm.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { MlpBwdDataParams pc; };
layout(std430, binding = 0) readonly buffer Params { float params[]; };
layout(std430, binding = 1) readonly buffer Dz { float dz[]; };
layout(std430, binding = 2) readonly buffer Act { float act[]; };
layout(std430, binding = 3) buffer DIn { float d_in[]; };

void main() {
    uint lid = gl_LocalInvocationIndex;
    uint tx = lid % 16, ty = lid / 16;
    uint row0 = gemm_row_tile() * GEMM_BM;
    uint c0 = gl_WorkGroupID.x * GEMM_BN;
    float acc[4][4];
    for (uint i = 0; i < 4; ++i)
        for (uint j = 0; j < 4; ++j) acc[i][j] = 0.0;
    for (uint k0 = 0; k0 < pc.fan_out; k0 += GEMM_BK) {
        for (uint e = lid; e < GEMM_BM * GEMM_BK; e += 256) {
            // dz tile: rows × K, K fastest.
            uint r = e / GEMM_BK, k = e % GEMM_BK;
            s_a[k][r] = (row0 + r < pc.n && k0 + k < pc.fan_out)
                ? dz[(row0 + r) * pc.dz_stride + k0 + k] : 0.0;
            // W tile: K × columns, columns fastest (W rows are contiguous in the column index).
            uint kb = e / GEMM_BN, c = e % GEMM_BN;
            s_b[kb][c] = (k0 + kb < pc.fan_out && c0 + c < pc.cols)
                ? params[pc.w_off + (k0 + kb) * pc.fan_in + pc.col0 + c0 + c] : 0.0;
        }
        barrier();
        GEMM_TILE_FMA(acc, tx, ty)
        barrier();
    }
    for (uint j = 0; j < 4; ++j) {
        uint c = c0 + tx + 16 * j;
        if (c >= pc.cols) continue;
        for (uint i = 0; i < 4; ++i) {
            uint r = row0 + ty + 16 * i;
            if (r >= pc.n) continue;
            float v = acc[i][j];
            if (pc.mask_stride != 0 && !(act[r * pc.mask_stride + pc.mask_col + c] > 0.0)) v = 0.0;
            uint o = r * pc.out_stride + pc.out_col + c;
            d_in[o] = pc.accumulate != 0 ? d_in[o] + v : v;
        }
    }
}
