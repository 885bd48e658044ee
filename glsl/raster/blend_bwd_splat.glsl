// One splat's gradient over a subgroup's PX pixels, back to front: included in both walks of
// blend_bwd_tile.glsl, inside its main. Reads a, con, col, f[FEAT], gfe[FEAT] and rel (the
// 0-based list position); updates the pixels' T and "behind" terms and declares this splat's
// per-lane sums (g_mean, g_abs, g_con, g_col, g_op, g_z, g_op_f) and any_live.
vec2 g_mean = vec2(0.0), g_abs = vec2(0.0);
vec3 g_con = vec3(0.0), g_col = vec3(0.0);
float g_op = 0.0, g_z = 0.0, g_op_f = 0.0;
bool any_live = false;
for (int i = 0; i < PX; ++i) {
    uint q = first + lane + S * uint(i);
    vec2 d = a.xy - (vec2(origin + uvec2(q % TILE, q / TILE)) + 0.5);
    float sigma = splat_sigma(con, d);
    float g = a.w * exp(-sigma);
    float alpha = min(pc.alpha_max, g);
    if (rel < last[i] && alpha >= ALPHA_MIN) {
        any_live = true;
        float Ti = T[i] / (1.0 - alpha);
        float w = alpha * Ti;
        vec4 go = g_out[i];
        g_col += w * go.rgb;
        g_z += w * g_depth[i];
        float g_alpha = Ti * (dot(go.rgb, col - R_rgb[i]) + go.a * (1.0 - R_a[i]) + g_depth[i] * (a.z - R_d[i]));
        R_rgb[i] = col * alpha + (1.0 - alpha) * R_rgb[i];
        R_a[i] = alpha + (1.0 - alpha) * R_a[i];
        R_d[i] = a.z * alpha + (1.0 - alpha) * R_d[i];
        float g_alpha_f = 0.0; // the feature channels' share of g_alpha
#if FEAT > 0
        for (int c = 0; c < FEAT; ++c) {
            gfe[c] += w * g_f[i * FEAT + c];
            g_alpha_f += Ti * g_f[i * FEAT + c] * (f[c] - R_f[i * FEAT + c]);
            R_f[i * FEAT + c] = f[c] * alpha + (1.0 - alpha) * R_f[i * FEAT + c];
        }
        g_alpha += g_alpha_f;
#endif
        T[i] = Ti;
        if (g < pc.alpha_max) { // unclamped: α = opacity · exp(−σ)
            g_op += g_alpha * exp(-sigma);
            g_op_f += g_alpha_f * exp(-sigma);
            float g_sigma = -g_alpha * alpha;
            vec2 gm = g_sigma * vec2(con.x * d.x + con.y * d.y, con.z * d.y + con.y * d.x);
            g_mean += gm;
            g_abs += abs(gm);
            g_con += g_sigma * vec3(0.5 * d.x * d.x, d.x * d.y, 0.5 * d.y * d.y);
        }
    }
}
