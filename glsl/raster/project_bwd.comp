#version 460
// Backward of `project`: from the per-splat 2D gradients that blend_bwd accumulated (mean2d,
// conic, opacity, colour, depth) to the 3D parameters. Recomputes the forward (cheaper than
// storing ~40 floats per Gaussian). Chain: conic = Σ2⁻¹ → Σ2 = J·W·R(q̂)·S²·R(q̂)ᵀ·Wᵀ·Jᵀ + 0.3·I
// (taken in the Gaussian's own frame, see below) → q̂ = q/|q|, s; mean through p = W·mean + t
// into mean2d, J (with
// the 1.3×fov clamp: a clamped coordinate passes no gradient to x or y, only through z) and
// depth. The SH view direction is detached, as in 3DGS/gsplat. Culled Gaussians get zeros.
// With pc.opacity_scale the splat's opacity was σ(o)·w (w = op_scale[i]): ∂L/∂o picks up the
// factor w and ∂L/∂w = g_op·σ(o) goes to d_op_scale (a transient's temporal weight); with
// pc.feat_detach, g_op less the feature channels' share (slot 12): the factor is held constant
// in the blend of the features (the motion pass's channels), ∂L/∂o keeps every share.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"
#include "raster.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { ProjectParams pc; };
layout(std430, binding = 0) readonly buffer Means { float means[]; };
layout(std430, binding = 1) readonly buffer Scales { float scales[]; };
layout(std430, binding = 2) readonly buffer Quats { vec4 quats[]; };
layout(std430, binding = 3) readonly buffer Opacity { float logits[]; };
layout(std430, binding = 4) readonly buffer ShDc { float sh_dc[]; };
layout(std430, binding = 5) readonly buffer ShRest { float sh_rest[]; };
layout(std430, binding = 6) readonly buffer Grad2d { float grad2d[]; };
layout(std430, binding = 7) writeonly buffer DMeans { float d_means[]; };
layout(std430, binding = 8) writeonly buffer DScales { float d_scales[]; };
layout(std430, binding = 9) writeonly buffer DQuats { vec4 d_quats[]; };
layout(std430, binding = 10) writeonly buffer DOpacity { float d_logits[]; };
layout(std430, binding = 11) writeonly buffer DShDc { float d_sh_dc[]; };
layout(std430, binding = 12) writeonly buffer DShRest { float d_sh_rest[]; };
layout(std430, binding = 13) readonly buffer OpScale { float op_scale[]; };     // [N] (opacity_scale)
layout(std430, binding = 14) writeonly buffer DOpScale { float d_op_scale[]; }; // [N] (opacity_scale)

// Coefficient k of Gaussian i: the DC band and the rest live in separate buffers.
void write_dsh(uint i, uint k, vec3 v) {
    if (k == 0u) {
        d_sh_dc[3 * i] = v.x;
        d_sh_dc[3 * i + 1] = v.y;
        d_sh_dc[3 * i + 2] = v.z;
    } else {
        uint o = (i * (pc.sh_coeffs - 1u) + k - 1u) * 3u;
        d_sh_rest[o] = v.x;
        d_sh_rest[o + 1] = v.y;
        d_sh_rest[o + 2] = v.z;
    }
}

