// Shared rasteriser maths: layouts, camera, quaternion, spherical harmonics.
#ifndef RASTER_GLSL
#define RASTER_GLSL

#define TILE 16
// α below this is skipped; transmittance below T_STOP ends a pixel (3DGS/gsplat rules).
#define ALPHA_MIN (1.0 / 255.0)
#define T_STOP 1e-4
// Bits of the raster overflow word (meta[64], bin_total.comp): bit 0, the tile intersections
// overflowed their capacity (the host grows and re-runs); bit 1, a blend's walk of a tile was
// cut by the device's loop budget while a pixel still took splats (the host reports an error:
// growing cannot help). Mirrored in src/kernels/raster.rs (`OVERFLOW_*`).
#define OVERFLOW_CAPACITY 1u
#define OVERFLOW_WALK_CUT 2u
#define DILATION 0.3

// Per-Gaussian splat record written by `project`, read by blend (3 × vec4):
//   [0] = (mean2d.x, mean2d.y, depth, opacity)   [1] = (conic a, b, c, radius)
//   [2] = (r, g, b, reach): |dy| past which α < 1/255 (alpha_extent's y, with
//         ProjectParams.splat_extent; else EXTENT_NONE): the band blends skip bands beyond it
#define SPLAT_STRIDE 3

// Per-Gaussian 2D gradient record accumulated by blend_bwd (stride 13 floats):
//   0-1 mean2d, 2-4 conic (a, b, c), 5 opacity (after sigmoid), 6-8 colour, 9 depth,
//   10-11 Σ|∂L/∂mean2d| (BlendParams.abs_grad), 12 the feature channels' share of slot 5
//   (BlendParams.feat_op: what project_bwd leaves out of the opacity factors' gradient)
#define G2D_STRIDE 13

mat3 cam_rot(ProjectParams p) {
    // GLSL matrices are column-major: build from rows, then transpose.
    return transpose(mat3(p.rot0.xyz, p.rot1.xyz, p.rot2.xyz));
}

// Rotation matrix of a unit quaternion (w, x, y, z).
mat3 quat_to_mat(vec4 q) {
    float w = q.x, x = q.y, y = q.z, z = q.w;
    return mat3(
        vec3(1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)),  // column 0
        vec3(2.0 * (x * y - w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z + w * x)),  // column 1
        vec3(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y))); // column 2
}

// Normalised quaternion; a (near-)zero quaternion becomes the identity (its gradient is then 0).
vec4 quat_normalize(vec4 q, out float len) {
    len = length(q);
    return len > 1e-12 ? q / len : vec4(1.0, 0.0, 0.0, 0.0);
}

// ∂L/∂q for R(q) = quat_to_mat(q), q = (w, x, y, z), given gR with gR[col][row] = ∂L/∂R_row,col.
vec4 quat_to_mat_grad(vec4 q, mat3 gR) {
    float w = q.x, x = q.y, y = q.z, z = q.w;
    float g00 = gR[0][0], g01 = gR[1][0], g02 = gR[2][0];
    float g10 = gR[0][1], g11 = gR[1][1], g12 = gR[2][1];
    float g20 = gR[0][2], g21 = gR[1][2], g22 = gR[2][2];
    return 2.0 * vec4(
        -z * g01 + y * g02 + z * g10 - x * g12 - y * g20 + x * g21,
        y * g01 + z * g02 + y * g10 - 2.0 * x * g11 - w * g12 + z * g20 + w * g21 - 2.0 * x * g22,
        -2.0 * y * g00 + x * g01 + w * g02 + x * g10 + z * g12 - w * g20 + z * g21 - 2.0 * y * g22,
        -2.0 * z * g00 - w * g01 + x * g02 + w * g10 - 2.0 * z * g11 + y * g12 + x * g20 + y * g21);
}

float sigmoid(float x) {
    // exp of a negative argument only: no overflow at ±30 or beyond.
    return x >= 0.0 ? 1.0 / (1.0 + exp(-x)) : exp(x) / (1.0 + exp(x));
}

