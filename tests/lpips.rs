//! LPIPS (AlexNet): every GPU stage against its CPU twin on identical inputs (the twin fed the
//! GPU's own previous stage), the convolution at shapes AlexNet does not use, the whole metric
//! against the reference PyTorch `lpips` package (fixture in tests/lpips/, made by
//! tools/lpips_fixture.py), the extremes, and bad weight files.

use std::path::{Path, PathBuf};

use dispflow_vk::kernels::lpips::{Lpips, LpipsConvParams, LpipsWeights, Plan, ALEXNET, MIN_SIDE};
use dispflow_vk::reference::lpips as twin;
use dispflow_vk::testing::{self, assert_close, Noise, Tol};
use dispflow_vk::train::score::lpips::{
    load_weights, parse_weights, random_weights, to_safetensors, LpipsScorer,
};
use dispflow_vk::vk::{Gpu, Recorder};

fn image(seed: u64, n: usize) -> Vec<[f32; 4]> {
    Noise::new(seed)
        .uniforms(4 * n, 0.0, 1.0)
        .chunks_exact(4)
        .map(|c| [c[0], c[1], c[2], c[3]])
        .collect()
}

fn to_f64(v: &[f32]) -> Vec<f64> {
    v.iter().map(|&x| x as f64).collect()
}

/// GPU LPIPS of one pair with the scorer; returns (stage values, scorer) for inspection.
fn gpu_stages(
    gpu: &Gpu,
    s: &mut LpipsScorer,
    w: u32,
    h: u32,
    a: &[[f32; 4]],
    b: &[[f32; 4]],
) -> [f64; 5] {
    let ab = gpu.buffer_from("lpips test img0", a).unwrap();
    let bb = gpu.buffer_from("lpips test img1", b).unwrap();
    let mut rec = Recorder::new(gpu).unwrap();
    s.record(&mut rec, (w, h), ab.all(), bb.all()).unwrap();
    rec.finish().unwrap();
    s.stage_values(gpu).unwrap()
}

#[test]
fn every_stage_matches_twin_on_identical_inputs() {
    let gpu = testing::gpu();
    let wts = random_weights(5);
    let kernels = Lpips::new(&gpu).unwrap();
    let wbuf = gpu.buffer_from("lpips weights", &wts.data).unwrap();
    for (seed, (w, h)) in [(1u64, (64u32, 48u32)), (2, (37, 31)), (3, (47, 66))] {
        let (a, b) = (
            image(seed, (w * h) as usize),
            image(seed + 100, (w * h) as usize),
        );
        let bufs = kernels.buffers(&gpu, w, h).unwrap();
        let (ab, bb) = (
            gpu.buffer_from("a", &a).unwrap(),
            gpu.buffer_from("b", &b).unwrap(),
        );
        let mut rec = Recorder::new(&gpu).unwrap();
        kernels.record(&mut rec, &bufs, wbuf.all(), &wts, ab.all(), bb.all());
        rec.finish().unwrap();
        let p = bufs.plan;
        let input: Vec<f32> = gpu.read(bufs.input()).unwrap();
        let want = twin::lpips_input(&a, &b, w as usize, h as usize);
        assert_close(
            "lpips_input",
            &input,
            &want,
            Tol::Normwise {
                abs: 1e-6,
                rel: 1e-6,
            },
        );
        let mut src = input;
        let (mut sw, mut sh) = (w as usize, h as usize);
        let mut pool_j = 0;
        for (i, s) in ALEXNET.iter().enumerate() {
            if s.pool_before {
                let got: Vec<f32> = gpu.read(bufs.pooled(pool_j)).unwrap();
                let want = twin::max_pool(&to_f64(&src), 2 * s.cin as usize, sw, sh);
                // A max picks one of its inputs: exact.
                assert_close(
                    &format!("max_pool {pool_j}"),
                    &got,
                    &want,
                    Tol::Normwise { abs: 0.0, rel: 0.0 },
                );
                src = got;
                pool_j += 1;
            }
            let (iw, ih) = p.conv_in[i];
            let (ow, oh) = p.conv_out[i];
            let got: Vec<f32> = gpu.read(bufs.features(i)).unwrap();
            let want = twin::conv(
                &to_f64(&src),
                2,
                iw as usize,
                ih as usize,
                s,
                wts.conv_weight(i),
                wts.conv_bias(i),
                ow as usize,
                oh as usize,
            );
            assert!(
                want.iter().any(|&v| v > 0.0),
                "conv{}: all features dead",
                i + 1
            );
            assert_close(
                &format!("{w}×{h} conv{}", i + 1),
                &got,
                &want,
                Tol::Normwise {
                    abs: 1e-6,
                    rel: 2e-5,
                },
            );
            src = got;
            (sw, sh) = (ow as usize, oh as usize);
        }
        let stages = bufs.stage_values(&gpu).unwrap();
        for (i, s) in ALEXNET.iter().enumerate() {
            let f: Vec<f32> = gpu.read(bufs.features(i)).unwrap();
            let (ow, oh) = p.conv_out[i];
            let want = twin::lpips_diff(
                &to_f64(&f),
                s.cout as usize,
                ow as usize,
                oh as usize,
                wts.lin_weight(i),
            );
            assert!(
                (stages[i] - want).abs() <= 1e-7 + 1e-5 * want.abs(),
                "{w}×{h} lpips_diff stage {}: gpu {} twin {want}",
                i + 1,
                stages[i]
            );
        }
    }
}

