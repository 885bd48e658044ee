#version 460
// Backward of `project`: from the per-splat 2D gradients that blend_bwd accumulated (mean2d,
// conic, opacity, colour, depth) to the 3D parameters. Recomputes the forward (cheaper than
// storing ~40 floats per Gaussian). Chain: conic = Σ2⁻¹ → Σ2 = J·Σc·Jᵀ + 0.3·I → Σc = W·Σ3·Wᵀ
// → Σ3 = M·Mᵀ, M = R(q̂)·diag(s) → q̂ = q/|q|; mean through p = W·mean + t into mean2d, J (with
// the 1.3×fov clamp: a clamped coordinate passes no gradient to x or y, only through z) and
// depth. The SH view direction is detached, as in 3DGS/gsplat. Culled Gaussians get zeros.
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
    vec3 mean = vec3(means[3 * i], means[3 * i + 1], means[3 * i + 2]);
    vec3 scale = vec3(scales[3 * i], scales[3 * i + 1], scales[3 * i + 2]);
    Proj r = project_gaussian(pc, mean, scale, quats[i]);
    if (!r.visible) {
        write3(i, vec3(0.0), vec3(0.0));
        d_quats[i] = vec4(0.0);
        d_logits[i] = 0.0;
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

    float s = sigmoid(logits[i]);
    d_logits[i] = g_op * s * (1.0 - s);

    // conic = Σ2⁻¹: ∂L/∂Σ2 = −Σ2⁻¹·G·Σ2⁻¹ with G the symmetric gradient (b appears twice).
    mat2 Ci = mat2(r.conic.x, r.conic.y, r.conic.y, r.conic.z);
    mat2 G = mat2(g_con.x, 0.5 * g_con.y, 0.5 * g_con.y, g_con.z);
    mat2 gS2 = -(Ci * G * Ci);
    mat3 gS2m = mat3(vec3(gS2[0], 0.0), vec3(gS2[1], 0.0), vec3(0.0));
    mat3 gSc = transpose(r.J) * gS2m * r.J;
    mat3 gJ = 2.0 * gS2m * r.J * r.Sc;
    mat3 gS3 = transpose(r.W) * gSc * r.W;
    mat3 gM = 2.0 * gS3 * r.M;
    vec3 d_scale = vec3(dot(gM[0], r.Rq[0]), dot(gM[1], r.Rq[1]), dot(gM[2], r.Rq[2]));
    mat3 gR = mat3(gM[0] * scale.x, gM[1] * scale.y, gM[2] * scale.z);
    vec4 gq = quat_to_mat_grad(r.qn, gR);
    d_quats[i] = r.qlen > 1e-12 ? (gq - r.qn * dot(r.qn, gq)) / r.qlen : vec4(0.0);

    // Camera-space mean: mean2d, Jacobian (math entries J_ab = J[b][a]) and depth.
    float fx = pc.intrinsics.x, fy = pc.intrinsics.y;
    float z = r.p.z, z2 = z * z, z3 = z2 * z;
    vec3 g_p = vec3(g_m2.x * fx / z, g_m2.y * fy / z, -(g_m2.x * fx * r.p.x + g_m2.y * fy * r.p.y) / z2);
    float gJ00 = gJ[0][0], gJ02 = gJ[2][0], gJ11 = gJ[1][1], gJ12 = gJ[2][1];
    g_p.z += -(gJ00 * fx + gJ11 * fy) / z2 + 2.0 * (gJ02 * fx * r.tx + gJ12 * fy * r.ty) / z3;
    float g_tx = -gJ02 * fx / z2, g_ty = -gJ12 * fy / z2;
    // tx = x unclamped; tx = z·limit when clamped (then ∂tx/∂z = tx / z).
    if (r.clamp_x) g_p.z += g_tx * r.tx / z; else g_p.x += g_tx;
    if (r.clamp_y) g_p.z += g_ty * r.ty / z; else g_p.y += g_ty;
    g_p.z += g_z;
    write3(i, transpose(r.W) * g_p, d_scale);
}
