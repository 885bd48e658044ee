//! Tracking on synthetic frames: balls drawn into ground truths whose renders miss them.

use super::*;

/// A camera at `centre` looking at the origin (world z up), 64×64.
fn look_at(centre: [f32; 3]) -> Camera {
    let c = glam::Vec3::from(centre);
    let fwd = (-c).normalize();
    let right = fwd.cross(glam::Vec3::Z).normalize();
    let down = fwd.cross(right);
    camera([right.to_array(), down.to_array(), fwd.to_array()], centre)
}

/// A 64×64 camera with rows `rot` (its axes in world coordinates) at `centre`.
fn camera(rot: [[f32; 3]; 3], centre: [f32; 3]) -> Camera {
    let c = glam::Vec3::from(centre);
    let trans = std::array::from_fn(|r| -glam::Vec3::from(rot[r]).dot(c));
    Camera {
        rot,
        trans,
        fx: 60.0,
        fy: 60.0,
        cx: 32.0,
        cy: 32.0,
        width: 64,
        height: 64,
        near: 0.01,
    }
}

const ORANGE: [f32; 4] = [0.9, 0.5, 0.1, 1.0];

/// The scene's bounds: the cube of side 4 about the origin.
fn cube() -> Bounds {
    Bounds {
        min: glam::Vec3::splat(-2.0),
        max: glam::Vec3::splat(2.0),
    }
}

/// Five cameras around the origin, one per frame.
fn five_cameras() -> [Camera; 5] {
    [
        [6.0, 0.0, 3.0],
        [0.0, 6.0, 3.0],
        [-6.0, 0.5, 3.0],
        [0.5, -6.0, 3.0],
        [4.0, 4.0, 4.0],
    ]
    .map(look_at)
}

/// [`five_cameras`] at 128×128.
fn five_cameras_128() -> [Camera; 5] {
    five_cameras().map(|c| Camera {
        fx: 2.0 * c.fx,
        fy: 2.0 * c.fy,
        cx: 2.0 * c.cx,
        cy: 2.0 * c.cy,
        width: 2 * c.width,
        height: 2 * c.height,
        ..c
    })
}

/// The pixel `p` projects into.
fn pixel_of(cam: &Camera, p: [f32; 3]) -> (u32, u32) {
    let q: [f32; 3] =
        std::array::from_fn(|r| (0..3).map(|a| cam.rot[r][a] * p[a]).sum::<f32>() + cam.trans[r]);
    (
        (cam.fx * q[0] / q[2] + cam.cx) as u32,
        (cam.fy * q[1] / q[2] + cam.cy) as u32,
    )
}

/// The ground truth of a ball of radius 0.15 at `p` on black, and a render without it.
fn frame(cam: &Camera, p: [f32; 3], colour: [f32; 4]) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    ball(cam, p, 0.15, colour)
}

/// The same, radius `r`.
fn ball(cam: &Camera, p: [f32; 3], r: f32, colour: [f32; 4]) -> (Vec<[f32; 4]>, Vec<[f32; 4]>) {
    let n = (cam.width * cam.height) as usize;
    let mut gt = vec![[0.0, 0.0, 0.0, 1.0]; n];
    let q: [f32; 3] =
        std::array::from_fn(|r| (0..3).map(|a| cam.rot[r][a] * p[a]).sum::<f32>() + cam.trans[r]);
    let (u, v) = (cam.fx * q[0] / q[2] + cam.cx, cam.fy * q[1] / q[2] + cam.cy);
    let rad = cam.fx * r / q[2];
    for y in 0..cam.height {
        for x in 0..cam.width {
            let (dx, dy) = (x as f32 + 0.5 - u, y as f32 + 0.5 - v);
            if dx * dx + dy * dy <= rad * rad {
                gt[(y * cam.width + x) as usize] = colour;
            }
        }
    }
    (gt, vec![[0.0, 0.0, 0.0, 1.0]; n])
}

