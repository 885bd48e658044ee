//! Twin of `glsl/raster/project.comp` and `glsl/raster/project_bwd.comp`: EWA projection of each
//! Gaussian (gsplat "classic"), colour from SH, opacity, tile rectangle.

use std::hash::{Hash, Hasher};

use super::{
    sigmoid, sigmoid_grad, BlendGrads, Camera, Gaussians, Gaussians64, ProjectGrads, Projected,
    Projected64, DILATION, QUAT_EPS, TILE,
};
use crate::reference::sh;

type M3 = [[f64; 3]; 3];

fn cross2(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

/// Rotation matrix of a unit quaternion (w, x, y, z); `r[row][col]`.
pub fn quat_to_rot(q: [f64; 4]) -> M3 {
    let [w, x, y, z] = q;
    [
        [
            1.0 - 2.0 * (y * y + z * z),
            2.0 * (x * y - w * z),
            2.0 * (x * z + w * y),
        ],
        [
            2.0 * (x * y + w * z),
            1.0 - 2.0 * (x * x + z * z),
            2.0 * (y * z - w * x),
        ],
        [
            2.0 * (x * z - w * y),
            2.0 * (y * z + w * x),
            1.0 - 2.0 * (x * x + y * y),
        ],
    ]
}

/// `Σ_ij g_ij · ∂R_ij/∂q` for the unnormalised map of [`quat_to_rot`].
fn quat_to_rot_vjp(q: [f64; 4], g: &M3) -> [f64; 4] {
    let [w, x, y, z] = q;
    let dw: M3 = [
        [0.0, -2.0 * z, 2.0 * y],
        [2.0 * z, 0.0, -2.0 * x],
        [-2.0 * y, 2.0 * x, 0.0],
    ];
    let dx: M3 = [
        [0.0, 2.0 * y, 2.0 * z],
        [2.0 * y, -4.0 * x, -2.0 * w],
        [2.0 * z, 2.0 * w, -4.0 * x],
    ];
    let dy: M3 = [
        [-4.0 * y, 2.0 * x, 2.0 * w],
        [2.0 * x, 0.0, 2.0 * z],
        [-2.0 * w, 2.0 * z, -4.0 * y],
    ];
    let dz: M3 = [
        [-4.0 * z, -2.0 * w, 2.0 * x],
        [2.0 * w, -4.0 * z, 2.0 * y],
        [2.0 * x, 2.0 * y, 0.0],
    ];
    let dot = |d: &M3| {
        let mut s = 0.0;
        for i in 0..3 {
            for j in 0..3 {
                s += d[i][j] * g[i][j];
            }
        }
        s
    };
    [dot(&dw), dot(&dx), dot(&dy), dot(&dz)]
}

/// Everything the forward computes for one visible Gaussian; the backward reuses it.
struct Fwd {
    /// Camera-space mean.
    p: [f64; 3],
    /// Normalised quaternion and the norm it was divided by (0 when replaced by identity).
    qn: [f64; 4],
    qnorm: f64,
    /// R(q̂).
    r: M3,
    /// The clamped x/z, y/z and whether the clamp was active.
    txz: f64,
    tyz: f64,
    clamp_x: bool,
    clamp_y: bool,
    /// The image of the Gaussian's axis k per unit scale, `v_k = T·R_k` with T = J·rot, and
    /// `a_k = s_k·v_k`: Σ2 = Σ_k a_k a_kᵀ + 0.3·I.
    v: [[f64; 2]; 3],
    a: [[f64; 2]; 3],
    det: f64,
    conic: [f64; 3],
    mean2d: [f64; 2],
    radius: u32,
    rect: [u32; 4],
    /// SH value before +0.5 and clamp; colour after.
    sh_dir: [f64; 3],
    color_raw: [f64; 3],
    color: [f64; 3],
    opacity: f64,
}

fn cam_rot(cam: &Camera) -> M3 {
    cam.rot.map(|r| r.map(f64::from))
}

/// Tile rectangle `[x0, y0, x1, y1)` of the pixels within `ext` (x, y) of `mean2d`, in f32
/// exactly as the GPU computes it.
fn rect_within(cam: &Camera, mean2d: [f64; 2], ext: [f32; 2]) -> [u32; 4] {
    let (tiles_x, tiles_y) = cam.tiles();
    let t = TILE as f32;
    // `as i32` saturates; `+ 1` must too.
    let lo = |m: f32, r: f32| ((m - r) / t).floor() as i32;
    let hi = |m: f32, r: f32| (((m + r) / t).floor() as i32).saturating_add(1);
    let (mx, my) = (mean2d[0] as f32, mean2d[1] as f32);
    let cl = |v: i32, n: u32| v.clamp(0, n as i32) as u32;
    [
        cl(lo(mx, ext[0]), tiles_x),
        cl(lo(my, ext[1]), tiles_y),
        cl(hi(mx, ext[0]), tiles_x),
        cl(hi(my, ext[1]), tiles_y),
    ]
}

/// The 3σ square: the tiles within `radius` of `mean2d` (`Proj::rect` on the GPU,
/// `SplatExtent::Radius`).
pub fn radius_rect(cam: &Camera, mean2d: [f64; 2], radius: u32) -> [u32; 4] {
    let r = radius as f32;
    rect_within(cam, mean2d, [r, r])
}

/// Mirrors `EXTENT_LOG_SLACK` and `EXTENT_REL_SLACK` in glsl/include/raster.glsl.
const EXTENT_LOG_SLACK: f32 = 1e-3;
const EXTENT_REL_SLACK: f32 = 1.0 / 65536.0;

/// Mirrors `EXTENT_NONE`: [`alpha_extent`] without a bound.
pub const EXTENT_NONE: f32 = 1e30;

/// Twin of `alpha_extent` (glsl/include/raster.glsl, read its comment), in f32 like the GPU:
/// the half-extents (x, y) in pixels past which α = `opacity`·exp(−σ) < 1/255, from the dilated
/// covariance's diagonal `cov_diag` (Σ2xx, Σ2yy); negative below opacity 1/255, [`EXTENT_NONE`]
/// past the slack's growth limit.
pub fn alpha_extent(cov_diag: [f64; 2], radius: u32, opacity: f64) -> [f32; 2] {
    let op = opacity as f32;
    if op.is_nan() || op < 1.0f32 / 255.0 {
        return [-1.0; 2];
    }
    let r = radius as f32;
    let kappa = r * r / (9.0 * DILATION as f32);
    let grow = 1.0 + kappa * EXTENT_REL_SLACK;
    if grow.is_nan() || grow > 1.5 {
        return [EXTENT_NONE; 2];
    }
    let k = 2.0 * ((op * 255.0).ln() + EXTENT_LOG_SLACK);
    cov_diag.map(|c| ((k * c as f32).sqrt() * grow + 0.5).ceil())
}

/// Twin of `opacity_rect`: the tiles of [`alpha_extent`]'s box capped by the 3σ square; none
/// below opacity 1/255.
pub fn opacity_rect(
    cam: &Camera,
    mean2d: [f64; 2],
    cov_diag: [f64; 2],
    radius: u32,
    opacity: f64,
) -> [u32; 4] {
    let e = alpha_extent(cov_diag, radius, opacity);
    if e[0] < 0.0 {
        return [0; 4];
    }
    let r = radius as f32;
    rect_within(cam, mean2d, e.map(|x| x.min(r)))
}

/// Forward for Gaussian `i`; `None` when culled. `factor`: the opacity factor the tile rectangle
/// sees (the GPU's `op_scale[i]`; 1 without factors); `Fwd::opacity` is without it.
fn project_one(cam: &Camera, g: &Gaussians64, i: usize, factor: f64) -> Option<Fwd> {
    let rot = cam_rot(cam);
    let mean = g.means[i];
    let mut p = [0.0; 3];
    for (a, pa) in p.iter_mut().enumerate() {
        *pa = cam.trans[a] as f64;
        for b in 0..3 {
            *pa += rot[a][b] * mean[b];
        }
    }
    let [x, y, z] = p;
    // 1. near plane; a non-finite position is culled too.
    if !x.is_finite() || !y.is_finite() || !z.is_finite() || z < cam.near as f64 {
        return None;
    }

    // 2. Rotation of the Gaussian.
    let q = g.quats[i];
    let qnorm = (q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]).sqrt();
    let (qn, qnorm) = if qnorm < QUAT_EPS || !qnorm.is_finite() {
        ([1.0, 0.0, 0.0, 0.0], 0.0)
    } else {
        (q.map(|v| v / qnorm), qnorm)
    };
    let r = quat_to_rot(qn);
    let s = g.scales[i];

    // 3. Jacobian with clamped x/z, y/z.
    let (fx, fy, cx, cy) = (cam.fx as f64, cam.fy as f64, cam.cx as f64, cam.cy as f64);
    let (w, h) = (cam.width as f64, cam.height as f64);
    let tan_fovx = 0.5 * w / fx;
    let tan_fovy = 0.5 * h / fy;
    let lim_x_pos = (w - cx) / fx + 0.3 * tan_fovx;
    let lim_x_neg = cx / fx + 0.3 * tan_fovx;
    let lim_y_pos = (h - cy) / fy + 0.3 * tan_fovy;
    let lim_y_neg = cy / fy + 0.3 * tan_fovy;
    let (xz, yz) = (x / z, y / z);
    let clamp_x = xz < -lim_x_neg || xz > lim_x_pos;
    let clamp_y = yz < -lim_y_neg || yz > lim_y_pos;
    let txz = xz.max(-lim_x_neg).min(lim_x_pos);
    let tyz = yz.max(-lim_y_neg).min(lim_y_pos);
    let (tx, ty) = (z * txz, z * tyz);
    let j = [
        [fx / z, 0.0, -fx * tx / (z * z)],
        [0.0, fy / z, -fy * ty / (z * z)],
    ];
    let mut t = [[0.0; 3]; 2];
    for a in 0..2 {
        for b in 0..3 {
            for k in 0..3 {
                t[a][b] += j[a][k] * rot[k][b];
            }
        }
    }
    // Σ2 = T·R·S²·Rᵀ·Tᵀ + 0.3 I = Σ_k a_k a_kᵀ + 0.3 I, a_k = s_k·T·R_k (R_k: column k of R).
    let mut v = [[0.0; 2]; 3];
    for (k, vk) in v.iter_mut().enumerate() {
        for row in 0..2 {
            vk[row] = (0..3).map(|l| t[row][l] * r[l][k]).sum();
        }
    }
    let a: [[f64; 2]; 3] = std::array::from_fn(|k| [s[k] * v[k][0], s[k] * v[k][1]]);
    let (mut xx, mut xy, mut yy) = (0.0, 0.0, 0.0);
    for ak in &a {
        xx += ak[0] * ak[0];
        xy += ak[0] * ak[1];
        yy += ak[1] * ak[1];
    }
    let sigma2 = [[xx + DILATION, xy], [xy, yy + DILATION]];
    let s01 = xy;

    // 4. conic. det Σ2 as the Cauchy–Binet sum of non-negative terms,
    // det = 0.09 + 0.3·(xx + yy) + Σ_{j<k} cross2(a_j, a_k)², like the GPU: the textbook
    // xx·yy − xy² cancels catastrophically for a near-singular Σ2 (in f32 already for a
    // needle a few hundred pixels long).
    let c = |j: usize, k: usize| cross2(a[j], a[k]);
    let det = DILATION * DILATION
        + DILATION * (xx + yy)
        + (c(0, 1).powi(2) + c(0, 2).powi(2) + c(1, 2).powi(2));
    if !det.is_finite() || det <= 0.0 {
        return None;
    }
    let conic = [sigma2[1][1] / det, -s01 / det, sigma2[0][0] / det];

    // 5. mean2d.
    let mean2d = [fx * x / z + cx, fy * y / z + cy];

    // 6. radius.
    let mid = 0.5 * (sigma2[0][0] + sigma2[1][1]);
    let lambda_max = mid + (mid * mid - det).max(0.1).sqrt();
    let radius_f = (3.0 * lambda_max.sqrt()).ceil();
    if radius_f.is_nan() || radius_f < 1.0 {
        return None;
    }
    let radius = radius_f as u32; // saturating

    // 7. the 3σ square culls; what is binned is the opacity-aware box inside it (step 9).
    let square = radius_rect(cam, mean2d, radius);
    if square[0] >= square[2] || square[1] >= square[3] {
        return None;
    }

    // 8. colour from SH, view direction detached.
    let centre = cam.centre();
    let mut dir = [
        mean[0] - centre[0],
        mean[1] - centre[1],
        mean[2] - centre[2],
    ];
    let len = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
    if len > 0.0 {
        dir = dir.map(|d| d / len);
    }
    let nc = g.sh_coeffs as usize;
    let coeffs = &g.sh[i * nc * 3..(i + 1) * nc * 3];
    let color_raw = sh::eval(g.sh_degree, dir, coeffs);
    let color = color_raw.map(|c| (c + 0.5).max(0.0));

    // 9. opacity, and the tiles binned (the GPU's opacity with the factor, in f32).
    let opacity = sigmoid(g.opacity_logits[i]);
    let op_drawn = (opacity as f32 * factor as f32) as f64;
    let cov_diag = [sigma2[0][0], sigma2[1][1]];
    let rect = opacity_rect(cam, mean2d, cov_diag, radius, op_drawn);

    Some(Fwd {
        p,
        qn,
        qnorm,
        r,
        txz,
        tyz,
        clamp_x,
        clamp_y,
        v,
        a,
        det,
        conic,
        mean2d,
        radius,
        rect,
        sh_dir: dir,
        color_raw,
        color,
        opacity,
    })
}

