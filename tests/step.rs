//! The whole-step CPU twin (`reference::step`, one DispFlow-GS step in direct order) against
//! central finite differences of its own f64 loss, for parameters of every group (canonical
//! means, log-scales, quaternions, opacity logits, SH DC and rest, MLP time net / trunk /
//! head; and with the control-node field, node positions and log-radii), and the
//! detached-statistics variant against the full gradient.
//!
//! (Over ~600 lines: one scene builder serves the twin's finite-difference checks and the GPU
//! step comparisons, which must see the same inputs, MLP and node fields alike.)

use dispflow_vk::model::deform::{MlpConfig, MlpLayout, TimeEncoding, OUT_DIMS};
use dispflow_vk::model::gaussians::HostGaussians;
use dispflow_vk::reference::nodes::nodes_knn;
use dispflow_vk::reference::raster::Camera;
use dispflow_vk::reference::step::{
    dispflow_step, step_loss_f64, NormGradMode, StepInputs, StepNodes, StepOutputs, StepParams64,
};
use dispflow_vk::testing::{max_abs, rot_from_angles, Noise};

// ---------------------------------------------------------------------------------------------
// Scene

/// A deterministic small scene: Gaussians in front of a 24×20 camera (2×2 tiles, the right and
/// bottom ones partial), a depth-2 width-16 MLP with the synthetic time net, a target image and a
/// scene-motion field, both non-degenerate.
struct Scene {
    gaussians: HostGaussians,
    sh_degree: u32,
    layout: MlpLayout,
    mlp_params: Vec<f32>,
    camera: Camera,
    target: Vec<[f32; 4]>,
    scene_motion: Vec<[f32; 2]>,
    /// The control-node field: node parameters [4M] and the KNN [N·NODE_K].
    nodes: Option<(Vec<f32>, Vec<u32>)>,
}

/// Nearest nodes per Gaussian in the node scenes.
const NODE_K: usize = 3;

const W: u32 = 24;
const H: u32 = 20;
const T1: f32 = 0.3;
const T2: f32 = 0.55;

/// The trainer's MLP for `mlp_depth = 2`, `mlp_width = 16` on a blender scene: synthetic time
/// net with its hidden width following the trunk width, no skip (depth < 3).
fn small_mlp() -> MlpConfig {
    let base = MlpConfig::synthetic();
    let time = match base.time {
        TimeEncoding::TimeNet { freqs, out, .. } => TimeEncoding::TimeNet {
            freqs,
            hidden: 16,
            out,
        },
        t => t,
    };
    MlpConfig {
        depth: 2,
        width: 16,
        skip: None,
        x_freqs: base.x_freqs,
        time,
    }
}

