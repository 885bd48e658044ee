//! GPU rasteriser vs its CPU twin (`reference::raster`, f64 inside) on identical inputs:
//! projection, blend forward (RGB, alpha, depth, transmittance, contributor counts, feature
//! channels), blend backward and project backward, on random scenes at several image sizes,
//! SH degrees and feature counts; and the opacity factors held constant in the blend of the
//! feature channels (`RenderOpts::detach_feature_weights`), against the twin and finite
//! differences.
//!
//! Tolerances: forward values are f32 on the GPU against f64-then-rounded in the twin, so a few
//! ulps of the largest term (abs 2e-5 on [0,1] colours). Gradients are sums of many per-pixel
//! terms accumulated with float atomics in arbitrary order and un-blended with T / (1 − α)
//! on the GPU; they are compared per quantity kind as max |gpu − twin| <= 2e-3 · max |twin|
//! + 1e-7.

mod raster_common;

use dispflow_vk::kernels::raster::{
    BlendBwdVariant, BlendFwdVariant, OutputGrads, RasterSize, Rasterizer, RenderOpts, SplatInputs,
    BAND_COVER_MAX, BAND_LIST_MAX, G2D_STRIDE,
};
use dispflow_vk::reference::raster as twin;
use dispflow_vk::testing::{self, assert_close, Noise, Tol};
use dispflow_vk::vk::Recorder;
use raster_common::*;

/// Gradients of one kind (all d mean2d, all d conic, …) against the twin's: one scale per
/// kind, its largest |twin|.
const KIND: Tol = Tol::Normwise {
    abs: 1e-7,
    rel: 2e-3,
};

