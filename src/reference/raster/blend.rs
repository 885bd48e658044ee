//! Twin of `glsl/raster/blend_fwd.comp` and `glsl/raster/blend_bwd.comp`: front-to-back alpha
//! blending of the depth-sorted Gaussians whose tile rectangle holds the pixel's tile.
//!
//! Brute force: every pixel walks every visible Gaussian in order of increasing depth (ties by
//! index) and keeps those whose `tile_rect` contains its tile — the same list, in the same
//! order, as the pixel's tile list after binning and sorting.

use std::hash::{Hash, Hasher};

use super::{BlendGrads, BlendOut, BlendParams, Projected, Projected64, ALPHA_MIN, TILE, T_MIN};

/// f64 counterpart of [`BlendOut`], from [`blend_fwd_f64`].
#[derive(Clone, Debug, Default)]
pub struct BlendOut64 {
    pub rgb: Vec<[f64; 3]>,
    pub alpha: Vec<f64>,
    pub depth: Vec<f64>,
    pub features: Vec<f64>,
    pub final_t: Vec<f64>,
    pub n_contrib: Vec<u32>,
    /// Hash of every discrete decision of the blend (per pixel and considered Gaussian: σ < 0
    /// clamped to 0, skipped for α < 1/255, blended, blended with α clamped, stop). Equal signatures
    /// mean the same smooth piece; used by finite-difference tests to detect straddles.
    pub signature: u64,
}

/// One Gaussian blended at a pixel, with what the backward needs.
struct Blended {
    i: usize,
    /// exp(−σ), α, transmittance before this Gaussian, whether α hit `alpha_max`.
    gauss: f64,
    alpha: f64,
    t: f64,
    clamped: bool,
    dx: f64,
    dy: f64,
}

/// Visible Gaussians sorted by (depth, index).
fn depth_order(proj: &Projected64) -> Vec<usize> {
    let mut order: Vec<usize> = (0..proj.len()).filter(|&i| proj.radius[i] > 0).collect();
    order.sort_by(|&a, &b| proj.depth[a].total_cmp(&proj.depth[b]).then(a.cmp(&b)));
    order
}

/// Walks pixel (px, py): the blended Gaussians, final T and n_contrib.
fn walk_pixel(
    p: &BlendParams,
    proj: &Projected64,
    order: &[usize],
    px: u32,
    py: u32,
    sig: &mut impl Hasher,
) -> (Vec<Blended>, f64, u32) {
    let (tx, ty) = (px / TILE, py / TILE);
    let (cx, cy) = (px as f64 + 0.5, py as f64 + 0.5);
    let alpha_max = p.alpha_max as f64;
    let mut list = Vec::new();
    let mut t = 1.0;
    let mut n_contrib = 0;
    let mut position = 0u32;
    for &i in order {
        let r = proj.tile_rect[i];
        if !(r[0] <= tx && tx < r[2] && r[1] <= ty && ty < r[3]) {
            continue;
        }
        position += 1;
        let [a, b, c] = proj.conic[i];
        let dx = proj.mean2d[i][0] - cx;
        let dy = proj.mean2d[i][1] - cy;
        // σ ≥ 0 for a positive-definite conic: a negative value is rounding of a near-singular
        // one (a needle on its own spine) and is blended as σ = 0, its gradient passed through.
        let sigma_raw = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy;
        let sigma = sigma_raw.max(0.0);
        if sigma_raw < 0.0 {
            (i, 0u8).hash(sig);
        }
        let gauss = (-sigma).exp();
        let raw = proj.opacity[i] * gauss;
        let clamped = raw > alpha_max;
        let alpha = if clamped { alpha_max } else { raw };
        if alpha < ALPHA_MIN {
            (i, 1u8).hash(sig);
            continue;
        }
        let test_t = t * (1.0 - alpha);
        if test_t < T_MIN {
            (i, 2u8).hash(sig);
            break;
        }
        (i, 3u8, clamped).hash(sig);
        list.push(Blended {
            i,
            gauss,
            alpha,
            t,
            clamped,
            dx,
            dy,
        });
        t = test_t;
        n_contrib = position;
    }
    (list, t, n_contrib)
}

fn check_inputs(p: &BlendParams, proj: &Projected64, features: usize) {
    let n = proj.len();
    assert_eq!(proj.conic.len(), n, "blend: conic.len() != N");
    assert_eq!(proj.depth.len(), n, "blend: depth.len() != N");
    assert_eq!(proj.radius.len(), n, "blend: radius.len() != N");
    assert_eq!(proj.tile_rect.len(), n, "blend: tile_rect.len() != N");
    assert_eq!(proj.color.len(), n, "blend: color.len() != N");
    assert_eq!(proj.opacity.len(), n, "blend: opacity.len() != N");
    assert_eq!(
        features,
        n * p.feature_dims as usize,
        "blend: features.len() != N * feature_dims"
    );
}

