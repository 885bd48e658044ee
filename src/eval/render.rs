//! `dispflow-vk render`: camera paths (test cameras, a fixed camera over time, orbit, spiral)
//! through a trained run, with the displacement-flow heatmap and per-frame 3DGS exports.

use std::path::PathBuf;

use glam::{Mat3, Vec3};

use super::run::{load_trainer, open_run};
use crate::error::{Error, Result};
use crate::kernels::raster::Camera;
use crate::report;
use crate::train::checkpoint::write_ply;
use crate::train::Trainer;
use crate::vk::Gpu;

/// Camera paths of `render`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum CameraPath {
    /// The test cameras at their own times, in time order.
    Test,
    /// One test camera (`--camera`, default 0) while time sweeps the dataset's range.
    Fixed,
    /// A circle around the scene at the training cameras' mean distance and height.
    Orbit,
    /// A small spiral around the mean training camera (forward-facing captures).
    Spiral,
}

#[derive(clap::Args, Debug, Clone)]
pub struct RenderArgs {
    /// Run directory written by `dispflow-vk train`.
    #[arg(long)]
    pub run: PathBuf,
    /// Dataset directory [default: the one recorded in the run's metrics.json].
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// Camera path.
    #[arg(long, value_enum, default_value_t = CameraPath::Test)]
    pub path: CameraPath,
    /// Freeze time at this value in [0, 1]: only the camera moves (camera motion alone).
    #[arg(long)]
    pub time: Option<f32>,
    /// Freeze the view at this test camera (index in time order): only time moves (scene
    /// motion alone).
    #[arg(long)]
    pub camera: Option<usize>,
    /// Frames of the fixed/orbit/spiral paths.
    #[arg(long, default_value_t = 60)]
    pub frames: u32,
    /// Put the displacement-flow heatmap (motion since the previous dataset time) and the
    /// dynamic mask (white where the render sees Gaussians the deformation moves) beside
    /// each frame.
    #[arg(long)]
    pub flow: bool,
    /// Also write the deformed Gaussians of every frame as standard 3DGS .ply files
    /// (`ply/frame_NNNN.ply`: with the transient Gaussians alive at that frame) plus
    /// `ply/canonical.ply` (and `ply/transients.ply` with their times and velocities).
    #[arg(long)]
    pub ply: bool,
    /// With --ply: also pack the per-frame PLYs into `ply/sequence.zip`, which brush's viewer
    /// plays as an animation (frames only, stored, natural order).
    #[arg(long, requires = "ply")]
    pub zip: bool,
    /// Also write the frames as a looping animated GIF, `animation.gif`.
    #[arg(long)]
    pub gif: bool,
    /// Frames per second of the GIF.
    #[arg(long, default_value_t = 12)]
    pub fps: u32,
    /// Output directory [default: RUN/render/<path>].
    #[arg(long)]
    pub out: Option<PathBuf>,
}

/// One view of a path.
#[derive(Clone, Copy, Debug)]
pub struct PathView {
    pub camera: Camera,
    pub time: f32,
}

/// A world-to-camera pose (OpenCV axes: x right, y down, z forward) at `eye` looking at
/// `target` with `up` as the world's up.
pub fn look_at(eye: Vec3, target: Vec3, up: Vec3) -> (Mat3, Vec3) {
    let z = (target - eye).normalize_or(Vec3::Z);
    // y = z × x must point down (−up): x = z × up.
    let mut x = z.cross(up);
    if x.length_squared() < 1e-12 {
        x = z.any_orthonormal_vector();
    }
    let x = x.normalize();
    let y = z.cross(x);
    let r = Mat3::from_cols(x, y, z).transpose();
    (r, -(r * eye))
}

fn with_pose(base: &Camera, r: Mat3, t: Vec3) -> Camera {
    Camera {
        rot: [
            r.row(0).to_array(),
            r.row(1).to_array(),
            r.row(2).to_array(),
        ],
        trans: t.to_array(),
        ..*base
    }
}

fn centre_of(c: &Camera) -> Vec3 {
    Vec3::from(c.centre().map(|v| v as f32))
}

