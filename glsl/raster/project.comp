#version 460
// Per Gaussian: camera-space mean, EWA-projected and dilated 2D covariance, conic, screen
// radius and tile rectangle, view-dependent SH colour and sigmoid opacity (times op_scale[i]
// when pc.opacity_scale: a transient's temporal weight). Culled Gaussians (opacity factor 0,
// behind the near plane, degenerate covariance, off screen) touch zero tiles; a zero factor
// culls before any projection work. With pc.splat_extent the rectangle is opacity_rect's:
// only the tiles where the blend can reach α ≥ 1/255 (none below opacity 1/255), so faint
// Gaussians are binned to fewer tiles and every image and gradient stays the same; and the
// splat record carries alpha_extent's y, with which the band blends step over the bands of a
// tile the splat cannot reach.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { ProjectParams pc; };
layout(std430, binding = 0) readonly buffer Means { float means[]; };          // [N,3]
layout(std430, binding = 1) readonly buffer Scales { float scales[]; };        // [N,3] linear
layout(std430, binding = 2) readonly buffer Quats { vec4 quats[]; };           // [N] (w,x,y,z)
layout(std430, binding = 3) readonly buffer Opacity { float logits[]; };       // [N]
// SH split in the DC band and the rest, so each can have its own learning rate:
layout(std430, binding = 4) readonly buffer ShDc { float sh_dc[]; };           // [N,3]
layout(std430, binding = 5) readonly buffer ShRest { float sh_rest[]; };       // [N,K-1,3]
layout(std430, binding = 6) writeonly buffer Splats { vec4 splats[]; };        // [N,3]
layout(std430, binding = 7) writeonly buffer Rects { uvec4 rects[]; };         // [N]
layout(std430, binding = 8) writeonly buffer Counts { uint counts[]; };        // [N] tiles touched
layout(std430, binding = 9) readonly buffer OpScale { float op_scale[]; };     // [N] (opacity_scale)

void cull(uint i) {
    splats[SPLAT_STRIDE * i] = vec4(0.0);
    splats[SPLAT_STRIDE * i + 1] = vec4(0.0);
    splats[SPLAT_STRIDE * i + 2] = vec4(0.0);
    rects[i] = uvec4(0);
    counts[i] = 0;
}

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.num_gaussians) return;
    float w = pc.opacity_scale != 0u ? op_scale[i] : 1.0;
    if (!(w > 0.0)) { // not alive at this time (or a NaN factor)
        cull(i);
        return;
    }
    vec3 mean = vec3(means[3 * i], means[3 * i + 1], means[3 * i + 2]);
    vec3 scale = vec3(scales[3 * i], scales[3 * i + 1], scales[3 * i + 2]);
    Proj r = project_gaussian(pc, mean, scale, quats[i]);
    if (!r.visible) {
        cull(i);
        return;
    }
    // View direction from the camera centre (-rotᵀ·trans); detached in the backward pass.
    vec3 centre = -(transpose(r.W) * pc.trans_near.xyz);
    vec3 dir = mean - centre;
    float dl = length(dir);
    dir = dl > 0.0 ? dir / dl : vec3(0.0, 0.0, 1.0);
    float b[16];
    sh_basis(dir, pc.sh_degree, b);
    vec3 col = b[0] * vec3(sh_dc[3 * i], sh_dc[3 * i + 1], sh_dc[3 * i + 2]);
    uint nb = min((pc.sh_degree + 1u) * (pc.sh_degree + 1u), pc.sh_coeffs);
    for (uint k = 1; k < nb; ++k) {
        uint o = (i * (pc.sh_coeffs - 1u) + k - 1u) * 3u;
        col += b[k] * vec3(sh_rest[o], sh_rest[o + 1], sh_rest[o + 2]);
    }
    col = max(col + 0.5, vec3(0.0));
    float opacity = sigmoid(logits[i]) * w;
    // The tiles binned: the 3σ square, or only those the blend can draw in (opacity_rect; the
    // splat record, its radius and so its visibility stay the same either way).
    uvec4 rect = pc.splat_extent != 0u ? opacity_rect(pc, r, opacity) : r.rect;
    float reach = pc.splat_extent != 0u ? alpha_extent(r, opacity).y : EXTENT_NONE;
    splats[SPLAT_STRIDE * i] = vec4(r.mean2d, r.p.z, opacity);
    splats[SPLAT_STRIDE * i + 1] = vec4(r.conic, r.radius);
    splats[SPLAT_STRIDE * i + 2] = vec4(col, reach);
    rects[i] = rect;
    counts[i] = (rect.z - rect.x) * (rect.w - rect.y);
}
