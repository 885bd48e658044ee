#version 460
// Densification statistics, after every backward pass (3DGS add_densification_stats): for each
// visible Gaussian (screen radius > 0) add ‖∂L/∂mean_ndc‖ (abs_grad: ‖Σ|∂L/∂mean_ndc|‖, the
// official Deformable-3DGS statistic, from slots 10-11) to grad_accum, 1 to denom, and keep
// the largest screen radius. ∂L/∂ndc = ∂L/∂pixel · (W/2, H/2). A non-finite gradient counts as
// a zero-length one (the view still counts in denom); grad_accum saturates at FLT_MAX.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "densify.glsl"
#include "raster.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { DensifyStatsParams pc; };
layout(std430, binding = 0) readonly buffer Grad2d { float grad2d[]; };   // [N,G2D_STRIDE]; 0-1 ∂L/∂mean2d (px)
layout(std430, binding = 1) readonly buffer Splats { vec4 splats[]; };    // [N,3]; [3i+1].w radius
layout(std430, binding = 2) buffer GradAccum { float grad_accum[]; };     // [capacity]
layout(std430, binding = 3) buffer Denom { float denom[]; };              // [capacity]
layout(std430, binding = 4) buffer MaxRadii { float max_radii[]; };       // [capacity]
// pc.skip_flags (flag, needed) overflow pairs: a discarded (overflowed) step adds nothing.
layout(std430, binding = 5) readonly buffer Skip { uint skip[]; };

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    bool skipped = false;
    for (uint k = 0u; k < pc.skip_flags; ++k) skipped = skipped || skip[2u * k] != 0u;
    if (i >= pc.num_gaussians || skipped) return;
    float radius = splats[3u * i + 1u].w;
    if (!(radius > 0.0)) return;
    uint at = G2D_STRIDE * i + (pc.abs_grad != 0u ? 10u : 0u); // Σ|g| (slots 10-11) or Σg (0-1)
    float gx = grad2d[at] * (0.5 * float(pc.width));
    float gy = grad2d[at + 1u] * (0.5 * float(pc.height));
    float norm = 0.0;
    if (is_finite(gx) && is_finite(gy)) {
        // hypot without overflow of the squares.
        float a = abs(gx), b = abs(gy);
        float hi = max(a, b), lo = min(a, b);
        if (hi > 0.0) {
            float r = lo / hi;
            norm = hi * sqrt(1.0 + r * r);
        }
        if (!is_finite(norm)) norm = 0.0;
    }
    grad_accum[i] = min(grad_accum[i] + norm, FLT_MAX);
    denom[i] += 1.0;
    float m = max_radii[i];
    if (radius > m) max_radii[i] = radius;
}
