//! Transient Gaussians (issue 37): the temporal stage (`glsl/temporal/*.comp`) against its twin
//! on identical inputs (forward, backward, δ and its backward, the prune's peak), the twin
//! against central finite differences (f64), the opacity factor through the projection
//! (GPU vs twin, and the factor's gradient against finite differences of a rendered loss), and
//! the extremes: σ at its floor, a NaN width, an enormous velocity, a time far outside every
//! centre, every transient culled.

mod raster_common;

use dispflow_vk::kernels::deform::Drawn;
use dispflow_vk::kernels::raster::{OutputGrads, RasterSize, Rasterizer, RenderOpts, SplatInputs};
use dispflow_vk::kernels::temporal::{Temporal, TemporalGrads, TemporalInputs, TemporalParams};
use dispflow_vk::reference::raster as rtwin;
use dispflow_vk::reference::temporal as twin;
use dispflow_vk::testing::{self, assert_close, Noise, Tol};
use dispflow_vk::vk::Recorder;

/// `n` rows, the first `first` canonical; transients with centres around `t`, widths from
/// below the floor to several times it, velocities up to 3 units per unit time.
fn inputs(seed: u64, n: usize, p: &TemporalParams) -> twin::TemporalInputs {
    let mut r = Noise::new(seed);
    let mut x = twin::TemporalInputs::default();
    let floor = p.log_floor as f64;
    for _ in 0..n {
        x.means.push(std::array::from_fn(|_| r.uniform(-1.0, 1.0)));
        x.log_scales
            .push(std::array::from_fn(|_| r.uniform(-4.0, -1.0)));
        x.quats.push(std::array::from_fn(|_| r.uniform(-1.0, 1.0)));
        x.centre.push(p.t as f64 + r.uniform(-0.15, 0.15));
        x.log_width.push(floor + r.uniform(-0.5, 1.5));
        x.velocity
            .push(std::array::from_fn(|_| r.uniform(-3.0, 3.0)));
    }
    x
}

fn params(n: usize, first: usize, t: f32) -> TemporalParams {
    TemporalParams {
        n: n as u32,
        first: first as u32,
        t,
        log_floor: (0.03f32).ln(),
        cutoff: 0.01,
        t2: t + 0.05,
        t_lo: 0.0,
        t_hi: 1.0,
    }
}

fn upstream(seed: u64, n: usize) -> twin::TemporalUpstream {
    let mut r = Noise::new(seed);
    let mut u = twin::TemporalUpstream::default();
    for _ in 0..n {
        u.means.push(std::array::from_fn(|_| r.uniform(-1.0, 1.0)));
        u.scales.push(std::array::from_fn(|_| r.uniform(-1.0, 1.0)));
        u.quats.push(std::array::from_fn(|_| r.uniform(-1.0, 1.0)));
        u.op_scale.push(r.uniform(-1.0, 1.0));
    }
    u
}

fn f32s<const K: usize>(v: &[[f64; K]]) -> Vec<f32> {
    v.iter().flat_map(|a| a.map(|x| x as f32)).collect()
}

fn flat(v: &[f64]) -> Vec<f32> {
    v.iter().map(|&x| x as f32).collect()
}

/// What the GPU produced.
struct Got {
    means: Vec<f32>,
    scales: Vec<f32>,
    quats: Vec<f32>,
    op_scale: Vec<f32>,
    g: [Vec<f32>; 6],
    delta: Vec<f32>,
    peak: Vec<f32>,
}

const NOISE: f32 = 12345.0;

