//! Trainer-side motion-term stages vs their twin: displacement δ and its backward into both
//! MLP passes, the L1 motion loss (confidence-weighted or not, including the degenerate-map
//! skip), and the scene signal: its residual correction and confidence against the twin, and
//! on image pairs with a known answer through the real TV-L1 estimator.

use dispflow_vk::kernels::dispflow::{DispFlow, SignalIo};
use dispflow_vk::kernels::flow::{FlowConfig, FlowEstimator, TvL1Flow};
use dispflow_vk::reference::dispflow as twin;
use dispflow_vk::testing::{self, Noise};
use dispflow_vk::vk::Recorder;

fn rand(r: &mut Noise, n: usize) -> Vec<f32> {
    (0..n)
        .map(|_| r.next_u32() as f32 / 4_294_967_296.0 - 0.5)
        .collect()
}

#[test]
fn displacement_forward_and_backward_match_twin() {
    let gpu = testing::gpu();
    let k = DispFlow::new(&gpu).unwrap();
    let n = 777usize;
    let mut r = Noise::new(1);
    let (o1, o2, dd, d1) = (
        rand(&mut r, 10 * n),
        rand(&mut r, 10 * n),
        rand(&mut r, 3 * n),
        rand(&mut r, 10 * n),
    );
    let b = |v: &[f32]| gpu.buffer_from("in", v).unwrap();
    let (o1b, o2b, ddb, d1b) = (b(&o1), b(&o2), b(&dd), b(&d1));
    let delta = gpu.buffer("delta", 12 * n as u64).unwrap();
    let d2b = gpu.buffer("d out t2", 40 * n as u64).unwrap();
    testing::fill_noise(&gpu, &delta, 1);
    testing::fill_noise(&gpu, &d2b, 2);
    let mut rec = Recorder::new(&gpu).unwrap();
    k.displacement(&mut rec, n as u32, o1b.all(), o2b.all(), delta.all());
    k.displacement_bwd(&mut rec, n as u32, ddb.all(), d1b.all(), d2b.all());
    rec.finish().unwrap();
    assert_eq!(
        gpu.read::<f32>(delta.all()).unwrap(),
        twin::displacement(&o1, &o2)
    );
    let (w1, w2) = twin::displacement_bwd(&dd, &d1);
    assert_eq!(gpu.read::<f32>(d1b.all()).unwrap(), w1);
    assert_eq!(gpu.read::<f32>(d2b.all()).unwrap(), w2);
}

#[test]
fn motion_l1_matches_twin_and_skips_degenerate_maps() {
    let gpu = testing::gpu();
    let k = DispFlow::new(&gpu).unwrap();
    for (px, flags, with_conf) in [
        (1usize, [0u32, 0], false),
        (1000, [0, 0], false),
        (70_001, [0, 0], false),
        (500, [1, 0], false),
        (500, [0, 1], false),
        (1, [0, 0], true),
        (70_001, [0, 0], true),
        (500, [0, 1], true),
    ] {
        let mut r = Noise::new(px as u64 + with_conf as u64);
        let a: Vec<f32> = rand(&mut r, px).iter().map(|v| v + 0.5).collect();
        let s: Vec<f32> = rand(&mut r, px).iter().map(|v| v + 0.5).collect();
        // Confidences in [0, 1], some exactly 0 (a pixel that must not count).
        let c: Vec<f32> = rand(&mut r, px)
            .iter()
            .map(|v| (v * 1.6 + 0.5).clamp(0.0, 1.0))
            .collect();
        let (ab, sb, fb, cb) = (
            gpu.buffer_from("disp", &a).unwrap(),
            gpu.buffer_from("scene", &s).unwrap(),
            gpu.buffer_from("flags", &flags).unwrap(),
            gpu.buffer_from("conf", &c).unwrap(),
        );
        let d = gpu.buffer("d disp", 4 * px as u64).unwrap();
        let groups = px.div_ceil(256);
        let sums = gpu.buffer("sums", 4 * groups as u64).unwrap();
        testing::fill_noise(&gpu, &d, 3);
        let mut rec = Recorder::new(&gpu).unwrap();
        k.motion_l1(
            &mut rec,
            px as u32,
            0.1,
            ab.all(),
            sb.all(),
            fb.all(),
            d.all(),
            sums.all(),
            with_conf.then(|| cb.all()),
        );
        rec.finish().unwrap();
        let skip = flags != [0, 0];
        let conf = with_conf.then_some(&c[..]);
        let (want_v, want_g) = twin::motion_l1(&a, &s, conf, 0.1, skip);
        if with_conf && !skip && px > 1 {
            // The weighting changes the value: a twin that ignored it would not match.
            let (plain, _) = twin::motion_l1(&a, &s, None, 0.1, skip);
            assert!((plain - want_v).abs() > 1e-3 * plain, "{plain} vs {want_v}");
        }
        let got_v: f64 = gpu
            .read::<f32>(sums.elems::<f32>(0, groups as u64))
            .unwrap()
            .iter()
            .map(|&x| x as f64)
            .sum::<f64>()
            / px as f64;
        assert!(
            (got_v - want_v).abs() <= 1e-6 * (1.0 + want_v),
            "{px} px (conf {with_conf}): loss gpu {got_v} twin {want_v}"
        );
        let got_g: Vec<f32> = gpu.read(d.elems::<f32>(0, px as u64)).unwrap();
        for (i, (g, w)) in got_g.iter().zip(&want_g).enumerate() {
            assert!(
                (*g as f64 - w).abs() <= 1e-6 * w.abs() + 1e-12,
                "{px} px: grad[{i}] gpu {g} twin {w}"
            );
        }
        if skip {
            assert!(
                got_v == 0.0 && got_g.iter().all(|&g| g == 0.0),
                "a degenerate map skips the term"
            );
        }
    }
}

