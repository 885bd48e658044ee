#version 460
// m(p) = |v(p)| for an interleaved [H·W, C] field (C = 2 or 3), per-workgroup min and max with
// their first pixel (lexicographic (value, pixel) order, so the reduction order cannot change
// the result) and a non-finite flag. IQR mode also writes the sort input: key = the float bits
// of m (m ≥ 0, so bits order like values), value = the pixel.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "motion.glsl"

layout(local_size_x = MOTION_WG) in;

layout(push_constant) uniform Push { MotionNormParams pc; };
layout(std430, binding = 0) readonly buffer V { float v[]; };
layout(std430, binding = 1) writeonly buffer M { float m[]; };
layout(std430, binding = 2) writeonly buffer Parts { MinMaxPart parts[]; };
layout(std430, binding = 3) writeonly buffer Keys { uint keys[]; };
layout(std430, binding = 4) writeonly buffer Vals { uint vals[]; };

shared float s_mn[MOTION_WG];
shared float s_mx[MOTION_WG];
shared uint s_imn[MOTION_WG];
shared uint s_imx[MOTION_WG];
shared uint s_bad[MOTION_WG];

void main() {
    uint wg = motion_group(pc.groups_x);
    uint tid = gl_LocalInvocationIndex;
    uint p = wg * MOTION_WG + tid;
    float mn = POS_INF, mx = -POS_INF;
    uint imn = NONE, imx = NONE, bad = 0u;
    if (p < pc.n) {
        uint b = p * pc.channels;
        float z = pc.channels == 3u ? v[b + 2u] : 0.0;
        float mag = robust_norm(v[b], v[b + 1u], z);
        m[p] = mag;
        if (mag <= FLT_MAX) {
            mn = mag; mx = mag; imn = p; imx = p;
        } else {
            bad = 1u;
        }
        if (pc.mode == MODE_IQR) {
            keys[p] = floatBitsToUint(mag);
            vals[p] = p;
        }
    }
    s_mn[tid] = mn; s_imn[tid] = imn;
    s_mx[tid] = mx; s_imx[tid] = imx;
    s_bad[tid] = bad;
    barrier();
    for (uint off = MOTION_WG / 2u; off > 0u; off >>= 1) {
        if (tid < off) {
            uint o = tid + off;
            if (min_first(s_mn[o], s_imn[o], s_mn[tid], s_imn[tid])) { s_mn[tid] = s_mn[o]; s_imn[tid] = s_imn[o]; }
            if (max_first(s_mx[o], s_imx[o], s_mx[tid], s_imx[tid])) { s_mx[tid] = s_mx[o]; s_imx[tid] = s_imx[o]; }
            s_bad[tid] |= s_bad[o];
        }
        barrier();
    }
    if (tid == 0u) {
        parts[wg] = MinMaxPart(s_mn[0], s_mx[0], s_imn[0], s_imx[0], s_bad[0], 0u, 0u, 0u);
    }
}
