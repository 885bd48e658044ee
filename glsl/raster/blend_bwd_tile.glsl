// Blend backward, per-tile accumulation: the same maths as blend_bwd.glsl (read its header),
// with the loops swapped so each splat's gradient is summed over a band of the tile before it
// reaches memory. One workgroup per tile, TILE²/PX invocations, each owning PX pixels with
// their blend state in registers; each subgroup owns a band of S·PX consecutive pixels (S =
// its lanes, at most the workgroup) and walks the tile's splats back to front from its band's
// last contributor on its own (no barrier, no shared memory). Per splat it evaluates its PX
// pixels, sums the terms per lane, folds the lanes once (subgroupAdd) and one lane adds the sum
// with one float atomic per component.
//
// The two shapes of blend_fwd_tile.glsl (read its header), both for CPU devices:
// - whole tile (PX = 32, blend_bwd_tile_f*.comp): one lavapipe coroutine per tile; the
//   subgroup kernel pays, per splat and tile, one subgroupAdd and one float atomic per
//   component for each of its 32 coroutines and stages splats behind barriers: 11–18× slower
//   on the issue-14 scenes.
// - bands (PX = 8 and STEP_OVER, blend_bwd_band_f*.comp): 4 rows per subgroup at lavapipe's 8
//   lanes, stepping over the splats that miss the band's rows; a splat that reaches several
//   bands is folded and added once per band (so a tile of large splats goes whole:
//   blend_pick.glsl by the forward's cover sample, or blend_bwd_pick.comp by the forward's
//   stopping points, which the picked variant reads from band_pick).
// Results differ between shapes only in the order of the float sums. The fold is correct for
// any grouping of the invocations: lanes fold with the lanes of their subgroup that hold the
// same splat (a waterfall over distinct ids, one round where the subgroup is one band).
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_EXT_shader_atomic_float : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"

#define WG (TILE * TILE / PX)
layout(local_size_x = WG) in;

#include "blend_bwd_io.glsl"
// Which kernel draws each tile in the picked backward (BlendParams.pick 3 and 4); the binding
// after the interface's last (bindings stay dense).
#if FEAT > 0
layout(std430, binding = 11) readonly buffer BandPick { uint band_pick[]; };
#else
layout(std430, binding = 8) readonly buffer BandPick { uint band_pick[]; };
#endif
#define BAND_PICK_BUFFER
#include "blend_pick.glsl"

void add(uint idx, float v) {
    float s = subgroupAdd(v);
    if (subgroupElect() && s != 0.0) atomicAdd(grad2d[idx], s);
}

void main() {
    uint t = gl_LocalInvocationIndex;
    uint tile = gl_WorkGroupID.y * pc.tiles_x + gl_WorkGroupID.x;
    uvec2 range = ranges[tile];
    // The other kernel of the pass draws this tile (BlendParams.pick).
    if (!drawn_here(tile, gl_WorkGroupID.y, range)) return;
    uvec2 origin = gl_WorkGroupID.xy * TILE;
    uint S = min(gl_SubgroupSize, uint(WG));
    uint band = t / S, lane = t % S;
    uint first = band * S * PX;
    float row_lo = float(origin.y + first / TILE) + 0.5;
    float row_hi = float(origin.y + (first + S * PX - 1u) / TILE) + 0.5;

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
        uint q = first + lane + S * uint(i);
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
    // Nothing past the band's furthest last contributor matters (the subgroup's, when the
    // subgroup is wider than a band).
    uint end = range.x + subgroupMax(max_last);

    for (uint j = end; j > range.x;) {
#ifdef STEP_OVER
        // Step over the splats that reach no row of the band.
        uint gid = 0u;
        vec4 a = vec4(0.0), c4 = vec4(0.0);
        bool found = false;
        while (j > range.x) {
            --j;
            gid = ids[j];
            a = splats[SPLAT_STRIDE * gid];
            c4 = splats[SPLAT_STRIDE * gid + 2];
            if (a.y + c4.w >= row_lo && a.y - c4.w <= row_hi) {
                found = true;
                break;
            }
        }
        if (!found) break;
#else
        --j;
        uint gid = ids[j]; // uniform: broadcast loads below
        vec4 a = splats[SPLAT_STRIDE * gid];
        vec4 c4 = splats[SPLAT_STRIDE * gid + 2];
#endif
        uint rel = j - range.x; // 0-based position in the tile's list
        vec3 con = splats[SPLAT_STRIDE * gid + 1].xyz;
        vec3 col = c4.rgb;
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
        if (!subgroupAny(any_live)) continue;
        // Fold over the lanes holding this splat: one round where the subgroup is one band.
        for (;;) {
            if (gid != subgroupBroadcastFirst(gid)) continue;
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
            break;
        }
    }
}
