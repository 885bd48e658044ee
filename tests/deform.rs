//! Deformation composition: GPU vs twin (forward and backward, with and without D), twin vs
//! central finite differences, degenerate quaternions.

use dispflow_vk::kernels::deform::{Canonical, DeformApply, Drawn, LOG_SCALE_MAX};
use dispflow_vk::reference::deform::{deform_apply, deform_apply_bwd};
use dispflow_vk::testing::{self, Noise};
use dispflow_vk::vk::Recorder;

fn rand(r: &mut Noise, n: usize, scale: f32) -> Vec<f32> {
    (0..n)
        .map(|_| ((r.next_u32() as f32 / 4_294_967_296.0) - 0.5) * 2.0 * scale)
        .collect()
}

#[test]
fn twin_backward_matches_finite_differences() {
    let mut r = Noise::new(3);
    let v: Vec<f64> = rand(&mut r, 40, 1.0).into_iter().map(f64::from).collect();
    let (x, s, q) = (
        [v[0], v[1], v[2]],
        [v[3], v[4], v[5]],
        [v[6], v[7], v[8], v[9]],
    );
    let d: [f64; 10] = std::array::from_fn(|i| v[10 + i]);
    let (um, us, uq) = (
        [v[20], v[21], v[22]],
        [v[23], v[24], v[25]],
        [v[26], v[27], v[28], v[29]],
    );
    let loss = |x: [f64; 3], s: [f64; 3], q: [f64; 4], d: [f64; 10]| {
        let (m, sc, rt) = deform_apply(x, s, q, Some(&d));
        (0..3).map(|a| um[a] * m[a] + us[a] * sc[a]).sum::<f64>()
            + (0..4).map(|a| uq[a] * rt[a]).sum::<f64>()
    };
    let (gx, gs, gq, gd) = deform_apply_bwd(s, q, um, us, uq);
    let h = 1e-6;
    let fd = |f: &dyn Fn(f64) -> f64| (f(h) - f(-h)) / (2.0 * h);
    for a in 0..3 {
        let e = |k: usize, t: f64| {
            let mut y = [x, s];
            y[k][a] += t;
            loss(y[0], y[1], q, d)
        };
        assert!((fd(&|t| e(0, t)) - gx[a]).abs() < 1e-7);
        assert!((fd(&|t| e(1, t)) - gs[a]).abs() < 1e-7);
    }
    for a in 0..4 {
        let f = |t: f64| {
            let mut qq = q;
            qq[a] += t;
            loss(x, s, qq, d)
        };
        assert!((fd(&f) - gq[a]).abs() < 1e-7, "quat {a}");
    }
    for a in 0..10 {
        let f = |t: f64| {
            let mut dd = d;
            dd[a] += t;
            loss(x, s, q, dd)
        };
        assert!((fd(&f) - gd[a]).abs() < 1e-7, "d {a}");
    }
}