#[test]
fn a_ball_missing_from_every_frame_is_tracked_with_its_velocity() {
    let bounds = cube();
    // Five frames, each from another camera, the ball moving 0.37 per frame (more than
    // its diameter) along a slanted line. At 128×128: at 64 px the ball is 3 px wide and a
    // pixel centre's half-pixel error alone is 0.06 units at its depth, up to 0.6 of velocity
    // over 0.1 s, more than the 15 % asked (the colour and the patch trackers both sat at it).
    let cams = five_cameras_128();
    let (p0, vel) = ([-0.3f32, 0.2, 0.1], [3.0f32, -1.5, 1.0]);
    let speed = 3.5f32;
    let times: Vec<f32> = (0..5).map(|i| i as f32 * 0.1).collect();
    let pos = |t: f32| -> [f32; 3] { std::array::from_fn(|k| p0[k] + vel[k] * (t - 0.2)) };
    let dist = |a: [f32; 3], b: [f32; 3]| (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f32>().sqrt();
    let (x, y) = pixel_of(&cams[2], p0);
    let run = |places: &dyn Fn(usize) -> [f32; 3], v_max: f32| {
        let imgs: Vec<_> = (0..5).map(|i| frame(&cams[i], places(i), ORANGE)).collect();
        let res = |i: usize| Residual::new(&cams[i], times[i], &imgs[i].1, &imgs[i].0, 0.1);
        let tr = Tracker::new(res(2), vec![res(4), res(1), res(3), res(0)], v_max, &bounds);
        assert_eq!(tr.neighbours.len(), 4);
        assert!(
            (tr.neighbours[0].time - 0.1).abs() < 1e-6
                || (tr.neighbours[0].time - 0.3).abs() < 1e-6,
            "nearest first"
        );
        assert_eq!(tr.required(), 2, "3 others: one may miss");
        tr.track(x, y)
    };
    let t = run(&|i| pos(times[i]), 100.0).expect("tracked");
    assert!(t.explained >= 2, "{t:?}");
    assert!(dist(t.mean, p0) < 0.15, "mean {:?} vs {p0:?}", t.mean);
    assert!(
        dist(t.velocity, vel) < 0.15 * speed,
        "velocity {:?} vs {vel:?}",
        t.velocity
    );
    // A ball at places no constant velocity explains is not tracked.
    let jumps = [
        [1.5, 1.5, 0.0],
        [-1.5, 1.2, 1.0],
        p0,
        [1.4, -1.5, -1.0],
        [-1.2, -1.2, 1.5],
    ];
    assert_eq!(run(&|i| jumps[i], 100.0), None);
    // Nor is one faster than v_max.
    assert_eq!(run(&|i| pos(times[i]), 0.5 * speed), None);
}

#[test]
fn a_track_keeps_its_colour() {
    // The same motion, but the neighbours' wrong pixels are another colour (a blue ball
    // where the frame's is orange): not one object, no track.
    let bounds = cube();
    let cams = [[6.0, 0.0, 3.0], [0.0, 6.0, 3.0], [-6.0, 0.5, 3.0]].map(look_at);
    let p = [0.1f32, -0.2, 0.3];
    let imgs: Vec<_> = (0..3)
        .map(|i| {
            let colour = if i == 1 { ORANGE } else { [0.1, 0.2, 0.9, 1.0] };
            frame(&cams[i], p, colour)
        })
        .collect();
    let res = |i: usize| Residual::new(&cams[i], i as f32, &imgs[i].1, &imgs[i].0, 0.1);
    let (x, y) = pixel_of(&cams[1], p);
    let tr = Tracker::new(res(1), vec![res(0), res(2)], 100.0, &bounds);
    assert!(tr.track(x, y).is_none());
    // Same colour everywhere: a still ball is tracked with no velocity.
    let imgs: Vec<_> = (0..3).map(|i| frame(&cams[i], p, ORANGE)).collect();
    let res = |i: usize| Residual::new(&cams[i], i as f32, &imgs[i].1, &imgs[i].0, 0.1);
    let tr = Tracker::new(res(1), vec![res(0), res(2)], 100.0, &bounds);
    let t = tr.track(x, y).expect("tracked");
    let speed = t.velocity.iter().map(|v| v * v).sum::<f32>().sqrt();
    assert!(speed < 0.2, "{t:?}");
}

#[test]
fn a_big_ball_is_tracked_from_a_strided_subset_of_its_pixels() {
    // A ball whose image in the anchor has several times MAX_HYPOTHESES wrong pixels: the
    // strided hypotheses and the refinement still find a path on it.
    let (bounds, cams) = (cube(), five_cameras());
    let (p0, vel, r) = ([-0.3f32, 0.2, 0.1], [3.0f32, -1.5, 1.0], 0.8f32);
    let times: Vec<f32> = (0..5).map(|i| i as f32 * 0.1).collect();
    let pos = |t: f32| -> [f32; 3] { std::array::from_fn(|k| p0[k] + vel[k] * (t - 0.2)) };
    let imgs: Vec<_> = (0..5)
        .map(|i| ball(&cams[i], pos(times[i]), r, ORANGE))
        .collect();
    let res = |i: usize| Residual::new(&cams[i], times[i], &imgs[i].1, &imgs[i].0, 0.1);
    let tr = Tracker::new(res(2), vec![res(4), res(1), res(3), res(0)], 100.0, &bounds);
    assert!(
        tr.anchor.len() > 3 * MAX_HYPOTHESES,
        "{} anchor pixels",
        tr.anchor.len()
    );
    let (x, y) = pixel_of(&cams[2], p0);
    let t = tr.track(x, y).expect("tracked");
    // Silhouettes of one colour do not pin a surface point (any point inside the ball at
    // every time explains them): what matters is that the transient sits on the ball in
    // every frame of its life.
    for &ti in &times {
        let q: [f32; 3] = std::array::from_fn(|k| t.mean[k] + t.velocity[k] * (ti - 0.2));
        let c = pos(ti);
        let d = (0..3).map(|k| (q[k] - c[k]).powi(2)).sum::<f32>().sqrt();
        assert!(
            d < 1.2 * r,
            "at t = {ti}: {q:?} is {d} from the centre {c:?}; {t:?}"
        );
    }
}

#[test]
fn a_patch_tells_texture_apart_where_a_colour_does_not() {
    // Two 5×5 checkers of the same two colours, one the other's inverse: the centre pixels
    // are the same colour, the patches are not the same surface.
    let (w, h) = (5u32, 5u32);
    let (a, b) = ([0.9, 0.5, 0.1, 1.0], [0.1, 0.2, 0.9, 1.0]);
    let checker = |flip: bool| -> Vec<[f32; 4]> {
        (0..w * h)
            .map(|i| {
                let odd = (i % w + i / w) % 2 == 1;
                if odd == flip || i == 12 {
                    a
                } else {
                    b
                }
            })
            .collect()
    };
    let (p, q) = (checker(false), checker(true));
    assert_eq!(p[12], q[12], "same centre colour");
    let (pp, pq) = (Patch::of(&p, w, h, 2, 2), Patch::of(&q, w, h, 2, 2));
    assert_eq!(pp.distance(&pp), 0.0);
    assert!(pp.distance(&pq) > 2.0 * COLOUR_TOL, "{}", pp.distance(&pq));
    // Edge pixels repeat: a corner's patch is defined and matches itself.
    let corner = Patch::of(&p, w, h, 0, 0);
    assert_eq!(corner.distance(&corner), 0.0);
}

/// A camera at `c` looking along +z (no rotation).
fn forward(c: [f32; 3]) -> Camera {
    camera([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]], c)
}