/// Blends every pixel (see the module docs). `features` is `[N][K]`, K = `p.feature_dims`.
/// Per pixel: `d = mean2d − (px+0.5, py+0.5)`, `σ = max(½(a dx² + c dy²) + b dx dy, 0)`,
/// `α = min(alpha_max, o·exp(−σ))` (skip if < 1/255), stop without blending if `T(1−α) < 1e-4`,
/// else `w = αT` weights colour, depth and features and `T ← T(1−α)`; finally `rgb += T·bg`.
pub fn blend_fwd(p: &BlendParams, proj: &Projected, features: &[f32]) -> BlendOut {
    let f64s: Vec<f64> = features.iter().map(|&x| x as f64).collect();
    let o = blend_fwd_f64(p, &Projected64::from_f32(proj), &f64s);
    BlendOut {
        rgb: o.rgb.iter().map(|a| a.map(|x| x as f32)).collect(),
        alpha: o.alpha.iter().map(|&x| x as f32).collect(),
        depth: o.depth.iter().map(|&x| x as f32).collect(),
        features: o.features.iter().map(|&x| x as f32).collect(),
        final_t: o.final_t.iter().map(|&x| x as f32).collect(),
        n_contrib: o.n_contrib,
    }
}

/// [`blend_fwd`] in f64 without rounding.
pub fn blend_fwd_f64(p: &BlendParams, proj: &Projected64, features: &[f64]) -> BlendOut64 {
    check_inputs(p, proj, features.len());
    let k = p.feature_dims as usize;
    let npix = (p.width * p.height) as usize;
    let bg = p.background.map(f64::from);
    let order = depth_order(proj);
    let mut out = BlendOut64 {
        rgb: vec![[0.0; 3]; npix],
        alpha: vec![0.0; npix],
        depth: vec![0.0; npix],
        features: vec![0.0; npix * k],
        final_t: vec![0.0; npix],
        n_contrib: vec![0; npix],
        signature: 0,
    };
    let mut sig = std::collections::hash_map::DefaultHasher::new();
    for py in 0..p.height {
        for px in 0..p.width {
            let pix = (py * p.width + px) as usize;
            let (list, t, n_contrib) = walk_pixel(p, proj, &order, px, py, &mut sig);
            let mut rgb = [0.0; 3];
            let mut depth = 0.0;
            for e in &list {
                let w = e.alpha * e.t;
                for c in 0..3 {
                    rgb[c] += w * proj.color[e.i][c];
                }
                depth += w * proj.depth[e.i];
                for f in 0..k {
                    out.features[pix * k + f] += w * features[e.i * k + f];
                }
            }
            for c in 0..3 {
                rgb[c] += t * bg[c];
            }
            out.rgb[pix] = rgb;
            out.alpha[pix] = 1.0 - t;
            out.depth[pix] = depth;
            out.final_t[pix] = t;
            out.n_contrib[pix] = n_contrib;
        }
    }
    out.signature = sig.finish();
    out
}

/// Exact reverse-mode derivative of [`blend_fwd`] for the upstream gradients `d_rgb`, `d_alpha`,
/// `d_depth` (`[H·W]`) and `d_features` (`[H·W][K]`); an empty upstream slice means zero.
/// Skip/stop decisions and the `alpha_max` clamp are held fixed (where α was clamped, its
/// gradient wrt opacity and σ is 0). `fwd` must be `blend_fwd(p, proj, features)`; the twin
/// recomputes the per-pixel lists in f64 from `proj` and only checks `fwd`'s shape.
#[allow(clippy::too_many_arguments)]
pub fn blend_bwd(
    p: &BlendParams,
    proj: &Projected,
    features: &[f32],
    fwd: &BlendOut,
    d_rgb: &[[f32; 3]],
    d_alpha: &[f32],
    d_depth: &[f32],
    d_features: &[f32],
) -> BlendGrads {
    let npix = (p.width * p.height) as usize;
    assert_eq!(
        fwd.final_t.len(),
        npix,
        "blend_bwd: fwd is for another image size"
    );
    assert_eq!(
        fwd.n_contrib.len(),
        npix,
        "blend_bwd: fwd is for another image size"
    );
    let f64s: Vec<f64> = features.iter().map(|&x| x as f64).collect();
    blend_bwd_f64(
        p,
        &Projected64::from_f32(proj),
        &f64s,
        d_rgb,
        d_alpha,
        d_depth,
        d_features,
    )
}