/// Runs forward and backward (with and without D) on the GPU for the given canonical
/// parameters, MLP output and upstream gradients (`up`: drawn means [N,3], scales [N,3], rots
/// [N,4]) and compares every output with the twin: `|gpu − twin| ≤ rel · (1 + |twin|)`, all
/// finite. Returns the largest `|gpu − twin| / (1 + |twin|)`.
fn compare(x: &[f32], s: &[f32], q: &[f32], d: &[f32], up: &[f32], rel: f64) -> f64 {
    let gpu = testing::gpu();
    let k = DeformApply::new(&gpu).unwrap();
    let n = x.len() / 3;
    let b = |name: &str, v: &[f32]| gpu.buffer_from(name, v).unwrap();
    let (xb, sb, qb, db) = (b("x", x), b("s", s), b("q", q), b("d", d));
    let (um, us, uq) = (
        b("um", &up[..3 * n]),
        b("us", &up[3 * n..6 * n]),
        b("uq", &up[6 * n..]),
    );
    let out: Vec<_> = [3, 3, 4, 3, 3, 4, 10]
        .iter()
        .map(|&w| gpu.buffer("out", (w * n * 4) as u64).unwrap())
        .collect();
    for o in &out {
        testing::fill_noise(&gpu, o, 1);
    }
    let mut worst = 0.0f64;
    for use_d in [false, true] {
        let c = Canonical {
            means: xb.all(),
            log_scales: sb.all(),
            quats: qb.all(),
        };
        let drawn = Drawn {
            means: out[0].all(),
            scales: out[1].all(),
            quats: out[2].all(),
        };
        let grads = Canonical {
            means: out[3].all(),
            log_scales: out[4].all(),
            quats: out[5].all(),
        };
        let mut rec = Recorder::new(&gpu).unwrap();
        k.forward(&mut rec, n as u32, &c, use_d.then(|| db.all()), &drawn);
        let d_drawn = Drawn {
            means: um.all(),
            scales: us.all(),
            quats: uq.all(),
        };
        k.backward(
            &mut rec,
            n as u32,
            &c,
            &d_drawn,
            &grads,
            use_d.then(|| out[6].all()),
        );
        rec.finish().unwrap();
        let got: Vec<Vec<f32>> = out.iter().map(|o| gpu.read(o.all()).unwrap()).collect();
        for i in 0..n {
            let f = |v: &[f32], w: usize| -> Vec<f64> {
                v[w * i..w * i + w].iter().map(|&a| a as f64).collect()
            };
            let dd: [f64; 10] = f(d, 10).try_into().unwrap();
            let (m, sc, rt) = deform_apply(
                f(x, 3).try_into().unwrap(),
                f(s, 3).try_into().unwrap(),
                f(q, 4).try_into().unwrap(),
                use_d.then_some(&dd),
            );
            let (gx, gs, gq, gd) = deform_apply_bwd(
                f(s, 3).try_into().unwrap(),
                f(q, 4).try_into().unwrap(),
                f(&up[..3 * n], 3).try_into().unwrap(),
                f(&up[3 * n..6 * n], 3).try_into().unwrap(),
                f(&up[6 * n..], 4).try_into().unwrap(),
            );
            let mut check = |what: &str, g: &[f32], w: &[f64]| {
                for (a, (gv, wv)) in g.iter().zip(w).enumerate() {
                    let e = (*gv as f64 - wv).abs() / (1.0 + wv.abs());
                    worst = worst.max(e);
                    assert!(
                        gv.is_finite() && e <= rel,
                        "{what}[{i}][{a}] gpu {gv} twin {wv} (log-scales {:?}, deform {use_d})",
                        &s[3 * i..3 * i + 3]
                    );
                }
            };
            check("mean", &got[0][3 * i..3 * i + 3], &m);
            check("scale", &got[1][3 * i..3 * i + 3], &sc);
            check("rot", &got[2][4 * i..4 * i + 4], &rt);
            check("d x", &got[3][3 * i..3 * i + 3], &gx);
            check("d log scale", &got[4][3 * i..3 * i + 3], &gs);
            check("d quat", &got[5][4 * i..4 * i + 4], &gq);
            if use_d {
                check("d deform", &got[6][10 * i..10 * i + 10], &gd);
            }
        }
        if q[..4] == [0.0; 4] {
            assert_eq!(
                &got[5][..4],
                &[0.0; 4],
                "degenerate quaternion gets no gradient"
            );
        }
    }
    worst
}

#[test]
fn gpu_matches_twin() {
    let n = 1000usize;
    let mut r = Noise::new(9);
    let x = rand(&mut r, 3 * n, 2.0);
    let s = rand(&mut r, 3 * n, 3.0);
    let mut q = rand(&mut r, 4 * n, 1.0);
    q[..4].copy_from_slice(&[0.0; 4]); // degenerate quaternion: identity, no gradient
    let d = rand(&mut r, 10 * n, 0.1);
    let up = rand(&mut r, 10 * n, 1.0);
    let e = compare(&x, &s, &q, &d, &up, 1e-5);
    eprintln!("random: max |gpu − twin| / (1 + |twin|) = {e:.1e}");
}

#[test]
fn log_scale_overflow_is_clamped_on_gpu_and_twin() {
    // exp(log_scale) overflows f32 from 88.72 on; the composition clamps the log-scale at
    // LOG_SCALE_MAX = 44 (a drawn scale of 1.3e19) and gives it no gradient above. Values on
    // both sides of the clamp, at f32's exp overflow, up to f32::MAX and ±∞, with ds of either
    // sign and random upstream gradients up to ±1e3 (g = ds·e^44 ≈ 1e22 stays finite).
    assert_eq!(LOG_SCALE_MAX, 44.0);
    let ls = [
        -f32::INFINITY,
        -1e30,
        -104.0,
        -88.0,
        9.2,
        43.9,
        44.0,
        44.1,
        50.0,
        88.0,
        88.73,
        89.0,
        100.0,
        1e30,
        f32::MAX,
        f32::INFINITY,
    ];
    let n = 64;
    let mut r = Noise::new(10);
    let x = rand(&mut r, 3 * n, 2.0);
    let s: Vec<f32> = (0..3 * n).map(|i| ls[(i * 7) % ls.len()]).collect();
    let q = rand(&mut r, 4 * n, 1.0);
    let d = rand(&mut r, 10 * n, 1e3);
    let up = rand(&mut r, 10 * n, 1e3);
    // f32 exp's relative error grows with its argument (x·log2 e is rounded to an f32 near 63
    // at x = 44: ≈ 1.3e-6 of the result, plus the device's exp2): measured 6.2e-6 (3.4e-7 for
    // |x| ≤ 3 above); 5e-5 allowed.
    let e = compare(&x, &s, &q, &d, &up, 5e-5);
    eprintln!("log-scale extremes: max |gpu − twin| / (1 + |twin|) = {e:.1e}");
    // Above the clamp: the drawn scale is e^44 + ds, the log-scale gradient exactly 0.
    let (_, sc, _) = deform_apply(
        [0.0; 3],
        [89.0, f64::INFINITY, 44.0],
        [1.0, 0.0, 0.0, 0.0],
        None,
    );
    assert_eq!(sc[0], 44f64.exp());
    assert_eq!(sc[1], 44f64.exp());
    let (_, gs, _, _) = deform_apply_bwd(
        [89.0, 44.0, -f64::INFINITY],
        [1.0, 0.0, 0.0, 0.0],
        [0.0; 3],
        [1.0; 3],
        [0.0; 4],
    );
    assert_eq!(gs, [0.0, 44f64.exp(), 0.0]);
}

