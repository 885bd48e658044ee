//! GPU rasteriser vs its CPU twin (`reference::raster`, f64 inside) on identical inputs:
//! projection, blend forward (RGB, alpha, depth, transmittance, contributor counts, feature
//! channels), blend backward and project backward, on random scenes at several image sizes,
//! SH degrees and feature counts.
//!
//! Tolerances: forward values are f32 on the GPU against f64-then-rounded in the twin, so a few
//! ulps of the largest term (abs 2e-5 on [0,1] colours). Gradients are sums of many per-pixel
//! terms accumulated with float atomics in arbitrary order and un-blended with T / (1 − α)
//! on the GPU; they are compared per quantity kind as max |gpu − twin| <= 2e-3 · max |twin|
//! + 1e-7.

mod raster_common;

use dispflow_vk::kernels::raster::{Rasterizer, RenderOpts, G2D_STRIDE};
use dispflow_vk::reference::raster as twin;
use dispflow_vk::testing;
use raster_common::*;

fn close_kind(what: &str, got: &[f32], want: &[f64]) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    let scale = want.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let tol = 2e-3 * scale + 1e-7;
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(g.is_finite(), "{what}[{i}] = {g}");
        assert!(
            (*g as f64 - w).abs() <= tol,
            "{what}[{i}]: gpu {g}, twin {w} (tol {tol:.3e}, max |twin| {scale:.3e})"
        );
    }
}

fn close_abs(what: &str, got: &[f32], want: &[f32], abs: f32, rel: f32) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (g - w).abs() <= abs + rel * w.abs(),
            "{what}[{i}]: gpu {g}, twin {w}"
        );
    }
}

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
    };
    let up = Uploaded::new(&gpu, &scene);
    // Every forward variant, and every backward variant after each (the backward reads the
    // forward's final T and last contributors).
    for (fv, b, out) in render_each(&gpu, &mut rast, &cam, &up, &opts) {
        let ctx = format!(
            "seed {seed}, n {n}, {w}x{h}, sh {sh_degree}, k {k}, blend_fwd {}",
            fv.name()
        );

        let g = twin::Gaussians {
            means: &scene.means,
            scales: &scene.scales,
            quats: &scene.quats,
            opacity_logits: &scene.logits,
            sh: &scene.sh,
            sh_coeffs: scene.sh_coeffs,
            sh_degree,
        };
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
            close_abs(
                &format!("{ctx}: mean2d {i}"),
                &a[..2],
                &proj.mean2d[i],
                1e-3,
                1e-6,
            );
            close_abs(
                &format!("{ctx}: depth {i}"),
                &a[2..3],
                &[proj.depth[i]],
                0.0,
                1e-6,
            );
            close_abs(
                &format!("{ctx}: opacity {i}"),
                &a[3..4],
                &[proj.opacity[i]],
                1e-7,
                1e-6,
            );
            close_abs(
                &format!("{ctx}: conic {i}"),
                &c[..3],
                &proj.conic[i],
                1e-7,
                1e-4,
            );
            close_abs(
                &format!("{ctx}: colour {i}"),
                &col[..3],
                &proj.color[i],
                1e-6,
                1e-5,
            );
        }
        assert!(
            visible > n / 3,
            "{ctx}: only {visible} of {n} visible: the scene tests little"
        );

        let bp = twin::BlendParams {
            width: w,
            height: h,
            alpha_max: opts.alpha_max,
            background: opts.background,
            feature_dims: k,
        };
        let fwd = twin::blend_fwd(&bp, &proj, &scene.features);
        let px = (w * h) as usize;
        let rgb: Vec<f32> = out.rgba.iter().flat_map(|p| [p[0], p[1], p[2]]).collect();
        let alpha: Vec<f32> = out.rgba.iter().map(|p| p[3]).collect();
        close_abs(
            &format!("{ctx}: rgb"),
            &rgb,
            fwd.rgb.as_flattened(),
            2e-5,
            0.0,
        );
        close_abs(&format!("{ctx}: alpha"), &alpha, &fwd.alpha, 2e-5, 0.0);
        close_abs(&format!("{ctx}: depth"), &out.depth, &fwd.depth, 2e-5, 2e-5);
        close_abs(
            &format!("{ctx}: final T"),
            &out.final_t,
            &fwd.final_t,
            2e-5,
            1e-4,
        );
        close_abs(
            &format!("{ctx}: features"),
            &out.features,
            &fwd.features,
            2e-5,
            2e-5,
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
        for (v, grads) in backward_each(&gpu, &mut rast, &b, &cam, &up, &opts, &u) {
            let ctx = format!("{ctx}, blend_bwd {}", v.name());
            check_grads(&ctx, n, &grads, &bg, &pg, opts.abs_grad);
        }
    }
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
    close_kind(
        &format!("{ctx}: d mean2d"),
        &col(0, 2),
        bg.mean2d.as_flattened(),
    );
    close_kind(
        &format!("{ctx}: d conic"),
        &col(2, 5),
        bg.conic.as_flattened(),
    );
    close_kind(&format!("{ctx}: d opacity"), &col(5, 6), &bg.opacity);
    close_kind(
        &format!("{ctx}: d colour"),
        &col(6, 9),
        bg.color.as_flattened(),
    );
    close_kind(&format!("{ctx}: d depth"), &col(9, 10), &bg.depth);
    if abs_grad {
        let abs = col(10, 12);
        close_kind(
            &format!("{ctx}: Σ|d mean2d|"),
            &abs,
            bg.mean2d_abs.as_flattened(),
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
    close_kind(
        &format!("{ctx}: d features"),
        &grads.d_features,
        &bg.features,
    );

    close_kind(
        &format!("{ctx}: d means"),
        &grads.d_means,
        pg.means.as_flattened(),
    );
    close_kind(
        &format!("{ctx}: d scales"),
        &grads.d_scales,
        pg.scales.as_flattened(),
    );
    close_kind(
        &format!("{ctx}: d quats"),
        &grads.d_quats,
        pg.quats.as_flattened(),
    );
    close_kind(
        &format!("{ctx}: d logits"),
        &grads.d_logits,
        &pg.opacity_logits,
    );
    close_kind(&format!("{ctx}: d sh"), &grads.d_sh, &pg.sh);
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
