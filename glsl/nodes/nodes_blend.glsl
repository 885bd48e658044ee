// The blend of one Gaussian's K nearest node transforms (docs/nodes.md), shared by
// nodes_lbs.glsl and nodes_lbs_bwd.glsl with their workgroup size, push constants and first six
// bindings. `node_out` ([M,10] T, dq, ds) is declared as vec2 [M,5]: llvmpipe loops over the
// lanes once per SSBO access, so two floats a load halve the loops.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"
#include "nodes.glsl"
#include "access.glsl"

layout(local_size_x = 128) in;

layout(push_constant) uniform Push { NodesParams pc; };
ARR_RO(0, float, r32f, Means, means) // [N,3] canonical
ARR_RO(1, vec4, rgba32f, Quats, quats) // [N] canonical
ARR_RO(2, float, r32f, Nodes, nodes) // [4M]
ARR_RO(3, vec2, rg32f, NodeOut, node_out) // [M,10] as [M,5]
ARR_RO_U(4, uint, r32ui, Knn, knn) // [N,K]
ARR_RO_U(5, uint, r32ui, Idx, idx) // [rows] (flags 1)

// This invocation's row r and its Gaussian i (the dynamic Gaussian idx[r] with flags 1);
// false past the last row.
bool this_row(out uint r, out uint i) {
    r = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    i = r;
    if (r >= pc.n) return false;
    if ((pc.flags & 1u) != 0u) i = LDU1(idx, r);
    return true;
}

vec3 node_t(uint j) {
    vec2 a = LD2(node_out, 5 * j), b = LD2(node_out, 5 * j + 1);
    return vec3(a, b.x);
}

vec4 node_dq(uint j) {
    vec2 a = LD2(node_out, 5 * j + 1), b = LD2(node_out, 5 * j + 2), c = LD2(node_out, 5 * j + 3);
    return vec4(a.y, b, c.x);
}

vec3 node_ds(uint j) {
    vec2 a = LD2(node_out, 5 * j + 3), b = LD2(node_out, 5 * j + 4);
    return vec3(a.y, b);
}

// Per-slot state of one Gaussian's blend.
struct Blend {
    uint count;                 // valid slots (a prefix: NO_NODE slots come last)
    uint node[NODES_KMAX];
    vec3 v[NODES_KMAX];         // μ − p
    float w[NODES_KMAX];        // normalised weights
    float inv[NODES_KMAX];      // e^(−2ρ̃) = 1/σ²
    bool clamped[NODES_KMAX];   // ρ outside [RHO_MIN, RHO_MAX]: no radius gradient
    vec4 rn[NODES_KMAX];        // unit node rotation
    float rlen[NODES_KMAX];     // |(1,0,0,0) + dq|
    vec4 Q;                     // Σ w r̂
};

Blend blend_of(uint i, vec3 mu) {
    Blend b;
    b.count = 0;
    float amax = -1.0 / 0.0;
    float a[NODES_KMAX];
    // Every loop over the slots (here and in the kernels) runs to the constant NODES_KLOOP
    // (NODES_KMAX, or 4 in the _k4 kernels for K <= 4) with
    // the unused slots masked off by `s < b.count` (never multiplied by a zero weight: their
    // stand-in node 0 may hold anything): lavapipe keeps an array indexed by a run-time counter
    // in scratch memory, where each access is a loop over the lanes; unrolled, the slots live
    // in registers.
    for (uint s = 0; s < NODES_KLOOP; ++s) {
        uint j = s < pc.k ? LDU1(knn, i * pc.k + s) : NO_NODE;
        // The valid slots are a prefix: the first NO_NODE ends them.
        bool on = s == b.count && j < pc.m;
        j = on ? j : 0u;
        b.node[s] = j;
        float rho = LD1(nodes, 3 * pc.m + j);
        b.clamped[s] = !(rho >= RHO_MIN && rho <= RHO_MAX);
        b.inv[s] = exp(-2.0 * clamp(rho, RHO_MIN, RHO_MAX));
        b.v[s] = mu - vec3(LD1(nodes, 3 * j), LD1(nodes, 3 * j + 1), LD1(nodes, 3 * j + 2));
        a[s] = -0.5 * dot(b.v[s], b.v[s]) * b.inv[s];
        if (on) amax = max(amax, a[s]);
        vec4 r = node_dq(j);
        r.x += 1.0;
        b.rn[s] = quat_normalize(r, b.rlen[s]);
        if (on) b.count = s + 1;
    }
    float sum = 0.0;
    for (uint s = 0; s < NODES_KLOOP; ++s) {
        b.w[s] = s < b.count ? exp(a[s] - amax) : 0.0;
        sum += b.w[s];
    }
    b.Q = vec4(0.0);
    for (uint s = 0; s < NODES_KLOOP; ++s) {
        b.w[s] = s < b.count ? b.w[s] / sum : 0.0;
        if (s < b.count) b.Q += b.w[s] * b.rn[s];
    }
    return b;
}
