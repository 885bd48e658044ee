//! The dynamic/static split: the probe, the compaction and the row gather/expand against their
//! CPU twins (extremes included), and the split MLP against the dense one over the same rows
//! (static rows get their constant deformation, the MLP gradient only the dynamic rows').

use dispflow_vk::kernels::raster::Camera;
use dispflow_vk::kernels::scan::{Count, PrefixSum};
use dispflow_vk::kernels::sparse::{ProbeInputs, ProbeSample, SparseKernels, NO_ROW, RANGE_ROW};
use dispflow_vk::model::deform::{MlpConfig, MlpLayout, TimeEncoding, OUT_DIMS};
use dispflow_vk::model::dynamic::{DynamicSet, SplitSnapshot};
use dispflow_vk::model::gaussians::HostGaussians;
use dispflow_vk::model::state::{mlp_config_for, DeformState, GaussianState, Model};
use dispflow_vk::reference::sparse::{
    dyn_compact, dyn_flag, motion_probe, rows_expand, rows_gather,
};
use dispflow_vk::testing::{self, Noise};
use dispflow_vk::train::passes::sparsity::{Classifier, ProbeConfig};
use dispflow_vk::train::passes::{DeformPass, Slot, StepSizes};
use dispflow_vk::vk::Recorder;

/// Three probe samples on the GPU and the twin: pixels within 1e-5 relative, midranges
/// within 1 ulp-ish, flags equal wherever the pixels are not within that of the threshold;
/// returns the GPU flags.
fn probe_case(seed: u64, n: usize, extremes: bool) -> Vec<u32> {
    let gpu = testing::gpu();
    let k = SparseKernels::new(&gpu).unwrap();
    let mut r = Noise::new(seed);
    // A constant offset per Gaussian (not motion) plus a small variation; every third
    // Gaussian varies ~100× more.
    let offset = r.uniforms(n * 10, -0.2, 0.2);
    let mut samples: Vec<Vec<f32>> = (0..3)
        .map(|_| {
            let mut d = r.uniforms(n * 10, -1e-3, 1e-3);
            for i in (0..n).step_by(3) {
                d[10 * i] *= 100.0;
            }
            d.iter().zip(&offset).map(|(a, b)| a + b).collect()
        })
        .collect();
    let mut log_scales = r.uniforms(n * 3, -5.0, -1.0);
    let mut means = r.uniforms(n * 3, -1.0, 1.0);
    let cams = [[0.0, 0.0, -4.0, 100.0], [3.0, 0.5, 0.0, 140.0f32]];
    if extremes {
        samples[1][0] = f32::NAN; // a diverged deformation
        samples[2][10] = f32::INFINITY;
        log_scales[3 * 2] = 1e30; // clamped before exp
        means[3 * 3..3 * 4].copy_from_slice(&[0.0, 0.0, -4.0]); // on a camera centre
        for s in &mut samples {
            s[40..50].copy_from_slice(&offset[40..50]); // Gaussian 4: a pure offset
        }
    }
    let b = |name: &str, v: &[f32]| gpu.buffer_from(name, v).unwrap();
    let (ls, mb) = (b("log scales", &log_scales), b("means", &means));
    let cb = gpu.buffer_from("cams", &cams).unwrap();
    let range = gpu.buffer("range", (n * RANGE_ROW) as u64 * 4).unwrap();
    let flags = gpu.buffer("flags", n as u64 * 4).unwrap();
    let thr = 0.5;
    let mid = gpu.buffer("mid", n as u64 * 40).unwrap();
    for (j, buf) in [&range, &flags, &mid].iter().enumerate() {
        testing::fill_noise(&gpu, buf, 5 + j as u64);
    }
    let sample_bufs: Vec<_> = samples.iter().map(|s| b("deform", s)).collect();
    let mut rec = Recorder::new(&gpu).unwrap();
    for (j, d) in sample_bufs.iter().enumerate() {
        let x = ProbeInputs {
            deform: d.all(),
            log_scales: ls.all(),
            means: mb.all(),
            cams: cb.all(),
            num_cams: 2,
        };
        let s = ProbeSample {
            first: j == 0,
            last: j == 2,
            near: 1e-3,
        };
        k.probe(&mut rec, n as u32, &x, &s, range.all(), mid.all());
    }
    k.flag(&mut rec, n as u32, thr, range.all(), flags.all());
    rec.finish().unwrap();
    let got_r: Vec<f32> = gpu.read(range.all()).unwrap();
    let got_f: Vec<u32> = gpu.read(flags.all()).unwrap();
    let got_m: Vec<f32> = gpu.read(mid.all()).unwrap();
    let (want_px, want_m) = motion_probe(&samples, &log_scales, &means, &cams, 1e-3);
    let want_f = dyn_flag(&want_px, thr);
    for i in 0..n {
        let px = got_r[RANGE_ROW * i + 20];
        assert!(px.is_finite(), "pixels {i} = {px}");
        let tol = 1e-5 * want_px[i].abs().max(1e-2);
        assert!(
            (px - want_px[i]).abs() <= tol,
            "pixels {i}: gpu {px} twin {}",
            want_px[i]
        );
        if (want_px[i] - thr).abs() > tol {
            assert_eq!(got_f[i], want_f[i], "flag {i} (pixels {})", want_px[i]);
        }
        for c in 0..10 {
            let (g, w) = (got_m[10 * i + c], want_m[10 * i + c]);
            assert!(
                g == w || (g - w).abs() <= 1e-7 * (1.0 + w.abs()),
                "mid {i}.{c}: {g} vs {w}"
            );
        }
    }
    got_f
}

