//! CPU twin of one whole DispFlow-GS training step (direct order, DESIGN §2), composed of the
//! stage twins in f64: loss values and the gradient wrt every canonical Gaussian parameter and
//! every MLP parameter. It defines what the GPU step (`train::Trainer::record_dispflow_step`
//! with `motion_order = direct`) computes before Adam, with the optical flow replaced by a fixed
//! scene-motion field.
//!
//! The step, in order (N Gaussians, image H×W):
//! 1. `out_t = D(x, t)` for t = t1, t2 ([`mlp::forward_f64`], `Times::Batch`), x = canonical
//!    mean. The MLP input is detached: no gradient reaches x through the MLP.
//! 2. `δ_i = dx_i(t2) − dx_i(t1)` ([`dispflow::displacement`]).
//! 3. Drawn Gaussians at t1 ([`deform::deform_apply`]): `mean = x + dx`, `scale = exp(s) + ds`,
//!    `rot = normalize(q) + dr`. (The GPU also draws t2 for the intermediate render; with a fixed
//!    scene motion that render influences nothing, so the twin skips it.)
//! 4. Render of (camera, drawn t1) that also splats δ as 3 feature channels:
//!    `F_disp(p) = Σ_i w_i δ_i` ([`raster::project_f64`], [`raster::blend_fwd_f64`]). Colours use
//!    the SH view direction of the drawn mean, detached (as in the rasteriser).
//! 5. `L_photo = (1 − λ)·L1 + λ·(1 − SSIM)` of the rgb render against the target
//!    ([`loss::photometric_loss_f64`]).
//! 6. `m_disp = |F_disp|`, `m_scene = |scene_motion|`, each min-max normalised over the image
//!    ([`motion::normalize_f64`], eps [`MOTION_EPS`]). Either map degenerate: the motion term is
//!    skipped (loss 0, no gradient).
//! 7. `L_motion = α · mean_p |m̂_scene − m̂_disp|` ([`dispflow::motion_l1`]), back through the
//!    normalisation ([`NormGradMode`]) and the magnitude to `∂L/∂F_disp`.
//! 8. Blend backward with `∂L/∂rgb`, zero alpha and depth gradients and `∂L/∂F_disp` as the
//!    feature gradient; project backward ([`raster::blend_bwd_f64`], [`raster::project_bwd_f64`]).
//! 9. [`deform::deform_apply_bwd`]: canonical mean, log-scale, quaternion gradients and
//!    `∂L/∂out_t1`.
//! 10. [`dispflow::displacement_bwd`]: `∂out_t1.dx −= ∂δ`, `∂out_t2.dx = ∂δ`.
//! 11. [`mlp::backward`] at t1 plus at t2 → `d_mlp`.
//!
//! With the control-node field ([`StepNodes`], docs/nodes.md) step 1 runs the MLP at the node
//! positions (detached) and blends each Gaussian's deformation from its K nearest nodes
//! ([`nodes::nodes_lbs`], the KNN held fixed); step 11 first takes each deformation row's
//! gradient back through the blend ([`nodes::nodes_lbs_bwd`]: canonical means and rotations,
//! node positions and log-radii) and gathers it per node ([`nodes::nodes_gather`]) before the
//! MLP backward at the nodes.
//!
//! Everything is f64 from the f32 inputs on (no intermediate rounding); the only f32
//! computation is the rasteriser's tile rectangle, which follows the GPU bit for bit.
//!
//! [`step_loss_f64`] evaluates the same loss on an f64 copy of the parameters ([`StepParams64`]),
//! for finite differences. It holds fixed what the step detaches: the MLP input x is always
//! `inputs.gaussians.means` (never the perturbed copy), and the SH view direction can be pinned
//! to the drawn means of the unperturbed step ([`StepOutputs::drawn_means`]).

use std::hash::{Hash, Hasher};

use crate::kernels::motion::{NormFlag, NormMode, DEFAULT_EPS};
use crate::model::deform::{MlpLayout, OUT_DIMS};
use crate::model::gaussians::HostGaussians;
use crate::reference::raster::{self, BlendOut64, BlendParams, Camera, Gaussians64, Projected64};
use crate::reference::{deform, dispflow, loss, mlp, motion, nodes};

/// Flatness threshold of the motion normalisation (the trainer's `NormConfig` eps, 1e-6 as f32).
pub const MOTION_EPS: f64 = DEFAULT_EPS as f64;