dispflow_vk::subgroup_reruns!();

#[test]
fn backward_add_adds_a_second_renders_gradients() {
    // backward (render 1) then backward_add (render 2) = the twin's backward of each, summed.
    let gpu = testing::gpu();
    let k = DeformApply::new(&gpu).unwrap();
    let n = 500usize;
    let mut r = Noise::new(21);
    let (x, s, q) = (
        rand(&mut r, 3 * n, 2.0),
        rand(&mut r, 3 * n, 3.0),
        rand(&mut r, 4 * n, 1.0),
    );
    let (up1, up2) = (rand(&mut r, 10 * n, 1.0), rand(&mut r, 10 * n, 1.0));
    let b = |name: &str, v: &[f32]| gpu.buffer_from(name, v).unwrap();
    let (xb, sb, qb) = (b("x", &x), b("s", &s), b("q", &q));
    let drawn = |up: &[f32]| {
        [
            b("m", &up[..3 * n]),
            b("s", &up[3 * n..6 * n]),
            b("q", &up[6 * n..]),
        ]
    };
    let (d1, d2) = (drawn(&up1), drawn(&up2));
    let out: Vec<_> = [3, 3, 4, 10]
        .iter()
        .map(|&w| gpu.buffer("out", (w * n * 4) as u64).unwrap())
        .collect();
    for o in &out {
        testing::fill_noise(&gpu, o, 2);
    }
    let c = Canonical {
        means: xb.all(),
        log_scales: sb.all(),
        quats: qb.all(),
    };
    let grads = Canonical {
        means: out[0].all(),
        log_scales: out[1].all(),
        quats: out[2].all(),
    };
    fn as_drawn(d: &[dispflow_vk::vk::Buffer; 3]) -> Drawn<'_> {
        Drawn {
            means: d[0].all(),
            scales: d[1].all(),
            quats: d[2].all(),
        }
    }
    let mut rec = Recorder::new(&gpu).unwrap();
    k.backward(
        &mut rec,
        n as u32,
        &c,
        &as_drawn(&d1),
        &grads,
        Some(out[3].all()),
    );
    k.backward_add(&mut rec, n as u32, &c, &as_drawn(&d2), &grads, out[3].all());
    rec.finish().unwrap();
    let got: Vec<Vec<f32>> = out.iter().map(|o| gpu.read(o.all()).unwrap()).collect();
    for i in 0..n {
        let f = |v: &[f32], w: usize| -> Vec<f64> {
            v[w * i..w * i + w].iter().map(|&a| a as f64).collect()
        };
        let bwd = |up: &[f32]| {
            deform_apply_bwd(
                f(&s, 3).try_into().unwrap(),
                f(&q, 4).try_into().unwrap(),
                f(&up[..3 * n], 3).try_into().unwrap(),
                f(&up[3 * n..6 * n], 3).try_into().unwrap(),
                f(&up[6 * n..], 4).try_into().unwrap(),
            )
        };
        let (a, bb) = (bwd(&up1), bwd(&up2));
        let sum =
            |u: &[f64], v: &[f64]| -> Vec<f64> { u.iter().zip(v).map(|(p, q)| p + q).collect() };
        let want = [
            sum(&a.0, &bb.0),
            sum(&a.1, &bb.1),
            sum(&a.2, &bb.2),
            sum(&a.3, &bb.3),
        ];
        for (o, (w, width)) in want.iter().zip([3, 3, 4, 10]).enumerate() {
            for c in 0..width {
                let g = got[o][width * i + c] as f64;
                assert!(
                    (g - w[c]).abs() <= 1e-5 * (1.0 + w[c].abs()),
                    "output {o} Gaussian {i} component {c}: gpu {g} twin sum {}",
                    w[c]
                );
            }
        }
    }
}