fn compare(seed: u64, n: usize, w: u32, h: u32, sh_degree: u32, k: u32) {
    let gpu = testing::gpu();
    let mut rast = Rasterizer::new(&gpu).unwrap();
    let scene = random_scene(seed, n, sh_degree, k);
    let cam = camera(w, h);
    // Even seeds also accumulate the absolute statistic (slots 10-11); odd ones must leave
    // them at zero.
    let opts = RenderOpts {
        background: [0.1, 0.2, 0.3],
        alpha_max: 0.99,
        abs_grad: seed % 2 == 0,
        detach_feature_weights: false,
    };
    let up = Uploaded::new(&gpu, &scene);
    // Every forward variant, and every backward variant after each (the backward reads the
    // forward's final T and last contributors).
    let forwards = render_each_access(&gpu, &mut rast, &cam, &up, &opts);
    // The whole tile through texel and through storage buffers: the same bits.
    same_bits("forward", &forwards[1].2, &forwards[forwards.len() - 1].2);
    for (fv, b, out) in forwards {
        let ctx = format!(
            "seed {seed}, n {n}, {w}x{h}, sh {sh_degree}, k {k}, blend_fwd {}",
            fv.name()
        );

        let g = scene.twin();
        let tcam = cam;
        let proj = twin::project(&tcam, &g);
        let splats: Vec<[f32; 4]> = gpu
            .read(b.splats.elems::<[f32; 4]>(0, 3 * n as u64))
            .unwrap();
        let mut visible = 0;
        for i in 0..n {
            let (a, c, col) = (splats[3 * i], splats[3 * i + 1], splats[3 * i + 2]);
            let twin_vis = proj.radius[i] > 0;
            assert_eq!(c[3] > 0.0, twin_vis, "{ctx}: gaussian {i} visibility");
            if !twin_vis {
                continue;
            }
            visible += 1;
            assert_close(
                &format!("{ctx}: mean2d {i}"),
                &a[..2],
                &proj.mean2d[i],
                Tol::Elementwise {
                    abs: 1e-3,
                    rel: 1e-6,
                },
            );
            assert_close(
                &format!("{ctx}: depth {i}"),
                &a[2..3],
                &[proj.depth[i]],
                Tol::Elementwise {
                    abs: 0.0,
                    rel: 1e-6,
                },
            );
            assert_close(
                &format!("{ctx}: opacity {i}"),
                &a[3..4],
                &[proj.opacity[i]],
                Tol::Elementwise {
                    abs: 1e-7,
                    rel: 1e-6,
                },
            );
            assert_close(
                &format!("{ctx}: conic {i}"),
                &c[..3],
                &proj.conic[i],
                Tol::Elementwise {
                    abs: 1e-7,
                    rel: 1e-4,
                },
            );
            assert_close(
                &format!("{ctx}: colour {i}"),
                &col[..3],
                &proj.color[i],
                Tol::Elementwise {
                    abs: 1e-6,
                    rel: 1e-5,
                },
            );
        }
        assert!(
            visible > n / 3,
            "{ctx}: only {visible} of {n} visible: the scene tests little"
        );

        let bp = twin_blend_params(&cam, &opts, k);
        let fwd = twin::blend_fwd(&bp, &proj, &scene.features);
        let px = (w * h) as usize;
        let rgb: Vec<f32> = out.rgba.iter().flat_map(|p| [p[0], p[1], p[2]]).collect();
        let alpha: Vec<f32> = out.rgba.iter().map(|p| p[3]).collect();
        assert_close(
            &format!("{ctx}: rgb"),
            &rgb,
            fwd.rgb.as_flattened(),
            Tol::Elementwise {
                abs: 2e-5,
                rel: 0.0,
            },
        );
        assert_close(
            &format!("{ctx}: alpha"),
            &alpha,
            &fwd.alpha,
            Tol::Elementwise {
                abs: 2e-5,
                rel: 0.0,
            },
        );
        assert_close(
            &format!("{ctx}: depth"),
            &out.depth,
            &fwd.depth,
            Tol::Elementwise {
                abs: 2e-5,
                rel: 2e-5,
            },
        );
        assert_close(
            &format!("{ctx}: final T"),
            &out.final_t,
            &fwd.final_t,
            Tol::Elementwise {
                abs: 2e-5,
                rel: 1e-4,
            },
        );
        assert_close(
            &format!("{ctx}: features"),
            &out.features,
            &fwd.features,
            Tol::Elementwise {
                abs: 2e-5,
                rel: 2e-5,
            },
        );
        let diff = out
            .n_contrib
            .iter()
            .zip(&fwd.n_contrib)
            .filter(|(a, b)| a != b)
            .count();
        assert_eq!(
            diff, 0,
            "{ctx}: {diff} pixels disagree on the last contributor"
        );

        let u = upstream(seed + 100, px, k as usize);
        let bg = twin_blend_bwd(&bp, &proj, &scene.features, &fwd, &u);
        let pg = twin::project_bwd(&tcam, &g, &proj, &bg);
        for (v, grads) in backward_each_access(&gpu, &mut rast, &b, &cam, &up, &opts, &u) {
            let ctx = format!("{ctx}, blend_bwd {}", v.name());
            check_grads(&ctx, n, &grads, &bg, &pg, opts.abs_grad);
        }
    }
}

/// Two renders with the same bits in every output.
fn same_bits(what: &str, a: &Rendered, b: &Rendered) {
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let rgba = |r: &Rendered| bits(&r.rgba.concat());
    assert!(
        rgba(a) == rgba(b)
            && bits(&a.depth) == bits(&b.depth)
            && bits(&a.final_t) == bits(&b.final_t)
            && a.n_contrib == b.n_contrib
            && bits(&a.features) == bits(&b.features),
        "{what}: the whole tile differs between texel and storage buffers"
    );
}

