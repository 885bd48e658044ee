//! Scenes shaped like the issue-14 workloads for the rasteriser bench, and the blend-forward and
//! blend-backward variant comparisons on them (all variants interleaved within each repetition,
//! so load on a shared machine hits all of them alike).

use super::{median, BenchRow, RasterCase};
use crate::data::synthetic::{sample_points, GenCamera};
use crate::error::{Error, Result};
use crate::kernels::raster::G2D_STRIDE;
use crate::kernels::raster::{BlendBwdVariant, BlendFwdVariant, Camera, DeviceShape};
use crate::testing::Noise;
use crate::vk::Gpu;

/// Host-side Gaussians: `means` [N,3], linear `scales` [N,3], `quats` [N,4], `logits` [N],
/// `sh` [N,16,3].
#[derive(Clone, Debug, Default)]
pub struct HostSplats {
    pub means: Vec<f32>,
    pub scales: Vec<f32>,
    pub quats: Vec<f32>,
    pub logits: Vec<f32>,
    pub sh: Vec<f32>,
}

/// The two scenes of issue 14's blend-backward target.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RasterScene {
    /// Stand-in for a held-out D-NeRF scene at 114×114 with 20k Gaussians: an object of three
    /// overlapping unit-ish spheres seen from 4 units with a 50° field of view (the object
    /// fills about half the image, the rest is background), Gaussians on its surfaces with
    /// log-uniform sizes 0.004–0.04 (flattened along one axis, as trained splats are) and
    /// opacities from faint to opaque.
    Dnerf,
    /// The built-in synthetic scene as the fast preset trains it: 160×120 (frame 30 of 60's
    /// camera), 10k Gaussians at the generator's surface points (room, rigid sphere, blob) with
    /// the 3DGS initial size (mean distance to the 3 nearest points).
    Builtin,
}

impl RasterScene {
    pub fn label(self) -> &'static str {
        match self {
            RasterScene::Dnerf => "D-NeRF-like 114×114",
            RasterScene::Builtin => "built-in 160×120",
        }
    }

    pub fn build(self) -> (HostSplats, Camera) {
        match self {
            RasterScene::Dnerf => dnerf_like(20_000),
            RasterScene::Builtin => builtin(10_000),
        }
    }
}

/// `seed`'s draws of [`Noise::uniform`] in `[0, 1]` plus half a step, so never 0 (as these
/// scenes have always been drawn).
fn draws(seed: u64) -> impl FnMut() -> f32 {
    let mut r = Noise::new(seed);
    move || r.uniform(0.0, 1.0) + 0.5 / 4_294_967_296.0
}

fn push_sh(h: &mut HostSplats, u: &mut impl FnMut() -> f32) {
    // A DC colour in [0, 1] plus small higher bands.
    h.sh.extend((0..3).map(|_| (u() - 0.5) / 0.282_094_8));
    h.sh.extend((3..48).map(|_| 0.1 * (u() - 0.5)));
}

fn dnerf_like(n: usize) -> (HostSplats, Camera) {
    let mut u = draws(114);
    let mut h = HostSplats::default();
    let centres = [[0.0, 0.0, 4.0], [0.5, -0.4, 4.3], [-0.45, 0.35, 4.2]];
    let radii = [0.8f32, 0.55, 0.5];
    for i in 0..n {
        let (c, r) = (centres[i % 3], radii[i % 3]);
        let dir = loop {
            let v = [2.0 * u() - 1.0, 2.0 * u() - 1.0, 2.0 * u() - 1.0];
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if l > 1e-3 && l <= 1.0 {
                break v.map(|x| x / l);
            }
        };
        h.means.extend((0..3).map(|k| c[k] + r * dir[k]));
        let s = 0.004 * 10f32.powf(u());
        h.scales.extend([s, s * (0.5 + u()), 0.2 * s]);
        h.quats.extend([u() - 0.5, u() - 0.5, u() - 0.5, u() - 0.5]);
        h.logits.push(8.0 * u() - 3.0);
        push_sh(&mut h, &mut u);
    }
    let (w, fov) = (114u32, 50f32.to_radians());
    let f = 0.5 * w as f32 / (0.5 * fov).tan();
    let cam = Camera {
        rot: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        trans: [0.0; 3],
        fx: f,
        fy: f,
        cx: 0.5 * w as f32,
        cy: 0.5 * w as f32,
        width: w,
        height: w,
        near: 0.01,
    };
    (h, cam)
}

