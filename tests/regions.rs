//! The region PSNRs (inside / outside the dilated motion mask) against a direct computation
//! on hand-made images, mask dilation, empty masks reported as absent (not NaN) in the
//! evaluation of a scene whose objects never move, and the displacement-EPE probe against its
//! CPU twin (the reference rasteriser blending the same projected motion).

mod train_common;

use dispflow_vk::data::synthetic::{self, Preset, SceneMotion};
use dispflow_vk::data::{self, LoadOptions};
use dispflow_vk::reference::raster as twin;
use dispflow_vk::testing;
use dispflow_vk::train::score::epe;
use dispflow_vk::train::score::regions::{dilate, region_psnr};
use dispflow_vk::train::Trainer;
use train_common::{tiny_config, tiny_dataset};

#[test]
fn dilation_is_a_disc_clipped_at_the_border() {
    // 7×5, one pixel set at (1, 2).
    let (w, h) = (7u32, 5u32);
    let mut m = vec![0u8; 35];
    m[2 * 7 + 1] = 1;
    let d = dilate(&m, w, h, 2);
    let want = |x: i32, y: i32| (x - 1) * (x - 1) + (y - 2) * (y - 2) <= 4;
    for y in 0..5 {
        for x in 0..7 {
            assert_eq!(d[(y * 7 + x) as usize], want(x, y), "({x}, {y})");
        }
    }
    assert_eq!(
        d.iter().filter(|&&v| v).count(),
        12,
        "13-pixel disc less (−1, 2)"
    );
    assert_eq!(
        dilate(&m, w, h, 0),
        m.iter().map(|&v| v != 0).collect::<Vec<_>>()
    );
}

#[test]
fn region_psnr_matches_a_direct_computation() {
    let (w, h) = (6u32, 4u32);
    let n = (w * h) as usize;
    let gt: Vec<[f32; 4]> = (0..n)
        .map(|i| [0.1 * (i % 5) as f32, 0.5, 0.25, 1.0])
        .collect();
    // Error 0.2 on the red channel in the left two columns, 0.05 on green elsewhere; alpha
    // differs everywhere and must not count.
    let render: Vec<[f32; 4]> = gt
        .iter()
        .enumerate()
        .map(|(i, g)| {
            let left = (i as u32 % w) < 2;
            [
                g[0] + if left { 0.2 } else { 0.0 },
                g[1] + if left { 0.0 } else { 0.05 },
                g[2],
                0.3,
            ]
        })
        .collect();
    // The mask covers column 0; dilated by 1 it covers columns 0 and 1 (the error region).
    let mask: Vec<u8> = (0..n).map(|i| (i as u32 % w == 0) as u8).collect();
    let r = region_psnr(&render, &gt, &mask, w, h, 1);
    let psnr = |per_channel_mse: f64| -10.0 * per_channel_mse.log10();
    let dynamic = psnr(0.2f64.powi(2) / 3.0);
    let fixed = psnr(0.05f64.powi(2) / 3.0);
    assert!(
        (r.dynamic.unwrap() - dynamic).abs() < 1e-4,
        "{r:?} vs {dynamic}"
    );
    assert!(
        (r.static_.unwrap() - fixed).abs() < 1e-4,
        "{r:?} vs {fixed}"
    );
    // Columns 0 and 1 of 6: a third of the image.
    assert!(
        (r.dynamic_share.unwrap() - 1.0 / 3.0).abs() < 1e-12,
        "{r:?}"
    );
    // Undilated: column 1's red error moves to the static side.
    let r0 = region_psnr(&render, &gt, &mask, w, h, 0);
    assert!(
        (r0.dynamic_share.unwrap() - 1.0 / 6.0).abs() < 1e-12,
        "{r0:?}"
    );
    let mixed = (4.0 * 0.04 + 16.0 * 0.0025) / (20.0 * 3.0);
    assert!((r0.static_.unwrap() - psnr(mixed)).abs() < 1e-4, "{r0:?}");
    // Empty and full masks: one side absent, never NaN.
    let empty = region_psnr(&render, &gt, &vec![0; n], w, h, 3);
    assert_eq!(empty.dynamic, None);
    assert_eq!(empty.dynamic_share, Some(0.0));
    assert!(empty.static_.unwrap().is_finite());
    let full = region_psnr(&render, &gt, &vec![1; n], w, h, 3);
    assert_eq!(full.static_, None);
    assert_eq!(full.dynamic_share, Some(1.0));
    // A perfect region reads +∞ (left out of means like a perfect frame's PSNR).
    let perfect = region_psnr(&gt, &gt, &mask, w, h, 1);
    assert_eq!(perfect.dynamic, Some(f64::INFINITY));
}

