//! Trainer-side motion-term stages vs their twin: displacement δ and its backward into both
//! MLP passes, the L1 motion loss (including the degenerate-map skip).

use dispflow_vk::kernels::dispflow::DispFlow;
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
    for (px, flags) in [
        (1usize, [0u32, 0]),
        (1000, [0, 0]),
        (70_001, [0, 0]),
        (500, [1, 0]),
        (500, [0, 1]),
    ] {
        let mut r = Noise::new(px as u64);
        let a: Vec<f32> = rand(&mut r, px).iter().map(|v| v + 0.5).collect();
        let s: Vec<f32> = rand(&mut r, px).iter().map(|v| v + 0.5).collect();
        let (ab, sb, fb) = (
            gpu.buffer_from("disp", &a).unwrap(),
            gpu.buffer_from("scene", &s).unwrap(),
            gpu.buffer_from("flags", &flags).unwrap(),
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
        );
        rec.finish().unwrap();
        let skip = flags != [0, 0];
        let (want_v, want_g) = twin::motion_l1(&a, &s, 0.1, skip);
        let got_v: f64 = gpu
            .read::<f32>(sums.elems::<f32>(0, groups as u64))
            .unwrap()
            .iter()
            .map(|&x| x as f64)
            .sum::<f64>()
            / px as f64;
        assert!(
            (got_v - want_v).abs() <= 1e-6 * (1.0 + want_v),
            "{px} px: loss gpu {got_v} twin {want_v}"
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

dispflow_vk::subgroup_reruns!();