fn scene(seed: u64, n: usize) -> Scene {
    let mut r = Noise::new(seed);
    // Camera: mildly rotated, off-centre principal point, centre at (0.1, −0.1, −4).
    let rot = rot_from_angles([0.08, -0.06, 0.05]);
    let centre = [0.1, -0.1, -4.0];
    let trans: [f32; 3] =
        std::array::from_fn(|i| -(0..3).map(|j| rot[i][j] * centre[j]).sum::<f64>() as f32);
    let rot32 = rot.map(|row| row.map(|v| v as f32));
    let (fx, fy) = (22.0f32, 21.0f32);
    let camera = Camera {
        rot: rot32,
        trans,
        fx,
        fy,
        cx: 11.3,
        cy: 10.6,
        width: W,
        height: H,
        near: 0.01,
    };
    let world = |pc: [f64; 3]| -> [f32; 3] {
        std::array::from_fn(|j| {
            (0..3)
                .map(|i| rot32[i][j] as f64 * (pc[i] - trans[i] as f64))
                .sum::<f64>() as f32
        })
    };

    let sh_degree = 1;
    let sh_coeffs = 4u32;
    let mut g = HostGaussians {
        sh_coeffs,
        ..Default::default()
    };
    for _ in 0..n {
        // Inside the view (±45 % of the half-extent), 3–5 units deep.
        let z = r.uniform(3.0, 5.0);
        let xz = r.uniform(-0.45, 0.45) * W as f64 / fx as f64;
        let yz = r.uniform(-0.45, 0.45) * H as f64 / fy as f64;
        g.means.push(world([xz * z, yz * z, z]));
        g.log_scales
            .push(std::array::from_fn(|_| r.uniform(0.12f64, 0.4).ln() as f32));
        let q: [f32; 4] = loop {
            let q = std::array::from_fn(|_| r.uniform(-1.0, 1.0) as f32);
            if q.iter().map(|v| v * v).sum::<f32>() > 0.2 {
                break q;
            }
        };
        g.quats.push(q);
        g.opacity.push(r.uniform(-1.0, 2.0) as f32);
        g.sh_dc
            .push(std::array::from_fn(|_| r.uniform(-0.8, 0.8) as f32));
        for _ in 0..3 * (sh_coeffs - 1) {
            g.sh_rest.push(r.uniform(-0.3, 0.3) as f32);
        }
    }

    // PyTorch-style init (the trainer's zero-initialised head would make δ ≡ 0), reshaped so the
    // displacement is visible but moderate: with 16 hidden units the time features barely move
    // the output, so trunk layer 0's weights on the time features are ×10; the head's dr and ds
    // rows ×0.3 keep the drawn rotations and scales near the canonical ones. Result: max |dx|
    // ≈ 0.5 (≈ 3 px), δ between t1 and t2 ≈ 0.15 (≈ 1 px), every Gaussian still in view.
    let layout = MlpLayout::new(&small_mlp()).unwrap();
    let mut mlp_params = layout.init_params(seed + 100);
    let trunk0 = layout.trunk()[0];
    let x_dims = layout.cfg.x_dims();
    for o in 0..trunk0.fan_out {
        let row = trunk0.w_off + o * trunk0.fan_in;
        for v in &mut mlp_params[row + x_dims..row + trunk0.fan_in] {
            *v *= 10.0;
        }
    }
    let head = layout.head();
    for o in 3..OUT_DIMS {
        for v in &mut mlp_params[head.w_off + o * head.fan_in..head.w_off + (o + 1) * head.fan_in] {
            *v *= 0.3;
        }
        mlp_params[head.b_off + o] *= 0.3;
    }

    // Target: smooth colour waves plus a little noise; scene motion: a smooth field with a
    // rotating part, so its magnitude varies across the image.
    let (mut target, mut scene_motion) = (Vec::new(), Vec::new());
    for py in 0..H {
        for px in 0..W {
            let (x, y) = (px as f64, py as f64);
            let mut u = || r.uniform(-0.05, 0.05);
            target.push([
                (0.5 + 0.3 * (0.4 * x + 0.2 * y).sin() + u()) as f32,
                (0.45 + 0.3 * (0.3 * y - 0.1 * x).cos() + u()) as f32,
                (0.4 + 0.25 * (0.25 * (x + y)).sin() + u()) as f32,
                1.0,
            ]);
            let (dx, dy) = (x - 14.0, y - 8.0);
            scene_motion.push([
                (0.3 + 0.08 * dy + 0.2 * (0.3 * x).sin()) as f32,
                (-0.1 - 0.06 * dx + 0.15 * (0.4 * y).cos()) as f32,
            ]);
        }
    }
    Scene {
        gaussians: g,
        sh_degree,
        layout,
        mlp_params,
        camera,
        target,
        scene_motion,
        nodes: None,
    }
}

/// [`scene`] deformed through `m` control nodes placed at the first `m` Gaussians' means
/// (radius 0.8: several nodes weigh on each Gaussian), each Gaussian blending its
/// [`NODE_K`] nearest.
fn node_scene(seed: u64, n: usize, m: usize) -> Scene {
    let mut s = scene(seed, n);
    let pos: Vec<[f32; 3]> = s.gaussians.means[..m].to_vec();
    let mut params: Vec<f32> = pos.iter().flatten().copied().collect();
    params.extend((0..m).map(|j| (0.8f32 + 0.05 * j as f32).ln()));
    let knn = nodes_knn(&s.gaussians.means, &pos, NODE_K, None);
    s.nodes = Some((params, knn));
    s
}

