// Body of nodes_lbs_bwd.comp (slots to NODES_KMAX) and nodes_lbs_bwd_k4.comp (4 slots: K <= 4);
// the wrapper defines NODES_KLOOP.
// Backward of nodes_lbs: from ∂L/∂D of each row to one contribution row per (Gaussian, slot)
// (∂T, ∂dq, ∂ds, ∂p, ∂ρ; summed per node by nodes_gather, no atomics) and to the canonical
// mean and quaternion, ADDED to their gradients (the composition's backward wrote them).
// Every path is differentiated, the weights' dependence on μ, p and ρ included.
// nodes_blend.glsl brings the includes, the push constants and bindings 0-5.
#include "nodes_blend.glsl"
ARR_RO(6, vec2, rg32f, DOut, g) // [rows,10] ∂L/∂D as [rows,5]
ARR_WO(7, vec4, rgba32f, Contrib, contrib)  // [N,K,4] (CONTRIB_VEC4)
ARR_RW(8, float, r32f, GMeans, g_means) // [N,3] +=
ARR_RW(9, vec4, rgba32f, GQuats, g_quats) // [N] +=

void main() {
    uint r, i;
    if (!this_row(r, i)) return;
    vec3 mu = vec3(LD1(means, 3 * i), LD1(means, 3 * i + 1), LD1(means, 3 * i + 2));
    Blend b = blend_of(i, mu);
    if (b.count == 0) return;
    vec2 g0 = LD2(g, 5 * r), g1 = LD2(g, 5 * r + 1), g2 = LD2(g, 5 * r + 2);
    vec2 g3 = LD2(g, 5 * r + 3), g4 = LD2(g, 5 * r + 4);
    vec3 gx = vec3(g0, g1.x);
    vec4 gr = vec4(g1.y, g2, g3.x);
    vec3 gs = vec3(g3.y, g4);

    // dr = q_b ⊗ q̂ − q̂.
    float ql, qbl;
    vec4 qn = quat_normalize(LD4(quats, i), ql);
    vec4 qb = quat_normalize(b.Q, qbl);
    vec4 g_qn = qmul(qconj(qb), gr) - gr;
    vec4 g_Q = unit_grad(qb, qbl, qmul(gr, qconj(qn)));

    // Per slot: ∂L/∂w before the softmax, and everything that does not go through w.
    float gw[NODES_KLOOP];
    float gbar = 0.0;
    vec3 g_mu = vec3(0.0);
    for (uint s = 0; s < NODES_KLOOP; ++s) {
        gw[s] = 0.0;
        if (s >= b.count) continue; // masked (nodes_blend.glsl)
        uint j = b.node[s];
        mat3 R = quat_to_mat(b.rn[s]);
        vec3 e = R * b.v[s] - b.v[s] + node_t(j);
        gw[s] = dot(gx, e) + dot(gs, node_ds(j)) + dot(g_Q, b.rn[s]);
        gbar += b.w[s] * gw[s];
    }
    for (uint s = 0; s < NODES_KLOOP; ++s) {
        if (s >= b.count) continue; // masked (nodes_blend.glsl)
        uint j = b.node[s];
        float w = b.w[s];
        mat3 R = quat_to_mat(b.rn[s]);
        vec4 g_rn = w * g_Q + quat_to_mat_grad(b.rn[s], w * outerProduct(gx, b.v[s]));
        vec4 g_dq = unit_grad(b.rn[s], b.rlen[s], g_rn);
        float ga = w * (gw[s] - gbar);
        vec3 g_v = w * (transpose(R) * gx - gx) - ga * b.inv[s] * b.v[s];
        float g_rho = b.clamped[s] ? 0.0 : ga * dot(b.v[s], b.v[s]) * b.inv[s];
        g_mu += g_v;
        uint o = (i * pc.k + s) * CONTRIB_VEC4;
        vec3 t = w * gx, d = w * gs, p = -g_v;
        ST4(contrib, o, vec4(t, g_dq.x));
        ST4(contrib, o + 1, vec4(g_dq.yzw, d.x));
        ST4(contrib, o + 2, vec4(d.yz, p.xy));
        ST4(contrib, o + 3, vec4(p.z, g_rho, 0.0, 0.0));
    }
#ifdef TEXEL_ACCESS
    for (uint a = 0; a < 3u; ++a) ST1(g_means, 3 * i + a, LD1(g_means, 3 * i + a) + g_mu[a]);
    vec4 g_q = unit_grad(qn, ql, g_qn);
    ST4(g_quats, i, LD4(g_quats, i) + g_q);
#else
    for (uint a = 0; a < 3u; ++a) g_means[3 * i + a] += g_mu[a];
    vec4 g_q = unit_grad(qn, ql, g_qn);
    g_quats[i] += g_q;
#endif
}
