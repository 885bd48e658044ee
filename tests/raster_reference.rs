//! The rasteriser's CPU twin (`reference::raster`) against an external oracle (gsplat), against
//! finite differences of itself, at the numerical extremes, and on hand-checkable scenes.

use std::collections::HashMap;
use std::path::PathBuf;

use dispflow_vk::reference::raster::{
    blend_bwd, blend_bwd_f64, blend_fwd, blend_fwd_f64, project, project_bwd, project_bwd_f64,
    project_f64, radius_rect, sigmoid, BlendGrads, BlendOut, BlendParams, Camera, Gaussians,
    Gaussians64, ProjectGrads, Projected,
};
use dispflow_vk::reference::sh;
use dispflow_vk::testing::{assert_close, Tol};
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64;

// ---------------------------------------------------------------------------------------------
// Helpers

/// An owned scene: camera, raw Gaussian parameters, per-Gaussian features, blend parameters.
#[derive(Clone)]
struct Scene {
    cam: Camera,
    means: Vec<[f32; 3]>,
    scales: Vec<[f32; 3]>,
    quats: Vec<[f32; 4]>,
    logits: Vec<f32>,
    sh: Vec<f32>,
    sh_coeffs: u32,
    sh_degree: u32,
    features: Vec<f32>,
    params: BlendParams,
}

impl Scene {
    fn empty(cam: Camera, sh_coeffs: u32, sh_degree: u32) -> Self {
        Scene {
            cam,
            means: vec![],
            scales: vec![],
            quats: vec![],
            logits: vec![],
            sh: vec![],
            sh_coeffs,
            sh_degree,
            features: vec![],
            params: BlendParams::new(cam.width, cam.height),
        }
    }

    /// Adds a Gaussian with degree-0 colour `rgb` (the SH DC term is set so that
    /// `C0·k + 0.5 = rgb`; higher coefficients zero) and zero features.
    fn push(&mut self, mean: [f32; 3], scale: [f32; 3], quat: [f32; 4], logit: f32, rgb: [f32; 3]) {
        self.means.push(mean);
        self.scales.push(scale);
        self.quats.push(quat);
        self.logits.push(logit);
        for k in 0..self.sh_coeffs {
            for &col in &rgb {
                let v = if k == 0 {
                    ((col as f64 - 0.5) / sh::C0) as f32
                } else {
                    0.0
                };
                self.sh.push(v);
            }
        }
        for _ in 0..self.params.feature_dims {
            self.features.push(0.0);
        }
    }

    fn g(&self) -> Gaussians<'_> {
        Gaussians {
            means: &self.means,
            scales: &self.scales,
            quats: &self.quats,
            opacity_logits: &self.logits,
            sh: &self.sh,
            sh_coeffs: self.sh_coeffs,
            sh_degree: self.sh_degree,
        }
    }

    fn npix(&self) -> usize {
        (self.params.width * self.params.height) as usize
    }

    fn render(&self) -> (Projected, BlendOut) {
        let proj = project(&self.cam, &self.g());
        let out = blend_fwd(&self.params, &proj, &self.features);
        (proj, out)
    }

    /// Forward, then backward for the given upstream gradients.
    fn grads(&self, up: &Upstream) -> (Projected, BlendOut, BlendGrads, ProjectGrads) {
        let (proj, out) = self.render();
        let bg = blend_bwd(
            &self.params,
            &proj,
            &self.features,
            &out,
            &up.rgb,
            &up.alpha,
            &up.depth,
            &up.features,
        );
        let pg = project_bwd(&self.cam, &self.g(), &proj, &bg);
        (proj, out, bg, pg)
    }
}

/// Upstream gradients (weights of the scalar loss), f32 as a GPU would hold them.
struct Upstream {
    rgb: Vec<[f32; 3]>,
    alpha: Vec<f32>,
    depth: Vec<f32>,
    features: Vec<f32>,
}

impl Upstream {
    fn random(rng: &mut Pcg64, npix: usize, k: usize) -> Self {
        let mut u = || rng.gen_range(-1.0f32..1.0);
        Upstream {
            rgb: (0..npix).map(|_| [u(), u(), u()]).collect(),
            alpha: (0..npix).map(|_| u()).collect(),
            depth: (0..npix).map(|_| 0.1 * u()).collect(),
            features: (0..npix * k).map(|_| u()).collect(),
        }
    }
}

fn identity_camera(width: u32, height: u32, f: f32) -> Camera {
    Camera {
        rot: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        trans: [0.0; 3],
        fx: f,
        fy: f,
        cx: width as f32 / 2.0,
        cy: height as f32 / 2.0,
        width,
        height,
        near: 0.01,
    }
}

const IDQ: [f32; 4] = [1.0, 0.0, 0.0, 0.0];

/// Every forward output and gradient is finite.
fn assert_all_finite(what: &str, out: &BlendOut, bg: &BlendGrads, pg: &ProjectGrads) {
    let f32s = out
        .rgb
        .iter()
        .flatten()
        .chain(&out.alpha)
        .chain(&out.depth)
        .chain(&out.features)
        .chain(&out.final_t);
    for x in f32s {
        assert!(x.is_finite(), "{what}: non-finite forward output {x}");
    }
    let grads = bg
        .mean2d
        .iter()
        .flatten()
        .chain(bg.conic.iter().flatten())
        .chain(&bg.opacity)
        .chain(bg.color.iter().flatten())
        .chain(&bg.depth)
        .chain(&bg.features)
        .chain(pg.means.iter().flatten())
        .chain(pg.scales.iter().flatten())
        .chain(pg.quats.iter().flatten())
        .chain(&pg.opacity_logits)
        .chain(&pg.sh);
    for x in grads {
        assert!(x.is_finite(), "{what}: non-finite gradient {x}");
    }
}

// ---------------------------------------------------------------------------------------------
// 1. gsplat oracle

fn gsplat_dir() -> Option<PathBuf> {
    let d = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/data/gsplat-reference"
    ));
    if d.is_dir() {
        Some(d)
    } else {
        dispflow_vk::testing::skip(
            "the gsplat reference cases",
            &format!("{} is absent", d.display()),
        );
        None
    }
}

/// All tensors of a safetensors file as (shape, f32 values).
fn load_tensors(path: &std::path::Path) -> HashMap<String, (Vec<usize>, Vec<f32>)> {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let st = safetensors::SafeTensors::deserialize(&bytes)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    st.tensors()
        .into_iter()
        .map(|(name, t)| {
            assert_eq!(t.dtype(), safetensors::Dtype::F32, "{name}: expected f32");
            let v = t
                .data()
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect();
            (name, (t.shape().to_vec(), v))
        })
        .collect()
}

