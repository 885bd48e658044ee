//! Fused Adam against the scalar twin (`reference::adam`, f64 inside) over several steps with
//! per-group learning rates from the 3DGS schedule, a visibility mask, and edge cases.
//!
//! Tolerance: the GPU evaluates the same expression in f32, a few roundings per step. m can
//! cancel (β1·m + (1 − β1)·g with opposite signs), so its error is bounded relative to the
//! magnitude of its terms, tracked as `m_abs` (the same recurrence on |g|):
//! `|Δm| ≤ 1e-6·m_abs`; v has no cancellation: `|Δv| ≤ 1e-6·|v|`; p: `|Δp| ≤ 4e-7·|p| + 1e-5·lr`
//! (the update is ≲ lr; its relative error follows m's).

use dispflow_vk::kernels::adam::{Adam, AdamBuffers, AdamGroup};
use dispflow_vk::kernels::shape::Access;
use dispflow_vk::model::optim::{AdamHyper, ExpLr};
use dispflow_vk::reference::adam::adam_step;
use dispflow_vk::testing::{self, Noise};
use dispflow_vk::vk::{Buffer, Gpu, Recorder};

struct Bufs {
    p: Buffer,
    g: Buffer,
    m: Buffer,
    v: Buffer,
}

impl Bufs {
    fn new(gpu: &Gpu, p: &[f32]) -> Bufs {
        let zeros = vec![0.0f32; p.len()];
        Bufs {
            p: gpu.buffer_from("adam p", p).unwrap(),
            g: gpu.buffer("adam g", p.len() as u64 * 4).unwrap(),
            m: gpu.buffer_from("adam m", &zeros).unwrap(),
            v: gpu.buffer_from("adam v", &zeros).unwrap(),
        }
    }
    fn ab(&self) -> AdamBuffers<'_> {
        AdamBuffers {
            params: self.p.all(),
            grads: self.g.all(),
            m: self.m.all(),
            v: self.v.all(),
        }
    }
    fn read(&self, gpu: &Gpu, n: usize) -> [Vec<f32>; 3] {
        [&self.p, &self.m, &self.v].map(|b| gpu.read::<f32>(b.elems::<f32>(0, n as u64)).unwrap())
    }
}

fn check(what: &str, got: &[f32], want: &[f32], scale: &[f32], rel: f32, abs: f32) {
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (g - w).abs() <= rel * scale[i].abs() + abs,
            "{what}[{i}]: gpu {g}, twin {w}"
        );
    }
}

#[test]
fn adam_matches_scalar_reference_over_steps_with_groups_and_mask() {
    // Both array accesses: storage buffers (GPUs) and texel buffers (CPU devices).
    for access in [Access::Buffer, Access::Texel] {
        matches_reference(access);
    }
}

