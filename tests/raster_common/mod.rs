//! Scene helpers shared by the rasteriser tests: host-side Gaussians, upload, run, read back.
#![allow(dead_code)]

use dispflow_vk::kernels::raster::{
    join_sh, split_sh, Access, BlendBwdVariant, BlendFwdVariant, Camera, OutputGrads,
    RasterBuffers, RasterSize, Rasterizer, RenderOpts, SplatInputs,
};
use dispflow_vk::testing::{self, Noise, TestGpu};
use dispflow_vk::vk::{Buffer, Recorder};

/// The variants' `name()` and `for_device()`.
pub use dispflow_vk::kernels::shape::DeviceShape;

#[derive(Clone, Debug, Default)]
pub struct Scene {
    pub means: Vec<[f32; 3]>,
    pub scales: Vec<[f32; 3]>,
    pub quats: Vec<[f32; 4]>,
    pub logits: Vec<f32>,
    pub sh: Vec<f32>,
    pub sh_coeffs: u32,
    pub sh_degree: u32,
    pub features: Vec<f32>,
    pub feature_dims: u32,
}

impl Scene {
    pub fn len(&self) -> usize {
        self.logits.len()
    }
    /// The scene as the twin's input.
    pub fn twin(&self) -> dispflow_vk::reference::raster::Gaussians<'_> {
        dispflow_vk::reference::raster::Gaussians {
            means: &self.means,
            scales: &self.scales,
            quats: &self.quats,
            opacity_logits: &self.logits,
            sh: &self.sh,
            sh_coeffs: self.sh_coeffs,
            sh_degree: self.sh_degree,
        }
    }
    pub fn push(
        &mut self,
        mean: [f32; 3],
        scale: [f32; 3],
        quat: [f32; 4],
        logit: f32,
        rgb: [f32; 3],
    ) {
        self.means.push(mean);
        self.scales.push(scale);
        self.quats.push(quat);
        self.logits.push(logit);
        // DC term so that colour = rgb: c = C0·sh0 + 0.5.
        let c0 = 0.282_094_8_f32;
        for k in 0..self.sh_coeffs {
            for c in rgb {
                self.sh.push(if k == 0 { (c - 0.5) / c0 } else { 0.0 });
            }
        }
        for c in 0..self.feature_dims {
            self.features
                .push(0.1 * (c as f32 + 1.0) * (self.len() as f32).sin());
        }
    }
}

/// A camera at the origin looking down +z.
pub fn camera(width: u32, height: u32) -> Camera {
    let f = 0.8 * width.max(height) as f32;
    Camera {
        rot: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        trans: [0.0, 0.0, 0.0],
        fx: f,
        fy: f,
        cx: 0.5 * width as f32 + 0.3,
        cy: 0.5 * height as f32 - 0.2,
        width,
        height,
        near: 0.01,
    }
}

/// Random Gaussians in front of `cam`, a mix of sizes, orientations and opacities.
pub fn random_scene(seed: u64, n: usize, sh_degree: u32, feature_dims: u32) -> Scene {
    let mut r = Noise::new(seed);
    let mut u = move || (r.next_u32() as f32 + 0.5) / 4_294_967_296.0;
    let sh_coeffs = (sh_degree + 1).pow(2);
    let mut s = Scene {
        sh_coeffs,
        sh_degree,
        feature_dims,
        ..Default::default()
    };
    for _ in 0..n {
        let z = 2.0 + 4.0 * u();
        s.means.push([(u() - 0.5) * z, (u() - 0.5) * z * 0.8, z]);
        s.scales
            .push([0.02 + 0.3 * u(), 0.02 + 0.3 * u(), 0.02 + 0.3 * u()]);
        s.quats.push([u() - 0.5, u() - 0.5, u() - 0.5, u() - 0.5]);
        s.logits.push(4.0 * u() - 2.0);
        for _ in 0..sh_coeffs * 3 {
            s.sh.push(0.6 * (u() - 0.5));
        }
        for _ in 0..feature_dims {
            s.features.push(2.0 * u() - 1.0);
        }
    }
    s
}

pub struct Uploaded {
    pub means: Buffer,
    pub scales: Buffer,
    pub quats: Buffer,
    pub logits: Buffer,
    pub sh_dc: Buffer,
    pub sh_rest: Buffer,
    pub features: Buffer,
    pub n: u32,
    pub sh_coeffs: u32,
    pub sh_degree: u32,
    pub feature_dims: u32,
}

