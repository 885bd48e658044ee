//! Indirect scene motion (MotionGS): the pair flow minus the camera flow of the rendered
//! depth. The kernel against its twin with the extremes (no surface, zero/negative/∞/NaN
//! depth, points behind the second camera, NaN flow), an analytic case (a plane at known
//! depth, a known camera translation: the camera flow is exactly the flow), and the whole
//! chain on a static scene under a known camera motion: rendered with the rasteriser at both
//! views, flow between the two renders by the GPU TV-L1 estimator, minus the camera flow of
//! the first render's depth: what remains (the scene motion) is near zero.

use dispflow_vk::kernels::dispflow::{CameraFlowParams, DispFlow};
use dispflow_vk::kernels::flow::{FlowConfig, FlowEstimator, TvL1Flow};
use dispflow_vk::kernels::raster::{Camera, Rasterizer, RenderOpts};
use dispflow_vk::reference::dispflow as twin;
use dispflow_vk::testing::{self, Noise, TestGpu};
use dispflow_vk::vk::{Buffer, Recorder};
use raster_common::{camera, Scene, Uploaded};

mod raster_common;

/// The GPU's camera_flow of the inputs.
fn gpu_camera_flow(
    gpu: &TestGpu,
    p: &CameraFlowParams,
    flow: &[[f32; 2]],
    rgba: &[[f32; 4]],
    depth: &[f32],
) -> Vec<[f32; 2]> {
    let k = DispFlow::new(gpu).unwrap();
    let (f, c, d) = (
        gpu.buffer_from("flow", flow).unwrap(),
        gpu.buffer_from("rgba", rgba).unwrap(),
        gpu.buffer_from("depth", depth).unwrap(),
    );
    let out = gpu.buffer("scene", 8 * flow.len() as u64).unwrap();
    testing::fill_noise(gpu, &out, 4);
    let mut rec = Recorder::new(gpu).unwrap();
    k.camera_flow(&mut rec, p, f.all(), c.all(), d.all(), out.all());
    rec.finish().unwrap();
    gpu.read(out.all()).unwrap()
}

fn moved(cam: Camera, trans: [f32; 3], yaw: f32) -> Camera {
    let (c, s) = (yaw.cos(), yaw.sin());
    Camera {
        rot: [[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]],
        trans,
        ..cam
    }
}

#[test]
fn camera_flow_matches_twin_with_extremes() {
    let gpu = testing::gpu();
    let (w, h) = (61u32, 37u32);
    let px = (w * h) as usize;
    let a = camera(w, h);
    // v2 three units back along z: points nearer than z = 3 fall behind it.
    let b = moved(a, [0.2, -0.1, -3.0], 0.05);
    let mut r = Noise::new(3);
    let mut flow: Vec<[f32; 2]> = (0..px)
        .map(|_| {
            [
                40.0 * r.uniform(0.0f32, 1.0) - 20.0,
                40.0 * r.uniform(0.0f32, 1.0) - 20.0,
            ]
        })
        .collect();
    let mut rgba: Vec<[f32; 4]> = (0..px)
        .map(|_| [0.5, 0.5, 0.5, r.uniform(0.0f32, 1.0)])
        .collect();
    let mut depth: Vec<f32> = (0..px)
        .map(|p| (0.5 + 9.5 * r.uniform(0.0f32, 1.0)) * rgba[p][3])
        .collect();
    flow[1] = [f32::NAN, 0.0];
    flow[2] = [0.0, f32::INFINITY];
    rgba[3][3] = 0.0;
    depth[4] = 0.0;
    depth[5] = -1.0;
    depth[6] = f32::INFINITY;
    depth[7] = f32::NAN;
    rgba[8][3] = 1.0;
    depth[8] = 1e30;
    for subtract in [true, false] {
        let p = CameraFlowParams::new(&a, &b, 0.5, subtract);
        let got = gpu_camera_flow(&gpu, &p, &flow, &rgba, &depth);
        let want = twin::camera_flow(&a, &b, &flow, &rgba, &depth, 0.5, subtract);
        let mut kept = 0;
        for q in 0..px {
            for k in 0..2 {
                let (g, t) = (got[q][k] as f64, want[q][k]);
                assert!(g.is_finite(), "subtract {subtract}: pixel {q}: {g}");
                assert!(
                    (g - t).abs() <= 1e-3 * (1.0 + t.abs()),
                    "subtract {subtract}: pixel {q}[{k}]: gpu {g} twin {t}"
                );
            }
            kept += (want[q] != [0.0; 2]) as usize;
        }
        for (q, w) in want.iter().enumerate().take(8).skip(1) {
            if subtract || q < 3 {
                assert_eq!(*w, [0.0; 2], "extreme pixel {q} gives no scene motion");
            }
        }
        // Some points are behind v2, some have no surface, most remain.
        assert!(
            kept > px / 4 && kept < px,
            "subtract {subtract}: {kept} of {px} kept"
        );
    }
}