/// The views of a path over the trainer's frames (`test` uses the test split).
pub fn camera_path(tr: &Trainer<'_>, a: &RenderArgs, target: Vec3) -> Result<Vec<PathView>> {
    let mut test: Vec<(Camera, f32)> = if tr.val.is_empty() {
        &tr.frames
    } else {
        &tr.val
    }
    .iter()
    .map(|f| (f.camera, f.time))
    .collect();
    test.sort_by(|a, b| a.1.total_cmp(&b.1));
    let (t0, t1) = tr
        .frames
        .iter()
        .chain(&tr.val)
        .fold((f32::MAX, f32::MIN), |(lo, hi), f| {
            (lo.min(f.time), hi.max(f.time))
        });
    let n = a.frames.max(1);
    let sweep = |k: u32| {
        if n == 1 {
            t0
        } else {
            t0 + (t1 - t0) * k as f32 / (n - 1) as f32
        }
    };
    let frozen_cam = match a.camera {
        Some(k) => Some(
            test.get(k)
                .ok_or_else(|| {
                    Error::Invalid(format!(
                        "--camera {k}: the run has {} test cameras (0..{})",
                        test.len(),
                        test.len().saturating_sub(1)
                    ))
                })?
                .0,
        ),
        None => None,
    };
    if let Some(t) = a.time {
        if !(0.0..=1.0).contains(&t) {
            return Err(Error::Invalid(format!(
                "--time {t}: expected a time in [0, 1]"
            )));
        }
    }
    let base = test[0].0;
    let centres: Vec<Vec3> = tr.frames.iter().map(|f| centre_of(&f.camera)).collect();
    let mean_c = centres.iter().copied().sum::<Vec3>() / centres.len().max(1) as f32;
    // World up: the mean of the cameras' −y axes (OpenCV y points down).
    let up = tr
        .frames
        .iter()
        .map(|f| -Vec3::from(f.camera.rot[1]))
        .sum::<Vec3>()
        .normalize_or(Vec3::Y);
    let mut views: Vec<PathView> = match a.path {
        CameraPath::Test => test
            .iter()
            .map(|&(camera, time)| PathView { camera, time })
            .collect(),
        CameraPath::Fixed => {
            let cam = frozen_cam.unwrap_or(base);
            (0..n)
                .map(|k| PathView {
                    camera: cam,
                    time: sweep(k),
                })
                .collect()
        }
        CameraPath::Orbit => {
            let off = mean_c - target;
            let h = off.dot(up);
            let radial = off - h * up;
            let radius = centres
                .iter()
                .map(|c| {
                    let o = *c - target;
                    (o - o.dot(up) * up).length()
                })
                .sum::<f32>()
                / centres.len().max(1) as f32;
            let e1 = radial.normalize_or(up.any_orthonormal_vector());
            let e2 = up.cross(e1);
            (0..n)
                .map(|k| {
                    let th = std::f32::consts::TAU * k as f32 / n as f32;
                    let eye = target + h * up + radius * (th.cos() * e1 + th.sin() * e2);
                    let (r, t) = look_at(eye, target, up);
                    PathView {
                        camera: with_pose(&base, r, t),
                        time: sweep(k),
                    }
                })
                .collect()
        }
        CameraPath::Spiral => {
            let fwd = (target - mean_c).normalize_or(Vec3::Z);
            let right = fwd.cross(up).normalize_or(Vec3::X);
            let spread = centres
                .iter()
                .map(|c| c.distance(mean_c))
                .fold(0.0, f32::max);
            let radius = (0.5 * spread).max(0.05 * mean_c.distance(target));
            (0..n)
                .map(|k| {
                    let th = 2.0 * std::f32::consts::TAU * k as f32 / n as f32;
                    let eye = mean_c
                        + radius * (th.cos() * right + th.sin() * up)
                        + 0.1 * radius * (0.5 * th).sin() * fwd;
                    let (r, t) = look_at(eye, target, up);
                    PathView {
                        camera: with_pose(&base, r, t),
                        time: sweep(k),
                    }
                })
                .collect()
        }
    };
    for v in &mut views {
        if let Some(c) = frozen_cam {
            v.camera = c;
        }
        if let Some(t) = a.time {
            v.time = t;
        }
    }
    Ok(views)
}