/// The GPU's scene signal of the given inputs: (scene motion, confidence).
fn gpu_signal(
    flows: (&[[f32; 2]], &[[f32; 2]]),
    photo: &[[f32; 4]],
    render_t1: &[[f32; 4]],
    residual: bool,
    sigma: f32,
    mask_px: f32,
) -> (Vec<[f32; 2]>, Vec<f32>) {
    let gpu = testing::gpu();
    let k = DispFlow::new(&gpu).unwrap();
    let px = photo.len();
    let b = |n, v: &[[f32; 2]]| gpu.buffer_from(n, v).unwrap();
    let (f2, f1) = (b("flow t2", flows.0), b("flow t1", flows.1));
    let ph = gpu.buffer_from("photo", photo).unwrap();
    let r1 = gpu.buffer_from("render t1", render_t1).unwrap();
    let scene = gpu.buffer("scene", 8 * px as u64).unwrap();
    let conf = gpu.buffer("conf", 4 * px as u64).unwrap();
    testing::fill_noise(&gpu, &scene, 5);
    testing::fill_noise(&gpu, &conf, 6);
    let mut rec = Recorder::new(&gpu).unwrap();
    let io = SignalIo {
        flow_t2: f2.all(),
        flow_t1: f1.all(),
        photo: ph.all(),
        render_t1: r1.all(),
        scene: scene.all(),
        conf: conf.all(),
    };
    k.scene_signal(&mut rec, px as u32, residual, sigma, mask_px, &io);
    rec.finish().unwrap();
    (
        gpu.read(scene.all()).unwrap(),
        gpu.read(conf.all()).unwrap(),
    )
}

#[test]
fn scene_signal_matches_twin_with_extremes() {
    let px = 70_001;
    let mut r = Noise::new(9);
    let v2 = |r: &mut Noise| -> Vec<[f32; 2]> {
        rand(r, 2 * px)
            .chunks(2)
            .map(|c| [c[0] * 40.0, c[1] * 40.0])
            .collect()
    };
    let img = |r: &mut Noise| -> Vec<[f32; 4]> {
        rand(r, 4 * px)
            .chunks(4)
            .map(|c| [c[0] + 0.5, c[1] + 0.5, c[2] + 0.5, 1.0])
            .collect()
    };
    let (mut f2, f1, photo, mut r1) = (v2(&mut r), v2(&mut r), img(&mut r), img(&mut r));
    // Extremes: a NaN and an infinite flow, an infinite render, a render equal to the photo.
    f2[3] = [f32::NAN, 0.0];
    f2[4] = [0.0, f32::INFINITY];
    r1[5] = [f32::INFINITY, 0.0, 0.0, 1.0];
    r1[6] = photo[6];
    // The last case filters with a motion mask (|s| < 10 px → 0; the flows reach 20 px).
    let cases = [
        (false, 0.0, 0.0),
        (true, 0.0, 0.0),
        (true, 0.1, 0.0),
        (false, 1e-3, 0.0),
        (true, 0.0, 10.0),
    ];
    for (residual, sigma, mask) in cases {
        let (s, c) = gpu_signal((&f2, &f1), &photo, &r1, residual, sigma, mask);
        let (ws, wc) =
            twin::scene_signal(&f2, &f1, &photo, &r1, residual, sigma as f64, mask as f64);
        if mask > 0.0 {
            let zeroed = ws.iter().filter(|v| v[0] == 0.0 && v[1] == 0.0).count();
            assert!(
                zeroed > px / 10 && zeroed < px * 9 / 10,
                "the mask case must zero some vectors and keep others: {zeroed} of {px}"
            );
        }
        for p in 0..px {
            for k in 0..2 {
                let (g, w) = (s[p][k] as f64, ws[p][k]);
                assert!(
                    (g - w).abs() <= 1e-6 * (1.0 + w.abs()),
                    "residual {residual} σ {sigma}: scene[{p}][{k}] gpu {g} twin {w}"
                );
            }
            assert!(
                (c[p] as f64 - wc[p]).abs() <= 1e-5,
                "residual {residual} σ {sigma}: conf[{p}] gpu {} twin {}",
                c[p],
                wc[p]
            );
        }
        assert!(s.iter().flatten().all(|v| v.is_finite()) && c.iter().all(|v| v.is_finite()));
        assert_eq!((s[3], s[4], c[3], c[4]), ([0.0; 2], [0.0; 2], 0.0, 0.0));
        if sigma > 0.0 {
            assert_eq!(c[5], 0.0, "an infinite render gives no confidence");
            assert_eq!(c[6], 1.0, "a render equal to the photo is fully trusted");
        } else {
            assert!(c
                .iter()
                .enumerate()
                .all(|(p, &v)| v == 1.0 || p == 3 || p == 4));
        }
        if residual {
            let d = f2[7][0] - f1[7][0];
            assert_eq!(s[7][0], d);
        }
    }
}

