#version 460
// Indirect scene motion (MotionGS): the flow photo(v1, t1) → photo(v2, t2) minus the camera
// flow, the pixel's point at the rendered depth of (v1, t1) reprojected into v2:
//   z = Σw·z / α (the blend pass's depth, normalised by its alpha),
//   X = R1ᵀ·(z·K1⁻¹·(p, 1) − t1),  p' = π(K2·(R2·X + t2)),  camera flow = p' − p,
// with R2·R1ᵀ and t2 − R2·R1ᵀ·t1 composed on the host (128 bytes of push constants),
// at pixel centres. Where the render has no surface (α < min_alpha), the depth is not finite
// or the point falls behind v2's near plane, the camera motion is unknown: the scene motion
// there is 0 (no motion claimed). subtract = 0 passes the raw pair flow through (the "no
// decomposition" ablation), with the same non-finite guard. The depth is detached (MotionGS).
// Twin: reference::dispflow::camera_flow.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { CameraFlowParams pc; };
layout(std430, binding = 0) readonly buffer Flow { vec2 flow[]; };    // [H·W] photo a → photo b
layout(std430, binding = 1) readonly buffer Rgba { vec4 rgba[]; };    // [H·W] render (v1, t1)
layout(std430, binding = 2) readonly buffer Depth { float depth[]; }; // [H·W] Σ w·z
layout(std430, binding = 3) writeonly buffer Scene { vec2 scene[]; }; // [H·W]

void main() {
    uint p = gl_GlobalInvocationID.x;
    if (p >= pc.width * pc.height) return;
    vec2 f = flow[p];
    bool ok = !(any(isnan(f)) || any(isinf(f)));
    if (pc.subtract != 0u) {
        vec2 px = vec2(float(p % pc.width), float(p / pc.width)) + 0.5;
        float a = rgba[p].w;
        float z = depth[p] / a;
        vec3 xc = z * vec3((px - pc.intr_a.zw) / pc.intr_a.xy, 1.0);
        vec3 y = vec3(dot(pc.rel0.xyz, xc), dot(pc.rel1.xyz, xc), dot(pc.rel2.xyz, xc))
               + vec3(pc.rel0.w, pc.rel1.w, pc.rel2.w);
        vec2 q = pc.intr_b.xy * y.xy / y.z + pc.intr_b.zw;
        ok = ok && a >= pc.min_alpha && z > 0.0 && !isinf(z) && y.z > pc.near_b;
        f -= q - px;
        ok = ok && !(any(isnan(f)) || any(isinf(f)));
    }
    scene[p] = ok ? f : vec2(0.0);
}