#[test]
fn probe_matches_twin() {
    for (seed, n) in [(1, 1), (2, 257), (3, 3000)] {
        let f = probe_case(seed, n, false);
        if n > 100 {
            let dynamic = f.iter().filter(|&&v| v == 1).count();
            // Every third Gaussian moves ~100× more: both classes must be present.
            assert!(dynamic > 0 && dynamic < n, "{dynamic} of {n} dynamic");
        }
    }
}

#[test]
fn probe_extremes_are_finite_or_dynamic() {
    let f = probe_case(4, 64, true);
    assert_eq!(f[0], 1, "a NaN deformation is never frozen");
    assert_eq!(f[1], 1, "an infinite deformation is never frozen");
    assert_eq!(f[4], 0, "a constant offset is not motion: static");
}

#[test]
fn compaction_gather_and_expand_match_twin() {
    let gpu = testing::gpu();
    let k = SparseKernels::new(&gpu).unwrap();
    let scan = PrefixSum::new(&gpu).unwrap();
    for (seed, n, p) in [
        (1u64, 1usize, 1u32),
        (2, 5000, 3),
        (3, 4099, 0),
        (4, 300, 100),
    ] {
        let mut r = Noise::new(seed);
        // p: percent dynamic (0: none, 100: all).
        let flags: Vec<u32> = (0..n).map(|_| (r.next_u32() % 100 < p) as u32).collect();
        let width = 10;
        let src = r.uniforms(n * width, -1.0, 1.0);
        let fb = gpu.buffer_from("flags", &flags).unwrap();
        let sb = gpu.buffer_from("src", &src).unwrap();
        let bytes = n as u64 * 4;
        let [off, idx, row_of, count] = ["offsets", "idx", "row of", "count"]
            .map(|name| gpu.buffer(name, bytes.max(256)).unwrap());
        let gathered = gpu.buffer("gathered", bytes * width as u64).unwrap();
        let fixed = r.uniforms(n * width, 5.0, 6.0);
        let fb2 = gpu.buffer_from("fixed", &fixed).unwrap();
        let expanded = gpu.buffer("expanded", bytes * width as u64).unwrap();
        for (i, b) in [&idx, &row_of, &count, &gathered, &expanded]
            .iter()
            .enumerate()
        {
            testing::fill_noise(&gpu, b, 10 + i as u64);
        }
        let scratch = scan.scratch(&gpu, n as u32).unwrap();
        let mut rec = Recorder::new(&gpu).unwrap();
        scan.record(
            &mut rec,
            &scratch,
            fb.all(),
            off.all(),
            Count::Host(n as u32),
        );
        k.compact(
            &mut rec,
            n as u32,
            fb.all(),
            off.all(),
            idx.all(),
            row_of.all(),
            count.elems::<u32>(0, 1),
        );
        rec.finish().unwrap();
        let c = gpu.read::<u32>(count.elems::<u32>(0, 1)).unwrap()[0];
        let (w_idx, w_row, w_c) = dyn_compact(&flags);
        assert_eq!(c, w_c, "count (n {n}, {p}% dynamic)");
        assert_eq!(
            gpu.read::<u32>(row_of.elems::<u32>(0, n as u64)).unwrap(),
            w_row
        );
        if c > 0 {
            assert_eq!(
                gpu.read::<u32>(idx.elems::<u32>(0, c as u64)).unwrap(),
                w_idx
            );
        }
        let mut rec = Recorder::new(&gpu).unwrap();
        k.gather(
            &mut rec,
            c,
            width as u32,
            idx.all(),
            sb.all(),
            gathered.all(),
        );
        let (rows, w) = (row_of.all(), width as u32);
        k.expand(
            &mut rec,
            n as u32,
            w,
            rows,
            gathered.all(),
            fb2.all(),
            expanded.all(),
        );
        rec.finish().unwrap();
        let want_g = rows_gather(&w_idx, &src, width);
        if c > 0 {
            let got: Vec<f32> = gpu
                .read(gathered.elems::<f32>(0, want_g.len() as u64))
                .unwrap();
            assert_eq!(got, want_g, "gather");
        }
        let got: Vec<f32> = gpu.read(expanded.all()).unwrap();
        let want_x = rows_expand(&w_row, &want_g, &fixed, width);
        assert_eq!(got, want_x, "expand");
        // Round trip: dynamic rows come back, static rows are their fixed rows.
        for i in 0..n {
            let row = &got[i * width..(i + 1) * width];
            if flags[i] == 1 {
                assert_eq!(row, &src[i * width..(i + 1) * width]);
            } else {
                assert_eq!(row, &fixed[i * width..(i + 1) * width]);
                assert_eq!(w_row[i], NO_ROW);
            }
        }
    }
}