/// How the motion loss's gradient passes the min-max normalisation statistics.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum NormGradMode {
    /// Min and max are constants of the backward: `∂m̂/∂m = 1/(max − min)` per pixel (the
    /// trainer's default; not the gradient of the loss).
    #[default]
    Detached,
    /// Autograd through min and max as well: the exact gradient of the loss.
    Full,
}

/// Everything one step reads. Shapes: `target` and `scene_motion` are `[H·W]` row-major for the
/// camera's H×W; `mlp_params` holds at least `mlp.total` floats.
#[derive(Clone, Copy, Debug)]
pub struct StepInputs<'a> {
    /// Canonical Gaussians (raw parameters: log-scales, unnormalised quaternions, opacity
    /// logits, SH split into DC and rest).
    pub gaussians: &'a HostGaussians,
    /// Active SH degree, `(sh_degree + 1)² <= gaussians.sh_coeffs`.
    pub sh_degree: u32,
    pub mlp: &'a MlpLayout,
    pub mlp_params: &'a [f32],
    pub camera: &'a Camera,
    pub t1: f32,
    pub t2: f32,
    /// rgba; alpha ignored.
    pub target: &'a [[f32; 4]],
    /// Fixed scene motion (replaces the optical flow of the render pair), 2 channels.
    pub scene_motion: &'a [[f32; 2]],
    pub background: [f32; 3],
    pub alpha_max: f32,
    pub lambda_ssim: f32,
    /// α of the motion term (0: photometric loss only).
    pub motion_weight: f32,
    pub norm_grad: NormGradMode,
    /// The control-node field; `None`: the MLP at every Gaussian.
    pub nodes: Option<StepNodes<'a>>,
}

/// The control-node field of a step: node parameters `[4M]` (positions, log-radii) and every
/// Gaussian's K nearest nodes `[N·K]` (`NO_NODE`-padded), held fixed.
#[derive(Clone, Copy, Debug)]
pub struct StepNodes<'a> {
    pub params: &'a [f32],
    pub knn: &'a [u32],
    pub k: usize,
}

/// f64 counterpart of [`HostGaussians`]: the canonical parameters (an unrounded copy for
/// finite differences) or the gradients wrt them, same shapes and layout.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Canonical64 {
    pub sh_coeffs: u32,
    pub means: Vec<[f64; 3]>,
    pub log_scales: Vec<[f64; 3]>,
    pub quats: Vec<[f64; 4]>,
    /// Opacity logits.
    pub opacity: Vec<f64>,
    pub sh_dc: Vec<[f64; 3]>,
    /// `[N, sh_coeffs − 1, 3]` flattened per Gaussian.
    pub sh_rest: Vec<f64>,
}

impl Canonical64 {
    /// Exact widening.
    pub fn from_host(g: &HostGaussians) -> Self {
        let w3 = |v: &[[f32; 3]]| v.iter().map(|a| a.map(f64::from)).collect();
        Canonical64 {
            sh_coeffs: g.sh_coeffs,
            means: w3(&g.means),
            log_scales: w3(&g.log_scales),
            quats: g.quats.iter().map(|a| a.map(f64::from)).collect(),
            opacity: g.opacity.iter().map(|&x| x as f64).collect(),
            sh_dc: w3(&g.sh_dc),
            sh_rest: g.sh_rest.iter().map(|&x| x as f64).collect(),
        }
    }

    /// All zero, for `n` Gaussians with `sh_coeffs` coefficients.
    pub fn zeros(n: usize, sh_coeffs: u32) -> Self {
        Canonical64 {
            sh_coeffs,
            means: vec![[0.0; 3]; n],
            log_scales: vec![[0.0; 3]; n],
            quats: vec![[0.0; 4]; n],
            opacity: vec![0.0; n],
            sh_dc: vec![[0.0; 3]; n],
            sh_rest: vec![0.0; n * 3 * (sh_coeffs as usize - 1)],
        }
    }

    pub fn len(&self) -> usize {
        self.means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// SH interleaved as the rasteriser reads it: `[N][sh_coeffs][3]`, DC first.
    fn sh_interleaved(&self) -> Vec<f64> {
        let rest = 3 * (self.sh_coeffs as usize - 1);
        let mut sh = Vec::with_capacity(self.len() * (3 + rest));
        for i in 0..self.len() {
            sh.extend_from_slice(&self.sh_dc[i]);
            sh.extend_from_slice(&self.sh_rest[i * rest..(i + 1) * rest]);
        }
        sh
    }
}

/// The differentiable parameters of one step in f64: canonical Gaussians and the MLP's flat
/// parameter buffer (layout [`MlpLayout`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StepParams64 {
    pub gaussians: Canonical64,
    pub mlp: Vec<f64>,
    /// Node parameters `[4M]` (empty without the node field).
    pub nodes: Vec<f64>,
}

