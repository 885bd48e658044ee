//! The synthetic scene generator: determinism, the nerfies round trip, exact masks and flow,
//! and what `auto`'s lacking route reads on the `events` scene's own pictures.
//!
//! Over 600 lines on purpose: a list of independent claims about one generator, each a test
//! with its own scene; splitting it would only add test binaries (each one a link and a start).

mod data_util;

use std::path::Path;

use dispflow_vk::data::synthetic::{
    self, events, Ball, GenCamera, Hit, Preset, Scene, SceneMotion,
};
use dispflow_vk::data::{self, check, PointSource};
use glam::{DVec2, DVec3};

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

/// Sums of a rendered view: `(Σ rgb, Σ flow, Σ |flow|, moving pixels)`.
fn view_sums(r: &synthetic::Rendered) -> (f64, f64, f64, usize) {
    let sum = |v: &[f32]| v.iter().map(|&x| x as f64).sum::<f64>();
    let abs = r.flow.iter().map(|&x| x.abs() as f64).sum::<f64>();
    let moving = r.mask.iter().filter(|&&v| v == 1).count();
    (sum(&r.rgb), sum(&r.flow), abs, moving)
}

/// The default (moving) scene is the one generated before motion kinds existed: a view's sums and
/// pixels match values recorded from that generator, and `generate` writes the same files as
/// `generate_with(.., Moving, ..)`.
#[test]
fn moving_kind_is_unchanged() {
    let cam = GenCamera::for_frame(10, 24, 48, 40);
    let r = synthetic::render_view(&Scene::new(5), &cam, 0.4, 0.45);
    let (rgb, flow, abs, moving) = view_sums(&r);
    // Recorded with the generator at 37bb229 (before SceneMotion).
    assert_eq!(moving, 229);
    assert!((rgb - 2_003.011_66).abs() < 1e-4, "{rgb}");
    assert!((flow - 266.630_63).abs() < 1e-4, "{flow}");
    assert!((abs - 292.848_14).abs() < 1e-4, "{abs}");
    assert_eq!(r.mask[900], 1);
    assert!(
        (r.flow[1800] - 0.123_102_315).abs() < 1e-6
            && (r.flow[1801] - 0.007_803_893_6).abs() < 1e-6
    );
    assert!((r.rgb[2100] - 0.411_280_6).abs() < 1e-6 && (r.rgb[3600] - 0.086_151_51).abs() < 1e-6);
    let m = synthetic::render_view(&Scene::with_motion(5, SceneMotion::Moving), &cam, 0.4, 0.45);
    assert!(m.rgb == r.rgb && m.mask == r.mask && m.flow == r.flow);

    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    let s = synthetic::generate(Preset::Tiny, 5, &a).unwrap();
    assert_eq!(s.motion, SceneMotion::Moving);
    synthetic::generate_with(Preset::Tiny, 5, SceneMotion::Moving, &b).unwrap();
    let fa = files(&a);
    assert_eq!(fa, files(&b));
    for f in &fa {
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap(),
            "{f:?}"
        );
    }
}

fn motion_recorded(dir: &Path) -> String {
    let j: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("synthetic.json")).unwrap()).unwrap();
    j["motion"].as_str().unwrap().to_string()
}

/// Renders from one fixed camera at `t0` and `t1` (flow towards `t + 0.05`).
fn fixed_view_pair(scene: &Scene, t0: f64, t1: f64) -> (synthetic::Rendered, synthetic::Rendered) {
    let cam = GenCamera::for_frame(7, 24, 48, 40);
    (
        synthetic::render_view(scene, &cam, t0, t0 + 0.05),
        synthetic::render_view(scene, &cam, t1, t1 + 0.05),
    )
}

