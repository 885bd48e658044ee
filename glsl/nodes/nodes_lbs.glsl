// Body of nodes_lbs.comp (slots to NODES_KMAX) and nodes_lbs_k4.comp (4 slots: K <= 4);
// the wrapper defines NODES_KLOOP.
// The control-node field's forward: each Gaussian's deformation row D = (dx, dr, ds) as the
// normalised-RBF blend of its K nearest nodes' transforms (docs/nodes.md), in the MLP field's
// layout so the composition and everything downstream are unchanged. flags 1: rows r are the
// dynamic Gaussians idx[r] (split model), written compactly.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"
#include "nodes.glsl"

layout(local_size_x = 128) in;

layout(push_constant) uniform Push { NodesParams pc; };
layout(std430, binding = 0) readonly buffer Means { float means[]; };     // [N,3] canonical
layout(std430, binding = 1) readonly buffer Quats { vec4 quats[]; };      // [N] canonical
layout(std430, binding = 2) readonly buffer Nodes { float nodes[]; };     // [4M]
layout(std430, binding = 3) readonly buffer NodeOut { vec2 node_out[]; }; // [M,10] as [M,5]
layout(std430, binding = 4) readonly buffer Knn { uint knn[]; };          // [N,K]
layout(std430, binding = 5) readonly buffer Idx { uint idx[]; };          // [rows] (flags 1)
layout(std430, binding = 6) writeonly buffer Out { vec2 d[]; };           // [rows,10] as [rows,5]

#include "nodes_blend.glsl"

void main() {
    uint r = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (r >= pc.n) return;
    uint i = (pc.flags & 1u) != 0u ? idx[r] : r;
    vec3 mu = vec3(means[3 * i], means[3 * i + 1], means[3 * i + 2]);
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
        vec4 qn = quat_normalize(quats[i], ql);
        vec4 qb = quat_normalize(b.Q, qbl);
        dr = qmul(qb, qn) - qn;
    }
    d[5 * r] = dx.xy;
    d[5 * r + 1] = vec2(dx.z, dr.x);
    d[5 * r + 2] = dr.yz;
    d[5 * r + 3] = vec2(dr.w, ds.x);
    d[5 * r + 4] = ds.yz;
}