impl StepParams64 {
    /// Exact widening of the step's own parameters.
    pub fn from_inputs(inp: &StepInputs<'_>) -> Self {
        StepParams64 {
            gaussians: Canonical64::from_host(inp.gaussians),
            mlp: inp.mlp_params.iter().map(|&x| x as f64).collect(),
            nodes: inp
                .nodes
                .map_or(Vec::new(), |n| n.params.iter().map(|&x| x as f64).collect()),
        }
    }
}

/// Loss values, gradients and the intermediates a GPU comparison needs.
#[derive(Clone, Debug, Default)]
pub struct StepOutputs {
    /// `(1 − λ)·L1 + λ·(1 − SSIM)`.
    pub photo_loss: f64,
    /// `α · mean_p |m̂_scene − m̂_disp|` (weighted); 0 when skipped.
    pub motion_loss: f64,
    /// A normalised map was degenerate: no motion loss, no motion gradient.
    pub motion_skipped: bool,
    /// ∂(photo + motion)/∂ canonical parameters (Detached: the trainer's gradient, see
    /// [`NormGradMode`]).
    pub d_gaussians: Canonical64,
    /// ∂L/∂ every MLP parameter (`mlp.total` floats; padding 0).
    pub d_mlp: Vec<f64>,
    /// ∂L/∂ node parameters `[4M]` (empty without the node field).
    pub d_nodes: Vec<f64>,
    /// `[N]`: drawn means at t1 (also the SH view-direction points).
    pub drawn_means: Vec<[f64; 3]>,
    /// `[N]`: δ = dx(t2) − dx(t1).
    pub delta: Vec<[f64; 3]>,
    /// `[H·W]`: rendered rgb (background included).
    pub rgb: Vec<[f64; 3]>,
    /// `[H·W·3]`: F_disp, the splatted displacement.
    pub disp_flow: Vec<f64>,
    /// `[H·W]`: normalised magnitudes (zeros when that map is degenerate).
    pub m_hat_disp: Vec<f64>,
    pub m_hat_scene: Vec<f64>,
    /// `[H·W·3]`: ∂L/∂F_disp (the blend's feature gradient).
    pub d_disp_flow: Vec<f64>,
    /// `[N][3]`: ∂L/∂δ.
    pub d_delta: Vec<[f64; 3]>,
}

impl StepOutputs {
    pub fn total_loss(&self) -> f64 {
        self.photo_loss + self.motion_loss
    }
}

/// The loss of [`step_loss_f64`] and the signature of its discrete decisions.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepLoss {
    pub photo: f64,
    pub motion: f64,
    pub motion_skipped: bool,
    /// Hash of every discrete decision on the way: ReLU masks of both MLP passes, the
    /// rasteriser's culling/clamps/tile rectangles/skips/stops and depth order, the sign of every
    /// photometric residual, the motion skip, argmin/argmax of m_disp and the sign of every
    /// motion residual. Equal signatures: the same smooth piece of the loss.
    pub signature: u64,
}

impl StepLoss {
    pub fn total(&self) -> f64 {
        self.photo + self.motion
    }
}

/// Everything the forward computes, kept for the backward.
struct Forward {
    act_t1: mlp::Activations,
    act_t2: mlp::Activations,
    /// `[N·3]` flat.
    delta: Vec<f64>,
    drawn: Gaussians64,
    blend: BlendParams,
    proj: Projected64,
    out: BlendOut64,
    photo: f64,
    d_rgb: Vec<[f64; 3]>,
    disp: motion::Normalized,
    scene: motion::Normalized,
    skipped: bool,
    motion: f64,
    d_m_hat: Vec<f64>,
    signature: u64,
}