// sigmoid'(x) = e / (1 + e)², e = exp(−|x|): no cancellation, so it stays positive (≈ e^−|x|)
// where σ(1 − σ) rounds to 0 in f32 (|x| ≳ 17). With Adam's ε = 1e-15 even a 1e-13 gradient
// moves a saturated logit; an exact 0 would freeze it.
float sigmoid_grad(float x) {
    float e = exp(-abs(x));
    return e / ((1.0 + e) * (1.0 + e));
}

const float SH_C0 = 0.28209479177387814;
const float SH_C1 = 0.4886025119029199;
const float SH_C2[5] = float[5](1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
                                -1.0925484305920792, 0.5462742152960396);
const float SH_C3[7] = float[7](-0.5900435899266435, 2.890611442640554, -0.4570457994644658,
                                0.3731763325901154, -0.4570457994644658, 1.445305721320277,
                                -0.5900435899266435);

// Real SH basis values for a unit direction, 3DGS ordering and signs; unused bands are 0.
void sh_basis(vec3 d, uint degree, out float b[16]) {
    for (int k = 0; k < 16; ++k) b[k] = 0.0;
    b[0] = SH_C0;
    if (degree < 1u) return;
    float x = d.x, y = d.y, z = d.z;
    b[1] = -SH_C1 * y;
    b[2] = SH_C1 * z;
    b[3] = -SH_C1 * x;
    if (degree < 2u) return;
    float xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
    b[4] = SH_C2[0] * xy;
    b[5] = SH_C2[1] * yz;
    b[6] = SH_C2[2] * (2.0 * zz - xx - yy);
    b[7] = SH_C2[3] * xz;
    b[8] = SH_C2[4] * (xx - yy);
    if (degree < 3u) return;
    b[9] = SH_C3[0] * y * (3.0 * xx - yy);
    b[10] = SH_C3[1] * xy * z;
    b[11] = SH_C3[2] * y * (4.0 * zz - xx - yy);
    b[12] = SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
    b[13] = SH_C3[4] * x * (4.0 * zz - xx - yy);
    b[14] = SH_C3[5] * z * (xx - yy);
    b[15] = SH_C3[6] * x * (xx - 3.0 * yy);
}

float cross2(vec2 a, vec2 b) {
    return a.x * b.y - a.y * b.x;
}

// adj(Σ2)·g = 0.3·g + Σ_{k≠skip} cross2(g, a_k)·(a_k.y, −a_k.x), so Σ2⁻¹·g = adj(Σ2)·g / det
// without forming Σ2. With g = v_skip the skipped term is exactly zero (g ∥ a_skip), which is
// what keeps Σ2⁻¹·v_k accurate along a needle's long axis (size 1/λ_max) in f32; skip = −1
// keeps every term.
vec2 adj_mul(vec2 a[3], vec2 g, int skip) {
    vec2 r = DILATION * g;
    for (int k = 0; k < 3; ++k)
        if (k != skip) r += cross2(g, a[k]) * vec2(a[k].y, -a[k].x);
    return r;
}

// σ = ½(a dx² + c dy²) + b dx dy ≥ 0 of a conic (a, b, c) at offset d = mean2d − pixel. The
// conic is positive definite, so σ < 0 is rounding: a near-singular conic (a needle, whose
// along-axis curvature is below f32's resolution of a, b, c) on its own spine. It is blended
// as σ = 0 (α = opacity); skipping it (3DGS/gsplat) punched holes along a needle exactly where
// it is densest. The backward passes σ's gradient through the clamp.
float splat_sigma(vec3 con, vec2 d) {
    return max(0.5 * (con.x * d.x * d.x + con.z * d.y * d.y) + con.y * d.x * d.y, 0.0);
}

