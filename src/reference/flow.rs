//! Twin of `glsl/flow/*`: TV-L1 optical flow (Zach, Pock, Bischof 2007, duality-based, in the
//! form of Wedel et al. 2009 / OpenCV's `DualTVL1`) on a grey pyramid with warping, in f64.
//! Same stages, same iteration counts and the same update order as the GPU (see
//! `kernels::flow` for the algorithm and its conventions); plain loops.

use crate::kernels::flow::{pyramid_dims, FlowConfig, FLOW_GRAD_EPS, GREY_SCALE, TEXTURE_PASSES};

/// A planar f64 image.
#[derive(Clone, Debug)]
struct Plane {
    w: usize,
    h: usize,
    v: Vec<f64>,
}

impl Plane {
    fn at(&self, x: usize, y: usize) -> f64 {
        self.v[y * self.w + x]
    }
    /// Clamped integer read.
    fn clamped(&self, x: i64, y: i64) -> f64 {
        let x = x.clamp(0, self.w as i64 - 1) as usize;
        let y = y.clamp(0, self.h as i64 - 1) as usize;
        self.at(x, y)
    }
}

/// Bilinear sample at continuous pixel coordinates, the coordinates clamped to the image
/// (border replicate), as `flow_bilinear` in glsl/flow/flow.glsl.
fn bilinear(w: usize, h: usize, qx: f64, qy: f64, get: impl Fn(usize) -> f64) -> f64 {
    let qx = qx.clamp(0.0, (w - 1) as f64);
    let qy = qy.clamp(0.0, (h - 1) as f64);
    let x0 = (qx.floor() as usize).min(w - 1);
    let y0 = (qy.floor() as usize).min(h - 1);
    let x1 = (x0 + 1).min(w - 1);
    let y1 = (y0 + 1).min(h - 1);
    let (fx, fy) = (qx - x0 as f64, qy - y0 as f64);
    let top = get(y0 * w + x0) * (1.0 - fx) + get(y0 * w + x1) * fx;
    let bot = get(y1 * w + x0) * (1.0 - fx) + get(y1 * w + x1) * fx;
    top * (1.0 - fy) + bot * fy
}

/// Grey level `GREY_SCALE · (0.299 r + 0.587 g + 0.114 b)` (glsl/flow/grey.comp).
fn grey(img: &[[f32; 4]], w: usize, h: usize) -> Plane {
    let v = img
        .iter()
        .map(|p| {
            GREY_SCALE as f64 * (0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64)
        })
        .collect();
    Plane { w, h, v }
}

/// 5×5 binomial blur ([1 4 6 4 1]/16 separable, clamped border) of `src` centred on
/// `(cx, cy)`.
fn binomial_at(src: &Plane, cx: i64, cy: i64) -> f64 {
    const K: [f64; 5] = [1.0 / 16.0, 4.0 / 16.0, 6.0 / 16.0, 4.0 / 16.0, 1.0 / 16.0];
    let mut acc = 0.0;
    for (j, kj) in K.iter().enumerate() {
        let mut row = 0.0;
        for (i, ki) in K.iter().enumerate() {
            row += ki * src.clamped(cx + i as i64 - 2, cy + j as i64 - 2);
        }
        acc += kj * row;
    }
    acc
}

/// `w`×`h` samples of `f(x, y)`.
fn plane(w: usize, h: usize, f: impl Fn(i64, i64) -> f64) -> Plane {
    let v = (0..w * h)
        .map(|o| f((o % w) as i64, (o / w) as i64))
        .collect();
    Plane { w, h, v }
}

/// 5×5 binomial blur sampled at even pixels (glsl/flow/downsample.comp).
fn downsample(src: &Plane, w: usize, h: usize) -> Plane {
    plane(w, h, |x, y| binomial_at(src, 2 * x, 2 * y))
}

/// One 5×5 binomial blur pass, clamped border, same size (glsl/flow/prefilter.comp).
fn blur(src: &Plane) -> Plane {
    plane(src.w, src.h, |x, y| binomial_at(src, x, y))
}

/// `n` blur passes.
fn blurred(p: &Plane, n: u32) -> Plane {
    (0..n).fold(p.clone(), |q, _| blur(&q))
}

/// The texture part `I − β·S(I)`, `S` = [`TEXTURE_PASSES`] blur passes.
fn texture(p: &Plane, beta: f64) -> Plane {
    let s = blurred(p, TEXTURE_PASSES);
    Plane {
        v: p.v.iter().zip(&s.v).map(|(a, b)| a - beta * b).collect(),
        ..s
    }
}

