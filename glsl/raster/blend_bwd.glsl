// Backward of blend_fwd for one tile per workgroup: walks each pixel's blended splats back to
// front, recovering T_i = T_{i+1} / (1 − α_i) from the stored final transmittance, and the
// "behind" terms R (what lies behind splat i, per unit of T_{i+1}; for colour the background
// is the last layer) by R ← f_i α_i + (1 − α_i) R. Then for each blended output o = Σ f_i w_i:
//   ∂o/∂f_i = w_i,   ∂o/∂α_i = T_i (f_i − R_i)   (alpha output: f = 1, depth: f = z).
// Where α was clamped to alpha_max its derivative is zero. The σ ≥ 0 clamp of splat_sigma
// only removes rounding, so σ's gradient passes through it unchanged.
//
// Accumulation scheme: per splat in the batch, each invocation (pixel) computes its terms, a
// subgroupAdd folds them within the subgroup and one lane adds the sum to the splat's gradient
// record with a float atomic. So atomics per splat and tile = pixels / subgroup size (lavapipe:
// 32, NVIDIA: 8), not one per pixel.
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_EXT_shader_atomic_float : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"

layout(local_size_x = TILE, local_size_y = TILE) in;

#include "blend_bwd_io.glsl"
#if FEAT > 0
shared float s_feat[TILE * TILE * FEAT];
#endif

shared vec4 s_a[TILE * TILE];
shared vec4 s_b[TILE * TILE];
shared vec4 s_c[TILE * TILE];
shared uint s_id[TILE * TILE];
shared uint s_max_last;

void add(uint idx, float v) {
    float s = subgroupAdd(v);
    if (subgroupElect() && s != 0.0) atomicAdd(grad2d[idx], s);
}

void main() {
    uint tid = gl_LocalInvocationIndex;
    uvec2 pix = gl_WorkGroupID.xy * TILE + gl_LocalInvocationID.xy;
    bool inside = pix.x < pc.width && pix.y < pc.height;
    uint tile = gl_WorkGroupID.y * pc.tiles_x + gl_WorkGroupID.x;
    uvec2 range = ranges[tile];
    vec2 centre = vec2(pix) + 0.5;
    uint p = inside ? pix.y * pc.width + pix.x : 0u;

    float T = inside ? final_t[p] : 1.0;
    uint last = inside ? n_contrib[p] : 0u;
    vec4 g_out = inside ? d_rgba[p] : vec4(0.0);
    float g_depth = inside ? d_depth[p] : 0.0;
    vec3 R_rgb = pc.background.rgb;
    float R_a = 0.0, R_d = 0.0;
#if FEAT > 0
    float g_f[FEAT], R_f[FEAT];
    for (int c = 0; c < FEAT; ++c) {
        g_f[c] = inside ? d_feat[p * FEAT + c] : 0.0;
        R_f[c] = 0.0;
    }
#endif

    if (tid == 0) s_max_last = 0;
    barrier();
    atomicMax(s_max_last, last);
    barrier();
    uint end = range.x + s_max_last; // nothing past the furthest pixel's last splat matters

    for (uint stop = end; stop > range.x;) {
        uint start = stop > range.x + TILE * TILE ? stop - TILE * TILE : range.x;
        barrier(); // the previous batch is fully consumed
        uint j = start + tid;
        if (j < stop) {
            uint g = ids[j];
            s_id[tid] = g;
            s_a[tid] = splats[SPLAT_STRIDE * g];
            s_b[tid] = splats[SPLAT_STRIDE * g + 1];
            s_c[tid] = splats[SPLAT_STRIDE * g + 2];
#if FEAT > 0
            for (int c = 0; c < FEAT; ++c) s_feat[tid * FEAT + c] = feat[g * FEAT + c];
#endif
        }
        barrier();
        for (int k = int(stop - start) - 1; k >= 0; --k) {
            uint rel = start + uint(k) - range.x; // 0-based position in the tile's list
            vec4 a = s_a[k];
            vec3 con = s_b[k].xyz;
            vec2 d = a.xy - centre;
            float sigma = splat_sigma(con, d);
            float g = a.w * exp(-sigma);
            float alpha = min(pc.alpha_max, g);
            bool live = inside && rel < last && alpha >= ALPHA_MIN;
            if (!subgroupAny(live)) continue;

            vec2 g_mean = vec2(0.0);
            vec3 g_con = vec3(0.0), g_col = vec3(0.0);
            float g_op = 0.0, g_z = 0.0, g_op_f = 0.0;
#if FEAT > 0
            float gfe[FEAT];
            for (int c = 0; c < FEAT; ++c) gfe[c] = 0.0;
            float g_alpha_f = 0.0; // the feature channels' share of g_alpha
#endif
            if (live) {
                float Ti = T / (1.0 - alpha);
                float w = alpha * Ti;
                vec3 col = s_c[k].rgb;
                g_col = w * g_out.rgb;
                g_z = w * g_depth;
                float g_alpha = Ti * (dot(g_out.rgb, col - R_rgb) + g_out.a * (1.0 - R_a) + g_depth * (a.z - R_d));
                R_rgb = col * alpha + (1.0 - alpha) * R_rgb;
                R_a = alpha + (1.0 - alpha) * R_a;
                R_d = a.z * alpha + (1.0 - alpha) * R_d;
#if FEAT > 0
                for (int c = 0; c < FEAT; ++c) {
                    float f = s_feat[k * FEAT + c];
                    gfe[c] = w * g_f[c];
                    g_alpha_f += Ti * g_f[c] * (f - R_f[c]);
                    R_f[c] = f * alpha + (1.0 - alpha) * R_f[c];
                }
                g_alpha += g_alpha_f;
#endif
                T = Ti;
                if (g < pc.alpha_max) { // unclamped: α = opacity · exp(−σ)
                    g_op = g_alpha * exp(-sigma);
#if FEAT > 0
                    g_op_f = g_alpha_f * exp(-sigma);
#endif
                    float g_sigma = -g_alpha * alpha;
                    g_mean = g_sigma * vec2(con.x * d.x + con.y * d.y, con.z * d.y + con.y * d.x);
                    g_con = g_sigma * vec3(0.5 * d.x * d.x, d.x * d.y, 0.5 * d.y * d.y);
                }
            }
            uint base = s_id[k] * G2D_STRIDE;
            add(base + 0, g_mean.x);
            add(base + 1, g_mean.y);
            add(base + 2, g_con.x);
            add(base + 3, g_con.y);
            add(base + 4, g_con.z);
            add(base + 5, g_op);
            add(base + 6, g_col.r);
            add(base + 7, g_col.g);
            add(base + 8, g_col.b);
            add(base + 9, g_z);
            if (pc.abs_grad != 0u) { // uniform: the densification's absolute statistic
                add(base + 10, abs(g_mean.x));
                add(base + 11, abs(g_mean.y));
            }
            if (pc.feat_op != 0u) add(base + 12, g_op_f); // uniform
#if FEAT > 0
            for (int c = 0; c < FEAT; ++c) {
                float s = subgroupAdd(gfe[c]);
                if (subgroupElect() && s != 0.0) atomicAdd(grad_feat[s_id[k] * FEAT + c], s);
            }
#endif
        }
        stop = start;
    }
}
