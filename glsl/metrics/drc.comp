#version 460
// DRC partial sums per workgroup: (Σ F̂·[ΔE > 0], Σ F̂), ΔE(p) = mean_c |I_frozen − I_gt| −
// mean_c |I_full − I_gt| over RGB, tested as Σ_c|frozen − gt| > Σ_c|full − gt| (same sign;
// channels added in order, as the CPU twin does). The host finishes num / (den + ε).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "metrics.glsl"

layout(local_size_x = METRICS_WG) in;

layout(push_constant) uniform Push { MetricsParams pc; };
layout(std430, binding = 0) readonly buffer Score { float score[]; };
layout(std430, binding = 1) readonly buffer Frozen { vec4 frozen[]; };
layout(std430, binding = 2) readonly buffer Full { vec4 full[]; };
layout(std430, binding = 3) readonly buffer Gt { vec4 gt[]; };
layout(std430, binding = 4) writeonly buffer Sums { vec2 sums[]; };

shared vec2 s_sum[METRICS_WG];

void main() {
    uint wg = metrics_group(pc.groups_x);
    uint tid = gl_LocalInvocationIndex;
    uint p = wg * METRICS_WG + tid;
    vec2 acc = vec2(0.0);
    if (p < pc.n) {
        vec3 g = gt[p].rgb;
        vec3 a = abs(frozen[p].rgb - g), b = abs(full[p].rgb - g);
        float ea = a.x + a.y + a.z, eb = b.x + b.y + b.z;
        float f = score[p];
        acc = vec2(ea > eb ? f : 0.0, f);
    }
    s_sum[tid] = acc;
    barrier();
    for (uint off = METRICS_WG / 2u; off > 0u; off >>= 1) {
        if (tid < off) s_sum[tid] += s_sum[tid + off];
        barrier();
    }
    if (tid == 0u) sums[wg] = s_sum[0];
}
