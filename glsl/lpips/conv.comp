#version 460
// One convolution + bias + ReLU over a batch of planar images, as an implicit GEMM: rows =
// output pixels, columns = output channels, K = cin·k·k, the input patch gathered on the fly
// (zero outside the image = zero padding). The 64×64 tiled GEMM of the MLP (4×4 outputs per
// thread). Grid: x = pixel tiles, y = channel tiles, z = image of the batch.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "../mlp/gemm.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { LpipsConvParams pc; };
layout(std430, binding = 0) readonly buffer Src { float src[]; };          // [B][cin][in_h][in_w]
layout(std430, binding = 1) readonly buffer Weights { float weights[]; };  // all tensors
layout(std430, binding = 2) writeonly buffer Dst { float dst[]; };         // [B][cout][out_h][out_w]

// n / d for n < 2^24 without an integer division (CPU SIMD scalarises those): a float
// estimate, off by at most one, then corrected.
uint div_small(uint n, uint d, float inv_d) {
    uint q = uint(float(n) * inv_d);
    int r = int(n) - int(q * d);
    if (r < 0) q -= 1u;
    else if (r >= int(d)) q += 1u;
    return q;
}

void main() {
    uint lid = gl_LocalInvocationIndex;
    uint tx = lid % 16, ty = lid / 16;
    uint npix = pc.out_w * pc.out_h;
    uint p0 = gl_WorkGroupID.x * GEMM_BM;
    uint c0 = gl_WorkGroupID.y * GEMM_BN;
    uint b = gl_WorkGroupID.z;
    uint kk2 = pc.ksize * pc.ksize;
    uint kdim = pc.cin * kk2;
    float inv_kk2 = 1.0 / float(kk2), inv_k = 1.0 / float(pc.ksize);
    // Every K step this thread gathers column tx of rows ty + 16m: the rows' pixels (and
    // their patch corners) are fixed, only the tap (ci, ky, kx) moves.
    ivec2 corner[4];
    bool valid[4];
    for (uint m = 0; m < 4; ++m) {
        uint p = p0 + ty + 16 * m;
        valid[m] = p < npix;
        uint oy = p / pc.out_w, ox = p - oy * pc.out_w;
        corner[m] = ivec2(ox * pc.stride, oy * pc.stride) - int(pc.pad);
    }
    uint plane = pc.in_w * pc.in_h;
    uint src_b = b * pc.cin * plane;
    float acc[4][4];
    for (uint i = 0; i < 4; ++i)
        for (uint j = 0; j < 4; ++j) acc[i][j] = 0.0;
    for (uint k0 = 0; k0 < kdim; k0 += GEMM_BK) {
        uint k = k0 + tx;
        bool kin = k < kdim;
        uint ci = div_small(k, kk2, inv_kk2);
        uint rem = k - ci * kk2;
        uint ky = div_small(rem, pc.ksize, inv_k);
        ivec2 tap = ivec2(rem - ky * pc.ksize, ky);
        uint base = src_b + ci * plane;
        for (uint m = 0; m < 4; ++m) {
            ivec2 q = corner[m] + tap;
            bool inside = kin && valid[m] && q.x >= 0 && q.y >= 0 && q.x < int(pc.in_w)
                && q.y < int(pc.in_h);
            s_a[tx][ty + 16 * m] = inside ? src[base + uint(q.y) * pc.in_w + uint(q.x)] : 0.0;
            uint c = c0 + ty + 16 * m;
            s_b[tx][ty + 16 * m] = (kin && c < pc.cout) ? weights[pc.w_off + c * kdim + k] : 0.0;
        }
        barrier();
        GEMM_TILE_FMA(acc, tx, ty)
        barrier();
    }
    for (uint j = 0; j < 4; ++j) {
        uint c = c0 + tx + 16 * j;
        if (c >= pc.cout) continue;
        float bias = weights[pc.b_off + c];
        uint dst_c = (b * pc.cout + c) * npix;
        for (uint i = 0; i < 4; ++i) {
            uint p = p0 + ty + 16 * i;
            if (p < npix) dst[dst_c + p] = max(acc[i][j] + bias, 0.0);
        }
    }
}