fn matches_reference(access: Access) {
    let gpu = testing::gpu();
    let adam = Adam::with_access(&gpu, access).unwrap();
    let n = 10_000usize;
    let (split, row_len) = (3_001usize, 3usize); // group 1: rows of 3 floats from `split`
    let rows = (n - split).div_ceil(row_len);
    let mut noise = Noise::new(1);
    let mut p: Vec<f32> = (0..n).map(|_| noise.uniform(-2.0, 2.0)).collect();
    let mask: Vec<u32> = (0..rows).map(|r| (r % 3 != 1) as u32).collect();
    let (mut m, mut v) = (vec![0.0f32; n], vec![0.0f32; n]);
    let mut m_abs = vec![0.0f32; n];
    let b = Bufs::new(&gpu, &p);
    let maskb = gpu.buffer_from("adam mask", &mask).unwrap();
    let h = AdamHyper::default();
    let sched = [
        ExpLr {
            lr_init: 1e-3,
            lr_final: 1e-5,
            lr_delay_steps: 2,
            lr_delay_mult: 0.1,
            max_steps: 6,
        },
        ExpLr::deform(1.0, 6),
    ];
    let frozen_p = p.clone();
    for step in 1..=6u32 {
        // Gradients change every step; a stretch of exact zeros checks ε handling.
        let g: Vec<f32> = (0..n)
            .map(|i| {
                if (100..200).contains(&i) {
                    0.0
                } else {
                    noise.uniform(-1.0, 1.0) * 10f32.powi((i % 7) as i32 - 3)
                }
            })
            .collect();
        gpu.upload(b.g.all(), &g).unwrap();
        let lr = sched.map(|s| s.at(step as i64 - 1) as f32);
        let groups = [
            AdamGroup {
                first: 0,
                count: split as u32,
                lr: lr[0],
                mask: None,
            },
            AdamGroup {
                first: split as u32,
                count: (n - split) as u32,
                lr: lr[1],
                mask: Some((maskb.all(), row_len as u32)),
            },
        ];
        let mut rec = Recorder::new(&gpu).unwrap();
        adam.record(&mut rec, b.ab(), &groups, &h, step);
        rec.finish().unwrap();
        adam_step(&mut p, &g, &mut m, &mut v, 0..split, None, lr[0], &h, step);
        adam_step(
            &mut p,
            &g,
            &mut m,
            &mut v,
            split..n,
            Some((&mask, row_len)),
            lr[1],
            &h,
            step,
        );
        for (a, gi) in m_abs.iter_mut().zip(&g) {
            *a = h.beta1 * *a + (1.0 - h.beta1) * gi.abs();
        }
        let [gp, gm, gv] = b.read(&gpu, n);
        let lr_max = lr[0].max(lr[1]);
        let at = |what: &str| format!("{access:?} step {step} {what}");
        check(&at("p"), &gp, &p, &p, 4e-7, 1e-5 * lr_max);
        check(&at("m"), &gm, &m, &m_abs, 1e-6, 1e-30);
        check(&at("v"), &gv, &v, &v, 1e-6, 1e-30);
    }
    // Masked rows are untouched, bit for bit; visible rows moved; zero gradients never move p.
    let [gp, gm, gv] = b.read(&gpu, n);
    for (r, &mk) in mask.iter().enumerate() {
        for i in split + r * row_len..(split + (r + 1) * row_len).min(n) {
            if mk == 0 {
                assert_eq!(
                    (gp[i], gm[i], gv[i]),
                    (frozen_p[i], 0.0, 0.0),
                    "masked float {i}"
                );
            } else {
                assert_ne!(gp[i], frozen_p[i], "visible float {i} did not move");
            }
        }
    }
    assert_eq!(
        &gp[100..200],
        &frozen_p[100..200],
        "zero gradient, zero step"
    );
    assert!(gp.iter().all(|x| x.is_finite()));
}

#[test]
fn adam_first_step_is_lr_times_sign_and_empty_group_is_noop() {
    let gpu = testing::gpu();
    let adam = Adam::new(&gpu).unwrap();
    // Step 1 with bias correction: m̂ = g, v̂ = g², so Δp = −lr·g/(|g| + ε) = −lr·sign(g).
    let n = 1000;
    let p = vec![1.0f32; n];
    let b = Bufs::new(&gpu, &p);
    let g: Vec<f32> = (0..n)
        .map(|i| if i % 2 == 0 { 1e-8 } else { -3e4 })
        .collect();
    gpu.upload(b.g.all(), &g).unwrap();
    let h = AdamHyper::default();
    let mut rec = Recorder::new(&gpu).unwrap();
    let groups = [
        AdamGroup {
            first: 0,
            count: n as u32,
            lr: 0.01,
            mask: None,
        },
        AdamGroup {
            first: 0,
            count: 0,
            lr: 1.0,
            mask: None,
        },
    ];
    adam.record(&mut rec, b.ab(), &groups, &h, 1);
    rec.finish().unwrap();
    let [gp, _, _] = b.read(&gpu, n);
    for (i, x) in gp.iter().enumerate() {
        let want = if i % 2 == 0 { 0.99 } else { 1.01 };
        assert!((x - want).abs() < 1e-6, "p[{i}] = {x}");
    }
}

#[test]
fn adam_covers_more_than_65535_workgroups() {
    let gpu = testing::gpu();
    let adam = Adam::new(&gpu).unwrap();
    let n = 65_535 * 256 + 1000; // needs a second row of workgroups
    let b = Bufs::new(&gpu, &vec![0.0f32; n]);
    testing::fill_noise(&gpu, &b.g, 3);
    let g: Vec<f32> = (0..n)
        .map(|i| if i % 2 == 0 { 2.0 } else { -2.0 })
        .collect();
    gpu.upload(b.g.all(), &g).unwrap();
    let mut rec = Recorder::new(&gpu).unwrap();
    let groups = [AdamGroup {
        first: 0,
        count: n as u32,
        lr: 0.5,
        mask: None,
    }];
    adam.record(&mut rec, b.ab(), &groups, &AdamHyper::default(), 1);
    rec.finish().unwrap();
    let gp: Vec<f32> = gpu.read(b.p.elems::<f32>(0, n as u64)).unwrap();
    assert!(gp
        .iter()
        .enumerate()
        .all(|(i, x)| (x + if i % 2 == 0 { 0.5 } else { -0.5 }).abs() < 1e-6));
}