/// A sharp, textured photo: smooth waves plus a bright square with hard edges.
fn photo_image(w: usize, h: usize, shift: f64) -> Vec<[f32; 4]> {
    let mut v = Vec::with_capacity(w * h);
    for y in 0..h {
        for x in 0..w {
            let xs = x as f64 - shift;
            let (xf, yf) = (xs, y as f64);
            let mut c = 0.35
                + 0.12 * (xf * 0.41 + yf * 0.23).sin()
                + 0.1 * (xf * 0.17 - yf * 0.37 + 1.0).sin()
                + 0.08 * (xf * 0.07 + yf * 0.11 + 2.0).cos();
            if (20.0..36.0).contains(&xf) && (18.0..34.0).contains(&yf) {
                c += 0.35;
            }
            v.push([c as f32, (0.8 * c) as f32, (0.6 * c + 0.1) as f32, 1.0]);
        }
    }
    v
}

/// `passes` 5×5 binomial blurs (clamped border): what a half-trained render looks like.
fn blur(img: &[[f32; 4]], w: usize, h: usize, passes: usize) -> Vec<[f32; 4]> {
    const K: [f32; 5] = [1.0, 4.0, 6.0, 4.0, 1.0];
    let mut cur = img.to_vec();
    for _ in 0..passes {
        for horizontal in [true, false] {
            let src = cur.clone();
            for y in 0..h {
                for x in 0..w {
                    let mut acc = [0f32; 4];
                    for (i, k) in K.iter().enumerate() {
                        let o = i as i64 - 2;
                        let (sx, sy) = if horizontal {
                            ((x as i64 + o).clamp(0, w as i64 - 1), y as i64)
                        } else {
                            (x as i64, (y as i64 + o).clamp(0, h as i64 - 1))
                        };
                        let s = src[sy as usize * w + sx as usize];
                        for c in 0..4 {
                            acc[c] += k / 16.0 * s[c];
                        }
                    }
                    cur[y * w + x] = acc;
                }
            }
        }
    }
    cur
}

/// TV-L1 flow a → b on the GPU (default settings).
fn tvl1(a: &[[f32; 4]], b: &[[f32; 4]], w: u32, h: u32) -> Vec<[f32; 2]> {
    let gpu = testing::gpu();
    let est = TvL1Flow::new(&gpu, FlowConfig::default()).unwrap();
    let s = est.scratch(&gpu, w, h).unwrap();
    let (ab, bb) = (
        gpu.buffer_from("a", a).unwrap(),
        gpu.buffer_from("b", b).unwrap(),
    );
    let out = gpu.buffer("flow", 8 * a.len() as u64).unwrap();
    let mut rec = Recorder::new(&gpu).unwrap();
    est.record(&mut rec, &s, ab.all(), bb.all(), out.all());
    rec.finish().unwrap();
    gpu.read(out.all()).unwrap()
}