/// Projects every Gaussian (see the module docs for the conventions), in f64, rounding the
/// outputs to f32. The tile rectangle is computed in f32 from the rounded `mean2d` and `radius`
/// like the GPU: `x0 = clamp(i32(floor((mx − r)/16)), 0, tiles_x)`,
/// `x1 = clamp(i32(floor((mx + r)/16)) + 1, 0, tiles_x)`, same for y; an empty rectangle culls.
/// What is kept is the opacity-aware box inside it ([`opacity_rect`], `SplatExtent::OpacityBox`,
/// the GPU's default): empty for a visible Gaussian of opacity < 1/255.
///
/// Culled (radius 0, empty rect, zero conic/colour/opacity): camera z < `near` or not finite,
/// 2D determinant ≤ 0 or not finite, radius 0, no tile touched. A quaternion of norm < 1e-12 is
/// replaced by the identity rotation (its gradient is then 0).
pub fn project(cam: &Camera, g: &Gaussians) -> Projected {
    project_f64(cam, &Gaussians64::from_f32(g)).to_f32()
}

/// [`project`] without rounding (the tile rectangle is still computed in f32 from the f32-rounded
/// mean and radius, so it equals [`project`]'s).
pub fn project_f64(cam: &Camera, g: &Gaussians64) -> Projected64 {
    project_with(cam, g, |_| 1.0)
}