#[test]
fn static_kind_has_no_motion_but_a_moving_camera() {
    let tmp = tempfile::tempdir().unwrap();
    let (st, mv) = (tmp.path().join("static"), tmp.path().join("moving"));
    let s = synthetic::generate_with(Preset::Tiny, 6, SceneMotion::Static, &st).unwrap();
    assert_eq!(s.motion, SceneMotion::Static);
    assert_eq!(motion_recorded(&st), "static");
    synthetic::generate(Preset::Tiny, 6, &mv).unwrap();
    let ds = data::load(&st, &data_util::opts()).unwrap();
    assert_eq!(ds.frames().count(), 24);
    for f in ds.frames() {
        assert!(f.mask.as_ref().unwrap().iter().all(|&v| v == 0), "{}", f.id);
        assert!(
            f.flow.as_ref().unwrap().iter().all(|&v| v == 0.0),
            "{}",
            f.id
        );
    }
    // The camera arc is the moving scene's; the first frame (t = 0) is identical.
    for f in ["camera/000010.json", "rgb/1x/000000.png", "points.npy"] {
        assert_eq!(
            std::fs::read(st.join(f)).unwrap(),
            std::fs::read(mv.join(f)).unwrap(),
            "{f}"
        );
    }
    let read = |f: &str| std::fs::read(st.join(f)).unwrap();
    assert_ne!(read("rgb/1x/000000.png"), read("rgb/1x/000020.png"));
    // From a fixed camera, every time looks like t = 0.
    let scene = Scene::with_motion(6, SceneMotion::Static);
    let (a, b) = fixed_view_pair(&scene, 0.1, 0.8);
    assert!(a.rgb == b.rgb && a.mask.iter().chain(&b.mask).all(|&v| v == 0));
    assert!(a.flow.iter().chain(&b.flow).all(|&v| v == 0.0));
    let (z, _) = fixed_view_pair(&Scene::new(6), 0.0, 0.0);
    assert_eq!(a.rgb, z.rgb);
}

#[test]
fn late_kind_rests_then_moves() {
    let tmp = tempfile::tempdir().unwrap();
    let s = synthetic::generate_with(Preset::Tiny, 6, SceneMotion::Late, tmp.path()).unwrap();
    assert_eq!(s.motion, SceneMotion::Late);
    assert_eq!(motion_recorded(tmp.path()), "late");
    let ds = data::load(tmp.path(), &data_util::opts()).unwrap();
    for f in ds.frames() {
        let k: usize = f.id.parse().unwrap();
        let (m, flow) = (f.mask.as_ref().unwrap(), f.flow.as_ref().unwrap());
        let moving = m.iter().filter(|&&v| v == 1).count();
        let nonzero = flow.iter().filter(|&&v| v != 0.0).count();
        // t_{k+1} = (k+1)/23 ≤ 0.5 up to k = 10; frame 11 starts the motion towards t_12.
        if k <= 10 {
            assert_eq!((moving, nonzero), (0, 0), "frame {k}");
        } else {
            assert!(
                moving > 64 && nonzero > moving,
                "frame {k}: {moving} moving, {nonzero} flow"
            );
        }
    }
    let scene = Scene::with_motion(6, SceneMotion::Late);
    let (a, b) = fixed_view_pair(&scene, 0.1, 0.4);
    assert!(a.rgb == b.rgb && a.mask.iter().chain(&b.mask).all(|&v| v == 0));
    assert!(a.flow.iter().chain(&b.flow).all(|&v| v == 0.0));
    // The second half replays the moving trajectory at double speed: late t = 0.75 is moving 0.5.
    let (c, d) = fixed_view_pair(&scene, 0.6, 0.75);
    assert!(c.rgb != d.rgb && c.mask.contains(&1) && d.mask.contains(&1));
    let (e, _) = fixed_view_pair(&Scene::new(6), 0.5, 0.5);
    assert_eq!(d.rgb, e.rgb);
}

