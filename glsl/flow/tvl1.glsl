// One TV-L1 iteration (Zach–Pock–Bischof; order as OpenCV DualTVL1) in one pass, ping-pong:
//   v = u + thresholding step of the linearised data term λ|ρ(v)| (coupling θ),
//   u' = v + θ·div p,
//   p' = (p + τ/θ·∇u') / (1 + τ/θ·|∇u'|)     (per flow component; forward differences).
// Each invocation also recomputes u' at its +x and +y neighbours (a pure function of the
// inputs) to get ∇u' without a second dispatch.
// p = (p1x, p1y, p2x, p2y): the dual of ∇u.x then ∇u.y.
// Reads: width, height, lambda_theta, theta, tau_theta.
// Body of tvl1.comp (storage buffers) and tvl1_texel.comp (texel buffers, glsl/include/access.glsl).
#ifndef TVL1_GLSL
#define TVL1_GLSL
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "flow.glsl"
#include "access.glsl"

layout(local_size_x = 16, local_size_y = 16) in;

layout(push_constant) uniform Push { FlowParams pc; };
ARR_RO(0, vec4, rgba32f, Warp, warp)
ARR_RO(1, vec2, rg32f, UIn, u_in)
ARR_RO(2, vec4, rgba32f, PIn, p_in)
ARR_WO(3, vec2, rg32f, UOut, u_out)
ARR_WO(4, vec4, rgba32f, POut, p_out)

// p with its x parts zeroed on the last column and its y parts on the last row (the adjoint
// of forward differences that are zero there).
vec4 p_eff(uint x, uint y) {
    vec4 p = LD4(p_in, y * pc.width + x);
    if (x + 1u >= pc.width) { p.x = 0.0; p.z = 0.0; }
    if (y + 1u >= pc.height) { p.y = 0.0; p.w = 0.0; }
    return p;
}

vec2 u_step(uint x, uint y) {
    uint o = y * pc.width + x;
    vec4 wd = LD4(warp, o);
    vec2 u = LD2(u_in, o);
    vec2 g = wd.yz;
    float grad = wd.w;
    float rho = wd.x + g.x * u.x + g.y * u.y;
    float lt = pc.lambda_theta;
    vec2 d = vec2(0.0);
    if (rho < -lt * grad) {
        d = lt * g;
    } else if (rho > lt * grad) {
        d = -lt * g;
    } else if (grad > FLOW_GRAD_EPS) {
        d = -rho * g / grad;
    }
    vec4 p = p_eff(x, y);
    vec2 div = vec2(p.x + p.y, p.z + p.w);
    if (x > 0u) { vec4 q = p_eff(x - 1u, y); div -= vec2(q.x, q.z); }
    if (y > 0u) { vec4 q = p_eff(x, y - 1u); div -= vec2(q.y, q.w); }
    return u + d + pc.theta * div;
}

void main() {
    uint x = gl_GlobalInvocationID.x, y = gl_GlobalInvocationID.y;
    if (x >= pc.width || y >= pc.height) return;
    uint o = y * pc.width + x;
    vec2 u = u_step(x, y);
    vec2 gx = x + 1u < pc.width ? u_step(x + 1u, y) - u : vec2(0.0);
    vec2 gy = y + 1u < pc.height ? u_step(x, y + 1u) - u : vec2(0.0);
    float tt = pc.tau_theta;
    vec4 p = LD4(p_in, o);
    // Component k of the flow: gradient (gx[k], gy[k]).
    float den0 = 1.0 + tt * sqrt(gx.x * gx.x + gy.x * gy.x);
    float den1 = 1.0 + tt * sqrt(gx.y * gx.y + gy.y * gy.y);
    ST2(u_out, o, u);
    ST4(p_out, o, vec4((p.x + tt * gx.x) / den0, (p.y + tt * gy.x) / den0,
                       (p.z + tt * gx.y) / den1, (p.w + tt * gy.y) / den1));
}

#endif