fn gsplat_case(name: &str) {
    let Some(dir) = gsplat_dir() else { return };
    let t = load_tensors(&dir.join(format!("{name}.safetensors")));
    let get = |k: &str| -> &Vec<f32> { &t.get(k).unwrap_or_else(|| panic!("{name}: no {k}")).1 };
    let n = t["means"].0[0];
    let (w, h) = (123u32, 82u32);
    assert_eq!(t["out_img"].0, vec![h as usize, w as usize, 4]);
    let cam = Camera {
        rot: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        trans: [-0.123, -0.456, 8.0],
        fx: 61.5,
        fy: 61.5,
        cx: 61.5,
        cy: 41.0,
        width: w,
        height: h,
        near: 0.01,
    };
    let v3 = |v: &[f32]| -> Vec<[f32; 3]> { v.chunks(3).map(|c| [c[0], c[1], c[2]]).collect() };
    let means = v3(get("means"));
    let log_scales = v3(get("scales"));
    let scales: Vec<[f32; 3]> = log_scales.iter().map(|s| s.map(f32::exp)).collect();
    let quats: Vec<[f32; 4]> = get("quats")
        .chunks(4)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect();
    let g = Gaussians {
        means: &means,
        scales: &scales,
        quats: &quats,
        opacity_logits: get("opacities"),
        sh: get("coeffs"),
        sh_coeffs: 16,
        sh_degree: 3,
    };
    assert_eq!(g.sh.len(), n * 48);
    let params = BlendParams {
        width: w,
        height: h,
        alpha_max: 0.999,
        background: [0.0; 3],
        feature_dims: 0,
    };
    let proj = project(&cam, &g);
    let wide = |v: &[f32]| -> Vec<f64> { v.iter().map(|&x| x as f64).collect() };
    assert!(
        proj.radius.iter().all(|&r| r > 0),
        "{name}: a Gaussian was culled"
    );

    // Projection: gsplat computes in f32, so agreement is to f32 rounding of the operations
    // (|xy| ≤ ~150 px: a few ulp ≈ 1e-5; conics go through a 2×2 inverse: rel 1e-5).
    let xys: Vec<f64> = proj.mean2d.iter().flatten().map(|&x| x as f64).collect();
    assert_close(
        &format!("{name} xys"),
        &xys,
        &wide(get("xys")),
        Tol::Elementwise {
            abs: 1e-4,
            rel: 1e-6,
        },
    );
    let conics: Vec<f64> = proj.conic.iter().flatten().map(|&x| x as f64).collect();
    assert_close(
        &format!("{name} conics"),
        &conics,
        &wide(get("conics")),
        Tol::Elementwise {
            abs: 1e-7,
            rel: 1e-5,
        },
    );
    assert_close(
        &format!("{name} depths"),
        &wide(&proj.depth),
        &wide(get("depths")),
        Tol::Elementwise {
            abs: 1e-6,
            rel: 1e-6,
        },
    );

    // Forward image: RGB + accumulated alpha, to ~1e-5 (README: an f64 re-implementation
    // agreed to < 5e-6).
    let out = blend_fwd(&params, &proj, &[]);
    let mut img = Vec::with_capacity(out.rgb.len() * 4);
    for (rgb, a) in out.rgb.iter().zip(&out.alpha) {
        img.extend(rgb.iter().map(|&x| x as f64));
        img.push(*a as f64);
    }
    assert_close(
        &format!("{name} out_img"),
        &img,
        &wide(get("out_img")),
        Tol::Elementwise {
            abs: 1e-5,
            rel: 0.0,
        },
    );

    // Backward with v_out_img as the upstream gradient.
    let v_out = get("v_out_img");
    let d_rgb: Vec<[f32; 3]> = v_out.chunks(4).map(|c| [c[0], c[1], c[2]]).collect();
    let d_alpha: Vec<f32> = v_out.chunks(4).map(|c| c[3]).collect();
    let bg = blend_bwd(&params, &proj, &[], &out, &d_rgb, &d_alpha, &[], &[]);
    let pg = project_bwd(&cam, &g, &proj, &bg);

    // Stored gradients are rounded to ~4 significant digits: rel 1e-3, abs 1e-7 (README).
    let (rel, abs) = (1e-3, 1e-7);
    let chk = |what: &str, got: Vec<f64>, key: &str| {
        let want = wide(get(key));
        // The comparison must not be vacuous (all values below the absolute tolerance).
        let big = want.iter().filter(|w| w.abs() > 100.0 * abs).count();
        assert!(
            big * 2 > want.len(),
            "{name} {key}: mostly tiny reference values"
        );
        assert_close(
            &format!("{name} {what}"),
            &got,
            &want,
            Tol::Elementwise { abs, rel },
        )
    };
    // gsplat's v_xy and v_conics use the same conventions as BlendGrads: d = mean2d − pixel
    // centre and σ = ½(a dx² + c dy²) + b dx dy, so they compare without conversion.
    chk(
        "v_xy",
        bg.mean2d.iter().flatten().copied().collect(),
        "v_xy",
    );
    chk(
        "v_conics",
        bg.conic.iter().flatten().copied().collect(),
        "v_conics",
    );
    chk(
        "v_means",
        pg.means.iter().flatten().copied().collect(),
        "v_means",
    );
    // gsplat's scales are log-scales: d/d(log s) = s · d/ds.
    let v_log_scales = pg
        .scales
        .iter()
        .zip(&scales)
        .flat_map(|(d, s)| [0, 1, 2].map(|k| d[k] * s[k] as f64))
        .collect();
    chk("v_scales", v_log_scales, "v_scales");
    chk(
        "v_quats",
        pg.quats.iter().flatten().copied().collect(),
        "v_quats",
    );
    chk("v_opacities", pg.opacity_logits.clone(), "v_opacities");
    chk("v_coeffs", pg.sh.clone(), "v_coeffs");
}

#[test]
fn gsplat_tiny_case() {
    gsplat_case("tiny_case");
}

#[test]
fn gsplat_basic_case() {
    gsplat_case("basic_case");
}

// ---------------------------------------------------------------------------------------------
// 2. Finite differences of the whole f64 pipeline

use dispflow_vk::testing::rot_from_angles;

