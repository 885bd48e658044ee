//! The opacity-aware tile boxes (`SplatExtent::OpacityBox`, `opacity_rect` in
//! glsl/include/raster.glsl, with the CPU blends' row skip) against the 3σ squares
//! (`SplatExtent::Radius`, every row): on scenes full of faint Gaussians, with needles and
//! Gaussians too large for the box, every blend output and every gradient of every blend
//! variant is bit for bit the same, the tile intersections are strictly fewer, a
//! Gaussian fainter than 1/255 touches no tile, and the GPU's boxes are the twin's (with and
//! without opacity factors). The twin's blend is unchanged by its boxes too.
//!
//! Gradients are float-atomic sums: bit-reproducible on one lavapipe thread only, so the GPU
//! comparison re-runs itself on serial lavapipe (`testing::LP_SERIAL`) there.

mod raster_common;

use dispflow_vk::kernels::raster::{
    BlendFwdVariant, RasterBuffers, Rasterizer, RenderOpts, SplatExtent, SplatInputs,
};
use dispflow_vk::reference::raster as twin;
use dispflow_vk::testing::{self, Noise, TestGpu};
use raster_common::*;

const TEST_BITS: &str = "boxes_change_no_pixel_and_no_gradient";

/// `random_scene` with opacities from 0.0009 to 0.73 (a third of them below 1/255), a few
/// needles (long enough that the box is much smaller than the square, and one past the box's
/// growth limit) and a few Gaussians so large that the square stands.
fn faint_scene(seed: u64, n: usize, k: u32) -> Scene {
    let mut s = random_scene(seed, n, 1, k);
    let mut r = Noise::new(seed ^ 0x5eed);
    for l in s.logits.iter_mut() {
        *l = r.uniform(-7.0, 1.0);
    }
    for i in 0..n / 20 {
        s.scales[i] = [r.uniform(0.5, 3.0), 0.004, 0.01];
        s.logits[i] = r.uniform(-4.0, 2.0);
    }
    for i in n / 20..n / 20 + 3 {
        s.scales[i] = [2.5, 2.0, 2.2];
    }
    s
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

fn assert_same_bits(what: &str, got: &[f32], want: &[f32]) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    let (g, w) = (bits(got), bits(want));
    if let Some(i) = (0..g.len()).find(|&i| g[i] != w[i]) {
        panic!(
            "{what}: element {i} is {} with boxes, {} with squares",
            got[i], want[i]
        );
    }
}

fn render_with(
    gpu: &TestGpu,
    rast: &mut Rasterizer,
    e: SplatExtent,
    cam: &dispflow_vk::kernels::raster::Camera,
    up: &Uploaded,
    opts: &RenderOpts,
) -> (RasterBuffers, Rendered) {
    rast.set_splat_extent(e);
    render(gpu, rast, cam, up, opts)
}