#[test]
fn a_known_translation_over_a_plane_cancels_exactly() {
    let gpu = testing::gpu();
    let (w, h) = (40u32, 30u32);
    let px = (w * h) as usize;
    let a = camera(w, h);
    // v2 = v1 moved right by 0.3: a point at depth 5 moves left by fx·0.3/5 pixels.
    let b = moved(a, [-0.3, 0.0, 0.0], 0.0);
    let z = 5.0f32;
    let shift = -a.fx * 0.3 / z;
    let flow = vec![[shift, 0.0]; px];
    let rgba = vec![[0.5, 0.5, 0.5, 0.8]; px];
    let depth = vec![z * 0.8; px];
    let p = CameraFlowParams::new(&a, &b, 0.5, true);
    let got = gpu_camera_flow(&gpu, &p, &flow, &rgba, &depth);
    for (q, v) in got.iter().enumerate() {
        assert!(
            v[0].abs() < 1e-4 && v[1].abs() < 1e-4,
            "pixel {q}: scene motion {v:?} (flow {shift} px)"
        );
    }
    // Without the subtraction the raw pair flow comes through.
    let p = CameraFlowParams::new(&a, &b, 0.5, false);
    let got = gpu_camera_flow(&gpu, &p, &flow, &rgba, &depth);
    assert!(got.iter().all(|v| *v == [shift, 0.0]));
}

/// A textured wall of opaque Gaussians 3.5–4.5 units in front of the camera.
fn wall(seed: u64) -> Scene {
    let mut r = Noise::new(seed);
    let mut s = Scene {
        sh_coeffs: 1,
        ..Default::default()
    };
    for _ in 0..4000 {
        let z = 3.5 + r.uniform(0.0f32, 1.0);
        let (x, y) = (
            1.6 * (r.uniform(0.0f32, 1.0) - 0.5) * z,
            1.3 * (r.uniform(0.0f32, 1.0) - 0.5) * z,
        );
        let sc = 0.04 + 0.08 * r.uniform(0.0f32, 1.0);
        let rgb = [
            r.uniform(0.0f32, 1.0),
            r.uniform(0.0f32, 1.0),
            r.uniform(0.0f32, 1.0),
        ];
        s.push([x, y, z], [sc, sc, sc], [1.0, 0.0, 0.0, 0.0], 3.0, rgb);
    }
    s
}

#[test]
fn static_scene_under_known_camera_motion_has_no_indirect_scene_motion() {
    let gpu = testing::gpu();
    let (w, h) = (96u32, 72u32);
    let px = (w * h) as usize;
    let a = camera(w, h);
    let b = moved(a, [0.08, 0.03, 0.0], 0.015);
    let rast = Rasterizer::new(&gpu).unwrap();
    let up = Uploaded::new(&gpu, &wall(7));
    let opts = RenderOpts {
        background: [0.0; 3],
        alpha_max: 0.99,
        abs_grad: false,
        detach_feature_weights: false,
    };
    let (ra, oa) = raster_common::render(&gpu, &rast, &a, &up, &opts);
    let (rb, _) = raster_common::render(&gpu, &rast, &b, &up, &opts);
    let est = TvL1Flow::new(&gpu, FlowConfig::preset("default").unwrap()).unwrap();
    let scratch = est.scratch(&gpu, w, h).unwrap();
    let flow: Buffer = gpu.buffer("pair flow", 8 * px as u64).unwrap();
    let scene = gpu.buffer("scene", 8 * px as u64).unwrap();
    let k = DispFlow::new(&gpu).unwrap();
    let mut rec = Recorder::new(&gpu).unwrap();
    est.record(
        &mut rec,
        &scratch,
        ra.out_rgba.all(),
        rb.out_rgba.all(),
        flow.all(),
    );
    let p = CameraFlowParams::new(&a, &b, 0.5, true);
    let (rgba, depth) = (ra.out_rgba.all(), ra.out_depth.all());
    k.camera_flow(&mut rec, &p, flow.all(), rgba, depth, scene.all());
    rec.finish().unwrap();
    let f: Vec<[f32; 2]> = gpu.read(flow.all()).unwrap();
    let s: Vec<[f32; 2]> = gpu.read(scene.all()).unwrap();
    // Interior pixels with a surface (the border has content entering or leaving the view).
    let (mut flow_sum, mut scene_sum, mut count) = (0.0f64, 0.0f64, 0usize);
    for y in 6..h - 6 {
        for x in 6..w - 6 {
            let q = (y * w + x) as usize;
            if oa.rgba[q][3] < 0.5 {
                continue;
            }
            flow_sum += (f[q][0] as f64).hypot(f[q][1] as f64);
            scene_sum += (s[q][0] as f64).hypot(s[q][1] as f64);
            count += 1;
        }
    }
    let (mf, ms) = (flow_sum / count as f64, scene_sum / count as f64);
    eprintln!(
        "{count} pixels: mean |pair flow| {mf:.3} px, mean |indirect scene motion| {ms:.3} px"
    );
    assert!(count > px / 2, "the wall covers the view: {count} of {px}");
    assert!(mf > 1.5, "the camera motion is visible: {mf} px");
    assert!(
        ms < 0.25 * mf,
        "the camera flow explains the pair flow: {ms} of {mf} px remain"
    );
}

dispflow_vk::subgroup_reruns!();