impl Uploaded {
    pub fn new(gpu: &TestGpu, s: &Scene) -> Uploaded {
        let up = |name: &str, v: &[f32]| {
            if v.is_empty() {
                gpu.buffer(name, 16).unwrap()
            } else {
                gpu.buffer_from(name, v).unwrap()
            }
        };
        Uploaded {
            means: up("means", s.means.as_flattened()),
            scales: up("scales", s.scales.as_flattened()),
            quats: up("quats", s.quats.as_flattened()),
            logits: up("logits", &s.logits),
            sh_dc: up("sh dc", &split_sh(&s.sh, s.sh_coeffs as usize).0),
            sh_rest: up("sh rest", &split_sh(&s.sh, s.sh_coeffs as usize).1),
            features: up("features", &s.features),
            n: s.len() as u32,
            sh_coeffs: s.sh_coeffs,
            sh_degree: s.sh_degree,
            feature_dims: s.feature_dims,
        }
    }
    pub fn inputs(&self) -> SplatInputs<'_> {
        SplatInputs {
            n: self.n,
            means: self.means.all(),
            scales: self.scales.all(),
            quats: self.quats.all(),
            opacity_logits: self.logits.all(),
            sh_dc: self.sh_dc.all(),
            sh_rest: self.sh_rest.all(),
            sh_coeffs: self.sh_coeffs,
            sh_degree: self.sh_degree,
            features: (self.feature_dims > 0).then(|| (self.features.all(), self.feature_dims)),
            opacity_scale: None,
        }
    }
}

#[derive(Clone)]
pub struct Rendered {
    pub rgba: Vec<[f32; 4]>,
    pub depth: Vec<f32>,
    pub final_t: Vec<f32>,
    pub n_contrib: Vec<u32>,
    pub features: Vec<f32>,
}

/// Forward (growing capacity as needed) and read back.
pub fn render(
    gpu: &TestGpu,
    rast: &Rasterizer,
    cam: &Camera,
    up: &Uploaded,
    opts: &RenderOpts,
) -> (RasterBuffers, Rendered) {
    let size = RasterSize {
        max_gaussians: up.n.max(1),
        width: cam.width,
        height: cam.height,
        sh_coeffs: up.sh_coeffs,
        feature_dims: up.feature_dims,
        isect_capacity: 64,
    };
    let mut b = rast.buffers(gpu, &size).unwrap();
    for buf in [
        &b.out_rgba,
        &b.out_depth,
        &b.final_t,
        &b.n_contrib,
        &b.out_features,
        &b.splats,
    ] {
        testing::fill_noise(gpu, buf, 3);
    }
    rast.render_checked(gpu, &mut b, cam, &up.inputs(), opts)
        .unwrap();
    let px = (cam.width * cam.height) as u64;
    let out = Rendered {
        rgba: gpu.read(b.out_rgba.elems::<[f32; 4]>(0, px)).unwrap(),
        depth: gpu.read(b.out_depth.elems::<f32>(0, px)).unwrap(),
        final_t: gpu.read(b.final_t.elems::<f32>(0, px)).unwrap(),
        n_contrib: gpu.read(b.n_contrib.elems::<u32>(0, px)).unwrap(),
        features: gpu
            .read(b.out_features.elems::<f32>(0, px * up.feature_dims as u64))
            .unwrap(),
    };
    (b, out)
}

/// [`render`] once per blend-forward variant (every GPU-vs-twin forward comparison runs them
/// all), each into its own buffers; leaves `rast` on its default variant.
pub fn render_each(
    gpu: &TestGpu,
    rast: &mut Rasterizer,
    cam: &Camera,
    up: &Uploaded,
    opts: &RenderOpts,
) -> Vec<(BlendFwdVariant, RasterBuffers, Rendered)> {
    let default = rast.blend_fwd_variant();
    let out = BlendFwdVariant::ALL
        .iter()
        .map(|&v| {
            rast.set_blend_fwd_variant(v);
            let (b, r) = render(gpu, rast, cam, up, opts);
            (v, b, r)
        })
        .collect();
    rast.set_blend_fwd_variant(default);
    out
}