/// Runs every temporal kernel once. Canonical rows of the drawn and gradient buffers start as
/// `NOISE` and must stay so (the stage owns the transient rows only).
fn run(p: &TemporalParams, x: &twin::TemporalInputs, u: &twin::TemporalUpstream) -> Got {
    let gpu = testing::gpu();
    let k = Temporal::new(&gpu).unwrap();
    let n = p.n as usize;
    let b = |name: &str, v: &[f32]| gpu.buffer_from(name, v).unwrap();
    let noise = |w: usize| vec![NOISE; (w * n).max(1)];
    let logits: Vec<f32> = (0..n).map(|i| (i as f32 * 0.37).sin() * 3.0).collect();
    let xin = [
        b("means", &f32s(&x.means)),
        b("log scales", &f32s(&x.log_scales)),
        b("quats", &f32s(&x.quats)),
        b("centre", &flat(&x.centre)),
        b("log width", &flat(&x.log_width)),
        b("velocity", &f32s(&x.velocity)),
    ];
    let drawn = [b("dm", &noise(3)), b("ds", &noise(3)), b("dq", &noise(4))];
    let op = b("op", &noise(1));
    let up = [
        b("um", &f32s(&u.means)),
        b("us", &f32s(&u.scales)),
        b("uq", &f32s(&u.quats)),
        b("uw", &flat(&u.op_scale)),
    ];
    let grads: Vec<_> = [3, 3, 4, 1, 1, 3]
        .iter()
        .map(|&w| b("grad", &noise(w)))
        .collect();
    let delta = b("delta", &noise(3));
    let peak = b("peak", &noise(1));
    let lb = b("logits", &logits);
    let xi = TemporalInputs {
        means: xin[0].all(),
        log_scales: xin[1].all(),
        quats: xin[2].all(),
        centre: xin[3].all(),
        log_width: xin[4].all(),
        velocity: xin[5].all(),
    };
    let mut rec = Recorder::new(&gpu).unwrap();
    let d = Drawn {
        means: drawn[0].all(),
        scales: drawn[1].all(),
        quats: drawn[2].all(),
    };
    k.forward(&mut rec, p, &xi, &d, op.all());
    let dd = Drawn {
        means: up[0].all(),
        scales: up[1].all(),
        quats: up[2].all(),
    };
    let tg = TemporalGrads {
        means: grads[0].all(),
        log_scales: grads[1].all(),
        quats: grads[2].all(),
        centre: grads[3].all(),
        log_width: grads[4].all(),
        velocity: grads[5].all(),
    };
    k.backward(&mut rec, p, &xi, &dd, up[3].all(), &tg);
    k.displacement(&mut rec, p, xi.velocity, delta.all());
    // δ's upstream gradient: the drawn means' (any [N,3] will do).
    k.displacement_backward(&mut rec, p, up[0].all(), grads[5].all());
    k.peak(&mut rec, p, lb.all(), xi.centre, xi.log_width, peak.all());
    rec.finish().unwrap();
    let rd = |buf: &dispflow_vk::vk::Buffer| -> Vec<f32> { gpu.read(buf.all()).unwrap() };
    Got {
        means: rd(&drawn[0]),
        scales: rd(&drawn[1]),
        quats: rd(&drawn[2]),
        op_scale: rd(&op),
        g: std::array::from_fn(|i| rd(&grads[i])),
        delta: rd(&delta),
        peak: rd(&peak),
    }
}

/// `|gpu − twin| ≤ 1e-5·(1 + |twin|)`.
const TOL_1E5: Tol = Tol::Elementwise {
    abs: 1e-5,
    rel: 1e-5,
};
/// `|gpu − twin| ≤ 1e-4·(1 + |twin|)`.
const TOL_1E4: Tol = Tol::Elementwise {
    abs: 1e-4,
    rel: 1e-4,
};

/// Rows whose weight is within 1e-3 of the cut-off, or whose width is within 1e-4 of the floor:
/// the f32 GPU and the f64 twin may decide them differently.
fn on_an_edge(p: &TemporalParams, x: &twin::TemporalInputs, i: usize, t: f64) -> bool {
    let ls = x.log_width[i].max(p.log_floor as f64);
    let d = t - x.centre[i];
    let w = (-0.5 * d * d * (-2.0 * ls).exp()).exp();
    (w - p.cutoff as f64).abs() < 1e-3 || (x.log_width[i] - p.log_floor as f64).abs() < 1e-4
}

