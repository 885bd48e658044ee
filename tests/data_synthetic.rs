//! The synthetic scene generator: determinism, the nerfies round trip, exact masks and flow.

mod data_util;

use std::path::Path;

use dispflow_vk::data::synthetic::{self, GenCamera, Preset, Scene};
use dispflow_vk::data::{self, check, PointSource};
use glam::DVec3;

fn files(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push(p.strip_prefix(dir).unwrap().to_path_buf());
            }
        }
    }
    out.sort();
    out
}

#[test]
fn generator_is_deterministic_by_seed() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b, c) = (
        tmp.path().join("a"),
        tmp.path().join("b"),
        tmp.path().join("c"),
    );
    synthetic::generate(Preset::Tiny, 7, &a).unwrap();
    synthetic::generate(Preset::Tiny, 7, &b).unwrap();
    synthetic::generate(Preset::Tiny, 8, &c).unwrap();
    let fa = files(&a);
    assert_eq!(fa, files(&b));
    assert!(fa.len() > 4 * 24, "{} files", fa.len());
    for f in &fa {
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap(),
            "{f:?}"
        );
    }
    let img = Path::new("rgb/1x/000003.png");
    assert_ne!(
        std::fs::read(a.join(img)).unwrap(),
        std::fs::read(c.join(img)).unwrap()
    );
}

#[test]
fn tiny_scene_round_trips_through_the_nerfies_loader() {
    let tmp = tempfile::tempdir().unwrap();
    let s = synthetic::generate(Preset::Tiny, 1, tmp.path()).unwrap();
    assert_eq!((s.width, s.height, s.frames), (64, 64, 24));
    let ds = data::load(tmp.path(), &data_util::opts()).unwrap();
    assert_eq!((ds.train.len(), ds.val.len()), (21, 3));
    assert!(ds.warnings.is_empty(), "{:?}", ds.warnings);
    let times: Vec<f32> = {
        let mut t: Vec<f32> = ds.frames().map(|f| f.time).collect();
        t.sort_by(f32::total_cmp);
        t
    };
    assert_eq!((times[0], times[23]), (0.0, 1.0));
    for f in ds.frames() {
        let k: usize = f.id.parse().unwrap();
        assert!((f.time - k as f32 / 23.0).abs() < 1e-6);
        // The loaded (normalised) camera projects like the generator camera (raw units).
        let g = GenCamera::for_frame(k, 24, 64, 64);
        assert!(
            (f.camera.cx as f64 - g.cx).abs() < 1e-4 && (f.camera.fx as f64 - g.f).abs() < 1e-3
        );
        assert!(
            (f.camera.cx - 32.0).abs() > 1.0,
            "principal point should be off-centre"
        );
        for p in [DVec3::new(0.3, -0.2, 0.1), DVec3::new(-1.0, 0.5, -2.0)] {
            let want = g.project(p).unwrap();
            let pn =
                ((p - DVec3::from(synthetic::SCENE_CENTER)) * synthetic::SCENE_SCALE).as_vec3();
            let (got, _) = f.camera.project(pn).unwrap();
            assert!(
                (got.as_dvec2() - want).length() < 1e-3,
                "{got:?} vs {want:?}"
            );
        }
        assert_eq!(f.image.data.len(), 64 * 64 * 3);
    }
    // Points: from points.npy, normalised, in front of the first camera.
    assert!(matches!(ds.points.source, PointSource::Npy(_)));
    assert_eq!(ds.points.positions.len(), 3000);
    let raw = synthetic::sample_points(1, 3000);
    let want = ((raw[5] - DVec3::from(synthetic::SCENE_CENTER)) * synthetic::SCENE_SCALE).as_vec3();
    assert!((ds.points.positions[5] - want).length() < 1e-5);
    let cam = &ds.train[0].camera;
    let front = ds
        .points
        .positions
        .iter()
        .filter(|p| cam.to_camera(**p).z > 0.0)
        .count();
    // Side walls extend behind the camera, so not all of them; most are in front.
    assert!(front > 2400, "{front}");
    // The report.
    let rep = check::report(tmp.path(), &data_util::opts()).unwrap();
    assert!(rep.contains("train 21, val 3"), "{rep}");
    assert!(rep.contains("masks:       24 of 24"), "{rep}");
    assert!(rep.contains("scene flow:  24 of 24"), "{rep}");
}