#[test]
fn evaluation_reports_regions_where_masks_exist_and_nothing_where_they_are_empty() {
    let tmp = tempfile::tempdir().unwrap();
    let gpu = testing::gpu();
    let cfg = tiny_config(20);
    let opts = LoadOptions {
        progress: false,
        ..LoadOptions::default()
    };
    for (motion, moving) in [(SceneMotion::Moving, true), (SceneMotion::Static, false)] {
        let dir = tmp.path().join(format!("{motion:?}"));
        synthetic::generate_with(Preset::Tiny, 3, motion, &dir).unwrap();
        let ds = data::load(&dir, &opts).unwrap();
        let mut tr = Trainer::new(&gpu, &cfg, &ds).unwrap();
        let per = tr.evaluate(true).unwrap();
        for e in &per {
            let im = e.images.as_ref().unwrap();
            let mask = im.mask.as_ref().unwrap();
            assert_eq!(e.has_mask, mask.iter().any(|&v| v != 0));
            let want = region_psnr(&im.render, &im.gt, mask, im.width, im.height, 3);
            if e.has_mask {
                assert_eq!(
                    (e.dynamic_psnr, e.static_psnr),
                    (want.dynamic, want.static_)
                );
                assert!(e.dynamic_psnr.unwrap().is_finite());
                let share = e.dynamic_share.unwrap();
                assert!(share > 0.0 && share < 1.0 && share == want.dynamic_share.unwrap());
            } else {
                assert_eq!((e.dynamic_psnr, e.static_psnr), (None, None), "{}", e.id);
                assert_eq!(e.dynamic_share, None, "{}", e.id);
            }
        }
        let ctx = dispflow_vk::train::metrics::ReportContext {
            run: "r".into(),
            scene: "s".into(),
            dataset: "d".into(),
            device: "lavapipe".into(),
            iterations: 0,
            num_gaussians: tr.n(),
        };
        let r = dispflow_vk::train::metrics::Report::new(&cfg, ctx, per);
        let json = r.to_json();
        assert_eq!(r.dynamic_psnr.is_some(), moving, "{motion:?}");
        assert_eq!(
            json.contains("\"dynamic_psnr\""),
            moving,
            "absent, not NaN or null"
        );
        assert!(!json.contains("NaN"));
    }
}

