//! The rasteriser's CPU twin (`reference::raster`) against an external oracle (gsplat), against
//! finite differences of itself, at the numerical extremes, and on hand-checkable scenes.

use std::collections::HashMap;
use std::path::PathBuf;

use dispflow_vk::reference::raster::{
    blend_bwd, blend_bwd_f64, blend_fwd, blend_fwd_f64, project, project_bwd, project_bwd_f64,
    project_f64, sigmoid, BlendGrads, BlendOut, BlendParams, Camera, Gaussians, Gaussians64,
    ProjectGrads, Projected, TILE,
};
use dispflow_vk::reference::sh;
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
            for c in 0..3 {
                let v = if k == 0 {
                    ((rgb[c] as f64 - 0.5) / sh::C0) as f32
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

fn finite<'a>(v: impl IntoIterator<Item = &'a f64>) -> bool {
    v.into_iter().all(|x| x.is_finite())
}

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

/// `|got − want| ≤ abs + rel·|want|` elementwise; reports the worst entry.
fn assert_close(what: &str, got: &[f64], want: &[f64], rel: f64, abs: f64) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    let mut worst = (0.0, 0usize);
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        let excess = (g - w).abs() / (abs + rel * w.abs());
        assert!(excess.is_finite(), "{what}[{i}]: got {g}, want {w}");
        if excess > worst.0 {
            worst = (excess, i);
        }
    }
    let i = worst.1;
    eprintln!("{what}: worst |diff|/tol = {:.3} at [{i}]", worst.0);
    assert!(
        worst.0 <= 1.0,
        "{what}[{i}]: got {}, want {} (|diff| {:.3e} > {abs:e} + {rel:e}·|want|)",
        got[i],
        want[i],
        (got[i] - want[i]).abs()
    );
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
        eprintln!("skipping: {} is absent", d.display());
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
    let quats: Vec<[f32; 4]> = get("quats").chunks(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
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
    assert!(proj.radius.iter().all(|&r| r > 0), "{name}: a Gaussian was culled");

    // Projection: gsplat computes in f32, so agreement is to f32 rounding of the operations
    // (|xy| ≤ ~150 px: a few ulp ≈ 1e-5; conics go through a 2×2 inverse: rel 1e-5).
    let xys: Vec<f64> = proj.mean2d.iter().flatten().map(|&x| x as f64).collect();
    assert_close(&format!("{name} xys"), &xys, &wide(get("xys")), 1e-6, 1e-4);
    let conics: Vec<f64> = proj.conic.iter().flatten().map(|&x| x as f64).collect();
    assert_close(&format!("{name} conics"), &conics, &wide(get("conics")), 1e-5, 1e-7);
    assert_close(&format!("{name} depths"), &wide(&proj.depth), &wide(get("depths")), 1e-6, 1e-6);

    // Forward image: RGB + accumulated alpha, to ~1e-5 (README: an f64 re-implementation
    // agreed to < 5e-6).
    let out = blend_fwd(&params, &proj, &[]);
    let mut img = Vec::with_capacity(out.rgb.len() * 4);
    for (rgb, a) in out.rgb.iter().zip(&out.alpha) {
        img.extend(rgb.iter().map(|&x| x as f64));
        img.push(*a as f64);
    }
    assert_close(&format!("{name} out_img"), &img, &wide(get("out_img")), 0.0, 1e-5);

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
        assert!(big * 2 > want.len(), "{name} {key}: mostly tiny reference values");
        assert_close(&format!("{name} {what}"), &got, &want, rel, abs)
    };
    // gsplat's v_xy and v_conics use the same conventions as BlendGrads: d = mean2d − pixel
    // centre and σ = ½(a dx² + c dy²) + b dx dy, so they compare without conversion.
    chk("v_xy", bg.mean2d.iter().flatten().copied().collect(), "v_xy");
    chk("v_conics", bg.conic.iter().flatten().copied().collect(), "v_conics");
    chk("v_means", pg.means.iter().flatten().copied().collect(), "v_means");
    // gsplat's scales are log-scales: d/d(log s) = s · d/ds.
    let v_log_scales = pg
        .scales
        .iter()
        .zip(&scales)
        .flat_map(|(d, s)| [0, 1, 2].map(|k| d[k] * s[k] as f64))
        .collect();
    chk("v_scales", v_log_scales, "v_scales");
    chk("v_quats", pg.quats.iter().flatten().copied().collect(), "v_quats");
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