// Everything the forward projection computes that the backward needs again.
struct Proj {
    bool visible;
    vec3 p;          // camera-space mean
    float tx, ty;    // clamped x, y used in the Jacobian
    bool clamp_x, clamp_y;
    mat3 W;          // world-to-camera rotation
    mat3 Rq;         // rotation of the Gaussian
    vec4 qn;         // normalised quaternion
    float qlen;
    mat3 J;          // EWA Jacobian (third row zero)
    vec2 v[3];       // image of the Gaussian's axis k per unit scale: (J·W·Rq[k]).xy
    vec2 a[3];       // scale[k] · v[k]: Σ2 = Σ_k a_k a_kᵀ + 0.3·I
    vec3 cov2;       // dilated 2D covariance (xx, xy, yy)
    float det;
    vec3 conic;
    vec2 mean2d;
    float radius;
    uvec4 rect;      // tiles [x0, y0, x1, y1)
};

Proj project_gaussian(ProjectParams pc, vec3 mean, vec3 scale, vec4 quat) {
    Proj r;
    r.visible = false;
    r.W = cam_rot(pc);
    r.p = r.W * mean + pc.trans_near.xyz;
    r.rect = uvec4(0);
    r.radius = 0.0;
    // `!(z >= near)` also rejects NaN.
    if (!(r.p.z >= pc.trans_near.w)) return r;
    float fx = pc.intrinsics.x, fy = pc.intrinsics.y, cx = pc.intrinsics.z, cy = pc.intrinsics.w;
    r.qn = quat_normalize(quat, r.qlen);
    r.Rq = quat_to_mat(r.qn);
    float z = r.p.z;
    float tanx = 0.5 * float(pc.width) / fx, tany = 0.5 * float(pc.height) / fy;
    float lxp = (float(pc.width) - cx) / fx + 0.3 * tanx, lxn = cx / fx + 0.3 * tanx;
    float lyp = (float(pc.height) - cy) / fy + 0.3 * tany, lyn = cy / fy + 0.3 * tany;
    float ux = r.p.x / z, uy = r.p.y / z;
    r.clamp_x = ux < -lxn || ux > lxp;
    r.clamp_y = uy < -lyn || uy > lyp;
    r.tx = z * clamp(ux, -lxn, lxp);
    r.ty = z * clamp(uy, -lyn, lyp);
    r.J = mat3(vec3(fx / z, 0.0, 0.0), vec3(0.0, fy / z, 0.0),
               vec3(-fx * r.tx / (z * z), -fy * r.ty / (z * z), 0.0));
    // Σ2 = J·W·Rq·S²·Rqᵀ·Wᵀ·Jᵀ + 0.3·I = Σ_k a_k a_kᵀ + 0.3·I, kept in the Gaussian's own
    // frame. The determinant is the Cauchy–Binet sum of non-negative terms,
    //   det = 0.09 + 0.3·(xx + yy) + Σ_{j<k} cross2(a_j, a_k)²,
    // where the textbook xx·yy − xy² cancels catastrophically in f32 for a (near-)singular Σ2
    // (a needle, an edge-on disc, 1e-8 next to 1e4 in one Gaussian): it came out off by orders
    // of magnitude or ≤ 0, culling or smearing visible Gaussians.
    mat3 TW = r.J * r.W;
    for (int k = 0; k < 3; ++k) {
        r.v[k] = (TW * r.Rq[k]).xy;
        r.a[k] = scale[k] * r.v[k];
    }
    float xx = 0.0, xy = 0.0, yy = 0.0;
    for (int k = 0; k < 3; ++k) {
        xx += r.a[k].x * r.a[k].x;
        xy += r.a[k].x * r.a[k].y;
        yy += r.a[k].y * r.a[k].y;
    }
    float c01 = cross2(r.a[0], r.a[1]), c02 = cross2(r.a[0], r.a[2]), c12 = cross2(r.a[1], r.a[2]);
    r.cov2 = vec3(xx + DILATION, xy, yy + DILATION);
    r.det = DILATION * DILATION + DILATION * (xx + yy) + (c01 * c01 + c02 * c02 + c12 * c12);
    if (!(r.det > 0.0) || isinf(r.det)) return r;
    r.conic = vec3(r.cov2.z, -r.cov2.y, r.cov2.x) / r.det;
    r.mean2d = vec2(fx * r.p.x / z + cx, fy * r.p.y / z + cy);
    float mid = 0.5 * (r.cov2.x + r.cov2.z);
    float lambda = mid + sqrt(max(0.1, mid * mid - r.det));
    r.radius = ceil(3.0 * sqrt(lambda));
    if (!(r.radius > 0.0) || any(isnan(r.mean2d)) || any(isinf(r.conic)) || any(isnan(r.conic))) return r;
    // Clamp in float before converting: radii of huge Gaussians overflow an int.
    vec2 lo = floor((r.mean2d - r.radius) / float(TILE));
    vec2 hi = floor((r.mean2d + r.radius) / float(TILE)) + 1.0;
    vec2 tiles = vec2(pc.tiles_x, pc.tiles_y);
    r.rect = uvec4(clamp(lo, vec2(0.0), tiles), clamp(hi, vec2(0.0), tiles));
    r.visible = r.rect.x < r.rect.z && r.rect.y < r.rect.w;
    return r;
}

