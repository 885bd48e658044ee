#version 460
// One workgroup: reduces the per-workgroup min/max partials (same lexicographic order, so the
// first pixel wins ties) and writes min, max, argmin, argmax, the non-finite flag and the
// binary exponent e of the max (max = f·2^e) into the statistics buffer.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "motion.glsl"

layout(local_size_x = MOTION_WG) in;

layout(push_constant) uniform Push { MotionNormParams pc; };
layout(std430, binding = 0) readonly buffer Parts { MinMaxPart parts[]; };
layout(std430, binding = 1) writeonly buffer Stats { uint stats[]; };

shared float s_mn[MOTION_WG];
shared float s_mx[MOTION_WG];
shared uint s_imn[MOTION_WG];
shared uint s_imx[MOTION_WG];
shared uint s_bad[MOTION_WG];

void main() {
    uint tid = gl_LocalInvocationIndex;
    float mn = POS_INF, mx = -POS_INF;
    uint imn = NONE, imx = NONE, bad = 0u;
    for (uint i = tid; i < pc.groups; i += MOTION_WG) {
        MinMaxPart q = parts[i];
        if (min_first(q.mn, q.imn, mn, imn)) { mn = q.mn; imn = q.imn; }
        if (max_first(q.mx, q.imx, mx, imx)) { mx = q.mx; imx = q.imx; }
        bad |= q.bad;
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
        bool nonfinite = s_bad[0] != 0u || s_imx[0] == NONE;
        int e = 0;
        if (!nonfinite && s_mx[0] > 0.0) frexp(s_mx[0], e);
        stats[NS_FLAG] = nonfinite ? FLAG_NONFINITE : FLAG_OK;
        stats[NS_EXP] = uint(e);
        stats[NS_MIN] = floatBitsToUint(s_mn[0]);
        stats[NS_MAX] = floatBitsToUint(s_mx[0]);
        stats[NS_ARGMIN] = s_imn[0];
        stats[NS_ARGMAX] = s_imx[0];
    }
}