/// [`blend_bwd`] on the f64 pipeline; the upstream gradients may be f32 (as the GPU holds them)
/// or f64.
pub fn blend_bwd_f64<T: Copy + Into<f64>>(
    p: &BlendParams,
    proj: &Projected64,
    features: &[f64],
    d_rgb: &[[T; 3]],
    d_alpha: &[T],
    d_depth: &[T],
    d_features: &[T],
) -> BlendGrads {
    check_inputs(p, proj, features.len());
    let n = proj.len();
    let k = p.feature_dims as usize;
    let npix = (p.width * p.height) as usize;
    for (name, len, want) in [
        ("d_rgb", d_rgb.len(), npix),
        ("d_alpha", d_alpha.len(), npix),
        ("d_depth", d_depth.len(), npix),
        ("d_features", d_features.len(), npix * k),
    ] {
        assert!(
            len == 0 || len == want,
            "blend_bwd: {name}.len() = {len}, expected 0 or {want}"
        );
    }
    let up = |v: &[T], i: usize| v.get(i).map_or(0.0, |&x| x.into());
    let bg = p.background.map(f64::from);
    let order = depth_order(proj);
    let mut g = BlendGrads {
        mean2d: vec![[0.0; 2]; n],
        mean2d_abs: vec![[0.0; 2]; n],
        conic: vec![[0.0; 3]; n],
        opacity: vec![0.0; n],
        opacity_features: vec![0.0; n],
        color: vec![[0.0; 3]; n],
        depth: vec![0.0; n],
        features: vec![0.0; n * k],
    };
    let mut sig = std::collections::hash_map::DefaultHasher::new();
    for py in 0..p.height {
        for px in 0..p.width {
            let pix = (py * p.width + px) as usize;
            let (list, _, _) = walk_pixel(p, proj, &order, px, py, &mut sig);
            let drgb: [f64; 3] =
                std::array::from_fn(|c| d_rgb.get(pix).map_or(0.0, |v| v[c].into()));
            let dalpha = up(d_alpha, pix);
            let ddepth = up(d_depth, pix);
            // rgb += T_final·bg, alpha = 1 − T_final.
            let mut dt = drgb[0] * bg[0] + drgb[1] * bg[1] + drgb[2] * bg[2] - dalpha;
            let mut dt_f = 0.0; // features have no background layer
            for e in list.iter().rev() {
                let i = e.i;
                let w = e.alpha * e.t;
                // dL/dw and the direct parameter gradients.
                let mut dw = ddepth * proj.depth[i];
                for c in 0..3 {
                    dw += drgb[c] * proj.color[i][c];
                    g.color[i][c] += w * drgb[c];
                }
                g.depth[i] += w * ddepth;
                // The features' share of dL/dw and of the "behind" term dt, kept apart for
                // `opacity_features` (dt is linear in the upstream gradients).
                let mut dw_f = 0.0;
                for f in 0..k {
                    let df = up(d_features, pix * k + f);
                    dw_f += df * features[i * k + f];
                    g.features[i * k + f] += w * df;
                }
                dw += dw_f;
                // T_next = T(1−α), w = αT.
                let dalpha_i = e.t * dw - e.t * dt;
                let dalpha_f = e.t * dw_f - e.t * dt_f;
                dt = (1.0 - e.alpha) * dt + e.alpha * dw;
                dt_f = (1.0 - e.alpha) * dt_f + e.alpha * dw_f;
                if e.clamped {
                    continue;
                }
                // α = o·exp(−σ).
                g.opacity[i] += dalpha_i * e.gauss;
                g.opacity_features[i] += dalpha_f * e.gauss;
                let dsigma = -dalpha_i * e.alpha;
                let [a, b, c] = proj.conic[i];
                g.conic[i][0] += dsigma * 0.5 * e.dx * e.dx;
                g.conic[i][1] += dsigma * e.dx * e.dy;
                g.conic[i][2] += dsigma * 0.5 * e.dy * e.dy;
                let gm = [
                    dsigma * (a * e.dx + b * e.dy),
                    dsigma * (b * e.dx + c * e.dy),
                ];
                for j in 0..2 {
                    g.mean2d[i][j] += gm[j];
                    g.mean2d_abs[i][j] += gm[j].abs();
                }
            }
        }
    }
    g
}
