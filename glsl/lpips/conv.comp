#version 460
// One convolution + bias + ReLU over a batch of planar images, direct, register-blocked: each
// invocation owns CONV_PX consecutive output pixels of a row × CONV_CO consecutive output
// channels, so per kernel tap it loads CONV_PX inputs and CONV_CO weights for
// CONV_PX · CONV_CO FMAs. On lavapipe every buffer or shared-memory read is a per-lane gather
// costing tens of FMAs (the MLP's shared-memory tiled GEMM runs at ~1/20 of the register FMA
// rate), so FMAs per load is what sets the speed; no shared memory, no barrier.
// Grid: x = (pixel block, output row), y = channel block, z = image of the batch.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

#define CONV_PX 8   // mirrored in src/kernels/lpips.rs
#define CONV_CO 32

layout(local_size_x = 64) in;

layout(push_constant) uniform Push { LpipsConvParams pc; };
layout(std430, binding = 0) readonly buffer Src { float src[]; };          // [B][cin][in_h][in_w]
layout(std430, binding = 1) readonly buffer Weights { float weights[]; };  // all tensors
layout(std430, binding = 2) writeonly buffer Dst { float dst[]; };         // [B][cout][out_h][out_w]

void main() {
    uint nbx = (pc.out_w + CONV_PX - 1u) / CONV_PX;
    uint t = gl_GlobalInvocationID.x;
    if (t >= nbx * pc.out_h) return;
    uint oy = t / nbx, ox0 = (t - oy * nbx) * CONV_PX;
    uint c0 = gl_GlobalInvocationID.y * CONV_CO;
    uint b = gl_GlobalInvocationID.z;
    int x0 = int(ox0 * pc.stride) - int(pc.pad), y0 = int(oy * pc.stride) - int(pc.pad);
    uint k = pc.ksize, kk = k * k, wrow = pc.cin * kk;
    int last_x = int(pc.in_w) - 1;
    // Channels past cout read the last channel's weights (never stored).
    uint wbase[CONV_CO];
    for (uint j = 0; j < CONV_CO; ++j) wbase[j] = pc.w_off + min(c0 + j, pc.cout - 1u) * wrow;
    float acc[CONV_PX][CONV_CO];
    for (uint i = 0; i < CONV_PX; ++i)
        for (uint j = 0; j < CONV_CO; ++j) acc[i][j] = 0.0;
    for (uint ci = 0; ci < pc.cin; ++ci) {
        uint sbase = (b * pc.cin + ci) * pc.in_w * pc.in_h;
        for (uint ky = 0; ky < k; ++ky) {
            int iy = y0 + int(ky);
            if (iy < 0 || iy >= int(pc.in_h)) continue;
            uint rbase = sbase + uint(iy) * pc.in_w;
            uint wtap = ci * kk + ky * k;
            for (uint kx = 0; kx < k; ++kx) {
                float v[CONV_PX], w[CONV_CO];
                // Zero padding without a branch: read a clamped address, then select.
                for (uint i = 0; i < CONV_PX; ++i) {
                    int ix = x0 + int(i * pc.stride + kx);
                    float s = src[rbase + uint(clamp(ix, 0, last_x))];
                    v[i] = (ix >= 0 && ix <= last_x) ? s : 0.0;
                }
                for (uint j = 0; j < CONV_CO; ++j) w[j] = weights[wbase[j] + wtap + kx];
                for (uint i = 0; i < CONV_PX; ++i)
                    for (uint j = 0; j < CONV_CO; ++j) acc[i][j] += v[i] * w[j];
            }
        }
    }
    uint npix = pc.out_w * pc.out_h;
    for (uint j = 0; j < CONV_CO; ++j) {
        uint c = c0 + j;
        if (c >= pc.cout) continue;
        float bias = weights[pc.b_off + c];
        uint o = (b * pc.cout + c) * npix + oy * pc.out_w;
        for (uint i = 0; i < CONV_PX; ++i)
            if (ox0 + i < pc.out_w) dst[o + ox0 + i] = max(acc[i][j] + bias, 0.0);
    }
}