#[test]
fn boxes_change_no_pixel_and_no_gradient() {
    let Some(gpu) = rerun_single_threaded(testing::gpu(), TEST_BITS) else {
        return;
    };
    let mut rast = Rasterizer::new(&gpu).unwrap();
    assert_eq!(rast.splat_extent(), SplatExtent::OpacityBox, "the default");
    for (seed, n, w, h, k) in [
        (1, 400, 64, 48, 0),
        (2, 600, 97, 71, 3),
        (3, 300, 40, 90, 6),
    ] {
        let scene = faint_scene(seed, n, k);
        let cam = camera(w, h);
        let up = Uploaded::new(&gpu, &scene);
        let opts = RenderOpts {
            background: [0.1, 0.2, 0.3],
            alpha_max: 0.99,
            abs_grad: true,
            detach_feature_weights: k > 0,
        };
        let u = upstream(seed + 10, (w * h) as usize, k as usize);
        for fv in BlendFwdVariant::ALL {
            rast.set_blend_fwd_variant(fv);
            let ctx = format!("seed {seed}, {w}x{h}, k {k}, blend_fwd {}", fv.name());
            let (bs, sq) = render_with(&gpu, &mut rast, SplatExtent::Radius, &cam, &up, &opts);
            let (bb, bx) = render_with(&gpu, &mut rast, SplatExtent::OpacityBox, &cam, &up, &opts);
            let (is, ib) = (
                bs.intersections(&gpu).unwrap(),
                bb.intersections(&gpu).unwrap(),
            );
            assert!(
                ib < is,
                "{ctx}: {ib} intersections with boxes, {is} with squares"
            );
            println!("{ctx}: {ib} intersections with boxes, {is} with squares");
            let flat = |r: &Rendered| r.rgba.as_flattened().to_vec();
            assert_same_bits(&format!("{ctx}: rgba"), &flat(&bx), &flat(&sq));
            assert_same_bits(&format!("{ctx}: depth"), &bx.depth, &sq.depth);
            assert_same_bits(&format!("{ctx}: final T"), &bx.final_t, &sq.final_t);
            assert_same_bits(&format!("{ctx}: features"), &bx.features, &sq.features);
            let grads_s = backward_each(&gpu, &mut rast, &bs, &cam, &up, &opts, &u);
            let grads_b = backward_each(&gpu, &mut rast, &bb, &cam, &up, &opts, &u);
            for ((bv, gb), (_, gs)) in grads_b.into_iter().zip(grads_s) {
                let c = format!("{ctx}, blend_bwd {}", bv.name());
                assert_same_bits(&format!("{c}: grad2d"), &gb.grad2d, &gs.grad2d);
                assert_same_bits(&format!("{c}: d features"), &gb.d_features, &gs.d_features);
                assert_same_bits(&format!("{c}: d means"), &gb.d_means, &gs.d_means);
                assert_same_bits(&format!("{c}: d scales"), &gb.d_scales, &gs.d_scales);
                assert_same_bits(&format!("{c}: d quats"), &gb.d_quats, &gs.d_quats);
                assert_same_bits(&format!("{c}: d logits"), &gb.d_logits, &gs.d_logits);
                assert_same_bits(&format!("{c}: d sh"), &gb.d_sh, &gs.d_sh);
            }
        }
        rast.set_blend_fwd_variant(BlendFwdVariant::for_device(&gpu.info));
    }
}

/// The GPU's rectangles: the twin's boxes (or squares), none for a visible Gaussian fainter
/// than 1/255; with opacity factors, the boxes of the factored opacities.
#[test]
#[allow(clippy::needless_range_loop)] // i indexes the GPU's rects and the twin's fields alike
fn gpu_boxes_are_the_twins() {
    let gpu = testing::gpu();
    let mut rast = Rasterizer::new(&gpu).unwrap();
    let opts = RenderOpts {
        background: [0.0; 3],
        alpha_max: 0.99,
        abs_grad: false,
        detach_feature_weights: false,
    };
    for (seed, n, w, h) in [(4, 500, 64, 48), (5, 800, 130, 70)] {
        let scene = faint_scene(seed, n, 0);
        let cam = camera(w, h);
        let up = Uploaded::new(&gpu, &scene);
        let mut r = Noise::new(seed);
        let factors: Vec<f32> = (0..n)
            .map(|i| if i % 7 == 0 { 0.0 } else { r.uniform(0.0, 1.5) })
            .collect();
        let fbuf = gpu.buffer_from("opacity factors", &factors).unwrap();
        let g = scene.twin();
        let g64 = twin::Gaussians64::from_f32(&g);
        let w64: Vec<f64> = factors.iter().map(|&x| x as f64).collect();
        let cases = [
            (SplatExtent::Radius, None, twin::project_f64(&cam, &g64)),
            (SplatExtent::OpacityBox, None, twin::project_f64(&cam, &g64)),
            (
                SplatExtent::OpacityBox,
                Some(fbuf.all()),
                twin::project_scaled_f64(&cam, &g64, &w64),
            ),
        ];
        for (e, f, proj) in cases {
            let ctx = format!("seed {seed}, {}, factors {}", e.name(), f.is_some());
            rast.set_splat_extent(e);
            let inputs = SplatInputs {
                opacity_scale: f,
                ..up.inputs()
            };
            let size = dispflow_vk::kernels::raster::RasterSize {
                max_gaussians: up.n,
                width: w,
                height: h,
                sh_coeffs: up.sh_coeffs,
                feature_dims: 0,
                isect_capacity: 64,
            };
            let mut b = rast.buffers(&gpu, &size).unwrap();
            rast.render_checked(&gpu, &mut b, &cam, &inputs, &opts)
                .unwrap();
            let rects = b.tile_rects(&gpu, up.n).unwrap();
            let (mut faint, mut shrunk) = (0, 0);
            for i in 0..n {
                let square = twin::radius_rect(&cam, proj.mean2d[i], proj.radius[i]);
                let want = match e {
                    _ if proj.radius[i] == 0 => [0; 4],
                    SplatExtent::Radius => square,
                    SplatExtent::OpacityBox => proj.tile_rect[i],
                };
                assert_eq!(rects[i], want, "{ctx}: gaussian {i}");
                if proj.radius[i] > 0 && (proj.opacity[i] as f32) < 1.0 / 255.0 {
                    if e == SplatExtent::OpacityBox {
                        assert_eq!(rects[i], [0; 4], "{ctx}: faint {i} touches tiles");
                    }
                    faint += 1;
                }
                let area = |r: [u32; 4]| (r[2] - r[0]) * (r[3] - r[1]);
                shrunk += (proj.radius[i] > 0 && area(want) < area(square)) as usize;
            }
            assert!(
                faint > n / 20 && (e == SplatExtent::Radius || shrunk > n / 4),
                "{ctx}: {faint} faint and {shrunk} shrunk of {n}: the scene tests little"
            );
        }
    }
}