#[test]
#[allow(clippy::needless_range_loop)] // one row's components across several arrays
fn temporal_kernels_match_the_twin() {
    for (seed, n, first) in [
        (1u64, 300usize, 120usize),
        (2, 64, 0),
        (3, 50, 50),
        (4, 1, 0),
    ] {
        let p = params(n, first, 0.4);
        let x = inputs(seed, n, &p);
        let u = upstream(seed + 10, n);
        let got = run(&p, &x, &u);
        let fwd = twin::forward(&p, &x);
        let bwd = twin::backward(&p, &x, &u);
        let disp = twin::displacement(&p, &x.velocity);
        let disp_bwd = twin::displacement_bwd(&p, &u.means);
        let logits: Vec<f64> = (0..n)
            .map(|i| ((i as f32 * 0.37).sin() * 3.0) as f64)
            .collect();
        let peak = twin::peak(&p, &logits, &x.centre, &x.log_width);
        let (mut alive, mut culled) = (0, 0);
        for i in 0..n {
            let ctx = format!("seed {seed}, row {i}");
            if i < first {
                // Canonical rows: factor 1, everything else untouched.
                assert_eq!(got.op_scale[i], 1.0, "{ctx}");
                assert_eq!(got.means[3 * i], NOISE, "{ctx}: drawn mean written");
                assert_eq!(got.g[3][i], NOISE, "{ctx}: centre gradient written");
                assert_eq!(got.delta[3 * i], NOISE, "{ctx}: δ written");
                assert_eq!(got.peak[i], logits[i] as f32, "{ctx}: peak");
                continue;
            }
            assert_close(
                &format!("{ctx}: δ"),
                &[got.delta[3 * i + 1]],
                &[disp[i].unwrap()[1]],
                TOL_1E5,
            );
            if on_an_edge(&p, &x, i, p.t as f64) {
                continue;
            }
            let w = fwd.op_scale[i];
            if w > 0.0 {
                alive += 1;
            } else {
                culled += 1;
            }
            assert_close(&format!("{ctx}: w"), &[got.op_scale[i]], &[w], TOL_1E5);
            for a in 0..3 {
                assert_close(
                    &format!("{ctx}: mean"),
                    &[got.means[3 * i + a]],
                    &[fwd.means[i].unwrap()[a]],
                    TOL_1E5,
                );
                assert_close(
                    &format!("{ctx}: scale"),
                    &[got.scales[3 * i + a]],
                    &[fwd.scales[i].unwrap()[a]],
                    TOL_1E5,
                );
                assert_close(
                    &format!("{ctx}: g mean"),
                    &[got.g[0][3 * i + a]],
                    &[bwd.means[i][a]],
                    TOL_1E5,
                );
                assert_close(
                    &format!("{ctx}: g log-scale"),
                    &[got.g[1][3 * i + a]],
                    &[bwd.log_scales[i][a]],
                    TOL_1E5,
                );
                let gv = bwd.velocity[i][a] + disp_bwd[i][a];
                assert_close(
                    &format!("{ctx}: g velocity"),
                    &[got.g[5][3 * i + a]],
                    &[gv],
                    TOL_1E4,
                );
            }
            for a in 0..4 {
                assert_close(
                    &format!("{ctx}: quat"),
                    &[got.quats[4 * i + a]],
                    &[fwd.quats[i].unwrap()[a]],
                    TOL_1E5,
                );
                assert_close(
                    &format!("{ctx}: g quat"),
                    &[got.g[2][4 * i + a]],
                    &[bwd.quats[i][a]],
                    TOL_1E4,
                );
            }
            assert_close(
                &format!("{ctx}: g centre"),
                &[got.g[3][i]],
                &[bwd.centre[i]],
                TOL_1E4,
            );
            assert_close(
                &format!("{ctx}: g log-width"),
                &[got.g[4][i]],
                &[bwd.log_width[i]],
                TOL_1E4,
            );
            if peak[i].is_finite() {
                assert_close(&format!("{ctx}: peak"), &[got.peak[i]], &[peak[i]], TOL_1E4);
            } else {
                assert_eq!(got.peak[i], f32::NEG_INFINITY, "{ctx}: a never-alive peak");
            }
        }
        if n - first > 20 {
            assert!(
                alive > 10 && culled > 0,
                "seed {seed}: {alive} alive, {culled} culled"
            );
        }
    }
}