fn builtin(n: usize) -> (HostSplats, Camera) {
    let pts = sample_points(0, n);
    let mut u = draws(160);
    let mut h = HostSplats::default();
    for (i, p) in pts.iter().enumerate() {
        // Mean distance to the 3 nearest points (brute force: 10^4 points, once).
        let mut best = [f64::INFINITY; 3];
        for (j, q) in pts.iter().enumerate() {
            let d = p.distance_squared(*q);
            if j != i && d < best[2] {
                best[2] = d;
                best.sort_by(f64::total_cmp);
            }
        }
        let s = (best.iter().map(|d| d.sqrt()).sum::<f64>() / 3.0) as f32;
        h.means.extend([p.x as f32, p.y as f32, p.z as f32]);
        h.scales.extend([s; 3]);
        h.quats.extend([1.0, 0.0, 0.0, 0.0]);
        h.logits.push(6.0 * u() - 2.0);
        push_sh(&mut h, &mut u);
    }
    let g = GenCamera::for_frame(30, 60, 160, 120);
    let rot = g.rotation;
    let t = -(rot * g.centre);
    let row = |r: usize| {
        let v = rot.row(r);
        [v.x as f32, v.y as f32, v.z as f32]
    };
    let cam = Camera {
        rot: [row(0), row(1), row(2)],
        trans: [t.x as f32, t.y as f32, t.z as f32],
        fx: g.f as f32,
        fy: g.f as f32,
        cx: g.cx as f32,
        cy: g.cy as f32,
        width: g.width,
        height: g.height,
        near: 0.01,
    };
    (h, cam)
}

/// Median GPU ms of the dispatches whose label contains `kernel`.
fn blend_ms(t: &crate::vk::Timings, kernel: &str) -> f64 {
    t.by_label()
        .iter()
        .filter(|(l, _)| l.contains(kernel))
        .map(|(_, ms)| ms)
        .sum()
}

/// Blend forward and blend backward, every variant of each on each scene, `reps` interleaved
/// repetitions (after one warm-up each): one row per (scene, pass, variant) with the median GPU
/// ms of the blend dispatch alone and, in its name, the speed-up over the GPU-shaped kernel
/// (shared / subgroup-atomic; M elements/s counts tile hits). Each backward reads the outputs
/// of the forward just before it (the last forward variant's).
pub fn blend_rows(gpu: &Gpu, scenes: &[RasterScene], reps: usize) -> Result<Vec<BenchRow>> {
    let mut rows = Vec::new();
    for &scene in scenes {
        let (h, cam) = scene.build();
        let mut case = RasterCase::from_host(gpu, &h, cam)?;
        let isect = case.intersections(gpu)?;
        verify_fwd_variants(gpu, &mut case, scene)?;
        verify_variants(gpu, &mut case, scene)?;
        let (nf, nb) = (BlendFwdVariant::ALL.len(), BlendBwdVariant::ALL.len());
        let mut ms = vec![Vec::new(); nf + nb];
        for rep in 0..=reps.max(1) {
            for (i, &v) in BlendFwdVariant::ALL.iter().enumerate() {
                case.set_blend_fwd_variant(v);
                let t = case.run(gpu, false)?;
                if rep > 0 {
                    ms[i].push(blend_ms(&t, "blend_fwd"));
                }
            }
            for (i, &v) in BlendBwdVariant::ALL.iter().enumerate() {
                case.set_blend_bwd_variant(v);
                let t = case.run_backward(gpu)?;
                if rep > 0 {
                    ms[nf + i].push(blend_ms(&t, "blend_bwd"));
                }
            }
        }
        let med: Vec<f64> = ms.into_iter().map(median).collect();
        let names = BlendFwdVariant::ALL
            .iter()
            .map(|v| ("blend_fwd", v.name(), "shared", 0))
            .chain(
                BlendBwdVariant::ALL
                    .iter()
                    .map(|v| ("blend_bwd", v.name(), "subgroup-atomic", nf)),
            );
        for (i, (pass, name, base, b)) in names.enumerate() {
            rows.push(BenchRow {
                kernel: format!(
                    "{pass} {name} {} ({isect} tile hits, {:.2}× {base})",
                    scene.label(),
                    med[b] / med[i]
                ),
                n: case.n,
                median_ms: med[i],
                m_per_s: isect as f64 / med[i] / 1e3,
                stages: vec![],
            });
        }
    }
    Ok(rows)
}