/// Mean of a vector field over the pixels at least 6 px inside the border.
fn interior_mean(f: &[[f32; 2]], w: usize, h: usize, g: impl Fn([f32; 2]) -> f64) -> f64 {
    let (mut s, mut n) = (0.0, 0.0);
    for y in 6..h - 6 {
        for x in 6..w - 6 {
            s += g(f[y * w + x]);
            n += 1.0;
        }
    }
    s / n
}

#[test]
fn residual_correction_removes_blur_motion_and_keeps_real_motion() {
    let (w, h) = (64usize, 56usize);
    let photo = photo_image(w, h, 0.0);
    // A static scene: the renders at t1 and t2 are both blurry (slightly differently so), and
    // the photo is sharp. All apparent motion photo → render is reconstruction error.
    let r1 = blur(&photo, w, h, 3);
    let r2 = blur(&photo, w, h, 4);
    let raw = tvl1(&photo, &r2, w as u32, h as u32);
    let res = tvl1(&photo, &r1, w as u32, h as u32);
    let (s, _) = gpu_signal((&raw, &res), &photo, &r1, true, 0.0, 0.0);
    let mag = |v: [f32; 2]| ((v[0] as f64).powi(2) + (v[1] as f64).powi(2)).sqrt();
    let (m_raw, m_res) = (interior_mean(&raw, w, h, mag), interior_mean(&s, w, h, mag));
    eprintln!("static blurred scene: mean |raw| {m_raw:.4} px, |corrected| {m_res:.4} px");
    assert!(
        m_raw > 0.05,
        "the blur must read as motion for this test to mean anything"
    );
    assert!(m_res < 0.5 * m_raw, "correction {m_res} vs raw {m_raw}");
    // A moving scene: the render at t2 shows the content 2 px to the right.
    let r2m = blur(&photo_image(w, h, 2.0), w, h, 4);
    let raw_m = tvl1(&photo, &r2m, w as u32, h as u32);
    let (sm, _) = gpu_signal((&raw_m, &res), &photo, &r1, true, 0.0, 0.0);
    let mean_x = interior_mean(&sm, w, h, |v| v[0] as f64);
    let mean_y = interior_mean(&sm, w, h, |v| v[1] as f64);
    eprintln!("moving scene: corrected mean flow ({mean_x:.3}, {mean_y:.3}) px, truth (2, 0)");
    assert!((mean_x - 2.0).abs() < 0.3 && mean_y.abs() < 0.3);
}

#[test]
fn confidence_is_low_where_the_render_misses_an_occluder() {
    let (w, h) = (64usize, 56usize);
    let photo = photo_image(w, h, 0.0);
    // The render lacks the square (an occluder the model has not learnt) and is blurry.
    let mut bare = photo.clone();
    for y in 18..34 {
        for x in 20..36 {
            for c in 0..3 {
                bare[y * w + x][c] -= [0.35, 0.28, 0.21][c];
            }
        }
    }
    let r1 = blur(&bare, w, h, 2);
    let zero = vec![[0f32; 2]; w * h];
    let (_, c) = gpu_signal((&zero, &zero), &photo, &r1, false, 0.05, 0.0);
    let (mut inside, mut outside) = ((0.0, 0), (0.0, 0));
    for y in 0..h {
        for x in 0..w {
            let v = c[y * w + x] as f64;
            let core = (23..33).contains(&x) && (21..31).contains(&y);
            let far = !(14..42).contains(&x) || !(12..40).contains(&y);
            if core {
                inside = (inside.0 + v, inside.1 + 1);
            } else if far {
                outside = (outside.0 + v, outside.1 + 1);
            }
        }
    }
    let (ci, co) = (inside.0 / inside.1 as f64, outside.0 / outside.1 as f64);
    eprintln!("confidence inside the missed occluder {ci:.4}, away from it {co:.4}");
    assert!(ci < 0.05 && co > 0.7, "inside {ci}, outside {co}");
}

dispflow_vk::subgroup_reruns!();

#[test]
fn grad_add_adds_elementwise() {
    let gpu = testing::gpu();
    let k = DispFlow::new(&gpu).unwrap();
    let n = 70_001usize;
    let mut r = Noise::new(31);
    let (a, b) = (rand(&mut r, n), rand(&mut r, n));
    let (ab, bb) = (
        gpu.buffer_from("src", &a).unwrap(),
        gpu.buffer_from("dst", &b).unwrap(),
    );
    let mut rec = Recorder::new(&gpu).unwrap();
    k.grad_add(&mut rec, n as u32, ab.all(), bb.all());
    rec.finish().unwrap();
    let got: Vec<f32> = gpu.read(bb.all()).unwrap();
    for i in 0..n {
        assert_eq!(got[i], a[i] + b[i], "element {i}");
    }
}