/// [`render_each`], then the whole tile once more in the other array access (texel or
/// storage buffers: [`other_access`]), last; leaves `rast` on its defaults. The twin tests
/// use it; the extremes keep the device's access (the whole step trains with it).
pub fn render_each_access(
    gpu: &TestGpu,
    rast: &mut Rasterizer,
    cam: &Camera,
    up: &Uploaded,
    opts: &RenderOpts,
) -> Vec<(BlendFwdVariant, RasterBuffers, Rendered)> {
    let mut out = render_each(gpu, rast, cam, up, opts);
    let v = BlendFwdVariant::TileRegs;
    let (b, r) = in_other_access(rast, |rast| {
        let default = rast.blend_fwd_variant();
        rast.set_blend_fwd_variant(v);
        let r = render(gpu, rast, cam, up, opts);
        rast.set_blend_fwd_variant(default);
        r
    });
    out.push((v, b, r));
    out
}

/// Runs `f` with `rast` in the other array access, then restores the access.
fn in_other_access<T>(rast: &mut Rasterizer, f: impl FnOnce(&mut Rasterizer) -> T) -> T {
    let access = rast.access();
    rast.set_access(other_access(access));
    let r = f(rast);
    rast.set_access(access);
    r
}

/// The array access a device does not pick (the whole-tile blends have both).
pub fn other_access(a: Access) -> Access {
    match a {
        Access::Texel => Access::Buffer,
        Access::Buffer => Access::Texel,
    }
}

pub struct Grads {
    pub grad2d: Vec<f32>,
    pub d_features: Vec<f32>,
    pub d_means: Vec<f32>,
    pub d_scales: Vec<f32>,
    pub d_quats: Vec<f32>,
    pub d_logits: Vec<f32>,
    pub d_sh: Vec<f32>,
}

/// Upstream gradients: rgba [px,4], depth [px], features [px,K].
pub struct Upstream {
    pub rgba: Vec<f32>,
    pub depth: Vec<f32>,
    pub features: Vec<f32>,
}

/// Backward of the last forward in `b` with the given upstream gradients.
pub fn backward(
    gpu: &TestGpu,
    rast: &Rasterizer,
    b: &RasterBuffers,
    cam: &Camera,
    up: &Uploaded,
    opts: &RenderOpts,
    u: &Upstream,
) -> Grads {
    let (d_rgba, d_depth, d_feat) = (&u.rgba, &u.depth, &u.features);
    let dr = gpu.buffer_from("d rgba", d_rgba).unwrap();
    let dd = gpu.buffer_from("d depth", d_depth).unwrap();
    let df = if d_feat.is_empty() {
        gpu.buffer("d feat", 16).unwrap()
    } else {
        gpu.buffer_from("d feat", d_feat).unwrap()
    };
    for buf in [
        &b.d_means,
        &b.d_scales,
        &b.d_quats,
        &b.d_opacity_logits,
        &b.d_sh_dc,
        &b.d_sh_rest,
        &b.grad2d,
        &b.d_features,
    ] {
        testing::fill_noise(gpu, buf, 4);
    }
    let mut rec = Recorder::new(gpu).unwrap();
    let d = OutputGrads {
        rgba: dr.all(),
        depth: Some(dd.all()),
        features: (up.feature_dims > 0).then(|| df.all()),
    };
    rast.backward(&mut rec, b, cam, &up.inputs(), opts, &d);
    rec.finish().unwrap();
    let n = up.n as u64;
    let rd =
        |buf: &Buffer, per: u64| -> Vec<f32> { gpu.read(buf.elems::<f32>(0, n * per)).unwrap() };
    Grads {
        grad2d: rd(&b.grad2d, dispflow_vk::kernels::raster::G2D_STRIDE),
        d_features: rd(&b.d_features, up.feature_dims as u64),
        d_means: rd(&b.d_means, 3),
        d_scales: rd(&b.d_scales, 3),
        d_quats: rd(&b.d_quats, 4),
        d_logits: rd(&b.d_opacity_logits, 1),
        d_sh: join_sh(
            &rd(&b.d_sh_dc, 3),
            &rd(&b.d_sh_rest, (up.sh_coeffs as u64 - 1) * 3),
            up.sh_coeffs as usize,
        ),
    }
}