/// [`project_f64`] with the tile rectangles of opacities times `w(i)` (the factors are applied
/// to the outputs by [`project_scaled_f64`]).
fn project_with(cam: &Camera, g: &Gaussians64, w: impl Fn(usize) -> f64) -> Projected64 {
    g.check();
    let n = g.len();
    let mut out = Projected64 {
        mean2d: vec![[0.0; 2]; n],
        conic: vec![[0.0; 3]; n],
        depth: vec![0.0; n],
        radius: vec![0; n],
        tile_rect: vec![[0; 4]; n],
        color: vec![[0.0; 3]; n],
        opacity: vec![0.0; n],
        signature: 0,
    };
    let mut hasher = std::collections::hash_map::DefaultHasher::new();
    for i in 0..n {
        let Some(f) = project_one(cam, g, i, w(i)) else {
            (i, false).hash(&mut hasher);
            continue;
        };
        out.mean2d[i] = f.mean2d;
        out.conic[i] = f.conic;
        out.depth[i] = f.p[2];
        out.radius[i] = f.radius;
        out.tile_rect[i] = f.rect;
        out.color[i] = f.color;
        out.opacity[i] = f.opacity;
        let col_clamped = f.color_raw.map(|c| c + 0.5 < 0.0);
        (i, true, f.rect, f.clamp_x, f.clamp_y, col_clamped).hash(&mut hasher);
    }
    out.signature = hasher.finish();
    out
}