#[test]
fn twin_gradients_match_finite_differences() {
    let p = params(40, 10, 0.4);
    let x = inputs(7, 40, &p);
    let u = upstream(8, 40);
    let g = twin::backward(&p, &x, &u);
    let loss = |x: &twin::TemporalInputs| -> f64 {
        let o = twin::forward(&p, x);
        let mut l = 0.0;
        for i in (p.first as usize)..(p.n as usize) {
            l += u.op_scale[i] * o.op_scale[i];
            let (m, s, q) = (
                o.means[i].unwrap(),
                o.scales[i].unwrap(),
                o.quats[i].unwrap(),
            );
            l += (0..3)
                .map(|a| u.means[i][a] * m[a] + u.scales[i][a] * s[a])
                .sum::<f64>();
            l += (0..4).map(|a| u.quats[i][a] * q[a]).sum::<f64>();
        }
        l
    };
    let h = 1e-6;
    let mut checked = 0;
    for i in (p.first as usize)..(p.n as usize) {
        if on_an_edge(&p, &x, i, p.t as f64) || twin::forward(&p, &x).op_scale[i] < 0.05 {
            continue; // a cull or the floor's kink within the step
        }
        let fd = |f: &dyn Fn(&mut twin::TemporalInputs, f64)| {
            let (mut a, mut b) = (x.clone(), x.clone());
            f(&mut a, h);
            f(&mut b, -h);
            (loss(&a) - loss(&b)) / (2.0 * h)
        };
        let near = |what: &str, fd: f64, an: f64| {
            assert!(
                (fd - an).abs() <= 1e-6 * (1.0 + an.abs()),
                "row {i} {what}: fd {fd}, twin {an}"
            )
        };
        near("c", fd(&|x, e| x.centre[i] += e), g.centre[i]);
        near("τ", fd(&|x, e| x.log_width[i] += e), g.log_width[i]);
        for a in 0..3 {
            near("v", fd(&|x, e| x.velocity[i][a] += e), g.velocity[i][a]);
            near("μ", fd(&|x, e| x.means[i][a] += e), g.means[i][a]);
            near("s", fd(&|x, e| x.log_scales[i][a] += e), g.log_scales[i][a]);
        }
        for a in 0..4 {
            near("q", fd(&|x, e| x.quats[i][a] += e), g.quats[i][a]);
        }
        // δ = v·(t2 − t1): ∂/∂v is (t2 − t1) per component.
        let dt = (p.t2 - p.t) as f64;
        let d = twin::displacement(&p, &x.velocity)[i].unwrap();
        near("δ", d[0], x.velocity[i][0] * dt);
        checked += 1;
    }
    assert!(checked > 10, "{checked} rows checked");
}

