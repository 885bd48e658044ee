//! The GPU rasteriser against gsplat (CUDA, "classic" mode): an external oracle computed by the
//! most used 3DGS implementation (../shared/data/gsplat-reference, conventions in its README).

use std::path::PathBuf;

use dispflow_vk::kernels::raster::{
    join_sh, split_sh, BlendBwdVariant, BlendFwdVariant, Camera, DeviceShape, OutputGrads,
    RasterSize, Rasterizer, RenderOpts, SplatInputs, G2D_STRIDE,
};
use dispflow_vk::testing::{self, assert_close, Tol};
use dispflow_vk::vk::Recorder;

fn data_dir() -> Option<PathBuf> {
    let d = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/gsplat-reference");
    d.is_dir().then_some(d)
}

struct Case {
    t: std::collections::HashMap<String, Vec<f32>>,
}

impl Case {
    fn load(name: &str) -> Option<Case> {
        let Some(dir) = data_dir() else {
            dispflow_vk::testing::skip(
                "the gsplat oracle",
                "../shared/data/gsplat-reference not found",
            );
            return None;
        };
        let bytes = std::fs::read(dir.join(name)).expect("read safetensors");
        let st = safetensors::SafeTensors::deserialize(&bytes).expect("parse safetensors");
        let t = st
            .tensors()
            .into_iter()
            .map(|(k, v)| {
                (
                    k.to_string(),
                    bytemuck::pod_collect_to_vec::<u8, f32>(v.data()),
                )
            })
            .collect();
        Some(Case { t })
    }
    fn get(&self, k: &str) -> &[f32] {
        &self.t[k]
    }
}

fn camera() -> Camera {
    Camera {
        rot: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        trans: [-0.123, -0.456, 8.0],
        fx: 61.5,
        fy: 61.5,
        cx: 61.5,
        cy: 41.0,
        width: 123,
        height: 82,
        near: 0.01,
    }
}