/// Every gradient of one backward run against the twin's.
fn check_grads(
    ctx: &str,
    n: usize,
    grads: &Grads,
    bg: &twin::BlendGrads,
    pg: &twin::ProjectGrads,
    abs_grad: bool,
) {
    let s = G2D_STRIDE as usize;
    let col = |lo: usize, hi: usize| -> Vec<f32> {
        (0..n)
            .flat_map(|i| grads.grad2d[s * i + lo..s * i + hi].to_vec())
            .collect()
    };
    assert_close(
        &format!("{ctx}: d mean2d"),
        &col(0, 2),
        bg.mean2d.as_flattened(),
        KIND,
    );
    assert_close(
        &format!("{ctx}: d conic"),
        &col(2, 5),
        bg.conic.as_flattened(),
        KIND,
    );
    assert_close(&format!("{ctx}: d opacity"), &col(5, 6), &bg.opacity, KIND);
    assert_close(
        &format!("{ctx}: d colour"),
        &col(6, 9),
        bg.color.as_flattened(),
        KIND,
    );
    assert_close(&format!("{ctx}: d depth"), &col(9, 10), &bg.depth, KIND);
    if abs_grad {
        let abs = col(10, 12);
        assert_close(
            &format!("{ctx}: Σ|d mean2d|"),
            &abs,
            bg.mean2d_abs.as_flattened(),
            KIND,
        );
        // |Σ| ≤ Σ|·| per component: the statistic bounds the plain gradient.
        for (a, m) in abs.iter().zip(col(0, 2)) {
            assert!(
                *a >= m.abs() * (1.0 - 1e-3) - 1e-7,
                "{ctx}: Σ|g| {a} < |Σg| {m}"
            );
        }
    } else {
        assert!(
            col(10, 12).iter().all(|&v| v == 0.0),
            "{ctx}: slots 10-11 written"
        );
    }
    assert!(
        col(12, 13).iter().all(|&v| v == 0.0),
        "{ctx}: slot 12 written without detach_feature_weights"
    );
    assert_close(
        &format!("{ctx}: d features"),
        &grads.d_features,
        &bg.features,
        KIND,
    );

    assert_close(
        &format!("{ctx}: d means"),
        &grads.d_means,
        pg.means.as_flattened(),
        KIND,
    );
    assert_close(
        &format!("{ctx}: d scales"),
        &grads.d_scales,
        pg.scales.as_flattened(),
        KIND,
    );
    assert_close(
        &format!("{ctx}: d quats"),
        &grads.d_quats,
        pg.quats.as_flattened(),
        KIND,
    );
    assert_close(
        &format!("{ctx}: d logits"),
        &grads.d_logits,
        &pg.opacity_logits,
        KIND,
    );
    assert_close(&format!("{ctx}: d sh"), &grads.d_sh, &pg.sh, KIND);
}

#[test]
fn small_images_and_one_pixel() {
    for seed in [1, 2, 3] {
        compare(seed, 40, 1, 1, 0, 0);
        compare(seed, 60, 17, 13, 1, 3);
    }
}

#[test]
fn medium_images_all_feature_counts() {
    for (seed, k) in [(4, 0), (5, 2), (6, 3), (8, 6)] {
        compare(seed, 200, 64, 48, 3, k);
    }
}

#[test]
fn non_square_and_multi_batch_tiles() {
    // 700 Gaussians on a narrow image: tiles hold more than one 256-splat batch.
    compare(7, 700, 96, 40, 2, 3);
}

dispflow_vk::subgroup_reruns!();