#[test]
fn a_straight_camera_path_tracks_a_still_surface_still() {
    // Five frames from a camera sliding along x: every (P, v) scaled about its path
    // projects alike, so the rays leave the depth free; the slowest track (the still ball
    // at its true depth) must win, in the grid and in the refinement.
    let bounds = cube();
    let cams: Vec<Camera> = (0..5)
        .map(|i| forward([-0.4 + 0.2 * i as f32, 0.0, -4.0]))
        .collect();
    let p = [0.1f32, -0.1, 0.5];
    let imgs: Vec<_> = (0..5).map(|i| ball(&cams[i], p, 0.3, ORANGE)).collect();
    let res = |i: usize| Residual::new(&cams[i], i as f32 * 0.1, &imgs[i].1, &imgs[i].0, 0.1);
    let tr = Tracker::new(res(2), vec![res(1), res(3), res(0), res(4)], 100.0, &bounds);
    let (x, y) = pixel_of(&cams[2], p);
    let t = tr.track(x, y).expect("tracked");
    let speed = t.velocity.iter().map(|v| v * v).sum::<f32>().sqrt();
    let d = (0..3)
        .map(|k| (t.mean[k] - p[k]).powi(2))
        .sum::<f32>()
        .sqrt();
    // The camera moves 2 units per time unit: a wrong member of the family moves about
    // that fast times its depth error's share.
    assert!(speed < 0.2, "{t:?}");
    assert!(d < 0.35, "{t:?} is {d} from {p:?}");
}