#[test]
fn conv_matches_twin_at_other_shapes() {
    // Channel counts off the 64×64 tile, K not a multiple of 16, strides and paddings AlexNet
    // does not use, a 1×1 output.
    let gpu = testing::gpu();
    let kernels = Lpips::new(&gpu).unwrap();
    let cases = [
        // cin, cout, k, stride, pad, in_w, in_h
        (5u32, 70u32, 4u32, 3u32, 0u32, 23u32, 17u32),
        (3, 64, 11, 4, 2, 35, 41),
        (7, 9, 1, 1, 0, 13, 5),
        (2, 130, 3, 2, 3, 9, 12),
        (4, 3, 5, 1, 2, 5, 5),
        (1, 1, 3, 1, 0, 3, 3),
    ];
    for (n, &(cin, cout, k, stride, pad, in_w, in_h)) in cases.iter().enumerate() {
        let out_w = (in_w + 2 * pad - k) / stride + 1;
        let out_h = (in_h + 2 * pad - k) / stride + 1;
        let spec = dispflow_vk::kernels::lpips::ConvSpec {
            cin,
            cout,
            ksize: k,
            stride,
            pad,
            pool_before: false,
        };
        let src = Noise::new(10 + n as u64).uniforms((2 * cin * in_w * in_h) as usize, -1.0, 1.0);
        let wt = Noise::new(20 + n as u64).uniforms((cout * cin * k * k) as usize, -0.5, 0.5);
        let bias = Noise::new(30 + n as u64).uniforms(cout as usize, -0.2, 0.2);
        let packed: Vec<f32> = [vec![9.0; 3], wt.clone(), bias.clone()].concat();
        let (sb, wb) = (
            gpu.buffer_from("src", &src).unwrap(),
            gpu.buffer_from("w", &packed).unwrap(),
        );
        let out = gpu
            .buffer("dst", (2 * cout * out_w * out_h) as u64 * 4)
            .unwrap();
        testing::fill_noise(&gpu, &out, n as u64);
        let p = LpipsConvParams {
            in_w,
            in_h,
            out_w,
            out_h,
            cin,
            cout,
            ksize: k,
            stride,
            pad,
            w_off: 3,
            b_off: 3 + wt.len() as u32,
            pad0: 0,
        };
        let mut rec = Recorder::new(&gpu).unwrap();
        kernels.record_conv(&mut rec, &p, 2, sb.all(), wb.all(), out.all());
        rec.finish().unwrap();
        let got: Vec<f32> = gpu
            .read(out.elems::<f32>(0, (2 * cout * out_w * out_h) as u64))
            .unwrap();
        let want = twin::conv(
            &to_f64(&src),
            2,
            in_w as usize,
            in_h as usize,
            &spec,
            &wt,
            &bias,
            out_w as usize,
            out_h as usize,
        );
        assert_close(
            &format!("conv case {n}"),
            &got,
            &want,
            Tol::Normwise {
                abs: 1e-6,
                rel: 1e-5,
            },
        );
    }
}

struct Pair {
    w: u32,
    h: u32,
    a: Vec<[f32; 4]>,
    b: Vec<[f32; 4]>,
    lpips: f64,
    stages: Vec<f64>,
    lpips_f64: f64,
}

fn fixture_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/lpips")
}