// Slack of alpha_extent (mirrored in Rust: reference::raster::project): the threshold's log
// is raised by EXTENT_LOG_SLACK (α's rounding in exp and the product, ~1e-6 relative) and the
// half-extent grown by the factor 1 + κ·EXTENT_REL_SLACK, κ = λ_max/λ_min ≤ radius²/(9·0.3),
// for the f32 conic's error in σ (relative, a few ulp times κ: the conic is adj(Σ2)/det of
// a rounded Σ2); past a growth of 1.5 (needles, radius ≳ 300 px) the 3σ square stands.
#define EXTENT_LOG_SLACK 1e-3
#define EXTENT_REL_SLACK (1.0 / 65536.0)

// Half-extents (x, y) in pixels past which the blend draws nothing of the splat: the blend
// skips α = opacity·exp(−σ) below 1/255 (ALPHA_MIN), and σ = ½ dᵀΣ2⁻¹d ≥ ½ dx²/Σ2xx (its
// minimum over dy), so no pixel with |dx| > sqrt(2 ln(255·opacity)·Σ2xx) is drawn; the same in
// y (gsplat's opacity-aware radius, per axis: the ellipse's bounding box). Whole pixels, padded
// by half a pixel. Negative: drawn nowhere (opacity < 1/255, and α ≤ opacity); EXTENT_NONE:
// no bound (the slack's growth past 1.5).
#define EXTENT_NONE 1e30
vec2 alpha_extent(Proj r, float opacity) {
    if (!(opacity >= ALPHA_MIN)) return vec2(-1.0);
    float kappa = r.radius * r.radius / (9.0 * DILATION);
    float grow = 1.0 + kappa * EXTENT_REL_SLACK;
    if (!(grow <= 1.5)) return vec2(EXTENT_NONE);
    float k = 2.0 * (log(opacity * 255.0) + EXTENT_LOG_SLACK);
    return ceil(sqrt(k * vec2(r.cov2.x, r.cov2.z)) * grow + 0.5);
}

// The tiles in which the blend can draw the splat: alpha_extent's box, capped at the 3σ
// radius, so the rectangle lies inside r.rect and holds every pixel the blend draws: images
// and gradients are those of r.rect, only the faint Gaussians' tile lists shrink. None below
// opacity 1/255.
uvec4 opacity_rect(ProjectParams pc, Proj r, float opacity) {
    vec2 e = alpha_extent(r, opacity);
    if (e.x < 0.0) return uvec4(0);
    vec2 ext = min(e, vec2(r.radius));
    vec2 lo = floor((r.mean2d - ext) / float(TILE));
    vec2 hi = floor((r.mean2d + ext) / float(TILE)) + 1.0;
    vec2 tiles = vec2(pc.tiles_x, pc.tiles_y);
    return uvec4(clamp(lo, vec2(0.0), tiles), clamp(hi, vec2(0.0), tiles));
}

#endif