/// [`backward`] once per blend-backward variant (every GPU-vs-twin comparison runs them all);
/// leaves `rast` on its default variant.
pub fn backward_each(
    gpu: &TestGpu,
    rast: &mut Rasterizer,
    b: &RasterBuffers,
    cam: &Camera,
    up: &Uploaded,
    opts: &RenderOpts,
    u: &Upstream,
) -> Vec<(BlendBwdVariant, Grads)> {
    let default = rast.blend_bwd_variant();
    let out = BlendBwdVariant::ALL
        .iter()
        .map(|&v| {
            rast.set_blend_bwd_variant(v);
            (v, backward(gpu, rast, b, cam, up, opts, u))
        })
        .collect();
    rast.set_blend_bwd_variant(default);
    out
}

/// [`backward_each`], then the whole tile once more in the other array access, last.
pub fn backward_each_access(
    gpu: &TestGpu,
    rast: &mut Rasterizer,
    b: &RasterBuffers,
    cam: &Camera,
    up: &Uploaded,
    opts: &RenderOpts,
    u: &Upstream,
) -> Vec<(BlendBwdVariant, Grads)> {
    let mut out = backward_each(gpu, rast, b, cam, up, opts, u);
    let v = BlendBwdVariant::TileAccum;
    let grads = in_other_access(rast, |rast| {
        let default = rast.blend_bwd_variant();
        rast.set_blend_bwd_variant(v);
        let g = backward(gpu, rast, b, cam, up, opts, u);
        rast.set_blend_bwd_variant(default);
        g
    });
    out.push((v, grads));
    out
}

/// Deterministic upstream gradients for `px` pixels and `k` feature channels.
pub fn upstream(seed: u64, px: usize, k: usize) -> Upstream {
    let mut r = Noise::new(seed);
    let mut u = move || (r.next_u32() as f32 / 4_294_967_296.0) - 0.5;
    Upstream {
        rgba: (0..4 * px).map(|_| u()).collect(),
        depth: (0..px).map(|_| 0.1 * u()).collect(),
        features: (0..k * px).map(|_| u()).collect(),
    }
}

/// The twin's blend backward for the same upstream gradients the GPU backward got.
pub fn twin_blend_bwd(
    bp: &dispflow_vk::reference::raster::BlendParams,
    proj: &dispflow_vk::reference::raster::Projected,
    features: &[f32],
    fwd: &dispflow_vk::reference::raster::BlendOut,
    u: &Upstream,
) -> dispflow_vk::reference::raster::BlendGrads {
    let px = u.depth.len();
    let d_rgb: Vec<[f32; 3]> = (0..px)
        .map(|p| [u.rgba[4 * p], u.rgba[4 * p + 1], u.rgba[4 * p + 2]])
        .collect();
    let d_alpha: Vec<f32> = (0..px).map(|p| u.rgba[4 * p + 3]).collect();
    dispflow_vk::reference::raster::blend_bwd(
        bp,
        proj,
        features,
        fwd,
        &d_rgb,
        &d_alpha,
        &u.depth,
        &u.features,
    )
}

/// On lavapipe with more than one thread (float-atomic sums in any order), re-runs the test
/// `name` of this binary serially ([`testing::LP_SERIAL`]) and checks it passed, then gives
/// `None` (the caller returns); gives the device back where the run is already
/// bit-reproducible. The device is released before the re-run, so this process's other tests
/// use it meanwhile (holding it serialised them behind the child: raster_binning's 15 s).
pub fn rerun_single_threaded(gpu: TestGpu, name: &str) -> Option<TestGpu> {
    if !gpu.info.name.contains("llvmpipe") || testing::lavapipe_is_serial() {
        return Some(gpu);
    }
    drop(gpu);
    let exe = std::env::current_exe().expect("the test binary's path");
    let out = std::process::Command::new(exe)
        .args([name, "--exact", "--nocapture"])
        .env("LP_NUM_THREADS", testing::LP_SERIAL)
        .output()
        .expect("re-run the test single-threaded");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.status.success() && text.contains("1 passed"),
        "single-threaded re-run:\n{text}"
    );
    None
}

/// The twin's blend parameters for a render of `cam` with `opts` and `k` feature channels.
pub fn twin_blend_params(
    cam: &Camera,
    opts: &RenderOpts,
    k: u32,
) -> dispflow_vk::reference::raster::BlendParams {
    dispflow_vk::reference::raster::BlendParams {
        width: cam.width,
        height: cam.height,
        alpha_max: opts.alpha_max,
        background: opts.background,
        feature_dims: k,
    }
}