/// The transients' temporal weights detached in the motion pass: opacity factors (every fourth
/// Gaussian culled) and 3 feature channels with upstream gradients on every output. Per
/// blend-backward variant, attached and detached: slot 12 (the features' share of the opacity
/// gradient), ∂L/∂w and ∂L/∂logit against the twin. The twin: its attached ∂L/∂w against
/// central differences of the whole rendered loss, its detached one against those of the loss
/// without the feature channels (the factor a constant in their blend), the logits' gradient
/// the same either way, and the features' share large enough that the two choices differ.
#[test]
fn feature_weights_detached_from_the_opacity_factors() {
    let gpu = testing::gpu();
    let mut rast = Rasterizer::new(&gpu).unwrap();
    let (k, cam) = (3u32, camera(40, 32));
    let scene = random_scene(31, 80, 1, k);
    let n = scene.len();
    let mut r = Noise::new(32);
    let w: Vec<f32> = (0..n)
        .map(|i| match i % 4 {
            0 => 0.0,
            _ => 0.05 + 0.95 * (r.next_u32() as f32 / 4_294_967_296.0),
        })
        .collect();
    let up = Uploaded::new(&gpu, &scene);
    let wb = gpu.buffer_from("w", &w).unwrap();
    let g = SplatInputs {
        opacity_scale: Some(wb.all()),
        ..up.inputs()
    };
    let size = RasterSize {
        max_gaussians: n as u32,
        width: cam.width,
        height: cam.height,
        sh_coeffs: up.sh_coeffs,
        feature_dims: k,
        isect_capacity: 64,
    };
    let mut b = rast.buffers(&gpu, &size).unwrap();
    let base = RenderOpts {
        background: [0.1, 0.2, 0.3],
        ..RenderOpts::default()
    };
    rast.render_checked(&gpu, &mut b, &cam, &g, &base).unwrap();
    let px = (cam.width * cam.height) as usize;
    let u = upstream(33, px, k as usize);

    // The twin, f64 from the same f32 inputs.
    let g64 = twin::Gaussians64::from_f32(&scene.twin());
    let w64: Vec<f64> = w.iter().map(|&v| v as f64).collect();
    let feats: Vec<f64> = scene.features.iter().map(|&v| v as f64).collect();
    let bp = twin_blend_params(&cam, &base, k);
    let d_rgb: Vec<[f64; 3]> = (0..px)
        .map(|p| std::array::from_fn(|c| u.rgba[4 * p + c] as f64))
        .collect();
    let d_alpha: Vec<f64> = (0..px).map(|p| u.rgba[4 * p + 3] as f64).collect();
    let d_depth: Vec<f64> = u.depth.iter().map(|&v| v as f64).collect();
    let d_feat: Vec<f64> = u.features.iter().map(|&v| v as f64).collect();
    let none: &[f64] = &[];
    let proj = twin::project_scaled_f64(&cam, &g64, &w64);
    let bg = twin::blend_bwd_f64(&bp, &proj, &feats, &d_rgb, &d_alpha, &d_depth, &d_feat);
    let photo = twin::blend_bwd_f64(&bp, &proj, &feats, &d_rgb, &d_alpha, &d_depth, none);
    let (pg_a, dw_a) = twin::project_scaled_bwd_f64(&cam, &g64, &w64, &bg, false);
    let (pg_d, dw_d) = twin::project_scaled_bwd_f64(&cam, &g64, &w64, &bg, true);
    let max = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for i in 0..n {
        let share = bg.opacity[i] - photo.opacity[i];
        assert!(
            (share - bg.opacity_features[i]).abs() <= 1e-9 * (1.0 + bg.opacity[i].abs()),
            "twin: Gaussian {i}'s feature share {} against full − photometric {share}",
            bg.opacity_features[i]
        );
    }
    assert_eq!(
        pg_a.opacity_logits, pg_d.opacity_logits,
        "logits keep every share"
    );
    let spread = dw_a.iter().zip(&dw_d).map(|(a, d)| (a - d).abs());
    let differ = spread.fold(0.0f64, f64::max);
    assert!(
        differ > 0.05 * max(&dw_a),
        "the features' share is too small to tell the choices apart ({differ:.3e})"
    );

    // Twin against central differences: attached = the whole loss, detached = the loss
    // without the feature channels.
    let loss = |w: &[f64], with_features: bool| -> f64 {
        let p = twin::project_scaled_f64(&cam, &g64, w);
        let o = twin::blend_fwd_f64(&bp, &p, &feats);
        let mut l = 0.0;
        for q in 0..px {
            l += (0..3).map(|c| d_rgb[q][c] * o.rgb[q][c]).sum::<f64>()
                + d_alpha[q] * o.alpha[q]
                + d_depth[q] * o.depth[q];
            if with_features {
                let f = k as usize;
                l += (0..f)
                    .map(|c| d_feat[q * f + c] * o.features[q * f + c])
                    .sum::<f64>();
            }
        }
        l
    };
    let h = 1e-6;
    let mut checked = 0;
    for i in (0..n)
        .filter(|&i| w[i] > 0.1 && proj.radius[i] > 0)
        .take(12)
    {
        for (with_features, want) in [(true, dw_a[i]), (false, dw_d[i])] {
            let (mut a, mut c) = (w64.clone(), w64.clone());
            a[i] += h;
            c[i] -= h;
            let fd = (loss(&a, with_features) - loss(&c, with_features)) / (2.0 * h);
            assert!(
                (fd - want).abs() <= 1e-5 * (1.0 + fd.abs()),
                "w {i} (features {with_features}): fd {fd}, twin {want}"
            );
        }
        checked += 1;
    }
    assert!(checked > 5, "{checked} factors checked");

    // The GPU, every blend-backward variant, attached and detached.
    let (dr, dd, df) = (
        gpu.buffer_from("d rgba", &u.rgba).unwrap(),
        gpu.buffer_from("d depth", &u.depth).unwrap(),
        gpu.buffer_from("d features", &u.features).unwrap(),
    );
    let s = G2D_STRIDE as usize;
    let default = rast.blend_bwd_variant();
    for v in BlendBwdVariant::ALL {
        rast.set_blend_bwd_variant(v);
        for detach in [false, true] {
            let ctx = format!("{}, detached {detach}", v.name());
            let opts = RenderOpts {
                detach_feature_weights: detach,
                ..base
            };
            testing::fill_noise(&gpu, &b.d_op_scale, 5);
            let og = OutputGrads {
                rgba: dr.all(),
                depth: Some(dd.all()),
                features: Some(df.all()),
            };
            let mut rec = Recorder::new(&gpu).unwrap();
            rast.backward(&mut rec, &b, &cam, &g, &opts, &og);
            rec.finish().unwrap();
            let read = |buf: &dispflow_vk::vk::Buffer, per: usize| -> Vec<f32> {
                gpu.read(buf.elems::<f32>(0, (n * per) as u64)).unwrap()
            };
            let grad2d = read(&b.grad2d, s);
            let slot12: Vec<f32> = (0..n).map(|i| grad2d[s * i + 12]).collect();
            if detach {
                assert_close(
                    &format!("{ctx}: slot 12"),
                    &slot12,
                    &bg.opacity_features,
                    KIND,
                );
            } else {
                assert!(slot12.iter().all(|&x| x == 0.0), "{ctx}: slot 12 written");
            }
            let want = if detach { &dw_d } else { &dw_a };
            assert_close(&format!("{ctx}: d w"), &read(&b.d_op_scale, 1), want, KIND);
            assert_close(
                &format!("{ctx}: d logits"),
                &read(&b.d_opacity_logits, 1),
                &pg_a.opacity_logits,
                KIND,
            );
        }
    }
    rast.set_blend_bwd_variant(default);
}

