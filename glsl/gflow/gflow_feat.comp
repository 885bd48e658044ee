#version 460
// Per Gaussian: the six Gaussian-flow channels (G = A − I, b = μ2 − A·μ1; gflow.glsl) from the
// splat records of the render at (v1, t1) and of the projection at (v1, t2). A Gaussian culled
// at either time (behind the camera, off screen, singular Σ2D: radius 0) or whose map is not
// finite gets zeros: it adds no flow and takes no gradient. Twin: reference::gflow::features.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"
#include "gflow.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { GFlowParams pc; };
layout(std430, binding = 0) readonly buffer Splats1 { vec4 splats1[]; };  // [N,3] at t1
layout(std430, binding = 1) readonly buffer Splats2 { vec4 splats2[]; };  // [N,3] at t2
layout(std430, binding = 2) writeonly buffer Feat { float feat[]; };      // [N,6]

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n) return;
    vec4 a1 = splats1[SPLAT_STRIDE * i], c1 = splats1[SPLAT_STRIDE * i + 1];
    vec4 a2 = splats2[SPLAT_STRIDE * i], c2 = splats2[SPLAT_STRIDE * i + 1];
    GfAffine r = gf_affine(c1.xyz, c2.xyz);
    vec2 b = a2.xy - vec2(r.A.x * a1.x + r.A.y * a1.y, r.A.z * a1.x + r.A.w * a1.y);
    bool ok = c1.w > 0.0 && c2.w > 0.0 && r.ok && !(any(isnan(b)) || any(isinf(b)));
    vec4 g = ok ? r.A - vec4(1.0, 0.0, 0.0, 1.0) : vec4(0.0);
    b = ok ? b : vec2(0.0);
    feat[GF_FEAT * i] = g.x;
    feat[GF_FEAT * i + 1] = g.y;
    feat[GF_FEAT * i + 2] = g.z;
    feat[GF_FEAT * i + 3] = g.w;
    feat[GF_FEAT * i + 4] = b.x;
    feat[GF_FEAT * i + 5] = b.y;
}
