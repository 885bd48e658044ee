// Deformable-3DGS composition: mean = x + dx, scale = exp(min(s, LOG_SCALE_MAX)) + ds,
// rot = normalize(q) + dr (the rasteriser normalises rot again). The clamp keeps a diverged
// log-scale (≥ 88.7 overflows f32 exp) finite; see common.glsl. Body of deform_apply.comp (USE_DEFORM 1: reads the
// MLP output) and deform_static.comp (USE_DEFORM 0: D ≡ 0, no MLP binding; the warm-up).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { DeformParams pc; };
layout(std430, binding = 0) readonly buffer Means { float means[]; };        // [N,3] canonical
layout(std430, binding = 1) readonly buffer LogScales { float log_scales[]; }; // [N,3]
layout(std430, binding = 2) readonly buffer Quats { vec4 quats[]; };         // [N]
layout(std430, binding = 3) writeonly buffer OutMeans { float out_means[]; };
layout(std430, binding = 4) writeonly buffer OutScales { float out_scales[]; };
layout(std430, binding = 5) writeonly buffer OutQuats { vec4 out_quats[]; };
#if USE_DEFORM
layout(std430, binding = 6) readonly buffer Deform { float d[]; };           // [N,10] dx, dr, ds
#endif

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n) return;
    vec3 dx = vec3(0.0), ds = vec3(0.0);
    vec4 dr = vec4(0.0);
#if USE_DEFORM
    {
        dx = vec3(d[10 * i], d[10 * i + 1], d[10 * i + 2]);
        dr = vec4(d[10 * i + 3], d[10 * i + 4], d[10 * i + 5], d[10 * i + 6]);
        ds = vec3(d[10 * i + 7], d[10 * i + 8], d[10 * i + 9]);
    }
#endif
    for (uint a = 0; a < 3u; ++a) {
        out_means[3 * i + a] = means[3 * i + a] + dx[a];
        float ls = log_scales[3 * i + a];
        out_scales[3 * i + a] = exp(ls > LOG_SCALE_MAX ? LOG_SCALE_MAX : ls) + ds[a];
    }
    vec4 q = quats[i];
    float len = length(q);
    out_quats[i] = (len > 1e-12 ? q / len : vec4(1.0, 0.0, 0.0, 0.0)) + dr;
}
