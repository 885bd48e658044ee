// Body of nodes_lbs.comp (slots to NODES_KMAX) and nodes_lbs_k4.comp (4 slots: K <= 4);
// the wrapper defines NODES_KLOOP.
// The control-node field's forward: each Gaussian's deformation row D = (dx, dr, ds) as the
// normalised-RBF blend of its K nearest nodes' transforms (docs/nodes.md), in the MLP field's
// layout so the composition and everything downstream are unchanged. flags 1: rows r are the
// dynamic Gaussians idx[r] (split model), written compactly.
// nodes_blend.glsl brings the includes, the push constants and bindings 0-5.
#include "nodes_blend.glsl"
ARR_WO(6, vec2, rg32f, Out, d) // [rows,10] as [rows,5]

void main() {
    uint r, i;
    if (!this_row(r, i)) return;
    vec3 mu = vec3(LD1(means, 3 * i), LD1(means, 3 * i + 1), LD1(means, 3 * i + 2));
    Blend b = blend_of(i, mu);
    vec3 dx = vec3(0.0), ds = vec3(0.0);
    vec4 dr = vec4(0.0);
    if (b.count > 0) {
        for (uint s = 0; s < NODES_KLOOP; ++s) {
            if (s >= b.count) continue; // masked (nodes_blend.glsl)
            uint j = b.node[s];
            dx += b.w[s] * (quat_to_mat(b.rn[s]) * b.v[s] - b.v[s] + node_t(j));
            ds += b.w[s] * node_ds(j);
        }
        float ql, qbl;
        vec4 qn = quat_normalize(LD4(quats, i), ql);
        vec4 qb = quat_normalize(b.Q, qbl);
        dr = qmul(qb, qn) - qn;
    }
    ST2(d, 5 * r, dx.xy);
    ST2(d, 5 * r + 1, vec2(dx.z, dr.x));
    ST2(d, 5 * r + 2, dr.yz);
    ST2(d, 5 * r + 3, vec2(dr.w, ds.x));
    ST2(d, 5 * r + 4, ds.yz);
}
