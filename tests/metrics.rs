//! Motion metrics: hand-worked AP and DRC cases on the GPU and the twin, GPU vs twin on random
//! maps (quantised scores with many ties, several sort blocks and scan levels), the MMAP mean
//! over frames.

use dispflow_vk::kernels::metrics::{mmap, MotionMetrics, DRC_EPS};
use dispflow_vk::reference::metrics::{average_precision, drc};
use dispflow_vk::testing::{self, Noise, TestGpu};
use dispflow_vk::vk::Recorder;

fn gpu_ap(
    gpu: &TestGpu,
    mm: &MotionMetrics,
    w: u32,
    h: u32,
    score: &[f32],
    mask: &[u32],
) -> Option<f64> {
    let b = mm.buffers(gpu, w, h).unwrap();
    for (i, buf) in b.all_buffers().into_iter().enumerate() {
        testing::fill_noise(gpu, buf, 40 + i as u64);
    }
    let s = gpu.buffer_from("score", score).unwrap();
    let m = gpu.buffer_from("mask", mask).unwrap();
    let mut rec = Recorder::new(gpu).unwrap();
    mm.record_ap(&mut rec, &b, s.all(), m.all());
    rec.finish().unwrap();
    b.ap(gpu).unwrap()
}

fn gpu_drc(
    gpu: &TestGpu,
    mm: &MotionMetrics,
    w: u32,
    h: u32,
    score: &[f32],
    imgs: [&[[f32; 4]]; 3],
) -> f64 {
    let b = mm.buffers(gpu, w, h).unwrap();
    for (i, buf) in b.all_buffers().into_iter().enumerate() {
        testing::fill_noise(gpu, buf, 60 + i as u64);
    }
    let s = gpu.buffer_from("score", score).unwrap();
    let [fr, fu, gt] = imgs.map(|im| gpu.buffer_from("image", im).unwrap());
    let mut rec = Recorder::new(gpu).unwrap();
    mm.record_drc(&mut rec, &b, s.all(), fr.all(), fu.all(), gt.all());
    rec.finish().unwrap();
    b.drc(gpu).unwrap()
}

/// Both implementations on one hand-worked case.
fn check_ap(
    gpu: &TestGpu,
    mm: &MotionMetrics,
    name: &str,
    score: &[f32],
    mask: &[u32],
    want: Option<f64>,
) {
    let n = score.len() as u32;
    let twin = average_precision(score, mask);
    let got = gpu_ap(gpu, mm, n, 1, score, mask);
    for (who, v) in [("twin", twin), ("gpu", got)] {
        match (v, want) {
            (None, None) => {}
            (Some(a), Some(b)) => assert!((a - b).abs() < 1e-6, "{name}: {who} AP {a}, want {b}"),
            _ => panic!("{name}: {who} AP {v:?}, want {want:?}"),
        }
    }
}

#[test]
fn ap_hand_worked_cases() {
    let gpu = testing::gpu();
    let mm = MotionMetrics::new(&gpu).unwrap();
    // Positives ranked first: P = 1 at every recall step.
    check_ap(
        &gpu,
        &mm,
        "perfect",
        &[0.9, 0.8, 0.3, 0.1],
        &[1, 1, 0, 0],
        Some(1.0),
    );
    // Inverted: order 0.9(−) 0.8(−) 0.2(+) 0.1(+): thresholds at ranks 3 and 4 add
    // ΔR = 1/2 with P = 1/3, then ΔR = 1/2 with P = 2/4: AP = 1/6 + 1/4 = 5/12.
    check_ap(
        &gpu,
        &mm,
        "inverted",
        &[0.1, 0.2, 0.8, 0.9],
        &[1, 1, 0, 0],
        Some(5.0 / 12.0),
    );
    // All scores tied: one threshold admitting everything: R = 1, P = 3/8.
    check_ap(
        &gpu,
        &mm,
        "all ties",
        &[0.5; 8],
        &[1, 0, 0, 1, 0, 1, 0, 0],
        Some(3.0 / 8.0),
    );
    // No moving pixel: undefined.
    check_ap(&gpu, &mm, "empty mask", &[0.5, 0.1, 0.9], &[0, 0, 0], None);
    // One positive, ranked third: P = 1/3 at R = 1.
    check_ap(
        &gpu,
        &mm,
        "single positive",
        &[0.1, 0.7, 0.4, 0.9, 0.2],
        &[0, 0, 1, 0, 0],
        Some(1.0 / 3.0),
    );
    // Ties inside: scores 0.9 0.9 | 0.5 0.5 0.5 | 0.1, labels 1 0 | 1 1 0 | 1, P = 4.
    // Threshold 0.9: TP 1 of 2 → P 1/2, ΔR 1/4. Threshold 0.5: TP 3 of 5 → P 3/5, ΔR 2/4.
    // Threshold 0.1: TP 4 of 6 → P 4/6, ΔR 1/4. AP = 1/8 + 3/10 + 1/6 = 71/120.
    check_ap(
        &gpu,
        &mm,
        "runs of ties",
        &[0.5, 0.9, 0.1, 0.5, 0.9, 0.5],
        &[1, 1, 1, 0, 0, 1],
        Some(71.0 / 120.0),
    );
    // −0 and +0 are one score: one threshold, P = 1/2.
    check_ap(&gpu, &mm, "signed zeros", &[0.0, -0.0], &[1, 0], Some(0.5));
    // Negative scores (e.g. a z-score map) order correctly: the positive has the highest.
    check_ap(
        &gpu,
        &mm,
        "negative scores",
        &[-1.5, -0.25, -3.0, 2.0],
        &[0, 0, 0, 1],
        Some(1.0),
    );
    check_ap(&gpu, &mm, "1x1", &[0.3], &[1], Some(1.0));
}