/// Central differences, clamped at the border (glsl/flow/gradient.comp).
fn gradient(i1: &Plane) -> Vec<[f64; 2]> {
    let (w, h) = (i1.w, i1.h);
    let mut g = vec![[0.0; 2]; w * h];
    for y in 0..h as i64 {
        for x in 0..w as i64 {
            g[y as usize * w + x as usize] = [
                0.5 * (i1.clamped(x + 1, y) - i1.clamped(x - 1, y)),
                0.5 * (i1.clamped(x, y + 1) - i1.clamped(x, y - 1)),
            ];
        }
    }
    g
}

/// Per pixel (ρ_c, I1x, I1y, |∇I1|²) of `I1` warped by `u` (glsl/flow/warp.comp):
/// `ρ(u) = ρ_c + ∇I1_w · u` linearises `I1(x + u) − I0(x)` around the current flow.
fn warp(i0: &Plane, i1: &Plane, g: &[[f64; 2]], u: &[[f64; 2]]) -> Vec<[f64; 4]> {
    let (w, h) = (i0.w, i0.h);
    let mut out = vec![[0.0; 4]; w * h];
    for y in 0..h {
        for x in 0..w {
            let o = y * w + x;
            let (qx, qy) = (x as f64 + u[o][0], y as f64 + u[o][1]);
            let i1w = bilinear(w, h, qx, qy, |k| i1.v[k]);
            let ix = bilinear(w, h, qx, qy, |k| g[k][0]);
            let iy = bilinear(w, h, qx, qy, |k| g[k][1]);
            let rho_c = i1w - ix * u[o][0] - iy * u[o][1] - i0.v[o];
            out[o] = [rho_c, ix, iy, ix * ix + iy * iy];
        }
    }
    out
}

/// Thresholding step plus the primal update at one pixel: `v` = argmin of the point-wise data
/// term, then `u = v + θ·div p` (glsl/flow/tvl1.comp: `u_step`).
#[allow(clippy::too_many_arguments)]
fn u_step(
    x: usize,
    y: usize,
    w: usize,
    h: usize,
    wd: &[[f64; 4]],
    u: &[[f64; 2]],
    p: &[[f64; 4]],
    lt: f64,
    theta: f64,
) -> [f64; 2] {
    let o = y * w + x;
    let [rho_c, ix, iy, grad] = wd[o];
    let rho = rho_c + ix * u[o][0] + iy * u[o][1];
    let d = if rho < -lt * grad {
        [lt * ix, lt * iy]
    } else if rho > lt * grad {
        [-lt * ix, -lt * iy]
    } else if grad > FLOW_GRAD_EPS as f64 {
        [-rho * ix / grad, -rho * iy / grad]
    } else {
        [0.0, 0.0]
    };
    // Divergence, the adjoint of the forward differences: p's x part counts only where
    // x < w − 1 and its y part only where y < h − 1.
    let px = |xx: usize, yy: usize, c: usize| if xx + 1 < w { p[yy * w + xx][c] } else { 0.0 };
    let py = |xx: usize, yy: usize, c: usize| if yy + 1 < h { p[yy * w + xx][c] } else { 0.0 };
    let mut div = [0.0; 2];
    for (k, dv) in div.iter_mut().enumerate() {
        let (cx, cy) = (2 * k, 2 * k + 1);
        let mut s = px(x, y, cx) + py(x, y, cy);
        if x > 0 {
            s -= px(x - 1, y, cx);
        }
        if y > 0 {
            s -= py(x, y - 1, cy);
        }
        *dv = s;
    }
    [
        u[o][0] + d[0] + theta * div[0],
        u[o][1] + d[1] + theta * div[1],
    ]
}

/// One TV-L1 iteration over the image: new u everywhere from (u, p), then the dual update of p
/// from the forward differences of the new u (glsl/flow/tvl1.comp does both in one dispatch).
fn iterate(
    w: usize,
    h: usize,
    wd: &[[f64; 4]],
    u: &mut Vec<[f64; 2]>,
    p: &mut Vec<[f64; 4]>,
    cfg: &FlowConfig,
) {
    let lt = cfg.lambda as f64 * cfg.theta as f64;
    let theta = cfg.theta as f64;
    let tt = cfg.tau as f64 / cfg.theta as f64;
    let mut un = vec![[0.0; 2]; w * h];
    for y in 0..h {
        for x in 0..w {
            un[y * w + x] = u_step(x, y, w, h, wd, u, p, lt, theta);
        }
    }
    let mut pn = vec![[0.0; 4]; w * h];
    for y in 0..h {
        for x in 0..w {
            let o = y * w + x;
            let mut q = [0.0; 4];
            for k in 0..2 {
                let gx = if x + 1 < w {
                    un[o + 1][k] - un[o][k]
                } else {
                    0.0
                };
                let gy = if y + 1 < h {
                    un[o + w][k] - un[o][k]
                } else {
                    0.0
                };
                let den = 1.0 + tt * (gx * gx + gy * gy).sqrt();
                q[2 * k] = (p[o][2 * k] + tt * gx) / den;
                q[2 * k + 1] = (p[o][2 * k + 1] + tt * gy) / den;
            }
            pn[o] = q;
        }
    }
    *u = un;
    *p = pn;
}

