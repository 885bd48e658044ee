#version 460
// MMAP, stage 2, after the sort (descending scores, ties kept in pixel order) and the
// exclusive scan of the sorted labels (tp_excl). Every run of equal keys is one threshold; the
// thread at the last index e of a run finds the run's first index s by binary search on the
// sorted keys and adds (TP_e − TP_{s−1}) · TP_e / (e + 1), i.e. P·(R_n − R_{n−1})·P_n. The host
// divides the sum by P (written by the last pixel's thread). Per-workgroup partial sums in a
// fixed tree order: deterministic.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "metrics.glsl"

layout(local_size_x = METRICS_WG) in;

layout(push_constant) uniform Push { MetricsParams pc; };
layout(std430, binding = 0) readonly buffer Keys { uint keys[]; };      // sorted ascending
layout(std430, binding = 1) readonly buffer Labels { uint labels[]; };  // 0/1, same order
layout(std430, binding = 2) readonly buffer TpExcl { uint tp_excl[]; };
layout(std430, binding = 3) writeonly buffer Sums { float sums[]; };    // [groups]
layout(std430, binding = 4) writeonly buffer Total { uint total[]; };   // [0] = positives P

shared float s_sum[METRICS_WG];

void main() {
    uint wg = metrics_group(pc.groups_x);
    uint tid = gl_LocalInvocationIndex;
    uint e = wg * METRICS_WG + tid;
    float contrib = 0.0;
    if (e < pc.n) {
        uint k = keys[e];
        if (e + 1u == pc.n || keys[e + 1u] != k) {
            // First index s with keys[s] == k (keys ascending, keys[e] == k).
            uint lo = 0u, hi = e;
            while (lo < hi) {
                uint mid = (lo + hi) >> 1;
                if (keys[mid] < k) lo = mid + 1u; else hi = mid;
            }
            uint tp = tp_excl[e] + labels[e];
            uint run_pos = tp - tp_excl[lo];
            contrib = float(run_pos) * (float(tp) / float(e + 1u));
        }
        if (e + 1u == pc.n) total[0] = tp_excl[e] + labels[e];
    }
    s_sum[tid] = contrib;
    barrier();
    for (uint off = METRICS_WG / 2u; off > 0u; off >>= 1) {
        if (tid < off) s_sum[tid] += s_sum[tid + off];
        barrier();
    }
    if (tid == 0u) sums[wg] = s_sum[0];
}