/// Reverse of [`project`]: chains the blend gradients (mean2d, conic, opacity, colour, depth)
/// back to the raw parameters. Gaussians culled in `proj` (radius 0) get zero gradients.
/// Features are not a projection output: their gradient is `d.features` itself.
pub fn project_bwd(cam: &Camera, g: &Gaussians, proj: &Projected, d: &BlendGrads) -> ProjectGrads {
    let g64 = Gaussians64::from_f32(g);
    assert_eq!(
        proj.radius.len(),
        g64.len(),
        "project_bwd: proj is for another N"
    );
    project_bwd_impl(cam, &g64, |i| proj.radius[i] == 0, d)
}

/// [`project_bwd`] for the f64 pipeline (culling recomputed from `g`).
pub fn project_bwd_f64(cam: &Camera, g: &Gaussians64, d: &BlendGrads) -> ProjectGrads {
    project_bwd_impl(cam, g, |_| false, d)
}

fn project_bwd_impl(
    cam: &Camera,
    g: &Gaussians64,
    culled: impl Fn(usize) -> bool,
    d: &BlendGrads,
) -> ProjectGrads {
    g.check();
    let n = g.len();
    assert_eq!(d.mean2d.len(), n, "project_bwd: d.mean2d.len() != N");
    assert_eq!(d.conic.len(), n, "project_bwd: d.conic.len() != N");
    assert_eq!(d.opacity.len(), n, "project_bwd: d.opacity.len() != N");
    assert_eq!(d.color.len(), n, "project_bwd: d.color.len() != N");
    assert_eq!(d.depth.len(), n, "project_bwd: d.depth.len() != N");
    let nc = g.sh_coeffs as usize;
    let mut out = ProjectGrads {
        means: vec![[0.0; 3]; n],
        scales: vec![[0.0; 3]; n],
        quats: vec![[0.0; 4]; n],
        opacity_logits: vec![0.0; n],
        sh: vec![0.0; g.sh.len()],
    };
    let rot = cam_rot(cam);
    let (fx, fy) = (cam.fx as f64, cam.fy as f64);
    for i in 0..n {
        if culled(i) {
            continue;
        }
        let Some(f) = project_one(cam, g, i, 1.0) else {
            continue;
        };
        let [x, y, z] = f.p;
        let mut dp = [0.0; 3];

        // Conic = Σ2⁻¹ with G = ∂L/∂C symmetric (b appears twice): ∂L/∂Σ2 = −C·G·C. Formed as a
        // matrix, C keeps its smallest eigenvalue 1/λ_max only to a relative ε·λ_max/0.3, which
        // is nothing for a needle or an edge-on disc (λ_max ≳ 1e9 px² fails even in f64). So the
        // chain runs in the Gaussian's frame with w_k = C·v_k = adj(Σ2)·v_k / det, where the
        // k-th term of adj(Σ2)·v_k = 0.3·v_k + Σ_j cross2(v_k, a_j)·perp(a_j) is exactly zero:
        //   Q_jk = −w_jᵀ G w_k,  ∂L/∂s_k = 2 s_k Q_kk,  ∂L/∂R_k = 2 s_k² Σ_j Q_jk R_j,
        //   ∂L/∂J = −2 Σ_k s_k² (C·G·w_k)(rot·R_k)ᵀ,  ⟨∂L/∂J, J⟩ = 2 Σ_k s_k² Q_kk.
        let [da, db, dc] = d.conic[i];
        let gmul = |u: [f64; 2]| [da * u[0] + 0.5 * db * u[1], 0.5 * db * u[0] + dc * u[1]];
        let adj_mul = |u: [f64; 2], skip: Option<usize>| {
            let mut out = [DILATION * u[0], DILATION * u[1]];
            for (j, aj) in f.a.iter().enumerate() {
                if Some(j) != skip {
                    let c = cross2(u, *aj);
                    out[0] += c * aj[1];
                    out[1] -= c * aj[0];
                }
            }
            out.map(|x| x / f.det)
        };
        let w: [[f64; 2]; 3] = std::array::from_fn(|k| adj_mul(f.v[k], Some(k)));
        let q: M3 = std::array::from_fn(|j| {
            std::array::from_fn(|k| {
                let gw = gmul(w[k]);
                -(w[j][0] * gw[0] + w[j][1] * gw[1])
            })
        });
        let s = g.scales[i];
        let s2 = s.map(|x| x * x);
        out.scales[i] = std::array::from_fn(|k| 2.0 * s[k] * q[k][k]);
        // dR[row][k] = ∂L/∂R_{row,k}.
        let mut dr = [[0.0; 3]; 3];
        for k in 0..3 {
            for row in 0..3 {
                dr[row][k] = 2.0 * s2[k] * (0..3).map(|j| q[j][k] * f.r[row][j]).sum::<f64>();
            }
        }
        // q̂ = q/|q|: dq = (dq̂ − q̂ (q̂·dq̂)) / |q|.
        if f.qnorm > 0.0 {
            let dqn = quat_to_rot_vjp(f.qn, &dr);
            let dot: f64 = (0..4).map(|k| dqn[k] * f.qn[k]).sum();
            out.quats[i] = std::array::from_fn(|k| (dqn[k] - f.qn[k] * dot) / f.qnorm);
        }
        // ∂L/∂J (2×3); its (0,0) and (1,1) entries enter only through ⟨∂L/∂J, J⟩ below.
        let mut dj = [[0.0; 3]; 2];
        for k in 0..3 {
            let h = adj_mul(gmul(w[k]), None);
            let axis: [f64; 3] =
                std::array::from_fn(|row| (0..3).map(|l| rot[row][l] * f.r[l][k]).sum());
            for row in 0..2 {
                for col in 0..3 {
                    dj[row][col] -= 2.0 * s2[k] * h[row] * axis[col];
                }
            }
        }
        let dj_dot_j: f64 = (0..3).map(|k| 2.0 * s2[k] * q[k][k]).sum();
        // J = [[fx/z, 0, −fx·tx/z²], [0, fy/z, −fy·ty/z²]], tx = z·clamp(x/z), ty likewise.
        let (tx, ty) = (z * f.txz, z * f.tyz);
        let z2 = z * z;
        let z3 = z2 * z;
        // ∂J/∂z at fixed tx, ty = −J/z + (third column fx·tx/z³, fy·ty/z³).
        dp[2] += -dj_dot_j / z + (dj[0][2] * fx * tx + dj[1][2] * fy * ty) / z3;
        let dtx = dj[0][2] * (-fx / z2);
        let dty = dj[1][2] * (-fy / z2);
        if f.clamp_x {
            dp[2] += dtx * f.txz; // tx = z · limit
        } else {
            dp[0] += dtx; // tx = x
        }
        if f.clamp_y {
            dp[2] += dty * f.tyz;
        } else {
            dp[1] += dty;
        }

        // mean2d = (fx x/z + cx, fy y/z + cy); depth = z.
        let [du, dv] = d.mean2d[i];
        dp[0] += du * fx / z;
        dp[1] += dv * fy / z;
        dp[2] += -du * fx * x / z2 - dv * fy * y / z2;
        dp[2] += d.depth[i];

        // p = rot · mean + trans.
        let mut dmean = [0.0; 3];
        for (bi, dm) in dmean.iter_mut().enumerate() {
            for ai in 0..3 {
                *dm += rot[ai][bi] * dp[ai];
            }
        }
        out.means[i] = dmean;

        // opacity = sigmoid(logit).
        out.opacity_logits[i] = d.opacity[i] * sigmoid_grad(g.opacity_logits[i]);

        // colour = max(SH + 0.5, 0): zero gradient where clamped.
        let dcol: [f64; 3] = std::array::from_fn(|ch| {
            if f.color_raw[ch] + 0.5 < 0.0 {
                0.0
            } else {
                d.color[i][ch]
            }
        });
        sh::eval_bwd(
            g.sh_degree,
            f.sh_dir,
            dcol,
            &mut out.sh[i * nc * 3..(i + 1) * nc * 3],
        );
    }
    out
}