/// A scene of transients rendered with their opacity factors: the GPU projection against the
/// twin, the GPU's ∂L/∂w and ∂L/∂logit against the twin's, and the twin's ∂L/∂w against
/// central differences of its own rendered loss.
#[test]
fn the_opacity_factor_through_the_rasteriser() {
    let gpu = testing::gpu();
    let rast = Rasterizer::new(&gpu).unwrap();
    let scene = raster_common::random_scene(21, 60, 1, 0);
    let cam = raster_common::camera(48, 40);
    let n = scene.len();
    let mut r = Noise::new(22);
    // Every third Gaussian culled by its factor, the rest in (0.05, 1].
    let w: Vec<f32> = (0..n)
        .map(|i| {
            if i % 3 == 0 {
                0.0
            } else {
                r.uniform(0.05, 1.0) as f32
            }
        })
        .collect();
    let up = raster_common::Uploaded::new(&gpu, &scene);
    let wb = gpu.buffer_from("w", &w).unwrap();
    let opts = RenderOpts::default();
    let size = RasterSize {
        max_gaussians: n as u32,
        width: cam.width,
        height: cam.height,
        sh_coeffs: up.sh_coeffs,
        feature_dims: 0,
        isect_capacity: 64,
    };
    let mut b = rast.buffers(&gpu, &size).unwrap();
    let g = SplatInputs {
        opacity_scale: Some(wb.all()),
        ..up.inputs()
    };
    rast.render_checked(&gpu, &mut b, &cam, &g, &opts).unwrap();
    let splats: Vec<[f32; 4]> = gpu
        .read(b.splats.elems::<[f32; 4]>(0, 3 * n as u64))
        .unwrap();
    let g64 = rtwin::Gaussians64::from_f32(&scene.twin());
    let w64: Vec<f64> = w.iter().map(|&v| v as f64).collect();
    let proj = rtwin::project_scaled_f64(&cam, &g64, &w64);
    let mut visible = 0;
    for i in 0..n {
        let (a, c) = (splats[3 * i], splats[3 * i + 1]);
        assert_eq!(c[3] > 0.0, proj.radius[i] > 0, "Gaussian {i} visibility");
        if w[i] == 0.0 {
            assert_eq!(c[3], 0.0, "Gaussian {i}: a zero factor culls");
            continue;
        }
        if proj.radius[i] > 0 {
            visible += 1;
            assert_close(
                &format!("opacity {i}"),
                &[a[3]],
                &[proj.opacity[i]],
                TOL_1E5,
            );
        }
    }
    assert!(visible > 10, "{visible} visible");
    let px = (cam.width * cam.height) as usize;
    let u = raster_common::upstream(23, px, 0);
    let (dr, dd) = (
        gpu.buffer_from("d rgba", &u.rgba).unwrap(),
        gpu.buffer_from("d depth", &u.depth).unwrap(),
    );
    let mut rec = Recorder::new(&gpu).unwrap();
    let og = OutputGrads {
        rgba: dr.all(),
        depth: Some(dd.all()),
        features: None,
    };
    rast.backward(&mut rec, &b, &cam, &g, &opts, &og);
    rec.finish().unwrap();
    let dw: Vec<f32> = gpu.read(b.d_op_scale.elems::<f32>(0, n as u64)).unwrap();
    let dl: Vec<f32> = gpu
        .read(b.d_opacity_logits.elems::<f32>(0, n as u64))
        .unwrap();
    let bp = rtwin::BlendParams {
        width: cam.width,
        height: cam.height,
        alpha_max: opts.alpha_max,
        background: opts.background,
        feature_dims: 0,
    };
    let d_rgb: Vec<[f64; 3]> = (0..px)
        .map(|p| std::array::from_fn(|c| u.rgba[4 * p + c] as f64))
        .collect();
    let d_alpha: Vec<f64> = (0..px).map(|p| u.rgba[4 * p + 3] as f64).collect();
    let d_depth: Vec<f64> = u.depth.iter().map(|&v| v as f64).collect();
    let none: &[f64] = &[];
    let bg = rtwin::blend_bwd_f64(&bp, &proj, none, &d_rgb, &d_alpha, &d_depth, none);
    let (pg, dw_twin) = rtwin::project_scaled_bwd_f64(&cam, &g64, &w64, &bg, false);
    let max = |v: &[f64]| v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    let (sw, sl) = (max(&dw_twin), max(&pg.opacity_logits));
    assert!(sw > 0.0 && sl > 0.0);
    for i in 0..n {
        assert!(
            (dw[i] as f64 - dw_twin[i]).abs() <= 2e-3 * sw + 1e-7,
            "∂L/∂w {i}: gpu {}, twin {}",
            dw[i],
            dw_twin[i]
        );
        assert!(
            (dl[i] as f64 - pg.opacity_logits[i]).abs() <= 2e-3 * sl + 1e-7,
            "∂L/∂logit {i}: gpu {}, twin {}",
            dl[i],
            pg.opacity_logits[i]
        );
    }
    let loss = |w: &[f64]| -> f64 {
        let p = rtwin::project_scaled_f64(&cam, &g64, w);
        let o = rtwin::blend_fwd_f64(&bp, &p, none);
        (0..px)
            .map(|k| {
                (0..3).map(|c| d_rgb[k][c] * o.rgb[k][c]).sum::<f64>()
                    + d_alpha[k] * o.alpha[k]
                    + d_depth[k] * o.depth[k]
            })
            .sum()
    };
    let h = 1e-6;
    let mut checked = 0;
    for i in (0..n)
        .filter(|&i| w[i] > 0.1 && proj.radius[i] > 0)
        .take(12)
    {
        let (mut a, mut b2) = (w64.clone(), w64.clone());
        a[i] += h;
        b2[i] -= h;
        let fd = (loss(&a) - loss(&b2)) / (2.0 * h);
        assert!(
            (fd - dw_twin[i]).abs() <= 1e-5 * (1.0 + fd.abs()),
            "w {i}: fd {fd}, twin {}",
            dw_twin[i]
        );
        checked += 1;
    }
    assert!(checked > 5);
}