void write3(uint i, vec3 dm, vec3 ds) {
    d_means[3 * i] = dm.x;
    d_means[3 * i + 1] = dm.y;
    d_means[3 * i + 2] = dm.z;
    d_scales[3 * i] = ds.x;
    d_scales[3 * i + 1] = ds.y;
    d_scales[3 * i + 2] = ds.z;
}

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.num_gaussians) return;
    float op_w = pc.opacity_scale != 0u ? op_scale[i] : 1.0;
    vec3 mean = vec3(means[3 * i], means[3 * i + 1], means[3 * i + 2]);
    vec3 scale = vec3(scales[3 * i], scales[3 * i + 1], scales[3 * i + 2]);
    Proj r;
    r.visible = false;
    if (op_w > 0.0) r = project_gaussian(pc, mean, scale, quats[i]);
    if (!r.visible) {
        write3(i, vec3(0.0), vec3(0.0));
        d_quats[i] = vec4(0.0);
        d_logits[i] = 0.0;
        if (pc.opacity_scale != 0u) d_op_scale[i] = 0.0;
        for (uint k = 0; k < pc.sh_coeffs; ++k) write_dsh(i, k, vec3(0.0));
        return;
    }
    uint gb = i * G2D_STRIDE;
    vec2 g_m2 = vec2(grad2d[gb], grad2d[gb + 1]);
    vec3 g_con = vec3(grad2d[gb + 2], grad2d[gb + 3], grad2d[gb + 4]);
    float g_op = grad2d[gb + 5];
    vec3 g_col = vec3(grad2d[gb + 6], grad2d[gb + 7], grad2d[gb + 8]);
    float g_z = grad2d[gb + 9];

    // Colour → SH coefficients (gradient only where max(·, 0) did not clamp).
    vec3 centre = -(transpose(r.W) * pc.trans_near.xyz);
    vec3 dir = mean - centre;
    float dl = length(dir);
    dir = dl > 0.0 ? dir / dl : vec3(0.0, 0.0, 1.0);
    float b[16];
    sh_basis(dir, pc.sh_degree, b);
    uint nb = min((pc.sh_degree + 1u) * (pc.sh_degree + 1u), pc.sh_coeffs);
    vec3 raw = vec3(0.5) + b[0] * vec3(sh_dc[3 * i], sh_dc[3 * i + 1], sh_dc[3 * i + 2]);
    for (uint k = 1; k < nb; ++k) {
        uint o = (i * (pc.sh_coeffs - 1u) + k - 1u) * 3u;
        raw += b[k] * vec3(sh_rest[o], sh_rest[o + 1], sh_rest[o + 2]);
    }
    vec3 g_raw = g_col * vec3(greaterThan(raw, vec3(0.0)));
    for (uint k = 0; k < pc.sh_coeffs; ++k) write_dsh(i, k, k < nb ? b[k] * g_raw : vec3(0.0));

    d_logits[i] = g_op * op_w * sigmoid_grad(logits[i]);
    if (pc.opacity_scale != 0u) {
        float g_op_w = pc.feat_detach != 0u ? g_op - grad2d[gb + 12] : g_op;
        d_op_scale[i] = g_op_w * sigmoid(logits[i]);
    }

    // conic = Σ2⁻¹, G the symmetric gradient (b appears twice): ∂L/∂Σ2 = −C·G·C. Formed as a
    // matrix in f32, C loses its smallest eigenvalue 1/λ_max (a needle's length) and every
    // gradient along the long axis came out as rounding noise, orders of magnitude too large.
    // So stay in the Gaussian's frame (a_k = s_k v_k, Σ2 = Σ_k a_k a_kᵀ + 0.3·I) with
    // w_k = C·v_k from adj_mul, whose self term cancels exactly:
    //   Q_jk = −w_jᵀ G w_k,  ∂L/∂s_k = 2 s_k Q_kk,  ∂L/∂Rq[k] = 2 s_k² Σ_j Q_jk Rq[j],
    //   ∂L/∂J = −2 Σ_k s_k² (C·G·w_k)(W·Rq[k])ᵀ,  ⟨∂L/∂J, J⟩ = 2 Σ_k s_k² Q_kk.
    mat2 G = mat2(g_con.x, 0.5 * g_con.y, 0.5 * g_con.y, g_con.z);
    vec2 w[3];
    for (int k = 0; k < 3; ++k) w[k] = adj_mul(r.a, r.v[k], k) / r.det;
    mat3 Q;
    for (int j = 0; j < 3; ++j)
        for (int k = 0; k < 3; ++k) Q[j][k] = -dot(w[j], G * w[k]);
    vec3 s2 = scale * scale;
    vec3 d_scale = 2.0 * scale * vec3(Q[0][0], Q[1][1], Q[2][2]);
    mat3 gR; // column k = ∂L/∂Rq[k]
    for (int k = 0; k < 3; ++k)
        gR[k] = 2.0 * s2[k] * (Q[0][k] * r.Rq[0] + Q[1][k] * r.Rq[1] + Q[2][k] * r.Rq[2]);
    vec4 gq = quat_to_mat_grad(r.qn, gR);
    d_quats[i] = r.qlen > 1e-12 ? (gq - r.qn * dot(r.qn, gq)) / r.qlen : vec4(0.0);
    // The third column of ∂L/∂J (math indices), which carries tx and ty.
    float gJ02 = 0.0, gJ12 = 0.0;
    for (int k = 0; k < 3; ++k) {
        vec2 h = adj_mul(r.a, G * w[k], -1) / r.det;
        float uz = (r.W * r.Rq[k]).z;
        gJ02 -= 2.0 * s2[k] * h.x * uz;
        gJ12 -= 2.0 * s2[k] * h.y * uz;
    }
    float gJJ = 2.0 * dot(s2, vec3(Q[0][0], Q[1][1], Q[2][2]));

    // Camera-space mean: mean2d, Jacobian (math entries J_ab = J[b][a]) and depth.
    float fx = pc.intrinsics.x, fy = pc.intrinsics.y;
    float z = r.p.z, z2 = z * z, z3 = z2 * z;
    vec3 g_p = vec3(g_m2.x * fx / z, g_m2.y * fy / z, -(g_m2.x * fx * r.p.x + g_m2.y * fy * r.p.y) / z2);
    // ∂J/∂z at fixed tx, ty is −J/z + (third column fx·tx/z³, fy·ty/z³).
    g_p.z += -gJJ / z + (gJ02 * fx * r.tx + gJ12 * fy * r.ty) / z3;
    float g_tx = -gJ02 * fx / z2, g_ty = -gJ12 * fy / z2;
    // tx = x unclamped; tx = z·limit when clamped (then ∂tx/∂z = tx / z).
    if (r.clamp_x) g_p.z += g_tx * r.tx / z; else g_p.x += g_tx;
    if (r.clamp_y) g_p.z += g_ty * r.ty / z; else g_p.y += g_ty;
    g_p.z += g_z;
    write3(i, transpose(r.W) * g_p, d_scale);
}