/// A model of `n` Gaussians with random means and a random (non-zero head) MLP.
fn model(gpu: &dispflow_vk::vk::Gpu, n: usize, seed: u64) -> Model {
    let mut r = Noise::new(seed);
    let pts: Vec<[f32; 3]> = (0..n)
        .map(|_| {
            let v = r.uniforms(3, -1.0, 1.0);
            [v[0], v[1], v[2]]
        })
        .collect();
    let g = HostGaussians::from_points(&pts, None, 0).unwrap();
    Model {
        gaussians: GaussianState::new(gpu, n as u32, 0, &g).unwrap(),
        deform: DeformState::new(gpu, mlp_config_for(true, 3, 32), seed, false).unwrap(),
        dynamic: DynamicSet::new(gpu, n as u32).unwrap(),
        nodes: None,
        transient: Default::default(),
    }
}

/// The split MLP computes exactly the dense MLP's rows for the dynamic Gaussians and exact
/// zeros for the static ones; its weight gradient equals the dense one with the static rows'
/// output gradients zeroed.
#[test]
fn split_mlp_equals_dense_mlp_on_the_dynamic_rows() {
    let gpu = testing::gpu();
    let n = 700;
    let mut m = model(&gpu, n, 3);
    let sizes = StepSizes {
        capacity: n as u32,
        width: 16,
        height: 16,
        sh_coeffs: 1,
        isect_guess: 1 << 10,
    };
    let pass = DeformPass::new(&gpu, &m.deform.cfg, None, &sizes, 1, true).unwrap();
    let mut r = Noise::new(9);
    let flags: Vec<u32> = (0..n).map(|_| (r.next_u32() % 4 == 0) as u32).collect();
    let d_out = r.uniforms(n * OUT_DIMS, -1.0, 1.0);
    let masked: Vec<f32> = (0..n * OUT_DIMS)
        .map(|j| {
            if flags[j / OUT_DIMS] == 1 {
                d_out[j]
            } else {
                0.0
            }
        })
        .collect();
    let run = |m: &Model, grads_in: &[f32]| -> (Vec<f32>, Vec<f32>) {
        let mut rec = Recorder::new(&gpu).unwrap();
        pass.mlp_forward(&mut rec, m, Slot::T1, 0.37);
        rec.finish().unwrap();
        gpu.upload(pass.output_grad(Slot::T1), grads_in).unwrap();
        let mut rec = Recorder::new(&gpu).unwrap();
        pass.mlp_backward(&mut rec, m, Slot::T1, false);
        rec.finish().unwrap();
        (
            gpu.read(pass.output(Slot::T1)).unwrap(),
            gpu.read(m.deform.grads.all()).unwrap(),
        )
    };
    // Same noise before both runs: padding between tensors is never written.
    testing::fill_noise(&gpu, &m.deform.grads, 4);
    let (dense_out, dense_grad) = run(&m, &masked);
    let fixed = r.uniforms(n * OUT_DIMS, -0.1, 0.1);
    let split = SplitSnapshot {
        flags: flags.clone(),
        fixed: fixed.clone(),
    };
    m.dynamic.upload(&gpu, Some(&split)).unwrap();
    assert_eq!(m.dynamic.split(), Some(flags.iter().sum::<u32>()));
    testing::fill_noise(&gpu, &m.deform.grads, 4);
    let (split_out, split_grad) = run(&m, &d_out);
    for i in 0..n {
        let (a, b) = (
            &split_out[i * OUT_DIMS..(i + 1) * OUT_DIMS],
            &dense_out[i * OUT_DIMS..(i + 1) * OUT_DIMS],
        );
        if flags[i] == 1 {
            for c in 0..OUT_DIMS {
                assert!((a[c] - b[c]).abs() <= 1e-6 * (1.0 + b[c].abs()), "row {i}");
            }
        } else {
            assert_eq!(
                a,
                &fixed[i * OUT_DIMS..(i + 1) * OUT_DIMS],
                "static row {i}"
            );
        }
    }
    assert!(
        dense_out.iter().any(|&v| v.abs() > 1e-3),
        "a non-trivial MLP"
    );
    let layout = &m.deform.layout;
    let used = |j: usize| {
        layout.linears.iter().any(|l| {
            (l.w_off..l.w_off + l.fan_in * l.fan_out).contains(&j)
                || (l.b_off..l.b_off + l.fan_out).contains(&j)
        })
    };
    let scale = (0..dense_grad.len())
        .filter(|&j| used(j))
        .fold(0.0f32, |a, j| a.max(dense_grad[j].abs()));
    assert!(scale > 0.0);
    for (j, (a, b)) in split_grad.iter().zip(&dense_grad).enumerate() {
        if !used(j) {
            assert_eq!(a.to_bits(), b.to_bits(), "padding {j} untouched");
            continue;
        }
        assert!(
            (a - b).abs() <= 1e-5 * scale,
            "weight grad {j}: split {a} dense {b}"
        );
    }
    // Nothing dynamic: no MLP work, zero gradient, zero output.
    let none = SplitSnapshot {
        flags: vec![0; n],
        fixed: fixed.clone(),
    };
    m.dynamic.upload(&gpu, Some(&none)).unwrap();
    testing::fill_noise(&gpu, &m.deform.grads, 5);
    let (out0, grad0) = run(&m, &d_out);
    assert_eq!(out0, fixed, "every row its fixed row");
    assert!((0..grad0.len())
        .filter(|&j| used(j))
        .all(|j| grad0[j] == 0.0));
}

