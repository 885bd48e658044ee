#version 460
// One sample of the motion probe: D(x, t_k) of every Gaussian folded into its running
// per-component minimum and maximum over the probe's times. On the last sample (the flags
// come after, from dyn_flag.comp, with a threshold that depends on every Gaussian's motion):
//   mid    = (min + max) / 2, the time-constant part of D, which a static Gaussian is drawn
//            with from then on (D's constant part is an offset the canonical Gaussian was
//            trained together with; dropping it would move the Gaussian);
//   motion = |Δdx|/2 + max_a |Δds_a|/2 + |Δdr|/2 · max_a scale_a   (Δ = max − min, scene
//            units: how far D moves the Gaussian away from `mid` at worst; |Δdr| · largest
//            scale bounds how far the ellipsoid's surface turns),
//   pixels = motion · focal_c / max(|x + mid_dx − o_c|, near), largest over the cameras.
// A non-finite D reads as "very large": a diverged Gaussian is never frozen silently.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { ProbeParams pc; };
layout(std430, binding = 0) readonly buffer Deform { float d[]; };          // [N,10] D(x, t_k)
layout(std430, binding = 1) readonly buffer LogScales { float log_scales[]; }; // [N,3]
layout(std430, binding = 2) readonly buffer Means { float means[]; };       // [N,3] canonical
layout(std430, binding = 3) readonly buffer Cams { vec4 cams[]; };          // [C] centre, focal px
layout(std430, binding = 4) buffer Range { float range[]; };                // [N,21] min, max, px
layout(std430, binding = 5) writeonly buffer Mid { float mid[]; };          // [N,10]

const float HUGE = 3.0e38;

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n) return;
    uint r = 21 * i;
    bool finite = true;
    for (uint c = 0; c < 10u; ++c) {
        float v = d[10 * i + c];
        finite = finite && abs(v) < HUGE; // false for NaN and ±inf
        float lo = pc.first != 0u ? v : min(range[r + c], v);
        float hi = pc.first != 0u ? v : max(range[r + 10 + c], v);
        range[r + c] = lo;
        range[r + 10 + c] = hi;
    }
    // A non-finite sample poisons the Gaussian for the whole probe (min/max may drop NaN).
    float seen_bad = (pc.first != 0u) ? 0.0 : range[r + 20];
    range[r + 20] = finite ? seen_bad : HUGE;
    if (pc.last == 0u) return;
    float lo[10], hi[10];
    for (uint c = 0; c < 10u; ++c) {
        lo[c] = range[r + c];
        hi[c] = range[r + 10 + c];
        mid[10 * i + c] = 0.5 * (lo[c] + hi[c]);
    }
    float smax = 0.0;
    for (uint a = 0; a < 3u; ++a) {
        float ls = log_scales[3 * i + a];
        smax = max(smax, exp(ls > LOG_SCALE_MAX ? LOG_SCALE_MAX : ls));
    }
    vec3 ddx = vec3(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]);
    vec4 ddr = vec4(hi[3] - lo[3], hi[4] - lo[4], hi[5] - lo[5], hi[6] - lo[6]);
    vec3 dds = vec3(hi[7] - lo[7], hi[8] - lo[8], hi[9] - lo[9]);
    float m = 0.5 * (length(ddx) + max(max(dds.x, dds.y), dds.z) + length(ddr) * smax);
    float px = HUGE;
    if (range[r + 20] == 0.0 && m < HUGE) {
        vec3 x = vec3(means[3 * i], means[3 * i + 1], means[3 * i + 2])
               + 0.5 * vec3(lo[0] + hi[0], lo[1] + hi[1], lo[2] + hi[2]);
        px = 0.0;
        for (uint c = 0; c < pc.num_cams; ++c) {
            float dist = max(distance(x, cams[c].xyz), pc.near);
            px = max(px, m * cams[c].w / dist);
        }
        if (!(px < HUGE)) px = HUGE;
    }
    range[r + 20] = px;
}