#[test]
fn guarded_step_is_a_no_op_when_any_overflow_flag_is_set() {
    let gpu = testing::gpu();
    let adam = Adam::new(&gpu).unwrap();
    let p0 = vec![1.0f32; 300];
    let groups = [AdamGroup {
        first: 0,
        count: 300,
        lr: 0.1,
        mask: None,
    }];
    let h = AdamHyper::default();
    // (flag, needed) pairs as the rasteriser writes them: a count alone never skips.
    for (pairs, skipped) in [
        (vec![0u32, 7, 0, 9], false),
        (vec![0, 7, 1, 9], true),
        (vec![1, 7, 0, 9], true),
        (vec![0, 5], false),
        (vec![3, 5], true),
    ] {
        let b = Bufs::new(&gpu, &p0);
        gpu.upload(b.g.all(), &vec![0.5f32; 300]).unwrap();
        let skip = gpu.buffer_from("skip pairs", &pairs).unwrap();
        let mut rec = Recorder::new(&gpu).unwrap();
        let pairs_slice = skip.slice(0, 4 * pairs.len() as u64);
        adam.record_guarded(&mut rec, b.ab(), &groups, &h, 1, pairs_slice);
        rec.finish().unwrap();
        let [p, m, v] = b.read(&gpu, 300);
        if skipped {
            assert!(
                p == p0 && m.iter().chain(&v).all(|&x| x == 0.0),
                "{pairs:?}: updated"
            );
        } else {
            assert!(
                p.iter().all(|&x| (x - 0.9).abs() < 1e-5),
                "{pairs:?}: not updated: {}",
                p[0]
            );
        }
    }
}

dispflow_vk::subgroup_reruns!();

/// The texel stage on slices that start inside their buffers (the views' offsets) gives the
/// buffer shape's floats bit for bit, and runs itself, not its storage-buffer twin (which a
/// dispatch takes only for bindings that cannot be texel views: recorder.rs's unit test).
#[test]
fn texel_views_at_an_offset_match_the_buffer_shape() {
    let gpu = testing::gpu();
    let n = 1001usize;
    let mut noise = Noise::new(5);
    let p0: Vec<f32> = (0..n + 4).map(|_| noise.uniform(-1.0, 1.0)).collect();
    let g: Vec<f32> = (0..n + 4).map(|_| noise.uniform(-1.0, 1.0)).collect();
    let groups = [AdamGroup {
        first: 0,
        count: n as u32,
        lr: 0.01,
        mask: None,
    }];
    let mut results = Vec::new();
    for access in [Access::Buffer, Access::Texel] {
        let adam = Adam::with_access(&gpu, access).unwrap();
        let b = Bufs::new(&gpu, &p0);
        gpu.upload(b.g.all(), &g).unwrap();
        let (offset, bytes) = (16u64, n as u64 * 4);
        let ab = AdamBuffers {
            params: b.p.slice(offset, bytes),
            grads: b.g.slice(offset, bytes),
            m: b.m.slice(offset, bytes),
            v: b.v.slice(offset, bytes),
        };
        let mut rec = Recorder::new(&gpu).unwrap();
        adam.record(&mut rec, ab, &groups, &AdamHyper::default(), 1);
        assert_eq!(rec.twin_dispatch_count(), 0, "{access:?}");
        rec.finish().unwrap();
        let p: Vec<f32> = gpu.read(b.p.all()).unwrap();
        assert_eq!(
            p[..4],
            p0[..4],
            "{access:?}: a float before the slice moved"
        );
        assert_eq!(
            p[4 + n..],
            p0[4 + n..],
            "{access:?}: a float after the slice moved"
        );
        assert!(
            p[4..4 + n].iter().zip(&p0[4..]).all(|(a, b)| a != b),
            "{access:?}: a float of the slice did not move"
        );
        results.push(p);
    }
    assert_eq!(results[0], results[1], "texel and buffer shapes differ");
}