/// A random scene seen by a rotated, off-centre camera. Gaussian 0 lies beyond the Jacobian's
/// x clamp, Gaussian 1 beyond its y clamp (both large enough to reach into the image), and
/// Gaussian 2 has its red channel clamped at 0 by `max(SH + 0.5, 0)`.
fn random_scene(seed: u64, w: u32, h: u32, n: usize, k: u32, sh_coeffs: u32, deg: u32) -> Scene {
    let mut rng = Pcg64::seed_from_u64(seed);
    let rot = rot_from_angles([0.2, -0.15, 0.1].map(|a| a * rng.gen_range(-1.0..1.0)));
    let centre = [0.3, -0.2, -4.0];
    let mut trans = [0.0f32; 3];
    for i in 0..3 {
        trans[i] = -(0..3).map(|j| rot[i][j] * centre[j]).sum::<f64>() as f32;
    }
    let rot32 = rot.map(|r| r.map(|x| x as f32));
    let (fx, fy) = (0.9 * w as f32, 0.95 * w as f32);
    let cam = Camera {
        rot: rot32,
        trans,
        fx,
        fy,
        cx: 0.45 * w as f32,
        cy: 0.55 * h as f32,
        width: w,
        height: h,
        near: 0.01,
    };
    let lim_x_pos = (w as f32 - cam.cx) / fx + 0.3 * 0.5 * w as f32 / fx;
    let lim_y_neg = cam.cy / fy + 0.3 * 0.5 * h as f32 / fy;
    let mut s = Scene::empty(cam, sh_coeffs, deg);
    s.params = BlendParams {
        width: w,
        height: h,
        alpha_max: 0.99,
        background: [0.1, 0.2, 0.3],
        feature_dims: k,
    };
    let world = |pc: [f64; 3]| -> [f32; 3] {
        // mean = rotᵀ (p_cam − trans)
        std::array::from_fn(|j| {
            (0..3)
                .map(|i| rot32[i][j] as f64 * (pc[i] - trans[i] as f64))
                .sum::<f64>() as f32
        })
    };
    // Gaussians 3, 4, 5 are stacked on one line of sight: 3 and 5 nearly opaque (α clamped to
    // alpha_max near their centres), so pixels there stop at 5 (T < 1e-4).
    let stack = (0.1 * w as f64 / fx as f64, -0.05 * h as f64 / fy as f64);
    for i in 0..n {
        let mut z: f64 = rng.gen_range(2.5..5.0);
        let (xz, yz, scale) = match i {
            0 => (1.25 * lim_x_pos as f64, 0.0, 0.9),
            1 => (0.0, -1.2 * lim_y_neg as f64, 0.9),
            3..=5 => {
                z = 2.0 + 0.4 * i as f64;
                (stack.0, stack.1, 0.5)
            }
            _ => (
                rng.gen_range(-0.45..0.45) * w as f64 / fx as f64,
                rng.gen_range(-0.45..0.45) * h as f64 / fy as f64,
                rng.gen_range(0.06..0.3),
            ),
        };
        s.means.push(world([xz * z, yz * z, z]));
        s.scales.push(std::array::from_fn(|_| {
            (scale * rng.gen_range(0.5..1.5)) as f32
        }));
        let q: [f32; 4] = loop {
            let q = std::array::from_fn(|_| rng.gen_range(-1.0f32..1.0));
            if q.iter().map(|v| v * v).sum::<f32>() > 0.1 {
                break q;
            }
        };
        s.quats.push(q);
        s.logits.push(match i {
            3 | 5 => 9.0,
            4 => 1.5,
            _ => rng.gen_range(-1.5..2.0),
        });
        for kk in 0..sh_coeffs {
            for c in 0..3 {
                let v = if kk == 0 {
                    if i == 2 && c == 0 {
                        -3.0
                    } else {
                        rng.gen_range(-0.6..0.6)
                    }
                } else {
                    rng.gen_range(-0.25..0.25)
                };
                s.sh.push(v);
            }
        }
        for _ in 0..k {
            s.features.push(rng.gen_range(-1.0..1.0));
        }
    }
    s
}