/// The band blends hand a tile to the whole-tile kernels when its splats span most of its
/// bands (`blend_pick.glsl`, twin `bin::band_tile`). Whatever the threshold, the image is the
/// whole-tile kernel's bit for bit (a tile drawn by neither kernel keeps the noise the buffers
/// were filled with; one drawn by both doubles its gradients) and every gradient matches the
/// twin; at a threshold of two bands per splat this scene's tiles go both ways.
#[test]
fn bands_or_whole_tiles_picked_per_tile() {
    let gpu = testing::gpu();
    let mut rast = Rasterizer::new(&gpu).unwrap();
    rast.set_blend_fwd_variant(BlendFwdVariant::TileBands);
    rast.set_blend_bwd_variant(BlendBwdVariant::TileBands);
    let (seed, k) = (41u64, 3u32);
    // Large splats on the left, a few hundred small ones on the right.
    let mut scene = random_scene(seed, 60, 1, k);
    let mut r = Noise::new(seed + 1);
    let mut u = move || (r.next_u32() as f32 + 0.5) / 4_294_967_296.0;
    for _ in 0..300 {
        let z = 2.0 + 2.0 * u();
        let (x, y) = ((0.05 + 0.45 * u()) * z, (u() - 0.5) * 0.7 * z);
        let s = 0.004 + 0.008 * u();
        let q = [u() - 0.5, u() - 0.5, u() - 0.5, u() - 0.5];
        scene.push(
            [x, y, z],
            [s, 1.5 * s, s],
            q,
            3.0 * u() - 1.0,
            [u(), u(), u()],
        );
    }
    let n = scene.len();
    let cam = camera(80, 56);
    let opts = RenderOpts {
        background: [0.1, 0.2, 0.3],
        alpha_max: 0.99,
        abs_grad: true,
        detach_feature_weights: false,
    };
    let up = Uploaded::new(&gpu, &scene);
    let px = (cam.width * cam.height) as usize;
    let u = upstream(seed + 100, px, k as usize);
    let g = scene.twin();
    let proj = twin::project(&cam, &g);
    let bp = twin_blend_params(&cam, &opts, k);
    let fwd = twin::blend_fwd(&bp, &proj, &scene.features);
    let bg = twin_blend_bwd(&bp, &proj, &scene.features, &fwd, &u);
    let pg = twin::project_bwd(&cam, &g, &proj, &bg);

    let mut images = Vec::new();
    // 16 (two bands per splat) splits this scene's tiles; the default, 32, keeps them in bands.
    assert_eq!(BAND_COVER_MAX, 32);
    for cover in [0, 16, 32] {
        rast.set_band_cover_max(cover);
        let (b, out) = render(&gpu, &rast, &cam, &up, &opts);
        if cover == 16 {
            // Which way each tile goes, from this render's lists and splat records.
            let ranges = b.tile_ranges(&gpu).unwrap();
            let ids = b.intersection_ids(&gpu).unwrap();
            let splats: Vec<[f32; 4]> = gpu
                .read(b.splats.elems::<[f32; 4]>(0, 3 * n as u64))
                .unwrap();
            let tiles_x = cam.width.div_ceil(16) as usize;
            let (mut bands, mut whole) = (0, 0);
            for (t, r) in ranges.iter().enumerate().filter(|(_, r)| r[1] > r[0]) {
                let list = &ids[r[0] as usize..r[1] as usize];
                let y = (t / tiles_x) as u32;
                match twin::bin::band_tile(y, list, &splats, BAND_LIST_MAX, cover) {
                    true => bands += 1,
                    false => whole += 1,
                }
            }
            assert!(
                bands > 0 && whole > 0,
                "the pick at 16 sends {bands} tiles to the bands and {whole} whole: the scene \
                 does not exercise it"
            );
        }
        let grads = backward(&gpu, &rast, &b, &cam, &up, &opts, &u);
        check_grads(&format!("band cover {cover}"), n, &grads, &bg, &pg, true);
        images.push((cover, out));
    }

    // The picked backward (default costs): each tile as the twin decides it from the forward's
    // stopping points, both ways in this scene, and the twin's gradients.
    rast.set_band_cover_max(BAND_COVER_MAX);
    rast.set_blend_bwd_variant(BlendBwdVariant::TilePicked);
    let (b, out) = render(&gpu, &rast, &cam, &up, &opts);
    let grads = backward(&gpu, &rast, &b, &cam, &up, &opts, &u);
    check_grads("picked backward", n, &grads, &bg, &pg, true);
    let picks = b.band_picks(&gpu).unwrap();
    let ranges = b.tile_ranges(&gpu).unwrap();
    let ids = b.intersection_ids(&gpu).unwrap();
    let splats: Vec<[f32; 4]> = gpu
        .read(b.splats.elems::<[f32; 4]>(0, 3 * n as u64))
        .unwrap();
    let tiles_x = cam.width.div_ceil(16);
    let c = rast.pick_costs();
    let mut ways = [0, 0];
    for (t, r) in ranges.iter().enumerate() {
        let list = &ids[r[0] as usize..r[1] as usize];
        let origin = [16 * (t as u32 % tiles_x), 16 * (t as u32 / tiles_x)];
        let want = twin::bin::band_pick(
            origin,
            list,
            &splats,
            &out.n_contrib,
            cam.width,
            cam.height,
            BAND_LIST_MAX,
            [c.band_splat, c.band_step, c.whole_splat],
        );
        assert_eq!(
            picks[t],
            want as u32,
            "tile {t} ({} splats): pick",
            list.len()
        );
        ways[want as usize] += (r[1] > r[0]) as usize;
    }
    assert!(
        ways[0] > 0 && ways[1] > 0,
        "the picked backward sends {} tiles whole and {} to the bands: the scene does not \
         exercise it",
        ways[0],
        ways[1]
    );

    let (_, first) = &images[0];
    for (cover, out) in &images[1..] {
        let same = out.rgba == first.rgba
            && out.depth == first.depth
            && out.final_t == first.final_t
            && out.n_contrib == first.n_contrib
            && out.features == first.features;
        assert!(
            same,
            "band cover {cover}: the image differs from the whole tiles'"
        );
    }
}
