#version 460
// norm_mag's CPU shape: the same outputs (m, the IQR sort input, one min/max partial per 256
// pixels) from a workgroup of 8 invocations, each folding 32 pixels (p = group·256 + lane +
// 8·i) in registers, then one barrier and lane 0 folding the 8. The tree kernel's eight
// barrier rounds over five shared arrays cost lavapipe (a 256-wide workgroup is 32 coroutines)
// 15 times this kernel's bwd_sums twin; min/max by (value, pixel) does not depend on the fold
// order, so both shapes write the same bits.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "motion.glsl"

#define RUN_LANES 8u
layout(local_size_x = RUN_LANES) in;

layout(push_constant) uniform Push { MotionNormParams pc; };
layout(std430, binding = 0) readonly buffer V { float v[]; };
layout(std430, binding = 1) writeonly buffer M { float m[]; };
layout(std430, binding = 2) writeonly buffer Parts { MinMaxPart parts[]; };
layout(std430, binding = 3) writeonly buffer Keys { uint keys[]; };
layout(std430, binding = 4) writeonly buffer Vals { uint vals[]; };

shared MinMaxPart s_part[RUN_LANES];

void main() {
    uint wg = motion_group(pc.groups_x);
    uint tid = gl_LocalInvocationIndex;
    float mn = POS_INF, mx = -POS_INF;
    uint imn = NONE, imx = NONE, bad = 0u;
    for (uint i = 0u; i < MOTION_WG / RUN_LANES; ++i) {
        uint p = wg * MOTION_WG + tid + RUN_LANES * i;
        if (p >= pc.n) break;
        uint b = p * pc.channels;
        float z = pc.channels == 3u ? v[b + 2u] : 0.0;
        float mag = robust_norm(v[b], v[b + 1u], z);
        m[p] = mag;
        if (mag <= FLT_MAX) {
            if (min_first(mag, p, mn, imn)) { mn = mag; imn = p; }
            if (max_first(mag, p, mx, imx)) { mx = mag; imx = p; }
        } else {
            bad = 1u;
        }
        if (pc.mode == MODE_IQR) {
            keys[p] = floatBitsToUint(mag);
            vals[p] = p;
        }
    }
    s_part[tid] = MinMaxPart(mn, mx, imn, imx, bad, 0u, 0u, 0u);
    barrier();
    if (tid == 0u) {
        for (uint k = 1u; k < RUN_LANES; ++k) {
            MinMaxPart q = s_part[k];
            if (min_first(q.mn, q.imn, mn, imn)) { mn = q.mn; imn = q.imn; }
            if (max_first(q.mx, q.imx, mx, imx)) { mx = q.mx; imx = q.imx; }
            bad |= q.bad;
        }
        parts[wg] = MinMaxPart(mn, mx, imn, imx, bad, 0u, 0u, 0u);
    }
}
