#version 460
// Densify step 4/4, per original Gaussian and per parameter section (one dispatch each): writes
// its surviving output rows, at the scanned offset, into the `next` buffers (params, Adam m, v).
//   keep:  [original]                         m, v kept
//   clone: [original, exact copy]             original keeps m, v; the copy gets 0
//   split: [child 0, child 1]                 m = v = 0
// A split child's mean is R(q̂)·(exp(log_scale) ⊙ z) + mean (z: split_normals), its log-scale
// log_scale − ln 1.6; every other section is copied.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"
#include "densify.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { DensifyParams pc; };
layout(std430, binding = 0) readonly buffer Action { uint action[]; };          // [N]
layout(std430, binding = 1) readonly buffer Offsets { uint offsets[]; };        // [N]
layout(std430, binding = 2) readonly buffer Src { float src[]; };               // [N, row_len]
layout(std430, binding = 3) readonly buffer SrcM { float src_m[]; };
layout(std430, binding = 4) readonly buffer SrcV { float src_v[]; };
layout(std430, binding = 5) readonly buffer LogScales { float log_scales[]; };  // [N,3] source
layout(std430, binding = 6) readonly buffer Quats { vec4 quats[]; };            // [N] source
layout(std430, binding = 7) writeonly buffer Dst { float dst[]; };              // [capacity, row_len]
layout(std430, binding = 8) writeonly buffer DstM { float dst_m[]; };
layout(std430, binding = 9) writeonly buffer DstV { float dst_v[]; };

void copy_row(uint i, uint o, bool moments) {
    uint L = pc.row_len;
    for (uint k = 0u; k < L; ++k) {
        dst[o * L + k] = src[i * L + k];
        dst_m[o * L + k] = moments ? src_m[i * L + k] : 0.0;
        dst_v[o * L + k] = moments ? src_v[i * L + k] : 0.0;
    }
}

void child_row(uint i, uint c, uint o) {
    uint L = pc.row_len;
    if (pc.section == SECTION_MEANS) {
        // Clamped like the deformation's exp (LOG_SCALE_MAX): a runaway log-scale (≥ 88.7
        // overflows f32 exp) must not give a split child an infinite mean.
        vec3 ls = vec3(log_scales[3u * i], log_scales[3u * i + 1u], log_scales[3u * i + 2u]);
        vec3 scale = exp(min(ls, vec3(LOG_SCALE_MAX)));
        float qlen;
        mat3 R = quat_to_mat(quat_normalize(quats[i], qlen));
        vec3 z = split_normals(pc.seed, pc.iteration, i, c);
        vec3 mean = vec3(src[3u * i], src[3u * i + 1u], src[3u * i + 2u]) + R * (scale * z);
        dst[3u * o] = mean.x;
        dst[3u * o + 1u] = mean.y;
        dst[3u * o + 2u] = mean.z;
    } else if (pc.section == SECTION_LOG_SCALES) {
        for (uint k = 0u; k < 3u; ++k) dst[3u * o + k] = src[3u * i + k] - LN_1_6;
    } else {
        for (uint k = 0u; k < L; ++k) dst[o * L + k] = src[i * L + k];
    }
    for (uint k = 0u; k < L; ++k) {
        dst_m[o * L + k] = 0.0;
        dst_v[o * L + k] = 0.0;
    }
}

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.num_gaussians) return;
    uint a = action[i];
    uint code = a & 3u;
    bool keep0 = (a & 4u) != 0u, keep1 = (a & 8u) != 0u;
    uint o = offsets[i];
    if (keep0) {
        if (code == ACT_SPLIT) child_row(i, 0u, o); else copy_row(i, o, true);
        o += 1u;
    }
    if (keep1) {
        if (code == ACT_SPLIT) child_row(i, 1u, o); else copy_row(i, o, false);
    }
}
