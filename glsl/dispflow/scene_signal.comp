#version 460
// The scene motion the motion term learns from, made robust to a half-trained render
// (src/kernels/dispflow.rs; twin: reference::dispflow::scene_signal):
//   residual correction: s = F(photo → render(v1, t2)) − F(photo → render(v1, t1)). The second
//   flow is the apparent motion that reconstruction error alone produces (the render at t1
//   should equal the photo); what remains is the change between t1 and t2. Subtracting at the
//   same pixel is the first-order form of composing the two fields.
//   confidence: c = exp(−e / σ), e = mean over RGB of |photo − render(v1, t1)|: where the
//   render does not yet reproduce the photo, its flow says little. σ = 0: c = 1.
//   motion-mask filtering (MotionGS-style ablation): |s| < mask_px pixels is set to 0.
// Non-finite inputs give c = 0 and s = 0 (never a NaN into the loss).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { SceneSignalParams pc; };
layout(std430, binding = 0) readonly buffer FlowT2 { vec2 flow_t2[]; };
layout(std430, binding = 1) readonly buffer FlowT1 { vec2 flow_t1[]; };
layout(std430, binding = 2) readonly buffer Photo { vec4 photo[]; };
layout(std430, binding = 3) readonly buffer RenderT1 { vec4 render_t1[]; };
layout(std430, binding = 4) writeonly buffer Scene { vec2 scene[]; };
layout(std430, binding = 5) writeonly buffer Conf { float conf[]; };

void main() {
    uint p = gl_GlobalInvocationID.x;
    if (p >= pc.n) return;
    vec2 s = flow_t2[p];
    if (pc.residual != 0u) s -= flow_t1[p];
    if (length(s) < pc.mask_px) s = vec2(0.0);
    float c = 1.0;
    if (pc.sigma > 0.0) {
        vec3 d = abs(photo[p].rgb - render_t1[p].rgb);
        c = exp(-((d.x + d.y + d.z) / 3.0) / pc.sigma);
    }
    bool ok = !(any(isnan(s)) || any(isinf(s)) || isnan(c) || isinf(c));
    scene[p] = ok ? s : vec2(0.0);
    conf[p] = ok ? c : 0.0;
}
