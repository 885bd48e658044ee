//! DESIGN §6 extremes through the GPU rasteriser, forward and backward: outputs and gradients
//! stay finite, culling is exact, and saturating cases give the documented values.

mod raster_common;

use dispflow_vk::kernels::raster::{Rasterizer, RenderOpts};
use dispflow_vk::testing;
use raster_common::*;

const ID: [f32; 4] = [1.0, 0.0, 0.0, 0.0];

fn all_finite(what: &str, v: &[f32]) {
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        panic!("{what}[{i}] = {} is not finite", v[i]);
    }
}

/// Renders, backpropagates random upstream gradients, and checks everything is finite.
fn run_finite(scene: &Scene, w: u32, h: u32) -> (Rendered, Grads) {
    let gpu = testing::gpu();
    let rast = Rasterizer::new(&gpu).unwrap();
    let cam = camera(w, h);
    let up = Uploaded::new(&gpu, scene);
    let opts = RenderOpts {
        background: [0.2, 0.3, 0.4],
        alpha_max: 0.99,
    };
    let (b, out) = render(&gpu, &rast, &cam, &up, &opts);
    let px = (w * h) as usize;
    let g = backward(
        &gpu,
        &rast,
        &b,
        &cam,
        &up,
        &opts,
        &upstream(9, px, scene.feature_dims as usize),
    );
    all_finite("rgba", out.rgba.as_flattened());
    all_finite("depth", &out.depth);
    all_finite("features", &out.features);
    for (n, v) in [
        ("grad2d", &g.grad2d),
        ("d_means", &g.d_means),
        ("d_scales", &g.d_scales),
        ("d_quats", &g.d_quats),
        ("d_logits", &g.d_logits),
        ("d_sh", &g.d_sh),
        ("d_features", &g.d_features),
    ] {
        all_finite(n, v);
    }
    (out, g)
}

/// (mean, scale, quaternion, opacity logit) of one Gaussian.
type Item = ([f32; 3], [f32; 3], [f32; 4], f32);

fn scene_with(items: &[Item]) -> Scene {
    let mut s = Scene {
        sh_coeffs: 4,
        sh_degree: 1,
        feature_dims: 3,
        ..Default::default()
    };
    for &(m, sc, q, l) in items {
        s.push(m, sc, q, l, [0.9, 0.5, 0.1]);
    }
    s
}

#[test]
fn tiny_and_huge_scales() {
    let (out, _) = run_finite(
        &scene_with(&[
            ([0.0, 0.0, 3.0], [1e-8; 3], ID, 2.0),
            ([0.1, 0.0, 4.0], [1e4; 3], ID, 0.0),
        ]),
        33,
        21,
    );
    // The 1e4-scale Gaussian covers the whole image.
    assert!(
        out.n_contrib.iter().all(|&c| c >= 1),
        "a 1e4-scale Gaussian touches every pixel"
    );
}

#[test]
fn opacity_logits_at_plus_minus_30() {
    let (out, g) = run_finite(
        &scene_with(&[
            ([0.0, 0.0, 3.0], [3.0; 3], ID, 30.0),
            ([0.0, 0.0, 2.0], [0.5; 3], ID, -30.0),
        ]),
        32,
        32,
    );
    // logit −30: α = 1e-13 < 1/255, never blended; logit +30: α clamped at 0.99 at the centre.
    let c = (16 * 32 + 16) as usize;
    assert!(
        (out.rgba[c][3] - 0.99).abs() < 1e-3,
        "centre alpha {}",
        out.rgba[c][3]
    );
    assert_eq!(g.d_logits[1], 0.0);
}

#[test]
fn near_zero_quaternion_is_identity() {
    let (out, g) = run_finite(
        &scene_with(&[(
            [0.0, 0.0, 3.0],
            [0.3, 0.1, 0.2],
            [1e-30, 0.0, 0.0, 0.0],
            1.0,
        )]),
        24,
        24,
    );
    assert!(out.n_contrib.iter().any(|&c| c > 0));
    assert!(
        g.d_quats.iter().all(|&x| x == 0.0),
        "no gradient through a degenerate quaternion"
    );
}

#[test]
fn behind_camera_and_on_near_plane() {
    let (out, g) = run_finite(
        &scene_with(&[
            ([0.0, 0.0, -3.0], [0.5; 3], ID, 2.0),
            ([0.0, 0.0, 0.01], [0.001; 3], ID, 2.0),
            ([0.0, 0.0, 0.0099], [0.5; 3], ID, 2.0),
        ]),
        16,
        16,
    );
    // Behind and just in front of the near plane: culled, zero gradients.
    for i in [0usize, 2] {
        assert!(
            g.d_means[3 * i..3 * i + 3].iter().all(|&x| x == 0.0),
            "gaussian {i} must be culled"
        );
    }
    assert!(out.rgba.iter().all(|p| p.iter().all(|x| x.is_finite())));
}

#[test]
fn camera_inside_a_gaussian() {
    let (out, _) = run_finite(
        &scene_with(&[([0.0, 0.0, 0.05], [2.0; 3], ID, 0.5)]),
        20,
        20,
    );
    assert!(
        out.n_contrib.iter().all(|&c| c == 1),
        "a Gaussian around the camera covers everything"
    );
}

#[test]
fn zero_gaussians_give_the_background() {
    let s = Scene {
        sh_coeffs: 1,
        ..Default::default()
    };
    let (out, _) = run_finite(&s, 17, 13);
    assert!(
        out.rgba.iter().all(|p| *p == [0.2, 0.3, 0.4, 0.0]),
        "empty scene renders the background"
    );
}

#[test]
fn all_culled_gives_the_background() {
    let s = scene_with(&[
        ([0.0, 0.0, -1.0], [0.5; 3], ID, 2.0),
        ([100.0, 0.0, 1.0], [0.01; 3], ID, 2.0),
    ]);
    let (out, g) = run_finite(&s, 17, 13);
    assert!(out.rgba.iter().all(|p| *p == [0.2, 0.3, 0.4, 0.0]));
    assert!(g.d_means.iter().all(|&x| x == 0.0));
}

#[test]
fn one_by_one_and_odd_sizes() {
    let s = random_scene(5, 30, 2, 2);
    for (w, h) in [(1, 1), (17, 13), (1, 40), (31, 1)] {
        let (out, _) = run_finite(&s, w, h);
        assert_eq!(out.rgba.len(), (w * h) as usize);
    }
}

#[test]
fn hundred_thousand_gaussians_in_one_tile() {
    // 10^5 faint splats all inside the first 16×16 tile: the blend walks many batches per tile.
    let n = 100_000;
    let mut s = Scene {
        sh_coeffs: 1,
        ..Default::default()
    };
    let mut r = testing::Noise::new(1);
    let cam = camera(64, 64);
    for i in 0..n {
        let (px, py) = (
            (r.next_u32() % 16) as f32 + 0.5,
            (r.next_u32() % 16) as f32 + 0.5,
        );
        let z = 1.0 + i as f32 * 1e-5;
        let x = (px - cam.cx) / cam.fx * z;
        let y = (py - cam.cy) / cam.fy * z;
        s.push([x, y, z], [1e-4; 3], ID, -4.0, [0.3, 0.6, 0.9]);
    }
    let (out, g) = run_finite(&s, 64, 64);
    assert!(
        out.n_contrib[0] > 100,
        "pixel 0 saw {} splats",
        out.n_contrib[0]
    );
    assert!(g.d_logits.iter().any(|&x| x != 0.0));
}

dispflow_vk::subgroup_reruns!();