/// Runs `render`; returns the PNG paths written.
pub fn run_render(a: &RenderArgs) -> Result<Vec<PathBuf>> {
    let run = open_run(&a.run, a.data.as_deref())?;
    let gpu = Gpu::new_default()?;
    eprintln!("device: {}", gpu.info);
    let (_ds, mut tr) = load_trainer(&gpu, &run)?;
    let path_name = format!("{:?}", a.path).to_lowercase();
    let out = a
        .out
        .clone()
        .unwrap_or_else(|| run.dir.join("render").join(&path_name));
    // The orbit/spiral look at the middle of the trained Gaussians (median per axis: robust
    // to far-away floaters).
    let target = {
        let mut axes =
            [0, 1, 2].map(|k| run.gaussians.means.iter().map(|m| m[k]).collect::<Vec<_>>());
        Vec3::from(axes.each_mut().map(|v| {
            v.sort_by(|a, b| a.total_cmp(b));
            v.get(v.len() / 2).copied().unwrap_or(0.0)
        }))
    };
    let views = camera_path(&tr, a, target)?;
    let mut times: Vec<f32> = tr.frames.iter().chain(&tr.val).map(|f| f.time).collect();
    times.sort_by(f32::total_cmp);
    times.dedup();
    if a.ply {
        let dir = out.join("ply");
        std::fs::create_dir_all(&dir).map_err(Error::io(&dir))?;
        // The canonical population (what the deformation moves); the transients' own file
        // beside it, as the run writes them.
        let (canonical, transients) = tr.gaussians()?.split_transients();
        write_ply(&dir.join("canonical.ply"), &canonical)?;
        if !transients.is_empty() {
            write_ply(&dir.join("transients.ply"), &transients)?;
        }
    }
    if a.gif && (a.fps == 0 || a.fps > 100) {
        return Err(Error::Invalid(format!(
            "--fps {}: expected 1 to 100 (GIF delays are hundredths of a second)",
            a.fps
        )));
    }
    let pb = report::progress(views.len() as u64, "render");
    let mut written = Vec::new();
    let mut gif_frames = Vec::new();
    let mut plys = Vec::new();
    for (k, v) in views.iter().enumerate() {
        let prev = if a.flow {
            times
                .iter()
                .copied()
                .filter(|&t| t < v.time)
                .reduce(f32::max)
        } else {
            None
        };
        let e = tr.render_view(&v.camera, v.time, prev)?;
        let im = e.images.expect("images requested");
        let (w, h) = (im.width, im.height);
        let render = report::rgb_image(&im.render, w, h)?;
        let img = if a.flow {
            let heat = report::heatmap(&im.motion, w, h)?;
            let t_label = format!("t={:.3}", v.time);
            let dynamic = tr.dynamic_mask(&v.camera, v.time)?;
            let dynamic = super::run::grey_image(&dynamic, w, h)?;
            report::labelled_strip(&[
                (t_label.as_str(), &render),
                ("disp. flow", &heat),
                ("dynamic", &dynamic),
            ])?
        } else {
            render
        };
        let path = out.join(format!("{k:04}.png"));
        report::save_png(&img, &path)?;
        written.push(path);
        if a.gif {
            gif_frames.push(img);
        }
        if a.ply {
            let g = tr.deformed_gaussians(v.time)?;
            let name = format!("frame_{k:04}.ply");
            let p = out.join("ply").join(&name);
            write_ply(&p, &g)?;
            plys.push((name, p));
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    if a.gif {
        let p = out.join("animation.gif");
        super::export::write_gif(&p, &gif_frames, a.fps)?;
        eprintln!("animation: {}", p.display());
    }
    if a.zip {
        let p = out.join("ply").join("sequence.zip");
        super::export::write_stored_zip(&p, &plys)?;
        eprintln!("PLY sequence for brush: {}", p.display());
    }
    eprintln!(
        "{} frames ({} path) in {}",
        written.len(),
        path_name,
        out.display()
    );
    gpu.check_validation("render")?;
    Ok(written)
}