fn check(inp: &StepInputs<'_>) {
    let g = inp.gaussians;
    let n = g.len();
    let rest = 3 * (g.sh_coeffs as usize).saturating_sub(1);
    for (name, len, want) in [
        ("log_scales", g.log_scales.len(), n),
        ("quats", g.quats.len(), n),
        ("opacity", g.opacity.len(), n),
        ("sh_dc", g.sh_dc.len(), n),
        ("sh_rest", g.sh_rest.len(), n * rest),
    ] {
        assert_eq!(
            len, want,
            "dispflow_step: gaussians.{name}.len() = {len}, expected {want}"
        );
    }
    let px = (inp.camera.width * inp.camera.height) as usize;
    assert_eq!(inp.target.len(), px, "dispflow_step: target.len() != H·W");
    assert_eq!(
        inp.scene_motion.len(),
        px,
        "dispflow_step: scene_motion.len() != H·W"
    );
    assert!(
        inp.mlp_params.len() >= inp.mlp.total,
        "dispflow_step: mlp_params.len() = {} < layout total {}",
        inp.mlp_params.len(),
        inp.mlp.total
    );
}

/// Steps 1–7 on `p`, the SH view direction taken from `view_means` (default: the drawn means).
fn forward(inp: &StepInputs<'_>, p: &StepParams64, view_means: Option<&[[f64; 3]]>) -> Forward {
    check(inp);
    let g = &p.gaussians;
    let n = g.len();
    assert_eq!(
        n,
        inp.gaussians.len(),
        "step_loss_f64: params are for another N"
    );
    let mut sig = std::collections::hash_map::DefaultHasher::new();

    // 1. D(x, t1), D(x, t2); x = the f32 canonical means of the inputs (detached), or the
    //    node positions and then the blend.
    let xyz: Vec<f32> = match inp.nodes {
        None => inp.gaussians.means.iter().flatten().copied().collect(),
        Some(nd) => nd.params[..3 * (nd.params.len() / 4)].to_vec(),
    };
    let act_t1 = mlp::forward_f64(inp.mlp, &p.mlp, &xyz, mlp::Times::Batch(inp.t1));
    let act_t2 = mlp::forward_f64(inp.mlp, &p.mlp, &xyz, mlp::Times::Batch(inp.t2));
    for a in [&act_t1, &act_t2] {
        for v in a.ht.iter().chain(a.h.iter().flatten()) {
            (*v > 0.0).hash(&mut sig);
        }
    }
    let (out_t1, out_t2) = match inp.nodes {
        None => (act_t1.out.clone(), act_t2.out.clone()),
        Some(nd) => {
            let blend = |act: &mlp::Activations| -> Vec<f64> {
                (0..n)
                    .flat_map(|i| {
                        let slots = node_slots(nd, &p.nodes, &act.out, i);
                        nodes::nodes_lbs(g.means[i], g.quats[i], &slots)
                    })
                    .collect()
            };
            (blend(&act_t1), blend(&act_t2))
        }
    };
    // 2. δ.
    let delta = dispflow::displacement(&out_t1, &out_t2);
    // 3. Drawn Gaussians at t1.
    let mut drawn = Gaussians64 {
        means: Vec::with_capacity(n),
        scales: Vec::with_capacity(n),
        quats: Vec::with_capacity(n),
        opacity_logits: g.opacity.clone(),
        sh: g.sh_interleaved(),
        sh_coeffs: g.sh_coeffs,
        sh_degree: inp.sh_degree,
    };
    for i in 0..n {
        let d: &[f64; OUT_DIMS] = out_t1[i * OUT_DIMS..(i + 1) * OUT_DIMS].try_into().unwrap();
        let (m, s, q) = deform::deform_apply(g.means[i], g.log_scales[i], g.quats[i], Some(d));
        drawn.means.push(m);
        drawn.scales.push(s);
        drawn.quats.push(q);
    }
    // 4. Render with δ as 3 feature channels.
    let cam = inp.camera;
    let blend = BlendParams {
        width: cam.width,
        height: cam.height,
        alpha_max: inp.alpha_max,
        background: inp.background,
        feature_dims: 3,
    };
    let mut proj = raster::project_f64(cam, &drawn);
    proj.signature.hash(&mut sig);
    if let Some(vm) = view_means {
        // Colours from the pinned view direction (the projection's colour depends on the mean
        // only through that detached direction).
        assert_eq!(vm.len(), n, "step_loss_f64: view_means.len() != N");
        let pinned = raster::project_f64(
            cam,
            &Gaussians64 {
                means: vm.to_vec(),
                ..drawn.clone()
            },
        );
        pinned.signature.hash(&mut sig);
        for i in 0..n {
            if proj.radius[i] > 0 {
                proj.color[i] = pinned.color[i];
            }
        }
    }
    let out = raster::blend_fwd_f64(&blend, &proj, &delta);
    out.signature.hash(&mut sig);
    // 5. Photometric loss.
    let (w, h) = (cam.width as usize, cam.height as usize);
    let x: Vec<[f64; 4]> = out
        .rgb
        .iter()
        .zip(&out.alpha)
        .map(|(c, &a)| [c[0], c[1], c[2], a])
        .collect();
    let y: Vec<[f64; 4]> = inp.target.iter().map(|v| v.map(f64::from)).collect();
    let (values, d_rgba) = loss::photometric_loss_f64(&x, &y, w, h, inp.lambda_ssim as f64);
    for (a, b) in x.iter().zip(&y) {
        for c in 0..3 {
            (a[c] - b[c]).partial_cmp(&0.0).hash(&mut sig);
        }
    }
    let d_rgb = d_rgba.iter().map(|v| [v[0], v[1], v[2]]).collect();
    // 6. Normalised magnitudes.
    let disp = motion::normalize_f64(&out.features, 3, NormMode::MinMax, MOTION_EPS);
    let scene_v: Vec<f64> = inp
        .scene_motion
        .iter()
        .flatten()
        .map(|&v| v as f64)
        .collect();
    let scene = motion::normalize_f64(&scene_v, 2, NormMode::MinMax, MOTION_EPS);
    let skipped = disp.stats.flag != NormFlag::Ok || scene.stats.flag != NormFlag::Ok;
    // 7. Motion loss and ∂/∂m̂_disp.
    let weight = inp.motion_weight as f64;
    let (mean_l1, d_m_hat) = dispflow::motion_l1(&disp.m_hat, &scene.m_hat, None, weight, skipped);
    (skipped, disp.stats.argmin, disp.stats.argmax).hash(&mut sig);
    if !skipped {
        for (a, b) in disp.m_hat.iter().zip(&scene.m_hat) {
            (a - b).partial_cmp(&0.0).hash(&mut sig);
        }
    }
    Forward {
        act_t1,
        act_t2,
        delta,
        drawn,
        blend,
        proj,
        out,
        photo: values.loss,
        d_rgb,
        disp,
        scene,
        skipped,
        motion: weight * mean_l1,
        d_m_hat,
        signature: sig.finish(),
    }
}

