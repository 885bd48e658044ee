#version 460
// Densify step 2/4, per original Gaussian: applies the budget, then the prune test to each of
// its output rows.
//
// Budget rule: originals are processed in index order with a running row total that starts at
// N (every original kept); an original whose growth (+1) would push the total past `capacity`
// is downgraded to keep. As every growth is 0 or 1, this is exactly: original i keeps its
// demanded clone/split iff the exclusive scan of growth at i is < capacity − N.
//
// Prune test of an output row (3DGS densify_and_prune, applied to the rows after densifying):
//   logit < logit(min_opacity)
//   or, when screen_prune bit 0: max_radii > max_screen_size (new rows: 0),
//   or, when screen_prune bit 1: max log-scale > ln(max_world_size) (children: log-scale − ln 1.6).
// Writes action[i] = code | keep0 << 2 | keep1 << 3 and rows[i] = keep0 + keep1.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "densify.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { DensifyParams pc; };
layout(std430, binding = 0) readonly buffer GrowthOffsets { uint growth_off[]; }; // [N] exclusive scan
layout(std430, binding = 1) readonly buffer MaxRadii { float max_radii[]; };      // [N]
layout(std430, binding = 2) readonly buffer LogScales { float log_scales[]; };    // [N,3]
layout(std430, binding = 3) readonly buffer Opacity { float logits[]; };          // [N]
layout(std430, binding = 4) buffer Action { uint action[]; };                     // [N] in: demanded
layout(std430, binding = 5) writeonly buffer Rows { uint rows[]; };               // [N]

bool pruned(float logit, float radius, float ls) {
    bool p = logit < pc.min_opacity_logit;
    if ((pc.screen_prune & 1u) != 0u) p = p || radius > pc.max_screen_size;
    if ((pc.screen_prune & 2u) != 0u) p = p || ls > pc.log_max_world_size;
    return p;
}

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.num_gaussians) return;
    uint code = action[i];
    if (code != ACT_KEEP && growth_off[i] >= pc.capacity - pc.num_gaussians) code = ACT_KEEP;
    float logit = logits[i];
    float ls = max_log_scale(log_scales[3u * i], log_scales[3u * i + 1u], log_scales[3u * i + 2u]);
    bool keep0, keep1;
    if (code == ACT_SPLIT) {
        keep0 = !pruned(logit, 0.0, ls - LN_1_6);
        keep1 = keep0;
    } else {
        keep0 = !pruned(logit, max_radii[i], ls);
        keep1 = code == ACT_CLONE && !pruned(logit, 0.0, ls);
    }
    action[i] = code | (keep0 ? 4u : 0u) | (keep1 ? 8u : 0u);
    rows[i] = (keep0 ? 1u : 0u) + (keep1 ? 1u : 0u);
}