#[test]
fn extremes_stay_finite_or_culled() {
    let n = 8;
    let mut p = params(n, 0, 0.5);
    let mut x = inputs(30, n, &p);
    x.log_width[0] = -200.0; // far below the floor: σ is the floor, τ gets no gradient
    x.centre[0] = 0.5;
    x.log_width[1] = f64::NAN; // a NaN width is the floor
    x.centre[1] = 0.5;
    x.velocity[2] = [1e20, -1e20, 1e20]; // an enormous velocity
    x.centre[2] = 0.49;
    x.log_width[3] = 80.0; // a width that never fades: w = 1
    x.centre[4] = 1e6; // a centre far outside the sequence: culled
    x.centre[5] = f64::INFINITY; // culled, not NaN
    let u = upstream(31, n);
    let got = run(&p, &x, &u);
    let all = |v: &[f32]| v.iter().all(|x| x.is_finite());
    assert!(
        got.op_scale.iter().all(|w| (0.0..=1.0).contains(w)),
        "{:?}",
        got.op_scale
    );
    assert!(got.op_scale[0] == 1.0 && got.op_scale[1] == 1.0 && got.op_scale[3] == 1.0);
    assert_eq!(got.g[4][0], 0.0, "τ below the floor: no gradient");
    assert_eq!(got.g[4][1], 0.0, "a NaN τ: no gradient");
    assert_eq!((got.op_scale[4], got.op_scale[5]), (0.0, 0.0));
    for (k, g) in got.g.iter().enumerate() {
        let skip_v = k == 5; // row 2's velocity gradient is the drawn-mean gradient times d: finite
        assert!(skip_v || all(g), "gradient section {k}: {g:?}");
    }
    assert!(all(&got.scales) && all(&got.quats));
    // Row 2's drawn mean is huge but finite: the projection culls it (tests/raster_extremes).
    assert!(got.means[6].abs() > 1e17 && got.means[6].is_finite());
    // A time far outside every centre: everything culled, all gradients 0.
    p.t = -50.0;
    x.log_width.iter_mut().for_each(|t| *t = p.log_floor as f64);
    let got = run(&p, &x, &u);
    assert!(got.op_scale.iter().all(|&w| w == 0.0), "{:?}", got.op_scale);
    for g in &got.g[..5] {
        assert!(g.iter().all(|&v| v == 0.0), "{g:?}");
    }
}