/// The total loss of the step at f64 parameters `p` (for finite differences), with the MLP input
/// x held at `inp.gaussians.means` and, when given, the SH view direction taken from
/// `view_means` (pass [`StepOutputs::drawn_means`] of the unperturbed step: the step treats that
/// direction as a constant). `inp.norm_grad` is irrelevant here (it only shapes the backward).
pub fn step_loss_f64(
    inp: &StepInputs<'_>,
    p: &StepParams64,
    view_means: Option<&[[f64; 3]]>,
) -> StepLoss {
    let f = forward(inp, p, view_means);
    StepLoss {
        photo: f.photo,
        motion: f.motion,
        motion_skipped: f.skipped,
        signature: f.signature,
    }
}

/// One full DispFlow-GS step (direct order) on the inputs' own parameters: losses, gradients
/// wrt the canonical Gaussians and the MLP, and the intermediates (see the module docs).
pub fn dispflow_step(inp: &StepInputs<'_>) -> StepOutputs {
    let p = StepParams64::from_inputs(inp);
    let f = forward(inp, &p, None);
    let g = &p.gaussians;
    let n = g.len();
    let nc = g.sh_coeffs as usize;

    // 7. (cont.) ∂L/∂m_disp through the normalisation, then ∂L/∂F_disp through |·|.
    let d_m = match inp.norm_grad {
        NormGradMode::Detached => motion::norm_backward_detached(&f.disp, &f.d_m_hat),
        NormGradMode::Full => motion::norm_backward(&f.disp, NormMode::MinMax, &f.d_m_hat),
    };
    let d_disp_flow = motion::magnitude_backward(&f.out.features, 3, &d_m);

    // 8. Blend and projection backward (alpha and depth gradients zero).
    let bg = raster::blend_bwd_f64::<f64>(
        &f.blend,
        &f.proj,
        &f.delta,
        &f.d_rgb,
        &[],
        &[],
        &d_disp_flow,
    );
    let pg = raster::project_bwd_f64(inp.camera, &f.drawn, &bg);

    // 9. Through the deformation to the canonical parameters and ∂L/∂out_t1.
    let mut d = Canonical64::zeros(n, g.sh_coeffs);
    let mut d_out_t1 = vec![0.0; n * OUT_DIMS];
    for i in 0..n {
        let (dx, ds, dq, dd) = deform::deform_apply_bwd(
            g.log_scales[i],
            g.quats[i],
            pg.means[i],
            pg.scales[i],
            pg.quats[i],
        );
        d.means[i] = dx;
        d.log_scales[i] = ds;
        d.quats[i] = dq;
        d_out_t1[i * OUT_DIMS..(i + 1) * OUT_DIMS].copy_from_slice(&dd);
        d.opacity[i] = pg.opacity_logits[i];
        let sh = &pg.sh[i * nc * 3..(i + 1) * nc * 3];
        d.sh_dc[i].copy_from_slice(&sh[..3]);
        d.sh_rest[i * (nc - 1) * 3..(i + 1) * (nc - 1) * 3].copy_from_slice(&sh[3..]);
    }

    // 10. δ backward into both MLP passes.
    let (d_out_t1, d_out_t2) = dispflow::displacement_bwd(&bg.features, &d_out_t1);

    // 11. (Through the blend and the per-node gather, then) MLP backward at t1 and t2, summed.
    let mut d_nodes = vec![0.0; p.nodes.len()];
    let mut at_nodes = |act: &mlp::Activations, d_out: Vec<f64>| -> Vec<f64> {
        let Some(nd) = inp.nodes else {
            return d_out;
        };
        let m = p.nodes.len() / 4;
        let mut contrib = vec![[0.0; 14]; n * nd.k];
        for i in 0..n {
            let slots = node_slots(nd, &p.nodes, &act.out, i);
            let up: [f64; OUT_DIMS] = d_out[i * OUT_DIMS..(i + 1) * OUT_DIMS].try_into().unwrap();
            let (gm, gq, rows) = nodes::nodes_lbs_bwd(g.means[i], g.quats[i], &slots, up);
            (0..3).for_each(|a| d.means[i][a] += gm[a]);
            (0..4).for_each(|a| d.quats[i][a] += gq[a]);
            contrib[i * nd.k..i * nd.k + rows.len()].copy_from_slice(&rows);
        }
        let (d_out_nodes, d_params) = nodes::nodes_gather(nd.knn, &contrib, m);
        for (j, r) in d_params.iter().enumerate() {
            (0..3).for_each(|a| d_nodes[3 * j + a] += r[a]);
            d_nodes[3 * m + j] += r[3];
        }
        d_out_nodes.into_iter().flatten().collect()
    };
    let d_out_t1 = at_nodes(&f.act_t1, d_out_t1);
    let d_out_t2 = at_nodes(&f.act_t2, d_out_t2);
    let mut d_mlp = mlp::backward(inp.mlp, &p.mlp, &f.act_t1, &d_out_t1);
    let d2 = mlp::backward(inp.mlp, &p.mlp, &f.act_t2, &d_out_t2);
    d_mlp.iter_mut().zip(&d2).for_each(|(a, b)| *a += b);

    let v3 = |v: &[f64]| v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    StepOutputs {
        photo_loss: f.photo,
        motion_loss: f.motion,
        motion_skipped: f.skipped,
        d_gaussians: d,
        d_mlp,
        d_nodes,
        drawn_means: f.drawn.means.clone(),
        delta: v3(&f.delta),
        rgb: f.out.rgb,
        disp_flow: f.out.features,
        m_hat_disp: f.disp.m_hat,
        m_hat_scene: f.scene.m_hat,
        d_disp_flow,
        d_delta: v3(&bg.features),
    }
}

/// The twin blend's slots of Gaussian `i`: its KNN row with the f64 node parameters `params`
/// `[4M]` and the node MLP outputs `out` `[M·10]`.
fn node_slots(nd: StepNodes<'_>, params: &[f64], out: &[f64], i: usize) -> Vec<nodes::Slot> {
    let m = params.len() / 4;
    nd.knn[i * nd.k..(i + 1) * nd.k]
        .iter()
        .take_while(|&&j| j != nodes::NO_NODE)
        .map(|&j| {
            let j = j as usize;
            nodes::Slot {
                p: [params[3 * j], params[3 * j + 1], params[3 * j + 2]],
                rho: params[3 * m + j],
                out: out[j * OUT_DIMS..(j + 1) * OUT_DIMS].try_into().unwrap(),
            }
        })
        .collect()
}
