// Blend backward, per-tile accumulation: the same maths as blend_bwd.glsl (read its header),
// with the loops swapped so each splat's gradient is summed over the whole tile before it
// reaches memory. One workgroup per tile, TILE²/PX invocations, each owning PX pixels of the
// tile (pixel q = invocation + WG·i) with their blend state in registers. Each subgroup walks
// the tile's splats back to front on its own (no barrier, no shared memory); per splat it
// evaluates its PX pixel groups, summing the terms per lane, then folds the lanes once
// (subgroupAdd) and one lane adds the sum with one float atomic per component. Pixel rows the
// splat cannot reach (its record's `reach`) are skipped, as in the forward.
//
// Why on lavapipe: a workgroup is ceil(WG/8) coroutines of 8 SIMD lanes. The subgroup kernel
// pays, per splat and tile, one subgroupAdd and one float atomic per component for every one
// of its 32 coroutines, and stages splats in shared memory behind barriers; with PX = 32 the
// workgroup is one coroutine, so per splat and tile it is 10 (+FEAT) horizontal sums and
// atomics, and the splat record is a uniform (broadcast) load. Measured (bench --suite
// raster): 11–18× the subgroup kernel; PX = 8 (4 coroutines) was 1.4–1.7× slower than PX = 32.
// On a GPU the 8-invocation workgroup leaves most of a warp idle: the host keeps the subgroup
// kernel there. Results differ from it only in the order of the float sums.
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_EXT_shader_atomic_float : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"

#define WG (TILE * TILE / PX)
#if (TILE % WG) != 0
#error "a pixel's row q / TILE must be uniform: WG must divide TILE"
#endif
layout(local_size_x = WG) in;

#include "blend_bwd_io.glsl"

void add(uint idx, float v) {
    float s = subgroupAdd(v);
    if (subgroupElect() && s != 0.0) atomicAdd(grad2d[idx], s);
}

void main() {
    uint t = gl_LocalInvocationID.x;
    uint tile = gl_WorkGroupID.y * pc.tiles_x + gl_WorkGroupID.x;
    uvec2 range = ranges[tile];
    // The other kernel of the pass draws this tile (BlendParams.list_min/list_max).
    uint listed = range.y - range.x;
    if (listed < pc.list_min || listed > pc.list_max) return;
    uvec2 origin = gl_WorkGroupID.xy * TILE;

    // Per pixel: transmittance, last contributor, upstream gradients, "behind" terms.
    float T[PX], R_a[PX], R_d[PX], g_depth[PX];
    uint last[PX];
    vec3 R_rgb[PX];
    vec4 g_out[PX];
#if FEAT > 0
    float g_f[PX * FEAT], R_f[PX * FEAT];
#endif
    uint max_last = 0;
    for (int i = 0; i < PX; ++i) {
        uint q = t + WG * uint(i);
        uvec2 pix = origin + uvec2(q % TILE, q / TILE);
        bool inside = pix.x < pc.width && pix.y < pc.height;
        uint p = inside ? pix.y * pc.width + pix.x : 0u;
        T[i] = inside ? final_t[p] : 1.0;
        last[i] = inside ? n_contrib[p] : 0u; // 0: never live
        g_out[i] = inside ? d_rgba[p] : vec4(0.0);
        g_depth[i] = inside ? d_depth[p] : 0.0;
        R_rgb[i] = pc.background.rgb;
        R_a[i] = 0.0;
        R_d[i] = 0.0;
#if FEAT > 0
        for (int c = 0; c < FEAT; ++c) {
            g_f[i * FEAT + c] = inside ? d_feat[p * FEAT + c] : 0.0;
            R_f[i * FEAT + c] = 0.0;
        }
#endif
        max_last = max(max_last, last[i]);
    }
    // Nothing past the subgroup's furthest last contributor matters.
    uint end = range.x + subgroupMax(max_last);

    for (uint j = end; j > range.x;) {
        --j;
        uint rel = j - range.x; // 0-based position in the tile's list
        uint gid = ids[j];      // uniform: broadcast loads below
        vec4 a = splats[SPLAT_STRIDE * gid];
        vec3 con = splats[SPLAT_STRIDE * gid + 1].xyz;
        vec4 c4 = splats[SPLAT_STRIDE * gid + 2];
        vec3 col = c4.rgb;
        float reach = c4.w; // |dy| past which α < 1/255 (alpha_extent)
#if FEAT > 0
        float f[FEAT];
        for (int c = 0; c < FEAT; ++c) f[c] = feat[gid * FEAT + c];
        float gfe[FEAT];
        for (int c = 0; c < FEAT; ++c) gfe[c] = 0.0;
#endif
        vec2 g_mean = vec2(0.0), g_abs = vec2(0.0);
        vec3 g_con = vec3(0.0), g_col = vec3(0.0);
        float g_op = 0.0, g_z = 0.0, g_op_f = 0.0;
        bool any_live = false;
        for (int i = 0; i < PX; ++i) {
            // Rows the splat cannot reach hold no α ≥ 1/255: skipped whole (as the forward).
            if (abs(a.y - (float(origin.y + (WG * uint(i)) / TILE) + 0.5)) > reach) continue;
            uint q = t + WG * uint(i);
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
        if (!subgroupAny(any_live)) continue;
        uint base = gid * G2D_STRIDE;
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
            add(base + 10, g_abs.x);
            add(base + 11, g_abs.y);
        }
        if (pc.feat_op != 0u) add(base + 12, g_op_f); // uniform
#if FEAT > 0
        for (int c = 0; c < FEAT; ++c) {
            float s = subgroupAdd(gfe[c]);
            if (subgroupElect() && s != 0.0) atomicAdd(grad_feat[gid * FEAT + c], s);
        }
#endif
    }
}
