// Gaussian flow (GaussianFlow / MotionGS) per Gaussian: the 2D affine map that carries the
// projected Gaussian at t1 onto itself at t2 under the same view,
//   x ↦ A·(x − μ1) + μ2,   A = Σ2(t2)^½ · Σ2(t1)^-½,
// with the symmetric square roots (rotation-aware, unlike a Cholesky factor, which turns a
// rotation into a shear). Both come from the conic Q = Σ2⁻¹ in closed form:
//   sqrtm(Q) = (Q + d·I) / t,  d = √det Q,  t = √(tr Q + 2d),  det sqrtm(Q) = d,
// so Σ^-½ = sqrtm(Q1) and Σ^½ = sqrtm(Q2)⁻¹ = adj(Q2 + d2·I) / (d2·t2).
// The flow at pixel p is Σ_i w_i (A_i·(p − μ1_i) + μ2_i − p) = G(p)·p + B(p) with the blended
// per-Gaussian channels G_i = A_i − I and b_i = μ2_i − A_i·μ1_i: six features the blend pass
// splats with its own weights (so the blend-weight gradient is the rasteriser's).
// 2×2 matrices are row-major vec4s (m00, m01, m10, m11). Twin: reference::gflow.
#ifndef GFLOW_GLSL
#define GFLOW_GLSL

#define GF_FEAT 6

vec4 gf_mul(vec4 x, vec4 y) {
    return vec4(x.x * y.x + x.y * y.z, x.x * y.y + x.y * y.w,
                x.z * y.x + x.w * y.z, x.z * y.y + x.w * y.w);
}

vec4 gf_t(vec4 x) { return x.xzyw; }

bool gf_finite4(vec4 v) { return !(any(isnan(v)) || any(isinf(v))); }

// sqrtm(Q) = U / t of a conic (a, b, c); false when Q is not positive definite (singular).
struct GfSqrt {
    vec4 U;
    float d, t;
};

bool gf_sqrt(vec3 q, out GfSqrt s) {
    float det = q.x * q.z - q.y * q.y;
    s.d = sqrt(max(det, 0.0));
    s.t = sqrt(max(q.x + q.z + 2.0 * s.d, 0.0));
    s.U = vec4(q.x + s.d, q.y, q.y, q.z + s.d);
    return det > 0.0 && s.t > 0.0 && !isinf(det) && !isnan(det) && !isinf(s.t);
}

// Everything the backward needs again.
struct GfAffine {
    bool ok;
    GfSqrt s1, s2;
    vec4 P1;   // Σ(t1)^-½
    vec4 N2;   // Σ(t2)^½
    vec4 A;
};

GfAffine gf_affine(vec3 q1, vec3 q2) {
    GfAffine r;
    bool ok1 = gf_sqrt(q1, r.s1);
    bool ok2 = gf_sqrt(q2, r.s2);
    r.P1 = r.s1.U / r.s1.t;
    r.N2 = vec4(r.s2.U.w, -r.s2.U.y, -r.s2.U.z, r.s2.U.x) / (r.s2.d * r.s2.t);
    r.A = gf_mul(r.N2, r.P1);
    r.ok = ok1 && ok2 && gf_finite4(r.A);
    return r;
}

// ∂L/∂q of sqrtm(q) = U/t from ∂L/∂sqrtm.
vec3 gf_sqrt_bwd(vec3 q, GfSqrt s, vec4 dP) {
    vec4 dU = dP / s.t;
    float dt = -dot(dP, s.U) / (s.t * s.t);
    float dd = dU.x + dU.w + dt / s.t;
    vec3 dq = vec3(dU.x + 0.5 * dt / s.t, dU.y + dU.z, dU.w + 0.5 * dt / s.t);
    return dq + dd * vec3(0.5 * q.z / s.d, -q.y / s.d, 0.5 * q.x / s.d);
}

#endif