/// Every forward variant's outputs against the shared-memory kernel's before timing: the same
/// last contributor per pixel and rgba, depth and final T within 2e-5 + 2e-5 · |value| (the
/// raster_twin tolerances; both variants run the same per-pixel operations in the same order).
fn verify_fwd_variants(gpu: &Gpu, case: &mut RasterCase, scene: RasterScene) -> Result<()> {
    let mut outs = Vec::new();
    for v in BlendFwdVariant::ALL {
        case.set_blend_fwd_variant(v);
        case.run(gpu, false)?;
        outs.push(case.forward_outputs(gpu)?);
    }
    let (want_f, want_n) = &outs[0];
    for (v, (got_f, got_n)) in BlendFwdVariant::ALL.iter().zip(&outs).skip(1) {
        let bad_n = want_n.iter().zip(got_n).filter(|(a, b)| a != b).count();
        let bad_f = want_f
            .iter()
            .zip(got_f)
            .filter(|(a, b)| !b.is_finite() || (*a - *b).abs() > 2e-5 + 2e-5 * a.abs())
            .count();
        if bad_n + bad_f > 0 {
            return Err(Error::Invalid(format!(
                "blend_fwd {} on {}: {bad_n} pixels differ from shared in their last contributor, \
                 {bad_f} rgba/depth/T values beyond 2e-5",
                v.name(),
                scene.label()
            )));
        }
    }
    Ok(())
}

/// Every variant's 2D gradients against the subgroup-atomic kernel's, per component kind
/// (max |Δ| <= 2e-3 · max |reference| + 1e-7, the raster_twin tolerance), before timing.
fn verify_variants(gpu: &Gpu, case: &mut RasterCase, scene: RasterScene) -> Result<()> {
    let mut grads = Vec::new();
    for v in BlendBwdVariant::ALL {
        case.set_blend_bwd_variant(v);
        case.run_backward(gpu)?;
        grads.push(case.grad2d(gpu)?);
    }
    let s = G2D_STRIDE as usize;
    for (v, got) in BlendBwdVariant::ALL.iter().zip(&grads).skip(1) {
        for (kind, lo, hi) in [
            ("mean2d", 0, 2),
            ("conic", 2, 5),
            ("opacity", 5, 6),
            ("colour", 6, 9),
        ] {
            let pick = |g: &[f32]| -> Vec<f32> {
                g.chunks_exact(s).flat_map(|r| r[lo..hi].to_vec()).collect()
            };
            let (want, got) = (pick(&grads[0]), pick(got));
            let scale = want.iter().fold(0f32, |m, x| m.max(x.abs()));
            let err = want
                .iter()
                .zip(&got)
                .fold(0f32, |m, (a, b)| m.max((a - b).abs()));
            // f32::max skips NaN: non-finite gradients are rejected on their own.
            if got.iter().any(|x| !x.is_finite()) || err > 2e-3 * scale + 1e-7 {
                return Err(Error::Invalid(format!(
                    "blend_bwd {} on {}: d {kind} differs from subgroup-atomic by {err:.3e} (max {scale:.3e})",
                    v.name(),
                    scene.label()
                )));
            }
        }
    }
    Ok(())
}
