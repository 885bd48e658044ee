// One splat blended into a subgroup's PX pixels, front to back: included in both walks of
// blend_fwd_tile.glsl, inside its main. Reads a (mean2d, depth, opacity), con, col, f[FEAT]
// and seen (the 1-based list position); updates T, C, D, F, last and live.
for (int i = 0; i < PX; ++i) {
    if ((live & (1u << uint(i))) == 0u) continue;
    uint q = first + lane + S * uint(i);
    vec2 centre = vec2(origin + uvec2(q % TILE, q / TILE)) + 0.5;
    vec2 d = a.xy - centre;
    float sigma = splat_sigma(con, d);
    float alpha = min(pc.alpha_max, a.w * exp(-sigma));
    if (alpha < ALPHA_MIN) continue;
    float test_t = T[i] * (1.0 - alpha);
    if (test_t < T_STOP) {
        live &= ~(1u << uint(i));
        continue;
    }
    float w = alpha * T[i];
    C[i] += w * col;
    D[i] += w * a.z;
#if FEAT > 0
    for (int c = 0; c < FEAT; ++c) F[i * FEAT + c] += w * f[c];
#endif
    T[i] = test_t;
    last[i] = seen;
}