fn fixture_pairs() -> Vec<Pair> {
    let bytes = std::fs::read(fixture_dir().join("pairs.safetensors"))
        .expect("tests/lpips/pairs.safetensors");
    let st = safetensors::SafeTensors::deserialize(&bytes).expect("parse pairs");
    let f64s = |name: &str| -> Vec<f64> {
        let t = st.tensor(name).unwrap_or_else(|_| panic!("{name}"));
        t.data()
            .chunks_exact(8)
            .map(|b| f64::from_le_bytes(b.try_into().unwrap()))
            .collect()
    };
    let mut out = Vec::new();
    for i in 0.. {
        let Ok(t0) = st.tensor(&format!("pair{i}.img0")) else {
            break;
        };
        let t1 = st.tensor(&format!("pair{i}.img1")).unwrap();
        let (h, w) = (t0.shape()[0], t0.shape()[1]);
        let img = |d: &[u8]| -> Vec<[f32; 4]> {
            d.chunks_exact(3)
                .map(|p| {
                    [
                        p[0] as f32 / 255.0,
                        p[1] as f32 / 255.0,
                        p[2] as f32 / 255.0,
                        1.0,
                    ]
                })
                .collect()
        };
        out.push(Pair {
            w: w as u32,
            h: h as u32,
            a: img(t0.data()),
            b: img(t1.data()),
            lpips: f64s(&format!("pair{i}.lpips"))[0],
            stages: f64s(&format!("pair{i}.stages")),
            lpips_f64: f64s(&format!("pair{i}.lpips_f64"))[0],
        });
    }
    assert!(out.len() >= 4, "fixture has {} pairs", out.len());
    out
}

/// The reference package on random AlexNet weights (see tools/lpips_fixture.py). Tolerance:
/// both sides run f32 networks whose sums are ordered differently (implicit GEMM vs PyTorch's
/// conv); the reference's own f32-vs-f64 spread is ~1e-8 on these values, ours ~1e-7, so
/// 1e-6 absolute + 1e-4 relative leaves room for other devices while a wrong padding, pool or
/// normalisation moves the values by 1e-3 or more.
#[test]
fn matches_reference_lpips_package() {
    let gpu = testing::gpu();
    let wts =
        load_weights(&fixture_dir().join("alex_random_f16.safetensors")).expect("fixture weights");
    let mut s = LpipsScorer::new(&gpu, wts.clone()).unwrap();
    let pairs = fixture_pairs();
    assert!(
        pairs.iter().filter(|p| p.lpips > 1e-3).count() >= 3,
        "degenerate fixture"
    );
    let (mut worst_gpu, mut worst_twin) = (0.0f64, 0.0f64);
    for p in &pairs {
        let got = gpu_stages(&gpu, &mut s, p.w, p.h, &p.a, &p.b);
        let total: f64 = got.iter().sum();
        let tw = twin::lpips(&wts, &p.a, &p.b, p.w as usize, p.h as usize).unwrap();
        let tw_total: f64 = tw.iter().sum();
        eprintln!(
            "{}×{}: reference {:.8} (f64 {:.8}), gpu {total:.8}, twin {tw_total:.8}",
            p.w, p.h, p.lpips, p.lpips_f64
        );
        let tol = |v: f64| 1e-6 + 1e-4 * v.abs();
        assert!(
            (total - p.lpips).abs() <= tol(p.lpips),
            "{}×{}: gpu {total} vs reference {}",
            p.w,
            p.h,
            p.lpips
        );
        for (i, (g, want)) in got.iter().zip(&p.stages).enumerate() {
            assert!(
                (g - want).abs() <= tol(*want),
                "{}×{} stage {}: gpu {g} vs reference {want}",
                p.w,
                p.h,
                i + 1
            );
        }
        // The f64 twin against the reference run in f64: only summation order differs.
        assert!(
            (tw_total - p.lpips_f64).abs() <= 1e-9 + 1e-7 * p.lpips_f64,
            "twin {tw_total} vs reference f64 {}",
            p.lpips_f64
        );
        worst_gpu = worst_gpu.max((total - p.lpips).abs());
        worst_twin = worst_twin.max((tw_total - p.lpips_f64).abs());
    }
    eprintln!(
        "max |gpu − reference| = {worst_gpu:.3e}, max |twin − reference f64| = {worst_twin:.3e}"
    );
}