/// The spawn and the forward agree with the tracker: a pixel tracked in frame 2 spawns a
/// transient (`spawn::transients_of`) centred at frame 2's time with the track's point and
/// velocity; the forward rule (`reference::temporal::forward`, the twin of the GPU's temporal
/// stage) draws it at another frame's time exactly where the track says, P + v·(t_j − t); and
/// there it lands on the ball in as many of the neighbours as the tracker asked to verify.
#[test]
fn a_tracked_transient_is_drawn_where_its_track_says_at_other_times() {
    use crate::kernels::temporal::TemporalParams;
    use crate::reference::temporal::{forward, TemporalInputs};
    use crate::train::config::TransientConfig;
    use crate::train::transients::spawn::{transients_of, SpawnFrame};
    let bounds = cube();
    let cams = five_cameras_128();
    let (p0, vel) = ([-0.3f32, 0.2, 0.1], [3.0f32, -1.5, 1.0]);
    let times: Vec<f32> = (0..5).map(|i| i as f32 * 0.1).collect();
    let pos = |t: f32| -> [f32; 3] { std::array::from_fn(|k| p0[k] + vel[k] * (t - 0.2)) };
    let imgs: Vec<_> = (0..5)
        .map(|i| frame(&cams[i], pos(times[i]), ORANGE))
        .collect();
    let res = |i: usize| Residual::new(&cams[i], times[i], &imgs[i].1, &imgs[i].0, 0.1);
    let tr = Tracker::new(res(2), vec![res(1), res(3), res(0), res(4)], 100.0, &bounds);
    let cfg = TransientConfig {
        pixels: 6,
        depths: 0, // only tracked pixels spawn
        min_error: 0.1,
        ..TransientConfig::default()
    };
    let f = SpawnFrame {
        camera: &cams[2],
        time: times[2],
        render: &imgs[2].1,
        gt: &imgs[2].0,
    };
    let (g, fs) = transients_of(&f, &cfg, &bounds, 0.1, 1, 100, Some(&tr));
    assert!(fs.tracked > 0 && g.len() == fs.tracked, "{fs:?}");
    let n = g.len();
    let x = TemporalInputs {
        means: g.means.iter().map(|m| m.map(f64::from)).collect(),
        log_scales: g.log_scales.iter().map(|s| s.map(f64::from)).collect(),
        quats: g.quats.iter().map(|q| q.map(f64::from)).collect(),
        centre: g.time.iter().map(|t| t[0] as f64).collect(),
        log_width: g.time.iter().map(|t| t[1] as f64).collect(),
        velocity: g.velocity.iter().map(|v| v.map(f64::from)).collect(),
    };
    let mut hits = vec![0usize; n];
    for j in [0usize, 1, 3, 4] {
        let p = TemporalParams {
            n: n as u32,
            first: 0,
            t: times[j],
            log_floor: (0.01f32).ln(),
            cutoff: 0.0,
            ..Default::default()
        };
        let drawn = forward(&p, &x);
        let w = cams[j].width;
        for (i, hit) in hits.iter_mut().enumerate() {
            assert_eq!(
                g.time[i][0], times[2],
                "centred at the spawning frame's time"
            );
            let dt = times[j] - times[2];
            let track: [f32; 3] = std::array::from_fn(|k| g.means[i][k] + g.velocity[i][k] * dt);
            let m = drawn.means[i].expect("a transient row");
            for k in 0..3 {
                assert!(
                    (m[k] - track[k] as f64).abs() < 1e-5,
                    "frame {j}, transient {i}: drawn {m:?}, track {track:?}"
                );
            }
            let (u, v) = pixel_of(&cams[j], m.map(|v| v as f32));
            let on = (-1i32..=1).any(|dy| {
                (-1i32..=1).any(|dx| {
                    let (xx, yy) = (u as i32 + dx, v as i32 + dy);
                    (0..w as i32).contains(&xx)
                        && (0..cams[j].height as i32).contains(&yy)
                        && imgs[j].0[(yy * w as i32 + xx) as usize] == ORANGE
                })
            });
            *hit += on as usize;
        }
    }
    assert!(
        hits.iter().all(|&h| h >= tr.required()),
        "frames each transient lands on the ball in: {hits:?} (the tracker asks {})",
        tr.required()
    );
}