fn run(name: &str) {
    let Some(c) = Case::load(name) else { return };
    let gpu = testing::gpu();
    let mut rast = Rasterizer::new(&gpu).unwrap();
    let n = c.get("opacities").len() as u32;
    let scales: Vec<f32> = c.get("scales").iter().map(|s| s.exp()).collect();
    let means = gpu.buffer_from("means", c.get("means")).unwrap();
    let sc = gpu.buffer_from("scales", &scales).unwrap();
    let quats = gpu.buffer_from("quats", c.get("quats")).unwrap();
    let op = gpu.buffer_from("opacities", c.get("opacities")).unwrap();
    let (dc, rest) = split_sh(c.get("coeffs"), 16);
    let sh_dc = gpu.buffer_from("sh dc", &dc).unwrap();
    let sh_rest = gpu.buffer_from("sh rest", &rest).unwrap();
    let cam = camera();
    let g = SplatInputs {
        n,
        means: means.all(),
        scales: sc.all(),
        quats: quats.all(),
        opacity_logits: op.all(),
        sh_dc: sh_dc.all(),
        sh_rest: sh_rest.all(),
        sh_coeffs: 16,
        sh_degree: 3,
        features: None,
        opacity_scale: None,
    };
    let opts = RenderOpts {
        background: [0.0; 3],
        alpha_max: 0.999,
        abs_grad: false,
        detach_feature_weights: false,
    };
    // Start with a capacity too small on purpose: render_checked must grow and re-run.
    let size = RasterSize {
        max_gaussians: n,
        width: cam.width,
        height: cam.height,
        sh_coeffs: 16,
        feature_dims: 0,
        isect_capacity: 1,
    };
    // Every blend-forward variant, each followed by every blend-backward variant.
    for fv in BlendFwdVariant::ALL {
        rast.set_blend_fwd_variant(fv);
        let fw = |x: &str| format!("blend_fwd {}: {x}", fv.name());
        let mut b = rast.buffers(&gpu, &size).unwrap();
        for buf in [&b.out_rgba, &b.splats, &b.grad2d, &b.d_means] {
            testing::fill_noise(&gpu, buf, 7);
        }
        rast.render_checked(&gpu, &mut b, &cam, &g, &opts).unwrap();
        assert!(b.isect_capacity() >= b.intersections(&gpu).unwrap());

        let splats: Vec<f32> = gpu
            .read(b.splats.elems::<[f32; 4]>(0, 3 * n as u64))
            .unwrap();
        let xys: Vec<f32> = (0..n as usize)
            .flat_map(|i| [splats[12 * i], splats[12 * i + 1]])
            .collect();
        let depths: Vec<f32> = (0..n as usize).map(|i| splats[12 * i + 2]).collect();
        let conics: Vec<f32> = (0..n as usize)
            .flat_map(|i| [splats[12 * i + 4], splats[12 * i + 5], splats[12 * i + 6]])
            .collect();
        assert_close(
            &fw("xys"),
            &xys,
            c.get("xys"),
            Tol::Elementwise {
                abs: 1e-4,
                rel: 1e-5,
            },
        );
        assert_close(
            &fw("depths"),
            &depths,
            c.get("depths"),
            Tol::Elementwise {
                abs: 1e-5,
                rel: 1e-6,
            },
        );
        assert_close(
            &fw("conics"),
            &conics,
            c.get("conics"),
            Tol::Elementwise {
                abs: 1e-6,
                rel: 1e-4,
            },
        );
        let img: Vec<f32> = gpu.read(b.out_rgba.all()).unwrap();
        assert_close(
            &fw("out_img"),
            &img,
            c.get("out_img"),
            Tol::Elementwise {
                abs: 2e-5,
                rel: 1e-4,
            },
        );

        let d_rgba = gpu.buffer_from("v_out_img", c.get("v_out_img")).unwrap();
        let d_depth = gpu
            .buffer_from(
                "zero depth grad",
                &vec![0f32; (cam.width * cam.height) as usize],
            )
            .unwrap();
        // Every blend-backward variant against the oracle.
        for v in BlendBwdVariant::ALL {
            rast.set_blend_bwd_variant(v);
            let what = |x: &str| format!("blend_fwd {}, blend_bwd {}: {x}", fv.name(), v.name());
            testing::fill_noise(&gpu, &b.grad2d, 8);
            let mut rec = Recorder::new(&gpu).unwrap();
            rast.backward(
                &mut rec,
                &b,
                &cam,
                &g,
                &opts,
                &OutputGrads {
                    rgba: d_rgba.all(),
                    depth: Some(d_depth.all()),
                    features: None,
                },
            );
            rec.finish().unwrap();
            let g2: Vec<f32> = gpu.read(b.grad2d.all()).unwrap();
            let s = G2D_STRIDE as usize;
            let v_xy: Vec<f32> = (0..n as usize)
                .flat_map(|i| [g2[s * i], g2[s * i + 1]])
                .collect();
            let v_con: Vec<f32> = (0..n as usize)
                .flat_map(|i| [g2[s * i + 2], g2[s * i + 3], g2[s * i + 4]])
                .collect();
            // Stored gradients carry ~4 significant digits (README): rel 2e-3, abs 1e-7.
            let (abs, rel) = (1e-7, 2e-3);
            assert_close(
                &what("v_xy"),
                &v_xy,
                c.get("v_xy"),
                Tol::Elementwise { abs, rel },
            );
            assert_close(
                &what("v_conics"),
                &v_con,
                c.get("v_conics"),
                Tol::Elementwise { abs, rel },
            );
            let rd = |buf: &dispflow_vk::vk::Buffer, len: usize| -> Vec<f32> {
                gpu.read::<f32>(buf.all()).unwrap()[..len].to_vec()
            };
            let nn = n as usize;
            assert_close(
                &what("v_means"),
                &rd(&b.d_means, 3 * nn),
                c.get("v_means"),
                Tol::Elementwise { abs, rel },
            );
            // gsplat differentiates log-scales: ∂L/∂log s = s · ∂L/∂s.
            let v_log: Vec<f32> = rd(&b.d_scales, 3 * nn)
                .iter()
                .zip(&scales)
                .map(|(g, s)| g * s)
                .collect();
            assert_close(
                &what("v_scales"),
                &v_log,
                c.get("v_scales"),
                Tol::Elementwise { abs, rel },
            );
            assert_close(
                &what("v_quats"),
                &rd(&b.d_quats, 4 * nn),
                c.get("v_quats"),
                Tol::Elementwise { abs, rel },
            );
            assert_close(
                &what("v_opacities"),
                &rd(&b.d_opacity_logits, nn),
                c.get("v_opacities"),
                Tol::Elementwise { abs, rel },
            );
            assert_close(
                &what("v_coeffs"),
                &join_sh(&rd(&b.d_sh_dc, 3 * nn), &rd(&b.d_sh_rest, 45 * nn), 16),
                c.get("v_coeffs"),
                Tol::Elementwise { abs, rel },
            );
        }
    }
}

#[test]
fn tiny_case_matches_gsplat() {
    run("tiny_case.safetensors");
}

#[test]
fn basic_case_matches_gsplat() {
    run("basic_case.safetensors");
}

dispflow_vk::subgroup_reruns!();