/// FNV-1a (64 bit) over every file of `dir`, in the byte order of their relative paths: each
/// path, a zero byte, then the file's bytes.
fn tree_checksum(dir: &Path) -> u64 {
    let mut names: Vec<String> = files(dir)
        .iter()
        .map(|p| p.to_str().unwrap().to_string())
        .collect();
    names.sort();
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for name in &names {
        let bytes = std::fs::read(dir.join(name)).unwrap();
        for &b in name.as_bytes().iter().chain(&[0u8]).chain(&bytes) {
            h ^= b as u64;
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    }
    h
}

/// Adding the `events` kind left the other kinds' files byte for byte as they were: checksums of
/// the tiny scene (seed 0) recorded at b5d2a7f, before that kind existed (the PNG bytes also
/// depend on the `png` crate's encoder, pinned by Cargo.lock).
#[test]
fn existing_kinds_match_recorded_checksums() {
    let tmp = tempfile::tempdir().unwrap();
    for (motion, want) in [
        (SceneMotion::Moving, 0xfac7_1436_fb8f_c285u64),
        (SceneMotion::Static, 0x6845_f28e_56c9_4348),
        (SceneMotion::Late, 0xa301_38bb_116d_6d65),
    ] {
        let dir = tmp.path().join(motion.name());
        synthetic::generate_with(Preset::Tiny, 0, motion, &dir).unwrap();
        assert_eq!(files(&dir).len(), 101, "{}", motion.name());
        let got = tree_checksum(&dir);
        assert_eq!(got, want, "{}: {got:#018x}", motion.name());
    }
}

/// What every pixel of `cam` sees at frame time `t` (the same rays as `render_view`).
fn hit_map(scene: &Scene, cam: &GenCamera, t: f64) -> Vec<Hit> {
    let (w, h) = (cam.width as usize, cam.height as usize);
    (0..w * h)
        .map(|o| {
            let px = DVec2::new((o % w) as f64 + 0.5, (o / w) as f64 + 0.5);
            scene.cast(cam.centre, cam.ray(px), t)
        })
        .collect()
}

fn ball_of(hit: &Hit) -> Option<Ball> {
    match hit {
        Hit::Event { ball, .. } => Some(*ball),
        _ => None,
    }
}

/// 4-connected components of `on` (`w` wide).
fn components(on: &[bool], w: usize) -> usize {
    let h = on.len() / w;
    let mut seen = vec![false; on.len()];
    let mut count = 0;
    for start in 0..on.len() {
        if !on[start] || seen[start] {
            continue;
        }
        count += 1;
        seen[start] = true;
        let mut stack = vec![start];
        while let Some(o) = stack.pop() {
            let (i, j) = (o % w, o / w);
            let mut near = Vec::with_capacity(4);
            if i > 0 {
                near.push(o - 1);
            }
            if i + 1 < w {
                near.push(o + 1);
            }
            if j > 0 {
                near.push(o - w);
            }
            if j + 1 < h {
                near.push(o + w);
            }
            for q in near {
                if on[q] && !seen[q] {
                    seen[q] = true;
                    stack.push(q);
                }
            }
        }
    }
    count
}

/// The per-object hit query over every frame of a preset: the appearing sphere is seen exactly
/// from `T_APPEAR` on, the vanishing one until `T_VANISH`, the splitting one whole until
/// `T_SPLIT` and as two pieces after, two separate blobs once they have moved apart. Each is
/// inside the frame and apart from the rigid sphere and the blob in every image.
#[test]
fn events_spheres_appear_vanish_and_split_on_schedule() {
    use events::{T_APPEAR, T_SPLIT, T_VANISH};
    let scene = Scene::with_motion(0, SceneMotion::Events);
    for preset in [Preset::Tiny, Preset::Small] {
        let (w, h, n, _) = preset.dims();
        // A sphere of radius 0.25 covers ~30 pixels at 64×64, ~200 at 160×120.
        let least = if preset == Preset::Tiny { 12 } else { 80 };
        for k in 0..n {
            let t = k as f64 / (n - 1) as f64;
            let cam = GenCamera::for_frame(k, n, w, h);
            let hits = hit_map(&scene, &cam, t);
            let count = |b: Ball| hits.iter().filter(|x| ball_of(x) == Some(b)).count();
            let what = format!("{} frame {k} (t = {t:.3})", preset.name());
            let seen = |b: Ball, present: bool, least: usize| {
                let c = count(b);
                assert!(
                    if present { c >= least } else { c == 0 },
                    "{what}: {b:?} covers {c} pixels"
                );
            };
            seen(Ball::Appearing, t >= T_APPEAR, least);
            seen(Ball::Vanishing, t < T_VANISH, least);
            seen(Ball::Splitting, t < T_SPLIT, least);
            // Each piece hides half the other just after the split.
            seen(Ball::PieceNeg, t >= T_SPLIT, least / 4);
            seen(Ball::PiecePos, t >= T_SPLIT, least / 4);
            let split: Vec<bool> = hits
                .iter()
                .map(|x| {
                    matches!(
                        ball_of(x),
                        Some(Ball::Splitting | Ball::PieceNeg | Ball::PiecePos)
                    )
                })
                .collect();
            let blobs = components(&split, w as usize);
            if t < T_SPLIT {
                assert_eq!(blobs, 1, "{what}");
            } else if t >= 0.8 {
                assert_eq!(blobs, 2, "{what}: the pieces should be apart");
            }
            // In frame, and never next to the other objects' pixels (no contact, no occlusion).
            let (wu, hu) = (w as usize, h as usize);
            for (o, x) in hits.iter().enumerate() {
                if ball_of(x).is_none() {
                    continue;
                }
                let (i, j) = (o % wu, o / wu);
                assert!(
                    i > 0 && j > 0 && i + 1 < wu && j + 1 < hu,
                    "{what}: {x:?} at the border"
                );
                for q in [o - 1, o + 1, o - wu, o + wu, o - wu - 1, o + wu + 1] {
                    assert!(
                        !matches!(hits[q], Hit::Rigid { .. } | Hit::Blob { .. }),
                        "{what}: {x:?} touches {:?}",
                        hits[q]
                    );
                }
            }
        }
    }
}

/// The written masks and flow of the `events` kind: finite flow, zero off the mask, and at the
/// frames that hold an event, the conventions of `synthetic/events.rs`.
#[test]
fn events_masks_and_flow_follow_the_conventions() {
    use events::{PIECE_SCALE, SPLIT_NORMAL};
    let tmp = tempfile::tempdir().unwrap();
    let s = synthetic::generate_with(Preset::Tiny, 0, SceneMotion::Events, tmp.path()).unwrap();
    assert_eq!(s.motion, SceneMotion::Events);
    assert_eq!(motion_recorded(tmp.path()), "events");
    let info: serde_json::Value =
        serde_json::from_slice(&std::fs::read(tmp.path().join("synthetic.json")).unwrap()).unwrap();
    assert_eq!(info["events"]["appearing"]["present"], "t >= 0.35");
    let ds = data::load(tmp.path(), &data_util::opts()).unwrap();
    assert_eq!(ds.frames().count(), 24);
    let scene = Scene::with_motion(0, SceneMotion::Events);
    let (w, n) = (64usize, 24usize);
    let time = |k: usize| k as f64 / (n - 1) as f64;
    // The frames whose interval [t_k, t_{k+1}] holds an event.
    let holds = |e: f64| (0..n).find(|&k| time(k) < e && e <= time(k + 1)).unwrap();
    let (k_appear, k_split, k_vanish) = (holds(0.35), holds(0.5), holds(0.65));
    assert_eq!((k_appear, k_split, k_vanish), (8, 11, 14));
    let mut checked = [0usize; 4];
    for f in ds.frames() {
        let k: usize = f.id.parse().unwrap();
        let (m, flow) = (f.mask.as_ref().unwrap(), f.flow.as_ref().unwrap());
        assert!(flow.iter().all(|v| v.is_finite()), "frame {k}");
        for (i, &mv) in m.iter().enumerate() {
            if mv == 0 {
                assert_eq!(
                    [flow[2 * i], flow[2 * i + 1]],
                    [0.0, 0.0],
                    "frame {k} px {i}"
                );
            }
        }
        assert!(m.contains(&1), "frame {k}: empty mask");
        let (t, t2) = (time(k), time(k + 1));
        let cam = GenCamera::for_frame(k, n, w as u32, w as u32);
        let hits = hit_map(&scene, &cam, t);
        let px_flow = |o: usize| DVec2::new(flow[2 * o] as f64, flow[2 * o + 1] as f64);
        for (o, x) in hits.iter().enumerate() {
            let (Some(ball), Hit::Event { p, .. }) = (ball_of(x), x) else {
                continue;
            };
            // Every event sphere's pixel is masked, except the whole splitting sphere at rest.
            let masked = ball != Ball::Splitting || k == k_split;
            assert_eq!(m[o] == 1, masked, "frame {k}: {ball:?} at px {o}");
            match ball {
                Ball::Vanishing if k == k_vanish => {
                    assert_eq!(px_flow(o), DVec2::ZERO, "frame {k}: vanishing px {o}");
                    checked[0] += 1;
                }
                Ball::Splitting if k == k_split => {
                    // The point follows the piece on its side of the plane, shrunk about it.
                    let c = Ball::Splitting.centre(t);
                    let piece = if (*p - c).dot(SPLIT_NORMAL) >= 0.0 {
                        Ball::PiecePos
                    } else {
                        Ball::PieceNeg
                    };
                    let q = piece.centre(t2) + PIECE_SCALE * (*p - c);
                    let want = cam.project(q).unwrap() - cam.project(*p).unwrap();
                    assert!((px_flow(o) - want).length() < 1e-4, "frame {k} px {o}");
                    assert!(want.length() > 1e-3);
                    checked[1] += 1;
                }
                Ball::Splitting => assert_eq!(px_flow(o), DVec2::ZERO, "frame {k}: at rest"),
                Ball::PieceNeg | Ball::PiecePos => {
                    // Pure translation along ∓/± the split normal, which the arc sees as ∓/± x.
                    let sign = if ball == Ball::PiecePos { 1.0 } else { -1.0 };
                    assert!(sign * px_flow(o).x > 0.05, "frame {k}: {ball:?} px {o}");
                    checked[2] += 1;
                }
                _ => assert!(px_flow(o).length() > 1e-4, "frame {k}: {ball:?} px {o}"),
            }
        }
        if k == k_appear {
            // Not there yet at t_k: where it will be (seen by camera k at t_{k+1}) is unmasked.
            let next = hit_map(&scene, &cam, t2);
            for (o, x) in next.iter().enumerate() {
                if ball_of(x) == Some(Ball::Appearing) {
                    assert!(matches!(hits[o], Hit::Room { .. }) && m[o] == 0);
                    checked[3] += 1;
                }
            }
        }
    }
    assert!(checked.iter().all(|&c| c >= 12), "{checked:?}");
}

/// `points.npy` of the `events` kind: the moving kind's first 7/8, then points on the spheres
/// present at `t = 0` (the vanishing and the whole splitting one), none on the appearing one.
#[test]
fn events_points_cover_the_spheres_present_at_t0() {
    let tmp = tempfile::tempdir().unwrap();
    synthetic::generate_with(Preset::Tiny, 3, SceneMotion::Events, tmp.path()).unwrap();
    let got = dispflow_vk::data::points::read_points_npy(&tmp.path().join("points.npy")).unwrap();
    let want = synthetic::sample_points_with(3, 3000, SceneMotion::Events);
    assert_eq!((got.len(), want.len()), (3000, 3000));
    assert!(got
        .iter()
        .zip(&want)
        .all(|(a, b)| (*a - *b).length() < 1e-5));
    let moving = synthetic::sample_points(3, 3000);
    assert_eq!(want[..2625], moving[..2625]);
    let on = |p: DVec3, b: Ball| ((p - b.centre(0.0)).length() - b.radius()).abs() < 0.02;
    let tail = &want[2625..];
    assert!(tail
        .iter()
        .all(|&p| on(p, Ball::Vanishing) || on(p, Ball::Splitting)));
    assert!(tail.iter().filter(|&&p| on(p, Ball::Vanishing)).count() > 150);
    assert!(tail.iter().filter(|&&p| on(p, Ball::Splitting)).count() > 150);
    let appears_at = Ball::Appearing.centre(events::T_APPEAR);
    assert!(want.iter().all(|p| p.distance(appears_at) > 0.3));
}

/// `transient.unexplained` on the `events` scene's own pictures, no training. A model that
/// draws the moving objects a frame late (a pose not learnt yet) is wrong where they are, but
/// draws their colours close by: no frame lacks anything. The same model without the spheres
/// that appear, vanish and split (the `moving` kind is the scene without them) lacks what most
/// frames of a round show, so the round opens `auto`'s lacking route.
#[test]
fn the_events_spheres_read_as_lacking_and_a_late_pose_does_not() {
    use dispflow_vk::train::config::TransientConfig;
    use dispflow_vk::train::transients::residual::{frame_residual, FrameResidual};
    use dispflow_vk::train::transients::rules::RoundRules;
    let (n, w, h) = (60usize, 160u32, 120u32);
    let rgba = |r: &synthetic::Rendered| -> Vec<[f32; 4]> {
        r.rgb.chunks(3).map(|c| [c[0], c[1], c[2], 1.0]).collect()
    };
    let dt = 1.0 / (n - 1) as f64;
    let (events, moving) = (
        Scene::with_motion(0, SceneMotion::Events),
        Scene::with_motion(0, SceneMotion::Moving),
    );
    let tc = TransientConfig::default();
    let (mut lacking, mut late) = (Vec::new(), Vec::new());
    // A round's 12 frames spread over the sequence, as the spawns look at them.
    for k in (2..n).step_by(5) {
        let cam = GenCamera::for_frame(k, n, w, h);
        let t = k as f64 * dt;
        let behind = rgba(&synthetic::render_view(&moving, &cam, t - dt, t));
        let truth = rgba(&synthetic::render_view(&moving, &cam, t, t + dt));
        let with_events = rgba(&synthetic::render_view(&events, &cam, t, t + dt));
        late.push(frame_residual(&behind, &truth, w, tc.min_error));
        lacking.push(frame_residual(&behind, &with_events, w, tc.min_error));
        assert_eq!(
            frame_residual(&truth, &truth, w, tc.min_error).unexplained,
            0.0
        );
    }
    let show = |v: &[FrameResidual]| {
        v.iter()
            .map(|r| format!("{:.4}/{:.2}", r.per_pixel(), r.unexplained))
            .collect::<Vec<_>>()
            .join(" ")
    };
    let round = RoundRules::of(&tc, &lacking, true);
    assert!(
        round.lacking_round && round.lacking >= 8,
        "without the events' spheres, frames (residual per px / unexplained): {}",
        show(&lacking)
    );
    let round = RoundRules::of(&tc, &late, true);
    assert!(
        late.iter().all(|r| r.unexplained < 0.01) && round.lacking == 0 && !round.lacking_round,
        "a frame late, frames (residual per px / unexplained): {}",
        show(&late)
    );
}