#[test]
fn a_still_hypothesis_is_kept_where_a_neighbour_confirms_it() {
    // A still ball missing from five frames. On the ray of a ball pixel of frame 2, the point
    // at the ball is wrong in the neighbours that see it, with the ball's patch: confirmed. A
    // point on the same ray a unit nearer projects onto background the neighbours draw right
    // (black on black): rejected, it would be a floater there. With no neighbour, nothing
    // says otherwise: kept.
    let bounds = cube();
    let cams = five_cameras_128();
    let p0 = [-0.3f32, 0.2, 0.1];
    let imgs: Vec<_> = (0..5).map(|i| frame(&cams[i], p0, ORANGE)).collect();
    let res = |i: usize| Residual::new(&cams[i], i as f32 * 0.1, &imgs[i].1, &imgs[i].0, 0.1);
    let tr = Tracker::new(res(2), vec![res(1), res(3), res(0), res(4)], 100.0, &bounds);
    let (x, y) = pixel_of(&cams[2], p0);
    let (o, d) = pixel_ray(&cams[2], x, y);
    let dot = |u: [f32; 3], v: [f32; 3]| (0..3).map(|a| u[a] * v[a]).sum::<f32>();
    let z = dot(std::array::from_fn(|a| p0[a] - o[a]), d) / dot(d, d);
    let at = |z: f32| -> [f32; 3] { std::array::from_fn(|a| o[a] + d[a] * z) };
    assert!(tr.confirms_still(x, y, at(z)), "the ball's own depth");
    assert!(
        !tr.confirms_still(x, y, at(z - 1.0)),
        "a unit in front of the ball"
    );
    assert!(!tr.confirms_still(x, y, at(z + 1.0)), "a unit behind it");
    let alone = Tracker::new(res(2), Vec::new(), 100.0, &bounds);
    assert!(
        alone.confirms_still(x, y, at(z - 1.0)),
        "no neighbour: kept"
    );
}

#[test]
fn auto_spawns_no_depth_hypothesis_that_no_neighbour_confirms() {
    // The ball jumps between frames (no track explains it), so frame 2's wrong pixels spawn
    // still hypotheses at `depths` depths; no neighbour sees the ball where they are. `auto`
    // (with `confirm`) spawns none of them; `on`, or `confirm = false`, spawns them all.
    use crate::train::config::{TransientConfig, TransientMode};
    use crate::train::transients::spawn::{transients_of, SpawnFrame};
    let bounds = cube();
    let cams = five_cameras_128();
    let places = [
        [1.5, 1.5, 0.0],
        [-1.5, 1.2, 1.0],
        [-0.3, 0.2, 0.1],
        [1.4, -1.5, -1.0],
        [-1.2, -1.2, 1.5],
    ];
    let imgs: Vec<_> = (0..5).map(|i| frame(&cams[i], places[i], ORANGE)).collect();
    let res = |i: usize| Residual::new(&cams[i], i as f32 * 0.1, &imgs[i].1, &imgs[i].0, 0.1);
    let tr = Tracker::new(res(2), vec![res(1), res(3), res(0), res(4)], 100.0, &bounds);
    let f = SpawnFrame {
        camera: &cams[2],
        time: 0.2,
        render: &imgs[2].1,
        gt: &imgs[2].0,
    };
    let spawn = |mode, confirm| {
        let cfg = TransientConfig {
            mode,
            confirm,
            ..TransientConfig::default()
        };
        transients_of(&f, &cfg, &bounds, 0.1, 1, usize::MAX, Some(&tr))
    };
    let (kept, s) = spawn(TransientMode::On, true);
    assert!(s.picked > 0 && s.tracked == 0, "{s:?}");
    assert_eq!(kept.len(), 4 * s.picked, "on: every depth hypothesis");
    assert_eq!(spawn(TransientMode::Auto, false).0.len(), kept.len());
    let (auto, s) = spawn(TransientMode::Auto, true);
    assert_eq!((auto.len(), s.rejected), (0, kept.len()), "{s:?}");
}
