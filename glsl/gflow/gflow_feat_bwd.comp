#version 460
// Backward of gflow_feat: ∂L/∂(G, b) per Gaussian → ∂L/∂(μ2D, conic) at t1 and at t2, added to
// the two renders' per-splat 2D gradient records (G2D_STRIDE), which their projection backward
// then takes to the Gaussians drawn at t1 and at t2. Zeros where the forward gave zeros.
// Twin: reference::gflow::features_bwd.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"
#include "gflow.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { GFlowParams pc; };
layout(std430, binding = 0) readonly buffer Splats1 { vec4 splats1[]; };
layout(std430, binding = 1) readonly buffer Splats2 { vec4 splats2[]; };
layout(std430, binding = 2) readonly buffer DFeat { float d_feat[]; };   // [N,6]
layout(std430, binding = 3) buffer Grad1 { float grad1[]; };             // [N,12], added to
layout(std430, binding = 4) buffer Grad2 { float grad2[]; };             // [N,12], added to

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n) return;
    vec4 a1 = splats1[SPLAT_STRIDE * i], c1 = splats1[SPLAT_STRIDE * i + 1];
    vec4 a2 = splats2[SPLAT_STRIDE * i], c2 = splats2[SPLAT_STRIDE * i + 1];
    GfAffine r = gf_affine(c1.xyz, c2.xyz);
    vec2 b = a2.xy - vec2(r.A.x * a1.x + r.A.y * a1.y, r.A.z * a1.x + r.A.w * a1.y);
    bool ok = c1.w > 0.0 && c2.w > 0.0 && r.ok && !(any(isnan(b)) || any(isinf(b)));
    if (!ok) return;
    uint o = GF_FEAT * i;
    vec4 dA = vec4(d_feat[o], d_feat[o + 1], d_feat[o + 2], d_feat[o + 3]);
    vec2 db = vec2(d_feat[o + 4], d_feat[o + 5]);
    // b = μ2 − A·μ1
    dA -= vec4(db.x * a1.x, db.x * a1.y, db.y * a1.x, db.y * a1.y);
    vec2 dmu1 = -vec2(r.A.x * db.x + r.A.z * db.y, r.A.y * db.x + r.A.w * db.y);
    // A = N2·P1, N2 = P2⁻¹
    vec4 dN2 = gf_mul(dA, gf_t(r.P1));
    vec4 dP1 = gf_mul(gf_t(r.N2), dA);
    vec4 dP2 = -gf_mul(gf_mul(gf_t(r.N2), dN2), gf_t(r.N2));
    vec3 dq1 = gf_sqrt_bwd(c1.xyz, r.s1, dP1);
    vec3 dq2 = gf_sqrt_bwd(c2.xyz, r.s2, dP2);
    uint g = G2D_STRIDE * i;
    grad1[g] += dmu1.x;
    grad1[g + 1] += dmu1.y;
    grad1[g + 2] += dq1.x;
    grad1[g + 3] += dq1.y;
    grad1[g + 4] += dq1.z;
    grad2[g] += db.x;
    grad2[g + 1] += db.y;
    grad2[g + 2] += dq2.x;
    grad2[g + 3] += dq2.y;
    grad2[g + 4] += dq2.z;
}