#[test]
fn identical_images_give_zero_and_constant_images_are_finite() {
    let gpu = testing::gpu();
    let wts = random_weights(7);
    let mut s = LpipsScorer::new(&gpu, wts.clone()).unwrap();
    let (w, h) = (MIN_SIDE, 40);
    let n = (w * h) as usize;
    let a = image(3, n);
    assert_eq!(
        gpu_stages(&gpu, &mut s, w, h, &a, &a),
        [0.0; 5],
        "identical images"
    );
    // Flat images: every conv sees only its bias and the padding; zero features anywhere get
    // 0 / (0 + 1e-10) = 0, never NaN.
    for (va, vb) in [(0.0, 1.0), (0.0, 0.0), (0.5, 0.25), (-3.0, 7.0)] {
        let a = vec![[va; 4]; n];
        let b = vec![[vb; 4]; n];
        let got = gpu_stages(&gpu, &mut s, w, h, &a, &b);
        let want = twin::lpips(&wts, &a, &b, w as usize, h as usize).unwrap();
        for i in 0..5 {
            assert!(
                got[i].is_finite(),
                "flat {va} vs {vb}: stage {} is {}",
                i + 1,
                got[i]
            );
            assert!(
                (got[i] - want[i]).abs() <= 1e-7 + 1e-4 * want[i].abs(),
                "flat {va} vs {vb} stage {}: gpu {} twin {}",
                i + 1,
                got[i],
                want[i]
            );
        }
    }
}

#[test]
fn too_small_images_are_a_clear_error() {
    let gpu = testing::gpu();
    let kernels = Lpips::new(&gpu).unwrap();
    for (w, h) in [(1, 1), (30, 64), (64, 30), (0, 0), (16, 16)] {
        let e = kernels
            .buffers(&gpu, w, h)
            .err()
            .unwrap_or_else(|| panic!("{w}×{h} accepted"))
            .to_string();
        assert!(
            e.contains("31×31") && e.contains(&format!("{w}×{h}")),
            "{e}"
        );
        assert!(twin::lpips(&random_weights(1), &[], &[], w as usize, h as usize).is_err());
    }
    let p = Plan::new(MIN_SIDE, MIN_SIDE).unwrap();
    assert_eq!(p.conv_out, [(7, 7), (3, 3), (1, 1), (1, 1), (1, 1)]);
    assert_eq!(Plan::new(64, 48).unwrap().conv_out[0], (15, 11));
}

fn weights_error(bytes: &[u8]) -> String {
    match parse_weights(Path::new("w.safetensors"), bytes) {
        Ok(_) => panic!("accepted a bad weight file"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn bad_weight_files_name_the_tensor() {
    let w = random_weights(2);
    let good = to_safetensors(&w, None, None);
    let back: LpipsWeights = parse_weights(Path::new("w"), &good).unwrap();
    assert_eq!(back, w, "round trip");
    let e = weights_error(&to_safetensors(&w, Some("conv3.weight"), None));
    assert!(
        e.contains("w.safetensors") && e.contains("conv3.weight") && e.contains("missing"),
        "{e}"
    );
    let e = weights_error(&to_safetensors(
        &w,
        None,
        Some(("conv2.weight", vec![192, 64, 3, 3], vec![0.1; 192 * 64 * 9])),
    ));
    assert!(
        e.contains("conv2.weight")
            && e.contains("[192, 64, 3, 3]")
            && e.contains("[192, 64, 5, 5]"),
        "{e}"
    );
    let mut nan = w.lin_weight(3).to_vec();
    nan[17] = f32::NAN;
    let e = weights_error(&to_safetensors(
        &w,
        None,
        Some(("lin4.weight", vec![1, 256, 1, 1], nan)),
    ));
    assert!(
        e.contains("lin4.weight") && e.contains("element 17") && e.contains("NaN"),
        "{e}"
    );
    let mut inf = w.conv_bias(0).to_vec();
    inf[0] = f32::INFINITY;
    let e = weights_error(&to_safetensors(
        &w,
        None,
        Some(("conv1.bias", vec![64], inf)),
    ));
    assert!(e.contains("conv1.bias") && e.contains("inf"), "{e}");
    let e = weights_error(b"PK\x03\x04 not a safetensors file at all");
    assert!(
        e.contains("not a safetensors file") && e.contains("tools/lpips_weights.py"),
        "{e}"
    );
    // A safetensors file that is not ours (e.g. a raw torchvision export): no metadata.
    let raw = safetensors::serialize(
        [(
            "features.0.weight",
            safetensors::tensor::TensorView::new(safetensors::Dtype::F32, vec![1], &[0u8; 4])
                .unwrap(),
        )],
        None,
    )
    .unwrap();
    let e = weights_error(&raw);
    assert!(
        e.contains("dispflow-lpips") && e.contains("tools/lpips_weights.py"),
        "{e}"
    );
}