/// Bilinear ×2 upsampling of (u, p) from a coarse to a fine level; fine pixel `x` sits at
/// coarse `x/2` (the downsampling takes even pixels); u is scaled by 2, p is not
/// (glsl/flow/upsample.comp).
fn upsample(
    u: &[[f64; 2]],
    p: &[[f64; 4]],
    (wc, hc): (usize, usize),
    (wf, hf): (usize, usize),
) -> (Vec<[f64; 2]>, Vec<[f64; 4]>) {
    let mut uf = vec![[0.0; 2]; wf * hf];
    let mut pf = vec![[0.0; 4]; wf * hf];
    for y in 0..hf {
        for x in 0..wf {
            let (qx, qy) = (0.5 * x as f64, 0.5 * y as f64);
            let o = y * wf + x;
            for c in 0..2 {
                uf[o][c] = 2.0 * bilinear(wc, hc, qx, qy, |k| u[k][c]);
            }
            for c in 0..4 {
                pf[o][c] = bilinear(wc, hc, qx, qy, |k| p[k][c]);
            }
        }
    }
    (uf, pf)
}

/// Dense flow from `a` to `b` (both [H·W] RGBA in [0,1], alpha ignored): `a(x) ≈ b(x + flow(x))`,
/// in pixels, [H·W] (x, y). `cfg` must be valid ([`FlowConfig::validate`]); images with NaN are
/// the caller's bug (asserted in debug builds).
pub fn tvl1_flow(
    cfg: &FlowConfig,
    a: &[[f32; 4]],
    b: &[[f32; 4]],
    w: usize,
    h: usize,
) -> Vec<[f64; 2]> {
    assert!(
        w > 0 && h > 0 && a.len() == w * h && b.len() == w * h,
        "image shapes"
    );
    debug_assert!(
        a.iter()
            .chain(b)
            .all(|p| p[..3].iter().all(|v| v.is_finite())),
        "NaN/Inf in a flow input image"
    );
    let dims = pyramid_dims(cfg, w as u32, h as u32);
    assert!(
        (cfg.finest as usize) < dims.len(),
        "finest below the levels"
    );
    let (mut g0, mut g1) = (blurred(&grey(a, w, h), cfg.blur_a), grey(b, w, h));
    if cfg.texture > 0.0 {
        (g0, g1) = (
            texture(&g0, cfg.texture as f64),
            texture(&g1, cfg.texture as f64),
        );
    }
    let mut i0 = vec![g0];
    let mut i1 = vec![g1];
    for &(lw, lh) in &dims[1..] {
        let (lw, lh) = (lw as usize, lh as usize);
        let n0 = downsample(i0.last().unwrap(), lw, lh);
        let n1 = downsample(i1.last().unwrap(), lw, lh);
        i0.push(n0);
        i1.push(n1);
    }
    let top = dims.len() - 1;
    let (cw, ch) = (dims[top].0 as usize, dims[top].1 as usize);
    let mut u = vec![[0.0; 2]; cw * ch];
    let mut p = vec![[0.0; 4]; cw * ch];
    for l in (0..=top).rev() {
        let (lw, lh) = (dims[l].0 as usize, dims[l].1 as usize);
        if l < top {
            let c = (dims[l + 1].0 as usize, dims[l + 1].1 as usize);
            (u, p) = upsample(&u, &p, c, (lw, lh));
        }
        if l < cfg.finest as usize {
            continue; // below the finest solved level: upsampling only
        }
        let g = gradient(&i1[l]);
        for _ in 0..cfg.warps {
            let wd = warp(&i0[l], &i1[l], &g, &u);
            for _ in 0..cfg.iterations {
                iterate(lw, lh, &wd, &mut u, &mut p, cfg);
            }
        }
    }
    u
}