#[test]
fn ap_gpu_matches_twin_on_random_maps() {
    let gpu = testing::gpu();
    let mm = MotionMetrics::new(&gpu).unwrap();
    for (seed, w, h, levels) in [
        (1u64, 17u32, 13u32, 17u32),
        (2, 64, 48, 5),
        (3, 64, 48, 0),     // continuous scores, almost no ties
        (4, 300, 200, 256), // 60 000 pixels: many sort blocks, two scan levels
        (5, 1, 1, 3),
    ] {
        let n = (w * h) as usize;
        let mut r = Noise::new(seed);
        let score: Vec<f32> = (0..n)
            .map(|_| {
                let u = (r.next_u32() >> 8) as f32 / 16_777_216.0;
                if levels > 0 {
                    (u * levels as f32).floor() / levels as f32
                } else {
                    u
                }
            })
            .collect();
        // Labels correlated with the score, so the AP is far from the positive rate.
        let mask: Vec<u32> = score
            .iter()
            .map(|&s| {
                ((r.next_u32() >> 8) as f32 / 16_777_216.0 < 0.2 + 0.6 * s) as u32
                    * (1 + r.next_u32() % 3)
            })
            .collect();
        let twin = average_precision(&score, &mask);
        let got = gpu_ap(&gpu, &mm, w, h, &score, &mask);
        match (got, twin) {
            (Some(a), Some(b)) => assert!(
                (a - b).abs() <= 1e-6,
                "seed {seed} {w}x{h}: gpu AP {a}, twin {b}"
            ),
            _ => assert_eq!(got, twin, "seed {seed}"),
        }
        if n > 1 {
            let b = twin.unwrap();
            let rate = mask.iter().filter(|&&l| l != 0).count() as f64 / n as f64;
            assert!(
                b > rate + 0.05,
                "seed {seed}: AP {b} vs positive rate {rate}"
            );
        }
    }
}

#[test]
fn mmap_skips_undefined_frames() {
    assert_eq!(mmap([Some(0.5), None, Some(1.0)]), Some(0.75));
    assert_eq!(mmap([None, None]), None);
    assert_eq!(mmap(Vec::<Option<f64>>::new()), None);
}

fn px(v: f32) -> [f32; 4] {
    [v, v, v, 1.0]
}

#[test]
fn drc_hand_worked_cases() {
    let gpu = testing::gpu();
    let mm = MotionMetrics::new(&gpu).unwrap();
    let gt = [px(0.5); 4];
    let good = [px(0.5); 4]; // error 0
    let bad = [px(0.8); 4]; // error 0.3 per channel
    let f = [1.0f32, 0.5, 0.25, 0.0];
    let sum: f64 = f.iter().map(|&x| x as f64).sum();
    // The full deformation improves everywhere: DRC = Σf / (Σf + ε) ≈ 1.
    let want_all = sum / (sum + DRC_EPS);
    // It improves nowhere (equal errors are not an improvement): 0.
    // Mixed: improved at pixels 0, 2, 3 → (1 + 0.25 + 0) / (1.75 + ε).
    let mixed_full = [good[0], bad[1], good[2], good[3]];
    let want_mixed = 1.25 / (1.75 + DRC_EPS);
    type Case<'a> = (&'a str, &'a [f32], [&'a [[f32; 4]]; 3], f64);
    let cases: Vec<Case> = vec![
        ("all improve", &f, [&bad, &good, &gt], want_all),
        ("none improve", &f, [&good, &bad, &gt], 0.0),
        ("equal errors", &f, [&bad, &bad, &gt], 0.0),
        ("mixed", &f, [&bad, &mixed_full, &gt], want_mixed),
        ("zero score", &[0.0; 4], [&bad, &good, &gt], 0.0),
    ];
    for (name, score, imgs, want) in cases {
        let t = drc(score, imgs[0], imgs[1], imgs[2]);
        let g = gpu_drc(&gpu, &mm, 2, 2, score, imgs);
        for (who, v) in [("twin", t), ("gpu", g)] {
            assert!(
                v.is_finite() && (v - want).abs() < 1e-7,
                "{name}: {who} {v}, want {want}"
            );
        }
    }
}

#[test]
fn drc_gpu_matches_twin() {
    let gpu = testing::gpu();
    let mm = MotionMetrics::new(&gpu).unwrap();
    for (seed, w, h) in [(1u64, 17u32, 13u32), (2, 64, 48), (3, 1, 1)] {
        let n = (w * h) as usize;
        let mut r = Noise::new(seed);
        let mut u = || (r.next_u32() >> 8) as f32 / 16_777_216.0;
        let score: Vec<f32> = (0..n).map(|_| u()).collect();
        let mut img = || -> Vec<[f32; 4]> { (0..n).map(|_| [u(), u(), u(), 1.0]).collect() };
        let (fr, fu, gt) = (img(), img(), img());
        let t = drc(&score, &fr, &fu, &gt);
        let g = gpu_drc(&gpu, &mm, w, h, &score, [&fr, &fu, &gt]);
        // f32 tree sums per workgroup vs f64: relative ~1e-7.
        assert!(
            (g - t).abs() <= 1e-6 * t.max(1e-3),
            "seed {seed}: gpu {g}, twin {t}"
        );
        if n > 100 {
            assert!(
                t > 0.3 && t < 0.7,
                "random images: about half improve ({t})"
            );
        }
    }
}

dispflow_vk::subgroup_reruns!();
