// Fused forward of the whole network for a block of ROWS Gaussians per workgroup: the
// encoding, every layer's activations and the skip concatenation stay in shared memory; only
// the weights (from global memory / cache) and the final [ROWS][10] outputs touch memory.
// No activations are stored, so this path serves evaluations without gradient (the
// intermediate render at t2, metrics) and costs no memory per Gaussian.
// Limits (checked on the host): width, time-net hidden ≤ FUSED_MAXW = 256, in_dims ≤ 128.
// The including shader defines ROWS, ACT (shared storage type), W_AT(i) (a weight as float)
// and the Params binding.
#ifndef FUSED_FWD_GLSL
#define FUSED_FWD_GLSL
#include "posenc.glsl"

#define FUSED_MAXW 256
#define FUSED_MAXIN 128

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { MlpFusedParams pc; };
layout(std430, binding = 1) readonly buffer Table { uint table[]; }; // [linear][fan_in, fan_out, w_off, b_off]
layout(std430, binding = 2) readonly buffer Xyz { float xyz[]; };
layout(std430, binding = 3) readonly buffer Times { float times[]; };
layout(std430, binding = 4) writeonly buffer Out { float out_[]; };

shared ACT s_x0[ROWS][FUSED_MAXIN];
shared ACT s_h[ROWS][FUSED_MAXW];

// The input column k of a layer: [x0 | h] when `cat`, else x0 (src 0) or h (src 1).
float in_at(uint r, uint k, uint src, uint ka) {
    if (src == 0 || (src == 2 && k < ka)) return float(s_x0[r][k]);
    return float(s_h[r][src == 2 ? k - ka : k]);
}

// dst 0: s_h, 1: s_x0 from column dst_col, 2: global out.
void layer(uint li, uint src, uint ka, bool relu, uint dst, uint dst_col, uint row0) {
    uint fan_in = table[4 * li], fan_out = table[4 * li + 1];
    uint w_off = table[4 * li + 2], b_off = table[4 * li + 3];
    uint o = gl_LocalInvocationIndex;
    float acc[ROWS];
    if (o < fan_out) {
        float b = W_AT(b_off + o);
        for (uint r = 0; r < ROWS; ++r) acc[r] = b;
        uint wrow = w_off + o * fan_in;
        for (uint k = 0; k < fan_in; ++k) {
            float w = W_AT(wrow + k);
            for (uint r = 0; r < ROWS; ++r) acc[r] += w * in_at(r, k, src, ka);
        }
    }
    barrier(); // every read of the input is done before anything is overwritten
    if (o < fan_out) {
        for (uint r = 0; r < ROWS; ++r) {
            float v = relu ? max(acc[r], 0.0) : acc[r];
            if (dst == 0) s_h[r][o] = STORE_ACT(v);
            else if (dst == 1) s_x0[r][dst_col + o] = STORE_ACT(v);
            else if (row0 + r < pc.n) out_[(row0 + r) * 10 + o] = v;
        }
    }
    barrier();
}

void main() {
    uint block = gl_WorkGroupID.x + gl_WorkGroupID.y * gl_NumWorkGroups.x;
    uint row0 = block * ROWS;
    if (row0 >= pc.n) return; // uniform per workgroup
    uint lid = gl_LocalInvocationIndex;
    uint xd = 3 + 6 * pc.x_freqs;
    // Encoding: raw values, then one (sin, cos) pair per task.
    for (uint e = lid; e < ROWS * 4; e += 256) {
        uint r = e / 4, c = e % 4, g = min(row0 + r, pc.n - 1);
        float v = c < 3 ? xyz[3 * g + c] : (pc.per_gaussian_time != 0 ? times[g] : pc.time);
        s_x0[r][c < 3 ? c : xd] = STORE_ACT(v);
    }
    uint tasks = 3 * pc.x_freqs + pc.t_freqs;
    for (uint e = lid; e < ROWS * tasks; e += 256) {
        uint r = e / tasks, q = e % tasks, g = min(row0 + r, pc.n - 1);
        if (q < 3 * pc.x_freqs) {
            uint c = q % 3, j = q / 3;
            vec2 s = sincos_pow2(xyz[3 * g + c], int(j));
            s_x0[r][3 + 6 * j + c] = STORE_ACT(s.x);
            s_x0[r][6 + 6 * j + c] = STORE_ACT(s.y);
        } else {
            uint j = q - 3 * pc.x_freqs;
            float t = pc.per_gaussian_time != 0 ? times[g] : pc.time;
            vec2 s = sincos_pow2(t, int(j));
            s_x0[r][xd + 1 + 2 * j] = STORE_ACT(s.x);
            s_x0[r][xd + 2 + 2 * j] = STORE_ACT(s.y);
        }
    }
    barrier();
    uint li = 0;
    if (pc.time_net != 0) {
        // γ(t) sits at columns xd.. of x0: read it through a shifted view.
        uint fan_in = table[0], fan_out = table[1], w_off = table[2], b_off = table[3];
        uint o = lid;
        float acc[ROWS];
        if (o < fan_out) {
            for (uint r = 0; r < ROWS; ++r) acc[r] = W_AT(b_off + o);
            for (uint k = 0; k < fan_in; ++k) {
                float w = W_AT(w_off + o * fan_in + k);
                for (uint r = 0; r < ROWS; ++r) acc[r] += w * float(s_x0[r][xd + k]);
            }
        }
        barrier();
        if (o < fan_out)
            for (uint r = 0; r < ROWS; ++r) s_h[r][o] = STORE_ACT(max(acc[r], 0.0));
        barrier();
        layer(1, 1, 0, false, 1, xd, row0); // t_feat overwrites γ(t)
        li = 2;
    }
    uint in_dims = xd + pc.t_feat;
    for (uint i = 0; i < pc.depth; ++i, ++li) {
        uint src = i == 0 ? 0 : (pc.skip != 0xffffffffu && i == pc.skip + 1 ? 2 : 1);
        layer(li, src, in_dims, true, 0, 0, row0);
    }
    layer(li, 1, 0, false, 2, 0, row0);
}

#endif