/// A deformation that moves the Gaussians with x0 > 0.1 along x for t + x0 > 1.1 only: the
/// "object" (x0 ≥ 0.6) starts moving half-way through the sequence, the "background"
/// (x0 < 0.1) never moves. One trunk layer: h = ReLU(k·x0 + k·t − 1.1·k), dx0 = h.
fn late_mover_params(layout: &MlpLayout, k: f32) -> Vec<f32> {
    let mut p = vec![0.0; layout.total];
    let (l0, head) = (&layout.trunk()[0], layout.head());
    let t_at = layout.cfg.x_dims(); // γ(t) = [t, sin, cos, …] right after γ(x) = [x, …]
    p[l0.w_off] = k; // row 0, input x0
    p[l0.w_off + t_at] = k; // row 0, input t
    p[l0.b_off] = -1.1 * k;
    p[head.w_off] = 1.0; // dx0 = h0
    p
}

/// A static Gaussian becomes dynamic again when the deformation at its position starts to
/// move (the probe evaluates D over static Gaussians too): the first split, under a
/// deformation that moves nothing, freezes everything; once D moves the object late in the
/// sequence, the next split finds exactly the object.
#[test]
fn late_mover_is_picked_up_by_the_next_split() {
    let gpu = testing::gpu();
    let n = 400;
    // x0 evenly over [−1, 1]; the rest random.
    let mut r = Noise::new(11);
    let pts: Vec<[f32; 3]> = (0..n)
        .map(|i| {
            let v = r.uniforms(2, -0.5, 0.5);
            [-1.0 + 2.0 * i as f32 / (n - 1) as f32, v[0], v[1]]
        })
        .collect();
    let g = HostGaussians::from_points(&pts, None, 0).unwrap();
    let cfg = MlpConfig {
        depth: 1,
        width: 4,
        skip: None,
        x_freqs: 2,
        time: TimeEncoding::Direct { freqs: 2 },
    };
    let mut m = Model {
        gaussians: GaussianState::new(&gpu, n as u32, 0, &g).unwrap(),
        deform: DeformState::new(&gpu, cfg, 1, true).unwrap(),
        dynamic: DynamicSet::new(&gpu, n as u32).unwrap(),
        nodes: None,
        transient: Default::default(),
    };
    let sizes = StepSizes {
        capacity: n as u32,
        width: 64,
        height: 64,
        sh_coeffs: 1,
        isect_guess: 1 << 10,
    };
    let pass = DeformPass::new(&gpu, &cfg, None, &sizes, 1, false).unwrap();
    // One camera 4 units from the origin, focal 100 px: 1 px ≈ 0.04 scene units there.
    let cam = Camera {
        rot: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        trans: [0.0, 0.0, 4.0],
        fx: 100.0,
        fy: 100.0,
        cx: 32.0,
        cy: 32.0,
        width: 64,
        height: 64,
        near: 0.01,
    };
    let probe = ProbeConfig::even(0.5, 0.0, 11, 0.0, 1.0);
    let classifier = Classifier::new(&gpu, n as u32, &[cam], probe).unwrap();
    // The zero-initialised head: nothing moves, everything is frozen.
    let s = classifier.classify(&gpu, &mut m, &pass).unwrap();
    assert_eq!((s.dynamic, s.n), (0, n as u32), "{s}");
    // "Training" teaches the MLP the late motion.
    let p = late_mover_params(&m.deform.layout, 1.0);
    gpu.upload(m.deform.params.all(), &p).unwrap();
    let s = classifier.classify(&gpu, &mut m, &pass).unwrap();
    let split = m.dynamic.download(&gpu, n as u32).unwrap().expect("split");
    eprintln!("{s}");
    for (i, pt) in pts.iter().enumerate() {
        let x0 = pt[0];
        // Range of dx0 over t ∈ [0, 1]: max(0, x0 − 0.1); its half is the motion about the
        // midrange, ≥ 0.25 scene units (≈ 6 px) for x0 ≥ 0.6.
        if x0 >= 0.6 {
            assert_eq!(
                split.flags[i], 1,
                "object Gaussian {i} (x0 {x0}) stays frozen"
            );
        }
        if x0 < 0.1 {
            assert_eq!(split.flags[i], 0, "background Gaussian {i} (x0 {x0}) moved");
            assert!(split.fixed[10 * i..10 * i + 10].iter().all(|&v| v == 0.0));
        }
    }
    // The object's frozen rows hold the midrange of D: for a Gaussian that stays static under
    // a deformation with a constant part, the constant part is kept.
    let object = split.flags.iter().filter(|&&f| f == 1).count();
    assert!(object >= n / 5, "{object} dynamic");
}

dispflow_vk::subgroup_reruns!();