/// The probe on the GPU against the reference rasteriser blending the same per-Gaussian
/// projected motion, with a random deformation head so the Gaussians move by pixels.
#[test]
fn displacement_epe_probe_matches_its_twin() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::gpu();
    let mut cfg = tiny_config(20);
    cfg.warm_up = 0;
    cfg.zero_deform_head = false;
    // The twin blends the MLP's per-Gaussian output (nodes are only placed by a step).
    cfg.deform_field.kind = dispflow_vk::model::nodes::FieldKind::Mlp;
    let mut tr = Trainer::new(&gpu, &cfg, &ds).unwrap();
    assert!(tr.view().deform_active);
    let mut checked = 0;
    for i in 0..tr.val.len() {
        let Some(gpu_probe) = tr.motion_probe(i).unwrap() else {
            continue;
        };
        let f = &tr.val[i];
        let (cam, t, (t_next, gt), mask) = (
            f.camera,
            f.time,
            f.next_flow.clone().unwrap(),
            f.mask.as_ref().unwrap().1.clone(),
        );
        let a = tr.deformed_gaussians(t).unwrap();
        let b = tr.deformed_gaussians(t_next).unwrap();
        let motion = epe::projected_motion(&cam, &a.means, &b.means);
        let scales: Vec<[f32; 3]> = a.log_scales.iter().map(|s| s.map(f32::exp)).collect();
        let k = a.sh_coeffs as usize;
        let sh: Vec<f32> = (0..a.means.len())
            .flat_map(|j| {
                let mut c = a.sh_dc[j].to_vec();
                c.extend_from_slice(&a.sh_rest[j * (k - 1) * 3..(j + 1) * (k - 1) * 3]);
                c
            })
            .collect();
        let g = twin::Gaussians {
            means: &a.means,
            scales: &scales,
            quats: &a.quats,
            opacity_logits: &a.opacity,
            sh: &sh,
            sh_coeffs: a.sh_coeffs,
            sh_degree: tr.view().sh_degree,
        };
        let proj = twin::project(&cam, &g);
        let mut p = twin::BlendParams::new(cam.width, cam.height);
        p.feature_dims = 3;
        let flat: Vec<f32> = motion.iter().flatten().copied().collect();
        let out = twin::blend_fwd(&p, &proj, &flat);
        let want = epe::masked_epe(&out.features, &gt, &mask).unwrap();
        let got = gpu_probe.epe.unwrap();
        assert!(
            (got - want).abs() <= 1e-3 * want.max(1.0),
            "frame {i}: EPE gpu {got}, twin {want}"
        );
        assert_eq!(gpu_probe.gt_len, epe::masked_len(&gt, &mask));
        assert_eq!(gpu_probe.p99, epe::motion_quantile(&motion, 0.99));
        let moved = gpu_probe.p50.unwrap();
        assert!(
            moved > 0.05,
            "the random head moves Gaussians: median {moved} px"
        );
        // A motionless model's EPE is the ground truth's length: this one differs from it.
        assert!((got - gpu_probe.gt_len.unwrap()).abs() > 1e-3);
        checked += 1;
    }
    assert!(
        checked > 0,
        "the tiny scene's test frames have flow and masks"
    );
}

#[test]
fn projection_and_quantiles() {
    let cam = dispflow_vk::kernels::raster::Camera {
        rot: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        trans: [0.0, 0.0, 0.0],
        fx: 100.0,
        fy: 50.0,
        cx: 10.0,
        cy: 20.0,
        width: 32,
        height: 32,
        near: 0.1,
    };
    let p = epe::project(&cam, [0.5, -0.2, 2.0]).unwrap();
    assert!(
        (p[0] - 35.0).abs() < 1e-5 && (p[1] - 15.0).abs() < 1e-5,
        "{p:?}"
    );
    assert_eq!(
        epe::project(&cam, [0.0, 0.0, 0.05]),
        None,
        "inside the near plane"
    );
    let m = epe::projected_motion(
        &cam,
        &[[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]],
        &[[0.03, 0.04, 1.0], [0.0, 0.0, -1.0]],
    );
    assert_eq!(m[0], [3.0, 2.0, 0.0]);
    assert_eq!(m[1], [0.0; 3], "an end behind the camera moves nothing");
    let q = epe::motion_quantile(&m, 1.0).unwrap();
    assert!((q - 13f64.sqrt()).abs() < 1e-6);
    assert_eq!(epe::motion_quantile(&[], 0.5), None);
    // EPE over the mask only.
    let blended = [1.0, 0.0, 9.0, 5.0, 5.0, 9.0];
    let gt = [1.0, 3.0, 0.0, 0.0];
    assert_eq!(epe::masked_epe(&blended, &gt, &[1, 0]), Some(3.0));
    assert_eq!(epe::masked_epe(&blended, &gt, &[0, 0]), None);
    assert_eq!(epe::masked_len(&[3.0, 4.0, 0.0, 0.0], &[1, 1]), Some(2.5));
}
