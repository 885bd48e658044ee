// Transient (time-local) Gaussians: shared helpers of glsl/temporal/*.comp (host wrapper
// src/kernels/temporal.rs, CPU twin src/reference/temporal.rs). Rows [first, n) of the model
// are transients: time centre c, log-width τ (σ = exp(max(τ, log_floor))), velocity v. At
// time t a transient is drawn at μ + v·(t − c) with its opacity multiplied by
// w(t) = exp(−½ (t − c)² / σ²), and is culled (w = 0) when w < cutoff. Rows [0, first) are
// the canonical population, drawn by the deformation and never touched here.
#ifndef TEMPORAL_GLSL
#define TEMPORAL_GLSL

struct Weight {
    float w;      // opacity factor (0: culled)
    float d;      // t − c
    float inv_s2; // 1 / σ²
    bool floored; // τ ≤ log_floor: σ is the floor, τ gets no gradient
};

Weight temporal_weight(float c, float tau, float t, TemporalParams p) {
    Weight r;
    r.floored = !(tau > p.log_floor); // a NaN τ is floored too
    float ls = r.floored ? p.log_floor : tau;
    r.d = t - c;
    r.inv_s2 = exp(-2.0 * ls);
    float e = 0.5 * r.d * r.d * r.inv_s2;
    r.w = exp(-e);
    // Culled below the cut-off, and wherever the exponent is not a number (c or t infinite).
    if (!(r.w >= p.cutoff)) r.w = 0.0;
    return r;
}

#endif