/// L = Σ_p u_rgb·rgb + u_a·alpha + u_d·depth + u_f·features on the unrounded pipeline, and the
/// signature of every discrete decision taken on the way. With `colors`, the projected colours
/// are replaced by those given: the view direction is detached by definition, so finite
/// differences wrt the means hold the colours (a function of the means only through that
/// direction) at their unperturbed values.
fn fd_loss(
    s: &Scene,
    g: &Gaussians64,
    feats: &[f64],
    up: &Upstream,
    colors: Option<&[[f64; 3]]>,
) -> (f64, (u64, u64)) {
    let mut proj = project_f64(&s.cam, g);
    if let Some(c) = colors {
        for (i, dst) in proj.color.iter_mut().enumerate() {
            if proj.radius[i] > 0 {
                *dst = c[i];
            }
        }
    }
    let out = blend_fwd_f64(&s.params, &proj, feats);
    let mut l = 0.0;
    for p in 0..out.rgb.len() {
        for c in 0..3 {
            l += up.rgb[p][c] as f64 * out.rgb[p][c];
        }
        l += up.alpha[p] as f64 * out.alpha[p] + up.depth[p] as f64 * out.depth[p];
    }
    for (u, f) in up.features.iter().zip(&out.features) {
        l += *u as f64 * f;
    }
    (l, (proj.signature, out.signature))
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Kind {
    Means,
    Scales,
    Quats,
    Logits,
    Sh,
    Features,
}

fn param<'a>(g: &'a mut Gaussians64, f: &'a mut [f64], kind: Kind, j: usize) -> &'a mut f64 {
    match kind {
        Kind::Means => &mut g.means[j / 3][j % 3],
        Kind::Scales => &mut g.scales[j / 3][j % 3],
        Kind::Quats => &mut g.quats[j / 4][j % 4],
        Kind::Logits => &mut g.opacity_logits[j],
        Kind::Sh => &mut g.sh[j],
        Kind::Features => &mut f[j],
    }
}

/// Analytic gradients (blend_bwd_f64 ∘ project_bwd_f64) vs central differences (h = 1e-6) for
/// every scalar parameter. A parameter whose ±h evaluation changes any discrete decision
/// (culling, tile rect, Jacobian or colour clamp, α < 1/255 skip, α clamp, T stop) straddles a
/// threshold, where FD is meaningless: it is skipped and counted, and at most 2% may be.
fn check_fd(s: &Scene, up_seed: u64) {
    let mut rng = Pcg64::seed_from_u64(up_seed);
    let k = s.params.feature_dims as usize;
    let up = Upstream::random(&mut rng, s.npix(), k);
    let g = Gaussians64::from_f32(&s.g());
    let feats: Vec<f64> = s.features.iter().map(|&x| x as f64).collect();

    let proj = project_f64(&s.cam, &g);
    let visible = proj.radius.iter().filter(|&&r| r > 0).count();
    assert!(
        visible + 1 >= g.len(),
        "scene: {visible} of {} visible",
        g.len()
    );
    let bg = blend_bwd_f64(
        &s.params,
        &proj,
        &feats,
        &up.rgb,
        &up.alpha,
        &up.depth,
        &up.features,
    );
    let pg = project_bwd_f64(&s.cam, &g, &bg);
    // The clamped cases must really be exercised: Gaussians 0 and 1 (beyond the Jacobian clamp)
    // contribute, Gaussian 2's red SH coefficients get exactly zero gradient.
    for i in [0, 1] {
        assert!(
            pg.means[i].iter().any(|v| v.abs() > 1e-6),
            "Gaussian {i} does not contribute"
        );
    }
    let nc = s.sh_coeffs as usize;
    for kk in 0..nc {
        assert_eq!(
            pg.sh[(2 * nc + kk) * 3],
            0.0,
            "clamped red channel has a gradient"
        );
    }

    // The α clamp must be engaged somewhere (α of Gaussian 3 at some pixel centre).
    let n_clamped = (0..s.npix())
        .filter(|&pix| {
            let (px, py) = (pix as u32 % s.params.width, pix as u32 / s.params.width);
            let [a, b, c] = proj.conic[3];
            let dx = proj.mean2d[3][0] - (px as f64 + 0.5);
            let dy = proj.mean2d[3][1] - (py as f64 + 0.5);
            let sigma = 0.5 * (a * dx * dx + c * dy * dy) + b * dx * dy;
            proj.opacity[3] * (-sigma).exp() > s.params.alpha_max as f64
        })
        .count();
    assert!(n_clamped > 0, "alpha_max clamp not exercised");

    let (l0, sig0) = fd_loss(s, &g, &feats, &up, None);
    let h = 1e-6;
    let kinds: [(Kind, Vec<f64>); 6] = [
        (Kind::Means, pg.means.iter().flatten().copied().collect()),
        (Kind::Scales, pg.scales.iter().flatten().copied().collect()),
        (Kind::Quats, pg.quats.iter().flatten().copied().collect()),
        (Kind::Logits, pg.opacity_logits.clone()),
        (Kind::Sh, pg.sh.clone()),
        (Kind::Features, bg.features.clone()),
    ];
    let (mut total, mut skipped) = (0usize, 0usize);
    for (kind, analytic) in kinds {
        let scale = analytic.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let (mut fd, mut an) = (vec![], vec![]);
        for (j, &a) in analytic.iter().enumerate() {
            let eval = |delta: f64| {
                let (mut g2, mut f2) = (g.clone(), feats.clone());
                *param(&mut g2, &mut f2, kind, j) += delta;
                let detach = (kind == Kind::Means).then_some(&proj.color[..]);
                fd_loss(s, &g2, &f2, &up, detach)
            };
            let ((lp, sp), (lm, sm)) = (eval(h), eval(-h));
            total += 1;
            if sp != sig0 || sm != sig0 {
                skipped += 1;
                continue;
            }
            fd.push((lp - lm) / (2.0 * h));
            an.push(a);
        }
        if analytic.is_empty() {
            assert!(kind == Kind::Features && k == 0);
            continue;
        }
        assert!(!an.is_empty(), "{kind:?}: nothing checked");
        if kind != Kind::Features || k > 0 {
            assert!(
                scale > 1e-3,
                "{kind:?}: gradient is vacuous (max {scale:e})"
            );
        }
        // FD error: rounding ≈ 1e-16·|L|/h plus truncation O(h²); both ≪ 1e-6·(1 + |L|).
        let abs = 1e-7 * (1.0 + l0.abs());
        assert_close(
            &format!("FD {kind:?} seed {up_seed}"),
            &an,
            &fd,
            Tol::Elementwise { abs, rel: 1e-5 },
        );
    }
    eprintln!("FD seed {up_seed}: {total} parameters, {skipped} skipped as straddling");
    assert!(
        skipped * 50 <= total,
        "{skipped} of {total} parameters straddle a threshold"
    );
}

#[test]
fn fd_small_image_sh0_no_features() {
    check_fd(&random_scene(1, 17, 13, 8, 0, 1, 0), 11);
}

#[test]
fn fd_sh3_features() {
    check_fd(&random_scene(2, 40, 32, 20, 3, 16, 3), 12);
}

/// Needles and an edge-on disc (σ2 nearly singular, λ_max up to 1e10 px²): the twin's backward
/// (taken in each Gaussian's frame, since ∂L/∂Σ2 = −C·G·C formed as a matrix is rounding noise
/// along the long axis even in f64) against central differences of the f64 pipeline. Scales
/// use a relative step (the long-axis gradient of the 1e4 disc is ~1e-11), quaternions and
/// means an absolute 1e-8 (tilting the edge-on disc adds (2e4·δ)² px² to its thin 0.3 px²:
/// with 1e-6 the curvature already biased the difference by 1e-4); scales below 1e-3 are not
/// differenced (their effect on L is below f64's resolution of L).
#[test]
fn fd_needles_and_edge_on_disc() {
    let mut s = Scene::empty(identity_camera(48, 40, 38.4), 1, 0);
    s.params.background = [0.1, 0.2, 0.3];
    let z45 = [0.923_879_5, 0.0, 0.0, 0.382_683_43];
    let q = [0.9, 0.1, -0.3, 0.2];
    s.push(
        [-0.2, -0.1, 5.0],
        [30.0, 1e-8, 1e-8],
        z45,
        1.0,
        [0.9, 0.2, 0.1],
    );
    s.push(
        [0.05, 0.0, 6.0],
        [1e3, 1e-8, 1e-8],
        z45,
        0.5,
        [0.2, 0.9, 0.1],
    );
    s.push([0.0, 0.0, 4.0], [1e4, 1e-8, 1e4], z45, 0.0, [0.1, 0.2, 0.9]);
    s.push([-0.3, 0.2, 4.5], [1e-8, 1e4, 1.0], q, 0.5, [0.6, 0.6, 0.2]);
    s.push([0.2, 0.1, 3.0], [2.0, 0.01, 0.3], q, -0.5, [0.3, 0.5, 0.7]);
    let up = Upstream::random(&mut Pcg64::seed_from_u64(21), s.npix(), 0);
    let g = Gaussians64::from_f32(&s.g());
    let proj = project_f64(&s.cam, &g);
    assert!(proj.radius.iter().all(|&r| r > 0), "all visible");
    let bg = blend_bwd_f64(
        &s.params,
        &proj,
        &[],
        &up.rgb,
        &up.alpha,
        &up.depth,
        &up.features,
    );
    let pg = project_bwd_f64(&s.cam, &g, &bg);
    let (l0, sig0) = fd_loss(&s, &g, &[], &up, None);
    let (mut checked, mut skipped) = (0, 0);
    for i in 0..g.len() {
        let mut params: Vec<(Kind, usize, f64, f64)> = vec![];
        for a in 0..3 {
            let sc = g.scales[i][a];
            if sc >= 1e-3 {
                params.push((Kind::Scales, 3 * i + a, 1e-3 * sc, pg.scales[i][a]));
            }
            params.push((Kind::Means, 3 * i + a, 1e-8, pg.means[i][a]));
        }
        for a in 0..4 {
            params.push((Kind::Quats, 4 * i + a, 1e-8, pg.quats[i][a]));
        }
        for (kind, j, h, an) in params {
            let eval = |delta: f64| {
                let mut g2 = g.clone();
                *param(&mut g2, &mut [], kind, j) += delta;
                let detach = (kind == Kind::Means).then_some(&proj.color[..]);
                fd_loss(&s, &g2, &[], &up, detach)
            };
            let ((lp, sp), (lm, sm)) = (eval(h), eval(-h));
            if sp != sig0 || sm != sig0 {
                skipped += 1;
                continue;
            }
            checked += 1;
            let fd = (lp - lm) / (2.0 * h);
            // Rounding of L (~1e-16·|L| per evaluation) over 2h, with 100× headroom; the
            // truncation error at these steps is below 1e-6 relative.
            let abs = 1e-14 * (1.0 + l0.abs()) / h;
            assert!(
                (an - fd).abs() <= 1e-4 * fd.abs() + abs,
                "Gaussian {i} {kind:?}[{j}]: analytic {an:e}, FD {fd:e} (step {h:e})"
            );
        }
    }
    eprintln!("needles FD: {checked} checked, {skipped} straddling");
    assert!(
        skipped * 10 <= checked,
        "{skipped} straddle, {checked} checked"
    );
    // The disc's in-image long axis: a real, tiny gradient that the matrix form got wrong by
    // 10³× with the opposite sign.
    assert!(pg.scales[2][0].abs() < 1e-9 && pg.scales[2][0] != 0.0);
}

#[test]
fn fd_sh1_of_16_features_small() {
    // Degree 1 active out of 16 stored coefficients: the unused ones get exactly zero gradient
    // (and their FD is zero too).
    let s = random_scene(3, 17, 13, 12, 3, 16, 1);
    check_fd(&s, 13);
    let up = Upstream::random(&mut Pcg64::seed_from_u64(5), s.npix(), 3);
    let (_, _, _, pg) = s.grads(&up);
    for i in 0..s.means.len() {
        for kk in 4..16 {
            for c in 0..3 {
                assert_eq!(pg.sh[(i * 16 + kk) * 3 + c], 0.0);
            }
        }
    }
}

#[test]
fn f32_wrappers_match_f64_path() {
    let s = random_scene(4, 40, 32, 20, 3, 16, 3);
    let up = Upstream::random(&mut Pcg64::seed_from_u64(14), s.npix(), 3);
    let (proj, out, bg, pg) = s.grads(&up);
    let g = Gaussians64::from_f32(&s.g());
    let feats: Vec<f64> = s.features.iter().map(|&x| x as f64).collect();
    let proj64 = project_f64(&s.cam, &g);
    let out64 = blend_fwd_f64(&s.params, &proj64, &feats);
    let bg64 = blend_bwd_f64(
        &s.params,
        &proj64,
        &feats,
        &up.rgb,
        &up.alpha,
        &up.depth,
        &up.features,
    );
    let pg64 = project_bwd_f64(&s.cam, &g, &bg64);
    // Same discrete structure, values to the f32 rounding of the projected quantities.
    assert_eq!(proj.radius, proj64.radius);
    assert_eq!(proj.tile_rect, proj64.tile_rect);
    assert_eq!(out.n_contrib, out64.n_contrib);
    let rgb: Vec<f64> = out.rgb.iter().flatten().map(|&x| x as f64).collect();
    let rgb64: Vec<f64> = out64.rgb.iter().flatten().copied().collect();
    assert_close(
        "rgb f32 vs f64",
        &rgb,
        &rgb64,
        Tol::Elementwise {
            abs: 1e-6,
            rel: 1e-6,
        },
    );
    let flat = |v: &[[f64; 3]]| v.iter().flatten().copied().collect::<Vec<_>>();
    let tol = |v: &[f64]| 1e-4 * v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let m64 = flat(&pg64.means);
    assert_close(
        "means f32 vs f64",
        &flat(&pg.means),
        &m64,
        Tol::Elementwise {
            abs: tol(&m64),
            rel: 1e-3,
        },
    );
    assert_close(
        "sh f32 vs f64",
        &pg.sh,
        &pg64.sh,
        Tol::Elementwise {
            abs: tol(&pg64.sh),
            rel: 1e-3,
        },
    );
    assert_close(
        "op f32 vs f64",
        &bg.opacity,
        &bg64.opacity,
        Tol::Elementwise {
            abs: tol(&bg64.opacity),
            rel: 1e-3,
        },
    );
}

// ---------------------------------------------------------------------------------------------
// 3. Numerical extremes (DESIGN §6): finite outputs and gradients, or documented culling.

/// Renders `s` and back-propagates random upstream gradients; asserts everything is finite and
/// that culled Gaussians get exactly zero gradients.
fn finite_everything(what: &str, s: &Scene) -> (Projected, BlendOut, BlendGrads, ProjectGrads) {
    let k = s.params.feature_dims as usize;
    let up = Upstream::random(&mut Pcg64::seed_from_u64(99), s.npix(), k);
    let r = s.grads(&up);
    let (proj, out, bg, pg) = &r;
    assert_all_finite(what, out, bg, pg);
    for (p, (a, t)) in out.alpha.iter().zip(&out.final_t).enumerate() {
        assert!((a + t - 1.0).abs() < 1e-6, "{what}: alpha + T != 1 at {p}");
        assert!((0.0..=1.0).contains(t), "{what}: T = {t} at {p}");
    }
    for i in 0..proj.radius.len() {
        if proj.radius[i] == 0 {
            assert_eq!(proj.tile_rect[i], [0; 4], "{what}: culled {i} has a rect");
            let zero = pg.means[i] == [0.0; 3]
                && pg.scales[i] == [0.0; 3]
                && pg.quats[i] == [0.0; 4]
                && pg.opacity_logits[i] == 0.0
                && bg.mean2d[i] == [0.0; 2];
            assert!(zero, "{what}: culled Gaussian {i} has a gradient");
        }
    }
    r
}

fn background_only(what: &str, s: &Scene, out: &BlendOut) {
    for p in 0..s.npix() {
        assert_eq!(out.rgb[p], s.params.background, "{what}: pixel {p}");
        assert_eq!(out.alpha[p], 0.0, "{what}: pixel {p}");
        assert_eq!(out.n_contrib[p], 0, "{what}: pixel {p}");
    }
}

fn cam_with_bg(w: u32, h: u32) -> Scene {
    let mut s = Scene::empty(identity_camera(w, h, 30.0), 16, 3);
    s.params.background = [0.1, 0.2, 0.3];
    s.params.feature_dims = 2;
    s
}

#[test]
fn extreme_scales() {
    let mut s = cam_with_bg(40, 32);
    let q = [0.9, 0.1, -0.3, 0.2];
    s.push([0.0, 0.0, 4.0], [1e-8; 3], q, 1.0, [0.9, 0.2, 0.1]);
    s.push([0.3, 0.1, 5.0], [1e4; 3], q, -1.0, [0.1, 0.9, 0.1]);
    s.push([-0.3, 0.2, 4.5], [1e-8, 1e4, 1.0], q, 0.5, [0.1, 0.2, 0.9]);
    s.push([0.2, -0.2, 3.5], [0.0; 3], q, 2.0, [0.5, 0.5, 0.5]); // singular Σ3
    let (proj, out, _, _) = finite_everything("extreme scales", &s);
    // All visible: the tiny ones are dilated to ~0.3 px², the huge one covers every tile.
    assert!(proj.radius.iter().all(|&r| r > 0));
    assert_eq!(proj.tile_rect[1], [0, 0, 3, 2]);
    // The tiny Gaussian's peak: Σ2 ≈ 0.3·I, so its conic is ≈ 1/0.3.
    assert!((proj.conic[0][0] - 1.0 / 0.3).abs() < 1e-4);
    assert!(
        out.alpha.iter().all(|&a| a > 0.0),
        "the 1e4 Gaussian covers everything"
    );
}

#[test]
fn extreme_opacity_logits() {
    let mut s = cam_with_bg(20, 20);
    s.push([0.0, 0.0, 4.0], [0.2; 3], IDQ, -30.0, [0.9, 0.2, 0.1]);
    s.push([0.0, 0.0, 5.0], [0.2; 3], IDQ, -1000.0, [0.9, 0.2, 0.1]);
    let (proj, out, _, pg) = finite_everything("logit -30", &s);
    assert!(proj.opacity[0] > 0.0 && proj.opacity[0] < 1e-12);
    assert_eq!(proj.opacity[1], 0.0);
    background_only("logit -30", &s, &out);
    assert_eq!(
        pg.opacity_logits,
        vec![0.0, 0.0],
        "skipped everywhere: no gradient"
    );

    let mut s = cam_with_bg(21, 21);
    s.push([0.0, 0.0, 4.0], [0.2; 3], IDQ, 30.0, [0.9, 0.2, 0.1]);
    s.push([1.0, 1.0, 5.0], [0.2; 3], IDQ, 1000.0, [0.9, 0.2, 0.1]);
    let (proj, out, _, _) = finite_everything("logit +30", &s);
    assert_eq!(proj.opacity, vec![1.0, 1.0]);
    // The centre pixel (on the first mean) has α clamped at alpha_max = 0.99.
    let centre = (10 * 21 + 10) as usize;
    assert!((out.alpha[centre] - 0.99).abs() < 1e-6);
}

#[test]
fn near_zero_quaternion_is_identity() {
    let mut s = cam_with_bg(24, 24);
    let scale = [0.1, 0.3, 0.2];
    s.push([0.0, 0.0, 4.0], scale, [0.0; 4], 1.0, [0.9, 0.2, 0.1]);
    s.push(
        [0.3, 0.0, 4.0],
        scale,
        [1e-20, 0.0, 0.0, 0.0],
        1.0,
        [0.9, 0.2, 0.1],
    );
    s.push(
        [-0.3, 0.0, 4.0],
        scale,
        [1e-13, -1e-13, 0.0, 1e-14],
        1.0,
        [0.9, 0.2, 0.1],
    );
    s.push(
        [0.0, 0.3, 4.0],
        scale,
        [1e-6, 0.0, 0.0, 0.0],
        1.0,
        [0.9, 0.2, 0.1],
    );
    let (proj, _, _, pg) = finite_everything("zero quaternion", &s);
    let mut id = s.clone();
    id.quats = vec![IDQ; 4];
    let proj_id = project(&id.cam, &id.g());
    // Norms below 1e-12 become the identity; 1e-6 normalises to the identity exactly.
    assert_eq!(proj.conic, proj_id.conic);
    for i in 0..3 {
        assert_eq!(
            pg.quats[i], [0.0; 4],
            "quaternion {i} below 1e-12: no gradient"
        );
    }
    assert!(pg.scales[0].iter().any(|v| *v != 0.0));
}

#[test]
fn behind_camera_and_near_plane() {
    let mut s = cam_with_bg(32, 32);
    let near = s.cam.near;
    let below = f32::from_bits(near.to_bits() - 1);
    s.push([0.0, 0.0, -5.0], [0.3; 3], IDQ, 1.0, [0.9, 0.2, 0.1]); // behind
    s.push([0.0, 0.0, 0.0], [0.3; 3], IDQ, 1.0, [0.9, 0.2, 0.1]); // at the camera centre
    s.push([0.0, 0.0, below], [0.01; 3], IDQ, 1.0, [0.9, 0.2, 0.1]); // just inside near
    s.push([f32::NAN, 0.0, 3.0], [0.3; 3], IDQ, 1.0, [0.9, 0.2, 0.1]); // not finite
    s.push([0.0, 0.0, near], [0.01; 3], IDQ, 1.0, [0.1, 0.2, 0.9]); // exactly on the near plane
    let (proj, out, _, pg) = finite_everything("near plane", &s);
    assert_eq!(
        proj.radius[..4],
        [0, 0, 0, 0],
        "culled: z < near or not finite"
    );
    // z == near is kept (culling is z < near): a 0.01 Gaussian 0.01 ahead covers the view.
    assert!(proj.radius[4] > 0);
    assert_eq!(proj.depth[4], near);
    assert!(out.alpha.iter().all(|&a| a > 0.0));
    assert!(pg.means[4].iter().all(|v| v.is_finite()));
}

#[test]
fn camera_inside_gaussian() {
    let mut s = cam_with_bg(32, 24);
    s.push(
        [0.0, 0.0, 0.5],
        [10.0, 8.0, 12.0],
        [0.8, 0.2, 0.1, -0.3],
        0.0,
        [0.3, 0.6, 0.9],
    );
    s.push([0.1, -0.1, 0.02], [5.0; 3], IDQ, -0.5, [0.9, 0.6, 0.3]);
    let (proj, out, _, _) = finite_everything("camera inside", &s);
    assert!(proj.radius.iter().all(|&r| r > 0));
    assert!(
        out.alpha.iter().all(|&a| a > 0.3),
        "both cover the whole image"
    );
}

#[test]
fn zero_gaussians() {
    let s = cam_with_bg(17, 13);
    let (proj, out, bg, pg) = finite_everything("zero Gaussians", &s);
    assert!(proj.radius.is_empty() && bg.features.is_empty() && pg.sh.is_empty());
    background_only("zero Gaussians", &s, &out);
    assert!(out.features.iter().all(|&f| f == 0.0) && out.final_t.iter().all(|&t| t == 1.0));
}

#[test]
fn all_culled() {
    let mut s = cam_with_bg(17, 13);
    s.push([0.0, 0.0, -1.0], [0.3; 3], IDQ, 1.0, [0.9, 0.2, 0.1]); // behind
    s.push([100.0, 0.0, 2.0], [0.01; 3], IDQ, 1.0, [0.9, 0.2, 0.1]); // far off-screen
    s.push([0.0, -50.0, 2.0], [0.01; 3], IDQ, 1.0, [0.9, 0.2, 0.1]); // far off-screen
    let (proj, out, _, pg) = finite_everything("all culled", &s);
    assert_eq!(proj.radius, vec![0, 0, 0]);
    background_only("all culled", &s, &out);
    assert!(pg.sh.iter().all(|&v| v == 0.0));
}

#[test]
fn one_by_one_image() {
    let mut s = cam_with_bg(1, 1);
    s.cam.fx = 2.0;
    s.cam.fy = 2.0;
    s.push([0.0, 0.0, 3.0], [0.5; 3], IDQ, 1.0, [0.9, 0.2, 0.1]);
    let (proj, out, bg, _) = finite_everything("1x1", &s);
    assert_eq!(proj.tile_rect[0], [0, 0, 1, 1]);
    assert_eq!(out.n_contrib, vec![1]);
    assert!(bg.opacity[0] != 0.0);
}

#[test]
fn non_multiple_of_16_image() {
    let mut s = cam_with_bg(17, 13);
    s.params.feature_dims = 0;
    // Centred on the bottom-right pixel (16, 12): mean2d = (16.5, 12.5).
    let z = 4.0f32;
    let (u, v) = (16.5f32, 12.5f32);
    let mean = [
        (u - s.cam.cx) * z / s.cam.fx,
        (v - s.cam.cy) * z / s.cam.fy,
        z,
    ];
    s.push(mean, [0.01; 3], IDQ, 1.0, [0.9, 0.2, 0.1]);
    let (proj, out, _, _) = finite_everything("17x13", &s);
    assert_eq!(s.cam.tiles(), (2, 1));
    assert!((proj.mean2d[0][0] - 16.5).abs() < 1e-4 && (proj.mean2d[0][1] - 12.5).abs() < 1e-4);
    assert_eq!(proj.tile_rect[0], [0, 0, 2, 1]);
    let last = s.npix() - 1;
    assert!(out.alpha[last] > 0.5, "bottom-right pixel is drawn");
    assert_eq!(out.alpha[0], 0.0, "top-left pixel is not");
}

#[test]
fn many_gaussians_in_one_tile() {
    let mut s = cam_with_bg(16, 16);
    s.params.feature_dims = 0;
    let mut rng = Pcg64::seed_from_u64(7);
    let n = 10_000;
    for _ in 0..n {
        let z = rng.gen_range(3.0..6.0f32);
        let (u, v) = (rng.gen_range(0.0..16.0f32), rng.gen_range(0.0..16.0f32));
        let mean = [
            (u - s.cam.cx) * z / s.cam.fx,
            (v - s.cam.cy) * z / s.cam.fy,
            z,
        ];
        let rgb = [rng.gen(), rng.gen(), rng.gen()];
        s.push(mean, [0.2; 3], [1.0, 0.2, 0.0, 0.1], -3.0, rgb);
    }
    let (proj, out, bg, _) = finite_everything("10^4 in one tile", &s);
    assert!(proj.tile_rect.iter().all(|r| *r == [0, 0, 1, 1]));
    // Every pixel saturates and stops before the end of its list: T ≥ 1e-4 remains.
    for p in 0..s.npix() {
        assert!(
            out.final_t[p] >= 1e-4 && out.final_t[p] < 1e-3,
            "T = {}",
            out.final_t[p]
        );
        assert!(out.n_contrib[p] > 0 && (out.n_contrib[p] as usize) < n);
    }
    assert!(bg.opacity.iter().any(|&v| v != 0.0));
}

// ---------------------------------------------------------------------------------------------
// 4. Hand-checkable scenes

/// One isotropic Gaussian straight ahead: Σ2 = ((f·s/z)² + 0.3)·I, so conic = (1/v, 0, 1/v).
fn single(w: u32, logit: f32, bg: [f32; 3]) -> (Scene, f64) {
    let (f, s_, z) = (30.0f32, 0.3f32, 4.0f32);
    let mut s = Scene::empty(identity_camera(w, w, f), 1, 0);
    s.params.background = bg;
    s.push([0.0, 0.0, z], [s_; 3], IDQ, logit, [0.2, 0.5, 0.8]);
    let v = (f as f64 * s_ as f64 / z as f64).powi(2) + 0.3;
    (s, v)
}

#[test]
fn single_gaussian_peak_equals_opacity_times_colour() {
    let (s, v) = single(33, 0.0, [0.0; 3]);
    let (proj, out) = s.render();
    let conic = proj.conic[0].map(|x| x as f64);
    assert_close(
        "conic",
        &conic,
        &[1.0 / v, 0.0, 1.0 / v],
        Tol::Elementwise {
            abs: 1e-7,
            rel: 1e-6,
        },
    );
    assert_eq!(proj.opacity[0], 0.5);
    // 33×33, cx = 16.5: pixel (16, 16)'s centre is the mean exactly.
    let c = 16 * 33 + 16;
    let want = [0.2, 0.5, 0.8].map(|x| 0.5 * x);
    let got = out.rgb[c].map(|x| x as f64);
    assert_close(
        "peak",
        &got,
        &want,
        Tol::Elementwise {
            abs: 1e-6,
            rel: 0.0,
        },
    );
    assert!((out.alpha[c] - 0.5).abs() < 1e-6);
    assert!((out.depth[c] - 2.0).abs() < 1e-6, "depth = w·z = 0.5·4");
    // One pixel to the right: dx = −1, σ = 0.5/v.
    let a = 0.5 * (-0.5 / v).exp();
    assert!((out.alpha[c + 1] as f64 - a).abs() < 1e-6);

    // 32×32, cx = 16: the nearest pixel centres are half a pixel off in x and y, σ = 0.25/v.
    let (s, v) = single(32, 0.0, [0.0; 3]);
    let (_, out) = s.render();
    let a = 0.5 * (-0.25 / v).exp();
    for p in [(15, 15), (16, 15), (15, 16), (16, 16)] {
        let got = out.rgb[p.1 * 32 + p.0].map(|x| x as f64);
        assert_close(
            "off-centre peak",
            &got,
            &[0.2, 0.5, 0.8].map(|x| a * x),
            Tol::Elementwise {
                abs: 1e-6,
                rel: 0.0,
            },
        );
    }
}

#[test]
fn alpha_max_clamp_and_background() {
    let bg = [0.1, 0.2, 0.3];
    for alpha_max in [0.99f32, 0.999] {
        let (mut s, _) = single(33, 30.0, bg);
        s.params.alpha_max = alpha_max;
        let (_, out) = s.render();
        let c = 16 * 33 + 16;
        let a = alpha_max as f64;
        let want: Vec<f64> = (0..3)
            .map(|k| a * [0.2, 0.5, 0.8][k] + (1.0 - a) * bg[k] as f64)
            .collect();
        assert_close(
            "clamped peak",
            &out.rgb[c].map(|x| x as f64),
            &want,
            Tol::Elementwise {
                abs: 1e-6,
                rel: 0.0,
            },
        );
        assert!((out.alpha[c] as f64 - a).abs() < 1e-6);
        // The clamp holds the gradient wrt opacity at that pixel at 0: only the clamped pixel
        // gets an upstream gradient, so the opacity gradient vanishes.
        let mut d_alpha = vec![0.0f32; s.npix()];
        d_alpha[c] = 1.0;
        let bgr = blend_bwd(&s.params, &s.render().0, &[], &out, &[], &d_alpha, &[], &[]);
        assert_eq!(bgr.opacity[0], 0.0);
        assert_eq!(bgr.mean2d[0], [0.0, 0.0]);
        // A corner far from the Gaussian shows the background exactly.
        assert_eq!(out.rgb[0], bg);
        assert_eq!(
            (out.alpha[0], out.final_t[0], out.n_contrib[0]),
            (0.0, 1.0, 0)
        );
    }
}

#[test]
fn depth_order_ties_skip_and_stop() {
    let bg = [0.1, 0.2, 0.3];
    let mut s = Scene::empty(identity_camera(33, 33, 30.0), 1, 0);
    s.params.background = bg;
    s.params.alpha_max = 0.999;
    let c = 16 * 33 + 16;
    let (c_back, c_front) = ([0.9f64, 0.1, 0.1], [0.1f64, 0.9, 0.1]);
    let (cb32, cf32) = (c_back.map(|x| x as f32), c_front.map(|x| x as f32));
    // Index 0 behind index 1: index 1 blends first.
    s.push([0.0, 0.0, 5.0], [0.3; 3], IDQ, 0.0, cb32);
    s.push([0.0, 0.0, 3.0], [0.3; 3], IDQ, 1.0, cf32);
    let (_, out) = s.render();
    let af = sigmoid(1.0) as f32 as f64;
    let want: Vec<f64> = (0..3)
        .map(|k| af * c_front[k] + (1.0 - af) * 0.5 * c_back[k] + (1.0 - af) * 0.5 * bg[k] as f64)
        .collect();
    assert_close(
        "two layers",
        &out.rgb[c].map(|x| x as f64),
        &want,
        Tol::Elementwise {
            abs: 1e-6,
            rel: 0.0,
        },
    );
    assert_eq!(out.n_contrib[c], 2);

    // Equal depths: ties go by index (index 0 first).
    let mut t = s.clone();
    t.means[1][2] = 5.0;
    let (_, out) = t.render();
    let want: Vec<f64> = (0..3)
        .map(|k| 0.5 * c_back[k] + 0.5 * af * c_front[k] + 0.5 * (1.0 - af) * bg[k] as f64)
        .collect();
    assert_close(
        "tie by index",
        &out.rgb[c].map(|x| x as f64),
        &want,
        Tol::Elementwise {
            abs: 1e-6,
            rel: 0.0,
        },
    );

    // α < 1/255 in front is skipped by the blend but counts in n_contrib's position when it is
    // in the tile's list (binned to its 3σ square); binned to its opacity-aware box it is in
    // no list at all. The image is the same either way.
    let mut u = s.clone();
    u.push([0.0, 0.0, 2.0], [0.3; 3], IDQ, -30.0, [1.0; 3]);
    let (mut proj_u, out_box) = u.render();
    assert_eq!(
        proj_u.tile_rect[2], [0; 4],
        "a Gaussian fainter than 1/255 has no tile"
    );
    assert_eq!(out_box.n_contrib[c], 2);
    let m = proj_u.mean2d[2].map(f64::from);
    proj_u.tile_rect[2] = radius_rect(&u.cam, m, proj_u.radius[2]);
    let out_u = blend_fwd(&u.params, &proj_u, &u.features);
    assert_eq!(out_u.n_contrib[c], 3);
    let (_, out_s) = s.render();
    assert_eq!(out_u.rgb[c], out_s.rgb[c]);
    assert_eq!(out_box.rgb[c], out_s.rgb[c]);

    // Stop: after one α = 0.999 layer T = 1e-3; a second would take it to 1e-6 < 1e-4, so it is
    // not blended and the pixel is done (the third is never reached).
    let mut v = Scene::empty(identity_camera(33, 33, 30.0), 1, 0);
    v.params = s.params;
    v.push([0.0, 0.0, 3.0], [0.3; 3], IDQ, 30.0, cf32);
    v.push([0.0, 0.0, 4.0], [0.3; 3], IDQ, 30.0, cb32);
    v.push([0.0, 0.0, 5.0], [0.3; 3], IDQ, 0.0, cb32);
    let (_, out) = v.render();
    assert_eq!(out.n_contrib[c], 1);
    let a = 0.999f32 as f64;
    assert!((out.final_t[c] as f64 - (1.0 - a)).abs() < 1e-9);
    let want: Vec<f64> = (0..3)
        .map(|k| a * c_front[k] + (1.0 - a) * bg[k] as f64)
        .collect();
    assert_close(
        "stop",
        &out.rgb[c].map(|x| x as f64),
        &want,
        Tol::Elementwise {
            abs: 1e-6,
            rel: 0.0,
        },
    );
}

#[test]
fn sh_basis_matches_3dgs_formulas() {
    // A few hand-evaluated basis values at dir = (x, y, z) = (0.48, 0.6, 0.64).
    let d = [0.48, 0.6, 0.64];
    let b = sh::basis(3, d);
    assert_eq!(b[0], sh::C0);
    assert!((b[1] + sh::C1 * 0.6).abs() < 1e-15);
    assert!((b[3] + sh::C1 * 0.48).abs() < 1e-15);
    assert!((b[6] - sh::C2[2] * (2.0 * 0.4096 - 0.2304 - 0.36)).abs() < 1e-15);
    assert!((b[15] - sh::C3[6] * 0.48 * (0.2304 - 3.0 * 0.36)).abs() < 1e-15);
    assert_eq!(sh::basis(1, d)[4..], [0.0; 12]);
}

#[test]
fn signatures_detect_threshold_crossings() {
    // The FD tests rely on the signatures to skip straddling samples: check they see each kind
    // of discrete decision change, and stay put for a smooth change.
    let (s, _) = single(33, 0.0, [0.0; 3]);
    let sig = |g: &Gaussians64| {
        let p = project_f64(&s.cam, g);
        let o = blend_fwd_f64(&s.params, &p, &[]);
        (p.signature, o.signature)
    };
    let g0 = Gaussians64::from_f32(&s.g());
    let base = sig(&g0);
    let mut g = g0.clone();
    g.opacity_logits[0] += 1e-6; // smooth (an FD step)
    assert_eq!(sig(&g), base);
    g.opacity_logits[0] = 6.0; // α clamped at the centre pixel
    assert_eq!(sig(&g).0, base.0);
    assert_ne!(sig(&g).1, base.1);
    let mut g = g0.clone();
    g.opacity_logits[0] = -5.0; // fewer pixels pass α ≥ 1/255
    assert_ne!(sig(&g).1, base.1);
    let mut g = g0.clone();
    g.means[0][0] = 3.0; // x/z = 0.75 > lim_x_pos = 0.7: Jacobian clamp
    assert_ne!(sig(&g).0, base.0);
    let mut g = g0.clone();
    g.sh[0] = -3.0; // red channel clamped at 0
    assert_ne!(sig(&g).0, base.0);
}