/// The twin's blend over its boxes equals its blend over the 3σ squares exactly (f64), the
/// forward and the backward; only the contributor positions (`n_contrib`) differ.
#[test]
fn twin_blend_is_the_same_over_boxes() {
    for (seed, n, w, h, k) in [(6, 300, 48, 40, 0), (7, 300, 40, 33, 3)] {
        let scene = faint_scene(seed, n, k);
        let cam = camera(w, h);
        let g64 = twin::Gaussians64::from_f32(&scene.twin());
        let boxes = twin::project_f64(&cam, &g64);
        let mut squares = boxes.clone();
        for i in 0..n {
            if boxes.radius[i] > 0 {
                squares.tile_rect[i] = twin::radius_rect(&cam, boxes.mean2d[i], boxes.radius[i]);
            }
        }
        assert_ne!(
            boxes.tile_rect, squares.tile_rect,
            "seed {seed}: no box is smaller"
        );
        let bp = twin::BlendParams {
            width: w,
            height: h,
            alpha_max: 0.99,
            background: [0.1, 0.2, 0.3],
            feature_dims: k,
        };
        let feats: Vec<f64> = scene.features.iter().map(|&x| x as f64).collect();
        let fb = twin::blend_fwd_f64(&bp, &boxes, &feats);
        let fs = twin::blend_fwd_f64(&bp, &squares, &feats);
        assert_eq!(fb.rgb, fs.rgb, "seed {seed}: rgb");
        assert_eq!(fb.alpha, fs.alpha, "seed {seed}: alpha");
        assert_eq!(fb.depth, fs.depth, "seed {seed}: depth");
        assert_eq!(fb.final_t, fs.final_t, "seed {seed}: final T");
        assert_eq!(fb.features, fs.features, "seed {seed}: features");
        let u = upstream(seed, (w * h) as usize, k as usize);
        let px = (w * h) as usize;
        let d_rgb: Vec<[f32; 3]> = (0..px)
            .map(|p| [u.rgba[4 * p], u.rgba[4 * p + 1], u.rgba[4 * p + 2]])
            .collect();
        let d_alpha: Vec<f32> = (0..px).map(|p| u.rgba[4 * p + 3]).collect();
        let bwd = |proj: &twin::Projected64| {
            twin::blend_bwd_f64(&bp, proj, &feats, &d_rgb, &d_alpha, &u.depth, &u.features)
        };
        let (gb, gs) = (bwd(&boxes), bwd(&squares));
        assert_eq!(gb.mean2d, gs.mean2d, "seed {seed}: d mean2d");
        assert_eq!(gb.mean2d_abs, gs.mean2d_abs, "seed {seed}: Σ|d mean2d|");
        assert_eq!(gb.conic, gs.conic, "seed {seed}: d conic");
        assert_eq!(gb.opacity, gs.opacity, "seed {seed}: d opacity");
        assert_eq!(gb.color, gs.color, "seed {seed}: d colour");
        assert_eq!(gb.depth, gs.depth, "seed {seed}: d depth");
        assert_eq!(gb.features, gs.features, "seed {seed}: d features");
    }
}

dispflow_vk::subgroup_reruns!();