#[test]
fn masks_and_flow_are_exact_and_consistent() {
    let tmp = tempfile::tempdir().unwrap();
    synthetic::generate(Preset::Tiny, 2, tmp.path()).unwrap();
    let ds = data::load(tmp.path(), &data_util::opts()).unwrap();
    for f in ds.frames() {
        let m = f.mask.as_ref().unwrap();
        let flow = f.flow.as_ref().unwrap();
        let moving = m.iter().filter(|&&v| v == 1).count();
        assert!(
            moving > 64 && moving < 64 * 64 / 2,
            "{} moving pixels {moving}",
            f.id
        );
        let mut nonzero = 0;
        for (i, &mv) in m.iter().enumerate() {
            let v = [flow[2 * i], flow[2 * i + 1]];
            if mv == 0 {
                assert_eq!(v, [0.0, 0.0], "static pixel {i} of {} has flow", f.id);
            } else if v[0].abs() + v[1].abs() > 1e-4 {
                nonzero += 1;
            }
        }
        assert!(nonzero as f32 > 0.95 * moving as f32);
    }
}

/// The flow moves the texture: the colour at `x` at `t_k` matches the colour at `x + flow` at
/// `t_{k+1}` seen from the same camera, much better than with zero flow.
#[test]
fn flow_warps_frame_onto_the_next_time() {
    let scene = Scene::new(4);
    let (w, h) = (160u32, 120u32);
    let cam = GenCamera::for_frame(20, 60, w, h);
    let (t0, t1) = (20.0 / 59.0, 21.0 / 59.0);
    let a = synthetic::render_view(&scene, &cam, t0, t1);
    let b = synthetic::render_view(&scene, &cam, t1, t1 + 1.0 / 59.0);
    let sample = |img: &[f32], x: f32, y: f32| -> Option<[f32; 3]> {
        let (fx, fy) = (x - 0.5, y - 0.5);
        if fx < 0.0 || fy < 0.0 || fx >= (w - 1) as f32 || fy >= (h - 1) as f32 {
            return None;
        }
        let (x0, y0) = (fx as usize, fy as usize);
        let (ax, ay) = (fx - x0 as f32, fy - y0 as f32);
        let at = |x: usize, y: usize, c: usize| img[(y * w as usize + x) * 3 + c];
        Some(std::array::from_fn(|c| {
            (at(x0, y0, c) * (1.0 - ax) + at(x0 + 1, y0, c) * ax) * (1.0 - ay)
                + (at(x0, y0 + 1, c) * (1.0 - ax) + at(x0 + 1, y0 + 1, c) * ax) * ay
        }))
    };
    let (mut err_flow, mut err_zero) = (Vec::new(), Vec::new());
    let mut max_flow = 0.0f32;
    for j in 0..h as usize {
        for i in 0..w as usize {
            let o = j * w as usize + i;
            if a.mask[o] == 0 {
                continue;
            }
            let (u, v) = (a.flow[2 * o], a.flow[2 * o + 1]);
            max_flow = max_flow.max(u.hypot(v));
            let (x, y) = (i as f32 + 0.5, j as f32 + 0.5);
            let src = &a.rgb[o * 3..o * 3 + 3];
            if let (Some(p), Some(q)) = (sample(&b.rgb, x + u, y + v), sample(&b.rgb, x, y)) {
                let d = |c: [f32; 3]| (0..3).map(|k| (c[k] - src[k]).abs()).sum::<f32>();
                err_flow.push(d(p));
                err_zero.push(d(q));
            }
        }
    }
    let mean = |v: &[f32]| v.iter().sum::<f32>() / v.len() as f32;
    assert!(
        max_flow > 0.5,
        "max flow {max_flow} px: the objects should move"
    );
    assert!(err_flow.len() > 500);
    let (ef, ez) = (mean(&err_flow), mean(&err_zero));
    assert!(ef < 0.5 * ez, "warp error with flow {ef}, without {ez}");
}

#[test]
fn rigid_motion_is_rigid_and_blob_deforms() {
    // Distances between points of the rigid sphere are preserved; the blob's are not.
    let p = [DVec3::new(0.0, 0.5, 0.0), DVec3::new(0.5, 0.0, 0.0)];
    let hits: Vec<_> = p
        .iter()
        .map(|d| synthetic::Hit::Rigid {
            p: Scene::rigid_centre(0.2) + Scene::rigid_rotation(0.2) * *d,
        })
        .collect();
    let moved: Vec<DVec3> = hits.iter().map(|h| Scene::advect(h, 0.2, 0.6)).collect();
    let before = match (hits[0], hits[1]) {
        (synthetic::Hit::Rigid { p: a }, synthetic::Hit::Rigid { p: b }) => (a - b).length(),
        _ => unreachable!(),
    };
    assert!(((moved[0] - moved[1]).length() - before).abs() < 1e-9);
    assert!((moved[0] - p[0]).length() > 0.1);
    let u = DVec3::new(0.0, 1.0, 0.0);
    assert!((Scene::blob_radius(u, 0.0) - Scene::blob_radius(u, 0.1)).abs() > 1e-3);
}
