// Shared by the densify stages: action codes, finiteness test, the max log-scale, and the
// split sampler. Mirrored exactly by src/reference/densify.rs (same arithmetic, same RNG).
#ifndef DENSIFY_GLSL
#define DENSIFY_GLSL

// action[i] = code | keep0 << 2 | keep1 << 3 (keep bits: output row 0 / 1 survives pruning).
#define ACT_KEEP 0u
#define ACT_CLONE 1u
#define ACT_SPLIT 2u

#define SECTION_COPY 0u
#define SECTION_MEANS 1u
#define SECTION_LOG_SCALES 2u

// ln(1.6) rounded to f32: a split child's log-scale is `log_scale - LN_1_6` (= log(scale / 1.6),
// 3DGS's 0.8·N with N = 2), one correctly rounded f32 subtraction on both sides.
#define LN_1_6 0.4700036292457356

#define FLT_MAX 3.4028234663852886e38

// Not NaN and not ±Inf, by bits (immune to fast-math assumptions).
bool is_finite(float x) {
    return (floatBitsToUint(x) & 0x7f800000u) != 0x7f800000u;
}

// Largest log-scale component, with NaN semantics fixed by the comparison order
// (the twin does the same: a NaN first component stays, later NaNs are skipped).
float max_log_scale(float a, float b, float c) {
    float m = a;
    if (b > m) m = b;
    if (c > m) m = c;
    return m;
}

// PCG hash (O'Neill; Jarzynski & Olano 2020).
uint pcg(uint v) {
    uint s = v * 747796405u + 2891336453u;
    uint w = ((s >> ((s >> 28u) + 4u)) ^ s) * 277803737u;
    return (w >> 22u) ^ w;
}

// RNG scheme (identical in the twin): uniform k (0..3) of child c (0/1) of original i is
//   h = pcg(seed ^ pcg(iteration ^ pcg(8·i + 4·c + k)))   (u32 wrap-around)
//   u = (float(h >> 9) + 0.5) / 2^23                        exact in f32 and f64, u in (0, 1)
// and the three normals of the child are Box–Muller pairs:
//   z0 = sqrt(−2 ln u0)·cos(2π u1), z1 = sqrt(−2 ln u0)·sin(2π u1), z2 = sqrt(−2 ln u2)·cos(2π u3).
float split_uniform(uint seed, uint iteration, uint i, uint c, uint k) {
    uint h = pcg(seed ^ pcg(iteration ^ pcg(8u * i + 4u * c + k)));
    return (float(h >> 9u) + 0.5) / 8388608.0;
}

vec3 split_normals(uint seed, uint iteration, uint i, uint c) {
    const float TWO_PI = 6.283185307179586;
    float u0 = split_uniform(seed, iteration, i, c, 0u);
    float u1 = split_uniform(seed, iteration, i, c, 1u);
    float u2 = split_uniform(seed, iteration, i, c, 2u);
    float u3 = split_uniform(seed, iteration, i, c, 3u);
    float r0 = sqrt(-2.0 * log(u0));
    float r1 = sqrt(-2.0 * log(u2));
    return vec3(r0 * cos(TWO_PI * u1), r0 * sin(TWO_PI * u1), r1 * cos(TWO_PI * u3));
}

#endif
