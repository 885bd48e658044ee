// Shared maths of the control-node field (docs/nodes.md): node layout, the clamped
// log-radius, Hamilton products. Node parameters are one buffer: positions [0, 3M), log-radii
// [3M, 4M). Quaternions are (w, x, y, z) in vec4 (.x = w), as the rasteriser's.
#ifndef NODES_GLSL
#define NODES_GLSL

#define NODES_KMAX 8
#define NO_NODE 0xffffffffu
// The log-radius is clamped before use: e^(−2ρ) stays finite in f32 for ρ ≥ −16 (a tiny
// radius makes the blend one-hot, not NaN), and ρ ≤ 8 keeps a huge radius from flattening
// every weight into rounding noise. No gradient outside.
#define RHO_MIN (-16.0)
#define RHO_MAX 8.0
// Floats per (Gaussian, slot) contribution row: ∂T 3, ∂dq 4, ∂ds 3, ∂p 3, ∂ρ 1.
#define CONTRIB 14
// A row is stored padded to 16 floats as 4 vec4 (components in the same order, 14 and 15 zero):
// llvmpipe loops over the lanes once per SSBO access, whatever its width, so a vec4 costs
// about what one float does.
#define CONTRIB_VEC4 4

vec4 qmul(vec4 a, vec4 b) {
    return vec4(a.x * b.x - a.y * b.y - a.z * b.z - a.w * b.w,
                a.x * b.y + a.y * b.x + a.z * b.w - a.w * b.z,
                a.x * b.z - a.y * b.w + a.z * b.x + a.w * b.y,
                a.x * b.w + a.y * b.z - a.z * b.y + a.w * b.x);
}

vec4 qconj(vec4 q) {
    return vec4(q.x, -q.y, -q.z, -q.w);
}

// Gradient wrt v of v/|v| given the gradient ĝ of the unit vector (0 below the fallback).
vec4 unit_grad(vec4 u, float len, vec4 g) {
    return len > 1e-12 ? (g - u * dot(u, g)) / len : vec4(0.0);
}

#endif
