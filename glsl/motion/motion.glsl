// Shared by glsl/motion/*.comp: modes, the layout of the statistics buffer, the robust
// magnitude and the per-pixel 2D grid. Mirrored in src/kernels/motion.rs where noted.
#ifndef MOTION_GLSL
#define MOTION_GLSL

#define MOTION_WG 256

#define MODE_MINMAX 0u
#define MODE_MAXABS 1u
#define MODE_ZSCORE 2u
#define MODE_IQR 3u

#define FLAG_OK 0u
#define FLAG_FLAT 1u
#define FLAG_NONFINITE 2u

#define NONE 0xFFFFFFFFu
#define FLT_MAX 3.402823466e38
#define FLT_MIN 1.175494351e-38
#define POS_INF uintBitsToFloat(0x7F800000u)
// Relative flatness: a denominator below 2^-20 of 2^e (max = f·2^e; IQR: of q75) is not
// resolved by an f32 map (src/kernels/motion.rs: REL_FLAT).
#define REL_FLAT (1.0 / 1048576.0)

// Statistics buffer (uint words; floats as bits). u = m·2^-e is the rescaled magnitude the
// normalisation works on (exact power-of-two scaling: no overflow in sums of squares, no
// denormal reciprocals). Mirrored by `kernels::motion::stat`.
#define NS_FLAG 0     // FLAG_*
#define NS_EXP 1      // int e, max = f·2^e, f in [0.5, 1)
#define NS_OFFSET 2   // float, u domain
#define NS_DENOM 3    // float, u domain
#define NS_MIN 4      // float, m domain
#define NS_MAX 5      // float, m domain
#define NS_ARGMIN 6   // pixel (first among ties)
#define NS_ARGMAX 7
#define NS_MEAN 8     // float, u domain (z-score only)
#define NS_STD 9      // float, u domain, population (z-score only)
#define NS_Q 10       // 3 floats, u domain: q25, q50, q75 (IQR only)
#define NS_QPIX 13    // 6 pixels: (lo, hi) of q25, q50, q75 (IQR only)
#define NS_WORDS 19

// Backward coefficients (floats; pixel ids as bits): ∂L/∂u_q = g_q·c_g + c0 + c1·m̂_q
// + Σ_k [q == pix_k]·w_k.
#define NB_CG 0
#define NB_C0 1
#define NB_C1 2
#define NB_SPECIAL 4  // 6 pairs (pixel, weight)
#define NB_WORDS 16

// Per-workgroup min/max partials of the magnitude pass.
struct MinMaxPart {
    float mn;
    float mx;
    uint imn;
    uint imx;
    uint bad;   // 1: the workgroup saw a non-finite magnitude
    uint pad0;
    uint pad1;
    uint pad2;
};

// Linear workgroup index of a 2D grid of `groups_x` columns, and the pixel of this thread.
uint motion_group(uint groups_x) {
    return gl_WorkGroupID.y * groups_x + gl_WorkGroupID.x;
}

// |(x, y, z)| without overflow or underflow of the squares: scale by the largest component.
// NaN in, NaN out; an overflowing result is +inf (the caller flags it).
float robust_norm(float x, float y, float z) {
    if (isnan(x) || isnan(y) || isnan(z)) return uintBitsToFloat(0x7FC00000u);
    float s = max(max(abs(x), abs(y)), abs(z));
    if (s == 0.0 || isinf(s)) return s;
    float a = x / s, b = y / s, c = z / s;
    return s * sqrt(a * a + b * b + c * c);
}

// (a, ia) precedes (b, ib) for a min reduction: smaller value, then lower pixel.
bool min_first(float a, uint ia, float b, uint ib) {
    return a < b || (a == b && ia < ib);
}
bool max_first(float a, uint ia, float b, uint ib) {
    return a > b || (a == b && ia < ib);
}

#endif
