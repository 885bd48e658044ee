// The blend of one Gaussian's K nearest node transforms (docs/nodes.md), shared by
// nodes_lbs.comp and nodes_lbs_bwd.comp. Expects the bindings `nodes` (node parameters),
// `node_out` ([M,10] T, dq, ds, declared as vec2 [M,5]: llvmpipe loops over the lanes once
// per SSBO access, so two floats a load halve the loops) and `knn`, and the push constants `pc`.

vec3 node_t(uint j) {
    vec2 a = node_out[5 * j], b = node_out[5 * j + 1];
    return vec3(a, b.x);
}

vec4 node_dq(uint j) {
    vec2 a = node_out[5 * j + 1], b = node_out[5 * j + 2], c = node_out[5 * j + 3];
    return vec4(a.y, b, c.x);
}

vec3 node_ds(uint j) {
    vec2 a = node_out[5 * j + 3], b = node_out[5 * j + 4];
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
        uint j = s < pc.k ? knn[i * pc.k + s] : NO_NODE;
        // The valid slots are a prefix: the first NO_NODE ends them.
        bool on = s == b.count && j < pc.m;
        j = on ? j : 0u;
        b.node[s] = j;
        float rho = nodes[3 * pc.m + j];
        b.clamped[s] = !(rho >= RHO_MIN && rho <= RHO_MAX);
        b.inv[s] = exp(-2.0 * clamp(rho, RHO_MIN, RHO_MAX));
        b.v[s] = mu - vec3(nodes[3 * j], nodes[3 * j + 1], nodes[3 * j + 2]);
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