impl Scene {
    fn inputs(&self, motion_weight: f32, norm_grad: NormGradMode) -> StepInputs<'_> {
        StepInputs {
            gaussians: &self.gaussians,
            sh_degree: self.sh_degree,
            mlp: &self.layout,
            mlp_params: &self.mlp_params,
            camera: &self.camera,
            t1: T1,
            t2: T2,
            target: &self.target,
            scene_motion: &self.scene_motion,
            background: [0.1, 0.2, 0.3],
            alpha_max: 0.99,
            lambda_ssim: 0.2,
            motion_weight,
            norm_grad,
            nodes: self.nodes.as_ref().map(|(params, knn)| StepNodes {
                params,
                knn,
                k: NODE_K,
            }),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Parameters

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Group {
    Means,
    LogScales,
    Quats,
    Opacity,
    ShDc,
    ShRest,
    /// MLP parameters of one Linear (index into `layout.linears`).
    Mlp(usize),
    /// Control-node parameters (index into [4M]: positions, then log-radii).
    Nodes,
}

/// One scalar parameter: its group and flat index within the group's array (Gaussian arrays
/// flattened row-major; MLP: index into the flat parameter buffer).
#[derive(Clone, Copy, Debug)]
struct Param(Group, usize);

fn slot(p: &mut StepParams64, Param(g, j): Param) -> &mut f64 {
    let c = &mut p.gaussians;
    match g {
        Group::Means => &mut c.means[j / 3][j % 3],
        Group::LogScales => &mut c.log_scales[j / 3][j % 3],
        Group::Quats => &mut c.quats[j / 4][j % 4],
        Group::Opacity => &mut c.opacity[j],
        Group::ShDc => &mut c.sh_dc[j / 3][j % 3],
        Group::ShRest => &mut c.sh_rest[j],
        Group::Mlp(_) => &mut p.mlp[j],
        Group::Nodes => &mut p.nodes[j],
    }
}

fn analytic(o: &StepOutputs, Param(g, j): Param) -> f64 {
    let d = &o.d_gaussians;
    match g {
        Group::Means => d.means[j / 3][j % 3],
        Group::LogScales => d.log_scales[j / 3][j % 3],
        Group::Quats => d.quats[j / 4][j % 4],
        Group::Opacity => d.opacity[j],
        Group::ShDc => d.sh_dc[j / 3][j % 3],
        Group::ShRest => d.sh_rest[j],
        Group::Mlp(_) => o.d_mlp[j],
        Group::Nodes => o.d_nodes[j],
    }
}

/// Every parameter of Gaussians `ids`, and 4 weights + 2 biases of every Linear of the MLP (time
/// net layers 0 and 1, trunk layers 0 and 1, head), drawn by a fixed seed.
fn params_to_check(s: &Scene, ids: &[usize]) -> Vec<Param> {
    let rest = 3 * (s.gaussians.sh_coeffs as usize - 1);
    let mut v = Vec::new();
    for &i in ids {
        v.extend((0..3).map(|a| Param(Group::Means, 3 * i + a)));
        v.extend((0..3).map(|a| Param(Group::LogScales, 3 * i + a)));
        v.extend((0..4).map(|a| Param(Group::Quats, 4 * i + a)));
        v.push(Param(Group::Opacity, i));
        v.extend((0..3).map(|a| Param(Group::ShDc, 3 * i + a)));
        v.extend((0..rest).map(|a| Param(Group::ShRest, rest * i + a)));
    }
    let mut r = Noise::new(77);
    for (k, l) in s.layout.linears.iter().enumerate() {
        for _ in 0..4 {
            let j = l.w_off + r.next_u32() as usize % (l.fan_in * l.fan_out);
            v.push(Param(Group::Mlp(k), j));
        }
        for _ in 0..2 {
            v.push(Param(
                Group::Mlp(k),
                l.b_off + r.next_u32() as usize % l.fan_out,
            ));
        }
    }
    if let Some((params, _)) = &s.nodes {
        v.extend((0..params.len()).map(|j| Param(Group::Nodes, j)));
    }
    v
}

fn group_name(s: &Scene, g: Group) -> String {
    match g {
        Group::Mlp(k) => format!("mlp {:?}", s.layout.linears[k].role),
        g => format!("{g:?}"),
    }
}

// ---------------------------------------------------------------------------------------------
// Tests

/// Central differences of the total loss (photo + motion) wrt parameters of every group against
/// the step's gradients, with the autograd (Full) normalisation gradient: the Detached variant
/// holds min and max constant in the backward by design, so it is not the derivative of the loss
/// and cannot be checked this way (see `twin_step_detached_differs_only_through_stats`).
///
/// Step h = 1e-6 (absolute; parameters are O(0.1–1)): in f64 the rounding error of the
/// difference quotient is ~1e-16·|L|·(terms)/h ≲ 1e-9 and the truncation error h²·|L'''|/6 ≲
/// 1e-10 on a smooth piece; observed |analytic − fd| ≤ 4e-10. The tolerance
/// |analytic − fd| ≤ 1e-6·|fd| + 1e-8 leaves a factor ≥ 25 over that, while a real mistake (a
/// flipped sign, a dropped term, a missing factor) is at least a few per cent of the checked
/// gradients, whose per-group maxima are 2e-3–6e-2 here: e.g. negating ∂L/∂δ or dropping the t2
/// MLP backward fails on the first time-net weight checked.
/// A parameter whose ±h evaluation changes a discrete decision (ReLU mask, culling, tile rect,
/// α clamp, 1/255 cut, T stop, depth order, sign of an L1 residual, argmin/argmax of m_disp —
/// the loss signature) straddles a kink where FD means nothing: it is skipped and counted.
#[test]
fn twin_step_matches_finite_differences() {
    fd_check(&scene(5, 40));
}

/// The same through the control-node field: the blend's gradients reach the canonical means
/// and rotations (not detached there), the node positions and radii, and the MLP at the nodes.
#[test]
fn twin_step_with_nodes_matches_finite_differences() {
    fd_check(&node_scene(5, 40, 6));
}

fn fd_check(s: &Scene) {
    let inp = s.inputs(0.5, NormGradMode::Full);
    let out = dispflow_step(&inp);
    assert!(!out.motion_skipped, "motion term skipped");
    assert!(out.motion_loss > 1e-3, "motion loss {}", out.motion_loss);
    let norm = |v: [f64; 3]| v.iter().map(|x| x * x).sum::<f64>().sqrt();
    let max_delta = out.delta.iter().map(|&d| norm(d)).fold(0.0, f64::max);
    let max_dx = (out.drawn_means.iter().zip(&s.gaussians.means))
        .map(|(d, m)| norm(std::array::from_fn(|a| d[a] - m[a] as f64)))
        .fold(0.0, f64::max);
    eprintln!(
        "photo {:.4}, motion {:.4}, max |δ| {max_delta:.3}, max |dx| {max_dx:.3} (1 px ≈ 0.18 at z = 4)",
        out.photo_loss, out.motion_loss
    );

    let p0 = StepParams64::from_inputs(&inp);
    let view = out.drawn_means.clone();
    let base = step_loss_f64(&inp, &p0, Some(&view));
    assert!(
        (base.total() - out.total_loss()).abs() <= 1e-14,
        "step_loss_f64 {} vs dispflow_step {}",
        base.total(),
        out.total_loss()
    );

    // The motion term really carries the MLP gradient checked below (so the test sees a
    // mistake in δ's backward or in the t2 pass): its share of each checked Linear is large.
    let photo_only = dispflow_step(&s.inputs(0.0, NormGradMode::Full));
    let ids = [0, 9, 17, 26, 35];
    let params = params_to_check(s, &ids);
    for &i in &ids {
        assert!(
            out.d_gaussians.opacity[i].abs() > 1e-5,
            "Gaussian {i} unseen"
        );
    }

    let h = 1e-6;
    // Per group: max relative error (|fd| floored at 1e-6), checked, skipped, max absolute error.
    let mut worst: Vec<(Group, f64, usize, usize, f64)> = Vec::new();
    let (mut total, mut skipped) = (0usize, 0usize);
    for &p in &params {
        let eval = |d: f64| {
            let mut q = p0.clone();
            *slot(&mut q, p) += d;
            step_loss_f64(&inp, &q, Some(&view))
        };
        let (lp, lm) = (eval(h), eval(-h));
        total += 1;
        let k = match worst.iter().position(|w| w.0 == p.0) {
            Some(k) => k,
            None => {
                worst.push((p.0, 0.0, 0, 0, 0.0));
                worst.len() - 1
            }
        };
        if lp.signature != base.signature || lm.signature != base.signature {
            skipped += 1;
            worst[k].3 += 1;
            continue;
        }
        let fd = (lp.total() - lm.total()) / (2.0 * h);
        let an = analytic(&out, p);
        assert!(
            (an - fd).abs() <= 1e-6 * fd.abs() + 1e-8,
            "{} [{}]: analytic {an:e}, finite difference {fd:e}",
            group_name(s, p.0),
            p.1
        );
        worst[k].1 = worst[k].1.max((an - fd).abs() / fd.abs().max(1e-6));
        worst[k].4 = worst[k].4.max((an - fd).abs());
        worst[k].2 += 1;
    }
    for &(g, err, checked, skip, abs_err) in &worst {
        let gmax = params
            .iter()
            .filter(|p| p.0 == g)
            .map(|&p| analytic(&out, p).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "{:>16}: {checked} checked, {skip} skipped, max |grad| {gmax:.2e}, max rel err {err:.2e}, max abs err {abs_err:.2e}",
            group_name(s, g)
        );
        assert!(checked >= 3, "{}: only {checked} checked", group_name(s, g));
        assert!(gmax > 1e-4, "{}: vacuous gradient", group_name(s, g));
        if let Group::Mlp(_) = g {
            let motion_part = params
                .iter()
                .filter(|p| p.0 == g)
                .map(|&p| (analytic(&out, p) - analytic(&photo_only, p)).abs())
                .fold(0.0, f64::max);
            assert!(
                motion_part > 0.05 * gmax,
                "{}: motion term's share of the gradient too small ({motion_part:e})",
                group_name(s, g)
            );
        }
    }
    eprintln!("{total} parameters, {skipped} skipped as straddling a kink");
    // The straddle detection is live: shifting every Gaussian by ~0.3 px (the dx bias) crosses
    // some kink.
    let mut q = p0.clone();
    q.mlp[s.layout.head().b_off] += 0.05;
    assert_ne!(
        step_loss_f64(&inp, &q, Some(&view)).signature,
        base.signature
    );
    assert!(
        skipped * 10 <= total,
        "{skipped} of {total} straddle a kink"
    );
}

fn flat_grads(o: &StepOutputs) -> Vec<f64> {
    let d = &o.d_gaussians;
    d.means
        .iter()
        .flatten()
        .chain(d.log_scales.iter().flatten())
        .chain(d.quats.iter().flatten())
        .chain(&d.opacity)
        .chain(d.sh_dc.iter().flatten())
        .chain(&d.sh_rest)
        .chain(&o.d_mlp)
        .copied()
        .collect()
}

/// Equal up to summation order: the MLP twin reduces its per-Gaussian gradients with rayon, so
/// two runs of the same step may differ in the last bits.
fn assert_same(what: &str, a: &[f64], b: &[f64]) {
    assert_eq!(a.len(), b.len());
    let scale = max_abs(a.iter().copied());
    let (i, d) = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .enumerate()
        .fold((0, 0.0), |m, (i, d)| if d > m.1 { (i, d) } else { m });
    assert!(
        d <= 1e-13 * scale,
        "{what}: [{i}] {} vs {} (max |grad| {scale:e})",
        a[i],
        b[i]
    );
}

/// Detached and Full differ only through the min/max statistics: identical with α = 0 (the
/// photometric gradient alone), and with α > 0 identical losses and a feature gradient ∂L/∂F_disp
/// that differs only at the argmin/argmax pixels of m_disp. The motion gradient is linear in α
/// and reaches the Gaussians and the MLP; a degenerate scene-motion map skips it entirely.
#[test]
fn twin_step_detached_differs_only_through_stats() {
    let s = scene(5, 40);
    let run = |a: f32, m: NormGradMode| dispflow_step(&s.inputs(a, m));

    let (d0, f0) = (
        run(0.0, NormGradMode::Detached),
        run(0.0, NormGradMode::Full),
    );
    assert_eq!(d0.motion_loss, 0.0);
    assert_eq!(d0.photo_loss, f0.photo_loss);
    assert_same(
        "α = 0: Detached vs Full",
        &flat_grads(&d0),
        &flat_grads(&f0),
    );
    assert!(d0.d_delta.iter().flatten().all(|&v| v == 0.0));

    let a = 0.1;
    let (d1, f1) = (run(a, NormGradMode::Detached), run(a, NormGradMode::Full));
    assert!(!d1.motion_skipped && d1.motion_loss > 0.0);
    assert_eq!(
        (d1.photo_loss, d1.motion_loss),
        (f1.photo_loss, f1.motion_loss)
    );
    assert_eq!(d1.photo_loss, d0.photo_loss);
    // ∂L/∂F_disp: Full − Detached is the statistics' term, on the argmin and argmax pixels.
    let first = |v: f64| d1.m_hat_disp.iter().position(|&m| m == v).unwrap();
    let (argmin, argmax) = (first(0.0), first(1.0));
    let mut diff_pixels = Vec::new();
    for (p, (x, y)) in d1
        .d_disp_flow
        .chunks_exact(3)
        .zip(f1.d_disp_flow.chunks_exact(3))
        .enumerate()
    {
        if x != y {
            diff_pixels.push(p);
        }
    }
    assert!(
        !diff_pixels.is_empty() && diff_pixels.iter().all(|&p| p == argmin || p == argmax),
        "Detached vs Full differ at pixels {diff_pixels:?} (argmin {argmin}, argmax {argmax})"
    );
    let gap = max_abs(
        flat_grads(&d1)
            .iter()
            .zip(&flat_grads(&f1))
            .map(|(x, y)| x - y),
    );
    assert!(
        gap > 1e-6,
        "α > 0: Detached and Full gradients agree ({gap:e})"
    );

    // The motion term's gradient: non-zero on Gaussians and MLP, linear in α.
    let (g0, g1) = (flat_grads(&d0), flat_grads(&d1));
    let g2 = flat_grads(&run(2.0 * a, NormGradMode::Detached));
    let m1: Vec<f64> = g1.iter().zip(&g0).map(|(x, y)| x - y).collect();
    let m2: Vec<f64> = g2.iter().zip(&g0).map(|(x, y)| x - y).collect();
    let n_g = g0.len() - d0.d_mlp.len();
    assert!(max_abs(m1[..n_g].iter().copied()) > 1e-4 * max_abs(g0[..n_g].iter().copied()));
    assert!(max_abs(m1[n_g..].iter().copied()) > 1e-2 * max_abs(g0[n_g..].iter().copied()));
    assert!(max_abs(d1.d_delta.iter().flatten().copied()) > 0.0);
    let lin = max_abs(m2.iter().zip(&m1).map(|(x, y)| x - 2.0 * y));
    assert!(
        lin <= 1e-9 * max_abs(m2.iter().copied()),
        "motion gradient not linear in α: {lin:e}"
    );

    // A flat scene motion is degenerate: no loss, no gradient (the α = 0 step exactly).
    let flat = vec![[0.25f32, -0.5]; s.scene_motion.len()];
    let skip = dispflow_step(&StepInputs {
        scene_motion: &flat,
        ..s.inputs(a, NormGradMode::Full)
    });
    assert!(skip.motion_skipped);
    assert_eq!(skip.motion_loss, 0.0);
    assert_same("skipped vs α = 0", &flat_grads(&skip), &g0);
}

// ---------------------------------------------------------------------------------------------
// The GPU step against the twin composition

mod gpu_step {
    use std::rc::Rc;

    use dispflow_vk::kernels::motion::{NormConfig, NormMode};
    use dispflow_vk::kernels::raster::Rasterizer;
    use dispflow_vk::model::dynamic::{DynamicSet, SplitSnapshot};
    use dispflow_vk::model::gaussians::Section;
    use dispflow_vk::model::state::{mlp_config_for, DeformState, GaussianState, Model};
    use dispflow_vk::reference::step::{dispflow_step, NormGradMode, StepOutputs};
    use dispflow_vk::testing;
    use dispflow_vk::train::config::{DensifyConfig, MotionOrder};
    use dispflow_vk::train::frames::GpuFrame;
    use dispflow_vk::train::method::{MotionRepresentation, SceneMotionKind};
    use dispflow_vk::train::passes::motion::{FixedMotion, MotionVariant};
    use dispflow_vk::train::passes::{
        AdamPass, DeformPass, DensifyPass, MotionTerm, OverflowWatch, PhotoLoss, RenderPass,
        StepSizes,
    };
    use dispflow_vk::train::passes::{SceneSignal, SignalConfig};
    use dispflow_vk::train::plan::{Decomposition, MotionPlan, StepLr, StepPlan};
    use dispflow_vk::train::step::{record_step, StepPasses};
    use dispflow_vk::vk::{Gpu, Recorder};

    use super::{node_scene, scene, small_mlp, Scene, H, NODE_K, T1, T2, W};
    use dispflow_vk::model::nodes::{FieldConfig, FieldKind, NodeSnapshot, NodeState};

    /// Gradients of one GPU step, per group, flattened like the twin's.
    struct GpuGrads {
        groups: Vec<(&'static str, Vec<f64>)>,
        photo_loss: f64,
    }

    /// `split`: the model split with every Gaussian dynamic (the split path — gather, compact
    /// MLP, expand, gradient gather — must give the dense path's numbers).
    fn run_gpu_step(gpu: &Gpu, s: &Scene, weight: f32, split: bool) -> GpuGrads {
        let cap = s.gaussians.len() as u32;
        assert_eq!(
            small_mlp(),
            mlp_config_for(true, 2, 16),
            "the trainer's MLP"
        );
        let deform = DeformState::new(gpu, small_mlp(), 0, false).unwrap();
        assert_eq!(deform.layout, s.layout);
        gpu.upload(deform.params.all(), &s.mlp_params).unwrap();
        let field = s.nodes.as_ref().map(|(params, _)| FieldConfig {
            kind: FieldKind::Nodes,
            nodes: params.len() as u32 / 4,
            knn: NODE_K as u32,
            ..FieldConfig::default()
        });
        let mut model = Model {
            gaussians: GaussianState::new(gpu, cap, s.sh_degree, &s.gaussians).unwrap(),
            deform,
            dynamic: DynamicSet::new(gpu, cap).unwrap(),
            nodes: field.map(|f| NodeState::new(gpu, f, cap).unwrap()),
            transient: Default::default(),
        };
        if split {
            let all = SplitSnapshot {
                flags: vec![1; cap as usize],
                fixed: vec![0.0; 10 * cap as usize],
            };
            model.dynamic.upload(gpu, Some(&all)).unwrap();
        }
        if let (Some(ns), Some((params, knn))) = (model.nodes.as_mut(), &s.nodes) {
            // The twin's KNN, taken as current (no recomputation inside the step).
            let zeros = vec![0.0; params.len()];
            let snap = NodeSnapshot {
                params: params.clone(),
                m: zeros.clone(),
                v: zeros,
                knn: knn.clone(),
            };
            ns.restore(gpu, &snap, cap, model.dynamic.generation())
                .unwrap();
            testing::fill_noise(gpu, &ns.grads, 8);
        }
        for b in [&model.gaussians.grads, &model.deform.grads] {
            testing::fill_noise(gpu, b, 7);
        }
        let sizes = StepSizes {
            capacity: cap,
            width: W,
            height: H,
            sh_coeffs: model.gaussians.layout.sh_coeffs,
            isect_guess: 1 << 12,
        };
        let raster = Rc::new(Rasterizer::new(gpu).unwrap());
        let roles = Decomposition::of(MotionOrder::Direct);
        let fixed = gpu
            .buffer_from("fixed scene motion", &s.scene_motion)
            .unwrap();
        let norm = NormConfig {
            detach_stats: true,
            ..NormConfig::new(NormMode::MinMax, 1e-6).unwrap()
        };
        let densify = DensifyConfig {
            budget: cap,
            ..DensifyConfig::default()
        };
        let cfg = &model.deform.cfg;
        let mut passes = StepPasses {
            deform: DeformPass::new(gpu, cfg, field.as_ref(), &sizes, 2, true).unwrap(),
            render: RenderPass::new(raster.clone(), gpu, &sizes, 3).unwrap(),
            loss: PhotoLoss::new(gpu, &sizes).unwrap(),
            motion: Some(
                MotionTerm::new(
                    gpu,
                    raster,
                    &sizes,
                    MotionVariant {
                        roles,
                        representation: MotionRepresentation::Displacement,
                        scene: SceneMotionKind::Direct,
                    },
                    norm,
                    SceneSignal::new(
                        gpu,
                        Box::new(FixedMotion(fixed)),
                        SignalConfig::default(),
                        sizes.pixels(),
                    )
                    .unwrap(),
                )
                .unwrap(),
            ),
            adam: AdamPass::new(gpu).unwrap(),
            densify: DensifyPass::new(gpu, densify, Default::default(), 1.0, 0).unwrap(),
            watch: OverflowWatch::new(gpu, "test overflow", 2).unwrap(),
            classifier: None,
        };
        let frame = |time: f32| GpuFrame {
            id: format!("t{time}"),
            camera: s.camera,
            time,
            target: gpu.buffer_from("target", &s.target).unwrap(),
            mask: None,
            prev_time: None,
            gt_flow: None,
            next_flow: None,
        };
        let frames = [frame(T1), frame(T2)];
        // Learning rates 0: the step's gradients are read after it, parameters stay put.
        let plan = StepPlan {
            iteration: 1,
            frame: 0,
            t1: T1,
            deform_active: true,
            background: [0.1, 0.2, 0.3],
            sh_degree: s.sh_degree,
            motion: (weight > 0.0).then_some(MotionPlan {
                pair: 1,
                t2: T2,
                weight,
                roles,
            }),
            lr: StepLr {
                means: 0.0,
                log_scales: 0.0,
                quats: 0.0,
                opacity: 0.0,
                sh_dc: 0.0,
                sh_rest: 0.0,
                deform: Some((0.0, 1)),
                centre: 0.0,
                log_width: 0.0,
                velocity: 0.0,
            },
            densify_stats: false,
            abs_grad: false,
            densify: None,
            opacity_reset: false,
            sparse: split,
            classify: false,
            spawn: false,
            detach_motion_weights: false,
        };
        let mut rec = Recorder::new(gpu).unwrap();
        record_step(&mut rec, &plan, &model, &mut passes, &frames, 0.2);
        rec.finish().unwrap();
        let (o0, o1) = (
            passes.watch.read(0, "render").unwrap(),
            passes.watch.read(1, "intermediate").unwrap(),
        );
        assert!(!o0.overflowed && !o1.overflowed);
        let g = &model.gaussians;
        let read = |s: Section| -> Vec<f64> {
            let v: Vec<f32> = gpu.read(g.grad(s)).unwrap();
            v.iter().map(|&x| x as f64).collect()
        };
        let mlp: Vec<f32> = gpu.read(model.deform.grads.all()).unwrap();
        // Every weight and bias of every Linear (the layout pads between them; padding is
        // never written, so it still holds the noise).
        let used: Vec<usize> = model
            .deform
            .layout
            .linears
            .iter()
            .flat_map(|l| {
                (l.w_off..l.w_off + l.fan_in * l.fan_out).chain(l.b_off..l.b_off + l.fan_out)
            })
            .collect();
        let mut groups = vec![
            ("means", read(Section::Means)),
            ("log_scales", read(Section::LogScales)),
            ("quats", read(Section::Quats)),
            ("opacity", read(Section::Opacity)),
            ("sh_dc", read(Section::ShDc)),
            ("sh_rest", read(Section::ShRest)),
            ("mlp", used.iter().map(|&i| mlp[i] as f64).collect()),
        ];
        if let Some(ns) = &model.nodes {
            let v: Vec<f32> = gpu.read(ns.grad_block()).unwrap();
            groups.push(("nodes", v.iter().map(|&x| x as f64).collect()));
        }
        GpuGrads {
            groups,
            photo_loss: passes.loss.values().loss,
        }
    }

    fn twin_groups(s: &Scene, o: &StepOutputs) -> Vec<(&'static str, Vec<f64>)> {
        let g = &o.d_gaussians;
        let used = s.layout.linears.iter().flat_map(|l| {
            (l.w_off..l.w_off + l.fan_in * l.fan_out).chain(l.b_off..l.b_off + l.fan_out)
        });
        let mut v = vec![
            ("means", g.means.as_flattened().to_vec()),
            ("log_scales", g.log_scales.as_flattened().to_vec()),
            ("quats", g.quats.as_flattened().to_vec()),
            ("opacity", g.opacity.clone()),
            ("sh_dc", g.sh_dc.as_flattened().to_vec()),
            ("sh_rest", g.sh_rest.clone()),
            ("mlp", used.map(|i| o.d_mlp[i]).collect()),
        ];
        if s.nodes.is_some() {
            v.push(("nodes", o.d_nodes.clone()));
        }
        v
    }

    /// max |gpu − twin| relative to the group's largest twin gradient, per group.
    fn rel_errors(gpu: &GpuGrads, twin: &[(&'static str, Vec<f64>)]) -> Vec<(&'static str, f64)> {
        gpu.groups
            .iter()
            .zip(twin)
            .map(|((name, a), (tname, b))| {
                assert_eq!((name, a.len()), (tname, b.len()), "group {name}");
                let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                assert!(scale > 0.0, "{name}: the twin's gradient is all zero");
                let err = a
                    .iter()
                    .zip(b)
                    .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
                (*name, err / scale)
            })
            .collect()
    }

    /// One full DispFlow step on the GPU (two MLP passes, displacement, the photometric render
    /// splatting δ, the intermediate render, a fixed scene-motion input in place of TV-L1,
    /// normalisation with detached statistics, motion L1, backward to every parameter) against
    /// the composition of the CPU twins, per parameter group.
    #[test]
    fn gpu_step_matches_the_twin_composition() {
        compare_with_twin(&scene(5, 40), &[(0.5, false), (0.0, false), (0.5, true)]);
    }

    /// The same step through the control-node field (dense and split): the MLP at 6 nodes,
    /// the blend, its backward into canonical means/rotations and node parameters, the gather.
    #[test]
    fn gpu_step_with_nodes_matches_the_twin_composition() {
        compare_with_twin(&node_scene(5, 40, 6), &[(0.5, false), (0.5, true)]);
    }

    fn compare_with_twin(s: &Scene, cases: &[(f32, bool)]) {
        let gpu = testing::gpu();
        for &(weight, split) in cases {
            let twin = dispflow_step(&s.inputs(weight, NormGradMode::Detached));
            assert!(weight == 0.0 || !twin.motion_skipped);
            let got = run_gpu_step(&gpu, s, weight, split);
            let errs = rel_errors(&got, &twin_groups(s, &twin));
            eprintln!("α = {weight}, split {split}: photo loss GPU {:.6} twin {:.6}; max |Δ| / max |twin| per group: {errs:?}", got.photo_loss, twin.photo_loss);
            assert!((got.photo_loss - twin.photo_loss).abs() < 1e-5 * twin.photo_loss.max(1.0));
            // f32 on the GPU (float atomics in blend backward, f32 MLP) against f64: 1e-3 of
            // the group's largest gradient, ~10× above what was measured (see the note).
            for (name, e) in errs {
                assert!(
                    e < 1e-3,
                    "α = {weight}: {name} gradients differ by {e:.2e} of their scale"
                );
            }
        }
        // The motion term is not a no-op: its gradients change every group the test compares.
        let with = twin_groups(s, &dispflow_step(&s.inputs(0.5, NormGradMode::Detached)));
        let without = twin_groups(s, &dispflow_step(&s.inputs(0.0, NormGradMode::Detached)));
        let gpu_with = run_gpu_step(&gpu, s, 0.5, false);
        for (((name, a), (_, b)), (_, g)) in with.iter().zip(&without).zip(&gpu_with.groups) {
            let scale = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let diff = a
                .iter()
                .zip(b)
                .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
            let gdiff = g
                .iter()
                .zip(b)
                .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
            eprintln!(
                "{name}: motion part {:.2e} of scale (GPU {:.2e})",
                diff / scale,
                gdiff / scale
            );
            if diff > 1e-2 * scale {
                assert!(
                    gdiff > 0.5 * diff,
                    "{name}: the GPU step's motion part is missing"
                );
            }
        }
    }
}

dispflow_vk::subgroup_reruns!();