/// Twin of the projection with opacity factors (`ProjectParams::opacity_scale`): [`project_f64`]
/// with each opacity multiplied by `w[i]`, and a Gaussian whose factor is not > 0 culled
/// (the transients' temporal weights).
pub fn project_scaled_f64(cam: &Camera, g: &Gaussians64, w: &[f64]) -> Projected64 {
    assert_eq!(w.len(), g.len(), "project_scaled: one factor per Gaussian");
    let mut p = project_with(cam, g, |i| w[i]);
    for (i, &wi) in w.iter().enumerate() {
        if wi > 0.0 {
            p.opacity[i] *= wi;
        } else {
            p.mean2d[i] = [0.0; 2];
            p.conic[i] = [0.0; 3];
            p.depth[i] = 0.0;
            p.radius[i] = 0;
            p.tile_rect[i] = [0; 4];
            p.color[i] = [0.0; 3];
            p.opacity[i] = 0.0;
        }
    }
    p
}

/// Reverse of [`project_scaled_f64`]: [`project_bwd_f64`] with the logits' gradient scaled by
/// the factor, and ∂L/∂w = ∂L/∂opacity · σ(logit) (0 where culled). `detach_features`: the
/// factor is a constant in the blend of the feature channels, so ∂L/∂w leaves out
/// `d.opacity_features` (the logits keep it: `project_bwd` with `feat_detach`).
pub fn project_scaled_bwd_f64(
    cam: &Camera,
    g: &Gaussians64,
    w: &[f64],
    d: &BlendGrads,
    detach_features: bool,
) -> (ProjectGrads, Vec<f64>) {
    let culled = |i: usize| w[i].is_nan() || w[i] <= 0.0;
    let mut pg = project_bwd_impl(cam, g, culled, d);
    let mut dw = vec![0.0; g.len()];
    for i in 0..g.len() {
        if culled(i) {
            continue;
        }
        pg.opacity_logits[i] *= w[i];
        let held = if detach_features {
            d.opacity_features[i]
        } else {
            0.0
        };
        dw[i] = (d.opacity[i] - held) * super::sigmoid(g.opacity_logits[i]);
    }
    (pg, dw)
}
