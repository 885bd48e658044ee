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
//   on the issue-14 scenes. It loads S list entries at a time back to front (lane l the entry
//   jb − 1 − l), shuffles each record to the tile, keeps each splat's folded sums in the lane
//   that loaded it and adds them to memory once per batch (per-lane loads and atomics are
//   loops over the lanes on llvmpipe: one per batch instead of one per splat; stop 74). Per
//   address the adds come in the order one add per splat gave them.
// - bands (PX = 8 and STEP_OVER, blend_bwd_band_f*.comp): 4 rows per subgroup at lavapipe's 8
//   lanes, stepping over the splats that miss the band's rows; a splat that reaches several
//   bands is folded and added once per band (so a tile of large splats goes whole:
//   blend_pick.glsl by the forward's cover sample, or blend_bwd_pick.comp by the forward's
//   stopping points, which the picked variant reads from band_pick).
// Results differ between shapes only in the order of the float sums. The bands' fold is
// correct for any grouping of the invocations: lanes fold with the lanes of their subgroup
// that hold the same splat (a waterfall over distinct ids, one round where the subgroup is one
// band). The whole tile's batches take lane t % S to be gl_SubgroupInvocationID's
// (consecutive invocations, lavapipe's layout).
#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_shuffle : require
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

// The subgroup's sum of v, kept by lane k (the lane that loaded the splat).
void fold(inout float acc, float v, uint lane, uint k) {
    float s = subgroupAdd(v);
    if (lane == k) acc = s;
}

// One lane's folded sum into memory (a zero sum adds nothing: skipped, as before).
void flush(uint idx, float s) {
    if (s != 0.0) atomicAdd(grad2d[idx], s);
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
        T[i] = inside ? LD1(final_t, p) : 1.0;
        last[i] = inside ? LDU1(n_contrib, p) : 0u; // 0: never live
        g_out[i] = inside ? LD4(d_rgba, p) : vec4(0.0);
        g_depth[i] = inside ? LD1(d_depth, p) : 0.0;
        R_rgb[i] = pc.background.rgb;
        R_a[i] = 0.0;
        R_d[i] = 0.0;
#if FEAT > 0
        for (int c = 0; c < FEAT; ++c) {
            g_f[i * FEAT + c] = inside ? LD1(d_feat, p * FEAT + c) : 0.0;
            R_f[i * FEAT + c] = 0.0;
        }
#endif
        max_last = max(max_last, last[i]);
    }
    // Nothing past the band's furthest last contributor matters (the subgroup's, when the
    // subgroup is wider than a band).
    uint end = range.x + subgroupMax(max_last);

#ifdef STEP_OVER
    for (uint j = end; j > range.x;) {
        // Step over the splats that reach no row of the band.
        uint gid = 0u;
        vec4 a = vec4(0.0), c4 = vec4(0.0);
        bool found = false;
        while (j > range.x) {
            --j;
            gid = LDU1(ids, j);
            a = LD4(splats, SPLAT_STRIDE * gid);
            c4 = LD4(splats, SPLAT_STRIDE * gid + 2);
            if (a.y + c4.w >= row_lo && a.y - c4.w <= row_hi) {
                found = true;
                break;
            }
        }
        if (!found) break;
        uint rel = j - range.x; // 0-based position in the tile's list
        vec3 con = LD4(splats, SPLAT_STRIDE * gid + 1).xyz;
        vec3 col = c4.rgb;
#if FEAT > 0
        float f[FEAT];
        for (int c = 0; c < FEAT; ++c) f[c] = LD1(feat, gid * FEAT + c);
        float gfe[FEAT];
        for (int c = 0; c < FEAT; ++c) gfe[c] = 0.0;
#endif
#include "blend_bwd_splat.glsl"
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
#else
    // The walk back to front in batches of S entries: lane l loads entry jb − 1 − l and, after
    // the batch, adds its splat's band sums to memory (per-lane loads and atomics are a loop
    // over the lanes on llvmpipe: one per batch instead of one per splat).
    for (uint jb = end; jb > range.x; jb -= min(S, jb - range.x)) {
        uint nb = min(S, jb - range.x);
        uint g_l = LDU1(ids, jb - 1u - min(lane, nb - 1u));
        vec4 a_l = LD4(splats, SPLAT_STRIDE * g_l);
        vec4 n_l = LD4(splats, SPLAT_STRIDE * g_l + 1);
        vec4 c_l = LD4(splats, SPLAT_STRIDE * g_l + 2);
#if FEAT > 0
        float f_l[FEAT], s_f[FEAT];
        for (int c = 0; c < FEAT; ++c) {
            f_l[c] = LD1(feat, g_l * FEAT + c);
            s_f[c] = 0.0;
        }
#endif
        // This lane's splat's sums over the tile (13 slots of the 2D gradient record).
        float s_g[13];
        for (int c = 0; c < 13; ++c) s_g[c] = 0.0;
        // Tested at its end, as in the forward (one loop-budget iteration per splat).
        uint k = 0u;
        do {
            uint rel = jb - 1u - k - range.x; // 0-based position in the tile's list
#include "blend_tile_take.glsl"
#if FEAT > 0
            float gfe[FEAT];
            for (int c = 0; c < FEAT; ++c) gfe[c] = 0.0;
#endif
#include "blend_bwd_splat.glsl"
            if (!subgroupAny(any_live)) continue;
            fold(s_g[0], g_mean.x, lane, k);
            fold(s_g[1], g_mean.y, lane, k);
            fold(s_g[2], g_con.x, lane, k);
            fold(s_g[3], g_con.y, lane, k);
            fold(s_g[4], g_con.z, lane, k);
            fold(s_g[5], g_op, lane, k);
            fold(s_g[6], g_col.r, lane, k);
            fold(s_g[7], g_col.g, lane, k);
            fold(s_g[8], g_col.b, lane, k);
            fold(s_g[9], g_z, lane, k);
            if (pc.abs_grad != 0u) { // uniform: the densification's absolute statistic
                fold(s_g[10], g_abs.x, lane, k);
                fold(s_g[11], g_abs.y, lane, k);
            }
            if (pc.feat_op != 0u) fold(s_g[12], g_op_f, lane, k); // uniform
#if FEAT > 0
            for (int c = 0; c < FEAT; ++c) fold(s_f[c], gfe[c], lane, k);
#endif
        } while (++k < nb);
        // Each lane's splat's sums, once per batch.
        uint base = g_l * G2D_STRIDE;
        for (int c = 0; c < 10; ++c) flush(base + uint(c), s_g[c]);
        if (pc.abs_grad != 0u) {
            flush(base + 10u, s_g[10]);
            flush(base + 11u, s_g[11]);
        }
        if (pc.feat_op != 0u) flush(base + 12u, s_g[12]);
#if FEAT > 0
        for (int c = 0; c < FEAT; ++c)
            if (s_f[c] != 0.0) atomicAdd(grad_feat[g_l * FEAT + c], s_f[c]);
#endif
    }
#endif
}
