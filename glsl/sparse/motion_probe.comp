#version 460
// One sample of the motion probe: how far the deformation D(x, t_k) moves each Gaussian, in
// pixels of the training view where that motion looks largest, as a running maximum over the
// probe's times. The last sample turns the maximum into the dynamic flag. A static Gaussian
// is drawn with D ≡ 0, so what is measured is D itself (not its change over time): freezing
// a Gaussian moves it by at most this much.
//   motion (scene units) = |dx| + max_a |ds_a| + |dr| · max_a scale_a
// (|dr| · largest scale bounds how far the ellipsoid's surface turns), then per camera c
//   pixels = motion · focal_c / max(|x + dx − o_c|, near).
// A non-finite motion reads as "very large": a diverged Gaussian is never frozen silently.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { ProbeParams pc; };
layout(std430, binding = 0) readonly buffer Deform { float d[]; };          // [N,10] D(x, t_k)
layout(std430, binding = 1) readonly buffer LogScales { float log_scales[]; }; // [N,3]
layout(std430, binding = 2) readonly buffer Means { float means[]; };       // [N,3] canonical
layout(std430, binding = 3) readonly buffer Cams { vec4 cams[]; };          // [C] centre, focal px
layout(std430, binding = 4) buffer Extent { float extent[]; };              // [N] running max, px
layout(std430, binding = 5) writeonly buffer Flags { uint flags[]; };       // [N] 1 = dynamic

const float HUGE = 3.0e38;

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n) return;
    vec3 dx = vec3(d[10 * i], d[10 * i + 1], d[10 * i + 2]);
    vec4 dr = vec4(d[10 * i + 3], d[10 * i + 4], d[10 * i + 5], d[10 * i + 6]);
    vec3 ds = vec3(d[10 * i + 7], d[10 * i + 8], d[10 * i + 9]);
    float smax = 0.0;
    for (uint a = 0; a < 3u; ++a) {
        float ls = log_scales[3 * i + a];
        smax = max(smax, exp(ls > LOG_SCALE_MAX ? LOG_SCALE_MAX : ls));
    }
    float m = length(dx) + max(max(abs(ds.x), abs(ds.y)), abs(ds.z)) + length(dr) * smax;
    float px = HUGE;
    if (m < HUGE) { // false for NaN and ±inf
        vec3 x = vec3(means[3 * i], means[3 * i + 1], means[3 * i + 2]) + dx;
        px = 0.0;
        for (uint c = 0; c < pc.num_cams; ++c) {
            float dist = max(distance(x, cams[c].xyz), pc.near);
            px = max(px, m * cams[c].w / dist);
        }
        if (!(px < HUGE)) px = HUGE;
    }
    float e = pc.first != 0u ? px : max(extent[i], px);
    extent[i] = e;
    if (pc.last != 0u) flags[i] = e > pc.threshold_px ? 1u : 0u;
}
