//! Photometric loss: CPU twin vs central finite differences (f64), GPU vs twin on identical
//! images (values and gradient), and the extremes (identical, flat, 1×1 images); the GPU
//! checks run both blur shapes (one pixel per invocation, the CPU devices' runs of 16).

use dispflow_vk::kernels::loss::{Access, BlurShape, PhotometricLoss};
use dispflow_vk::reference::loss::{photometric_loss, photometric_loss_f64};
use dispflow_vk::testing::{self, Noise};
use dispflow_vk::vk::Recorder;

fn image(seed: u64, n: usize) -> Vec<[f32; 4]> {
    let mut r = Noise::new(seed);
    (0..n)
        .map(|_| [0, 1, 2, 3].map(|_| (r.next_u32() >> 8) as f32 / 16_777_216.0))
        .collect()
}

#[test]
fn twin_gradient_matches_finite_differences() {
    let (w, h) = (9, 7);
    let x: Vec<[f64; 4]> = image(1, w * h).iter().map(|p| p.map(f64::from)).collect();
    // Keep |x − y| away from 0 so the L1 kink is not straddled.
    let y: Vec<[f64; 4]> = x
        .iter()
        .enumerate()
        .map(|(i, p)| p.map(|v| v + if i % 2 == 0 { 0.05 } else { -0.07 }))
        .collect();
    let (_, grad) = photometric_loss_f64(&x, &y, w, h, 0.2);
    let eps = 1e-6;
    let mut worst = 0.0f64;
    for q in 0..w * h {
        for c in 0..3 {
            let mut xp = x.clone();
            xp[q][c] += eps;
            let mut xm = x.clone();
            xm[q][c] -= eps;
            let fd = (photometric_loss_f64(&xp, &y, w, h, 0.2).0.loss
                - photometric_loss_f64(&xm, &y, w, h, 0.2).0.loss)
                / (2.0 * eps);
            let err = (fd - grad[q][c]).abs();
            worst = worst.max(err / (grad[q][c].abs() + 1e-6));
            assert!(
                err <= 1e-7 + 1e-5 * grad[q][c].abs(),
                "pixel {q} channel {c}: analytic {}, fd {fd}",
                grad[q][c]
            );
        }
        assert_eq!(grad[q][3], 0.0, "alpha gets no gradient");
    }
    eprintln!("worst relative FD error {worst:.2e}");
}

/// Every blur shape, each with the other stages through storage and through texel buffers.
const SHAPES: [(BlurShape, Access); 4] = [
    (BlurShape::Pixel, Access::Buffer),
    (BlurShape::Pixel, Access::Texel),
    (BlurShape::Rows, Access::Buffer),
    (BlurShape::Rows, Access::Texel),
];

fn gpu_loss(
    w: u32,
    h: u32,
    x: &[[f32; 4]],
    y: &[[f32; 4]],
    (blur, access): (BlurShape, Access),
) -> (dispflow_vk::kernels::loss::LossValues, Vec<[f32; 4]>) {
    let gpu = testing::gpu();
    let loss = PhotometricLoss::with_shapes(&gpu, blur, access).unwrap();
    let mut b = loss.buffers(&gpu, w, h).unwrap();
    let xb = gpu.buffer_from("render", x).unwrap();
    let yb = gpu.buffer_from("target", y).unwrap();
    let d = gpu.buffer("d render", (w * h) as u64 * 16).unwrap();
    testing::fill_noise(&gpu, &d, 1);
    let mut rec = Recorder::new(&gpu).unwrap();
    loss.record(&mut rec, &mut b, xb.all(), yb.all(), d.all(), 0.2);
    rec.finish().unwrap();
    (b.values(&gpu).unwrap(), gpu.read(d.all()).unwrap())
}

#[test]
fn gpu_matches_twin() {
    // Widths and heights below, at and across the rows blur's 16-pixel runs.
    let sizes = [
        (1u64, 1u32, 1u32),
        (2, 17, 13),
        (3, 64, 48),
        (4, 5, 40),
        (5, 33, 16),
    ];
    for ((seed, w, h), blur) in sizes.into_iter().flat_map(|s| SHAPES.map(|b| (s, b))) {
        let n = (w * h) as usize;
        let x = image(seed, n);
        let y = image(seed + 50, n);
        let (gv, gg) = gpu_loss(w, h, &x, &y, blur);
        let (tv, tg) = photometric_loss(&x, &y, w as usize, h as usize, 0.2);
        let ctx = format!("{w}x{h} {blur:?}");
        for (name, a, b) in [
            ("l1", gv.l1, tv.l1),
            ("mse", gv.mse, tv.mse),
            ("ssim", gv.ssim, tv.ssim),
            ("loss", gv.loss, tv.loss),
        ] {
            assert!(
                (a - b).abs() <= 1e-5 * b.abs().max(1e-3),
                "{ctx}: {name} gpu {a}, twin {b}"
            );
        }
        // f32 sums of 11-tap blurs vs f64 2D windows: compare against the gradient's scale.
        let scale = tg
            .iter()
            .flat_map(|p| p[..3].iter())
            .fold(0.0f64, |m, v| m.max(v.abs()));
        for (i, (g, t)) in gg.iter().zip(&tg).enumerate() {
            for c in 0..4 {
                assert!(
                    (g[c] as f64 - t[c]).abs() <= 1e-4 * scale,
                    "{ctx}: d[{i}][{c}] gpu {}, twin {}",
                    g[c],
                    t[c]
                );
            }
        }
    }
}

#[test]
fn identical_and_flat_images_are_finite() {
    for blur in SHAPES {
        identical_and_flat(blur);
    }
}

fn identical_and_flat(blur: (BlurShape, Access)) {
    let (w, h) = (23, 19);
    let x = image(9, w * h);
    let (v, g) = gpu_loss(w as u32, h as u32, &x, &x, blur);
    assert!(
        (v.ssim - 1.0).abs() < 1e-5 && v.l1 == 0.0 && v.mse == 0.0,
        "{v:?}"
    );
    assert!(v.psnr.is_infinite() && v.psnr > 0.0);
    assert!(
        g.iter().flatten().all(|d| d.is_finite() && d.abs() < 1e-6),
        "identical images: ~zero gradient"
    );
    // Flat images (zero variance everywhere): SSIM stays finite thanks to C1, C2.
    let flat = vec![[0.5f32; 4]; w * h];
    let black = vec![[0.0f32; 4]; w * h];
    let (v, g) = gpu_loss(w as u32, h as u32, &flat, &black, blur);
    assert!(
        v.ssim.is_finite() && v.loss.is_finite() && g.iter().flatten().all(|d| d.is_finite()),
        "{v:?}"
    );
    let (tv, _) = photometric_loss(&flat, &black, w, h, 0.2);
    assert!(
        (v.ssim - tv.ssim).abs() < 1e-5,
        "flat: gpu {} twin {}",
        v.ssim,
        tv.ssim
    );
}

dispflow_vk::subgroup_reruns!();
