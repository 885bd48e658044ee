//! `dispflow-vk eval` and `dispflow-vk render`: reopen a trained run directory (its
//! `config.toml`, `metrics.json`, `point_cloud.ply`, `deform.bin`), score it on the test split
//! and draw what a person wants to look at.

use std::path::{Path, PathBuf};

use glam::{Mat3, Vec3};
use serde::Serialize;

use super::checkpoint::{read_ply, write_atomic, write_ply};
use super::cli::{load_options, motion_means, FrameMetrics, LogLine};
use super::config::TrainConfig;
use super::{FrameEval, Trainer};
use crate::data::{self, Dataset};
use crate::error::{Error, Result};
use crate::kernels::raster::Camera;
use crate::model::gaussians::HostGaussians;
use crate::report::{self, Plot, Series, Table, PALETTE};
use crate::vk::Gpu;

/// A trained run as written by `dispflow-vk train`.
pub struct Run {
    pub dir: PathBuf,
    pub cfg: TrainConfig,
    pub data_dir: PathBuf,
    pub iterations: u32,
    pub gaussians: HostGaussians,
    pub mlp: Vec<f32>,
}

fn invalid(path: &Path, why: impl std::fmt::Display) -> Error {
    Error::Invalid(format!("{}: {why}", path.display()))
}

/// Reads a run directory, checking every file it needs; `data` overrides the dataset path
/// recorded in `metrics.json`.
pub fn open_run(dir: &Path, data: Option<&Path>) -> Result<Run> {
    if !dir.is_dir() {
        return Err(invalid(
            dir,
            "not a directory; expected a run directory written by `dispflow-vk train`",
        ));
    }
    let need = |name: &str| -> Result<PathBuf> {
        let p = dir.join(name);
        if p.is_file() {
            Ok(p)
        } else {
            Err(invalid(
                &p,
                "missing; a finished `dispflow-vk train` run writes config.toml, metrics.json, \
                 point_cloud.ply and deform.bin",
            ))
        }
    };
    let cfg = TrainConfig::from_toml_over(&TrainConfig::paper(), &need("config.toml")?)?;
    let metrics_path = need("metrics.json")?;
    let text = std::fs::read_to_string(&metrics_path).map_err(|source| Error::Io {
        path: metrics_path.display().to_string(),
        source,
    })?;
    let m: serde_json::Value =
        serde_json::from_str(&text).map_err(|e| invalid(&metrics_path, e))?;
    let iterations = m["iterations"]
        .as_u64()
        .and_then(|v| u32::try_from(v).ok())
        .ok_or_else(|| {
            invalid(
                &metrics_path,
                "field `iterations`: expected a non-negative integer",
            )
        })?;
    let data_dir =
        match data {
            Some(d) => d.to_path_buf(),
            None => PathBuf::from(m["dataset"].as_str().ok_or_else(|| {
                invalid(&metrics_path, "field `dataset`: expected the dataset path")
            })?),
        };
    if !data_dir.is_dir() {
        return Err(invalid(
            &data_dir,
            "the run's dataset is not there; pass --data DIR",
        ));
    }
    let gaussians = read_ply(&need("point_cloud.ply")?)?;
    let weights = need("deform.bin")?;
    let bytes = std::fs::read(&weights).map_err(|source| Error::Io {
        path: weights.display().to_string(),
        source,
    })?;
    if bytes.len() % 4 != 0 {
        return Err(invalid(
            &weights,
            format!("{} bytes is not a whole number of f32", bytes.len()),
        ));
    }
    let mlp: Vec<f32> = bytemuck::pod_collect_to_vec(&bytes);
    Ok(Run {
        dir: dir.to_path_buf(),
        cfg,
        data_dir,
        iterations,
        gaussians,
        mlp,
    })
}

/// Loads the run's dataset and a trainer holding its model.
pub fn load_trainer<'g>(gpu: &'g Gpu, run: &Run) -> Result<(Dataset, Trainer<'g>)> {
    let ds = data::load(&run.data_dir, &load_options(&run.cfg))?;
    let mut tr = Trainer::new(gpu, &run.cfg, &ds)?;
    tr.load_model(&run.gaussians, &run.mlp, run.iterations)
        .map_err(|e| invalid(&run.dir, format!("the saved model does not load: {e}")))?;
    Ok((ds, tr))
}

#[derive(clap::Args, Debug, Clone)]
pub struct EvalArgs {
    /// Run directory written by `dispflow-vk train` (repeat for several runs: one combined
    /// table with a row per run).
    #[arg(long, required = true)]
    pub run: Vec<PathBuf>,
    /// Dataset directory [default: the one recorded in the run's metrics.json].
    #[arg(long)]
    pub data: Option<PathBuf>,
    /// LPIPS network weights. Without it the LPIPS column reads "n/a" (never a made-up number).
    #[arg(long)]
    pub lpips_weights: Option<PathBuf>,
    /// Where the combined table of several runs goes [default: print it only].
    #[arg(long)]
    pub table: Option<PathBuf>,
    /// Skip the PNG strips and plots (metrics and tables only).
    #[arg(long)]
    pub no_pictures: bool,
}

/// `DIR/eval/metrics.json`.
#[derive(Debug, Serialize)]
pub struct EvalReport {
    pub run: String,
    pub method: String,
    pub scene: String,
    pub dataset: String,
    pub iterations: u32,
    pub num_gaussians: u32,
    pub psnr: f64,
    pub ssim: f64,
    pub l1: f64,
    /// Always `None` (serialised as null) unless LPIPS weights were given; see `lpips_note`.
    pub lpips: Option<f64>,
    pub lpips_note: String,
    /// Present when the test split has motion masks.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mmap: Option<f64>,
    pub drc: Option<f64>,
    /// MMAP of the optical flow frozen render → ground truth: an upper reference for how
    /// well the motion loss's signal separates moving pixels.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flow_mmap: Option<f64>,
    pub device: String,
    pub per_frame: Vec<FrameReport>,
}

#[derive(Debug, Serialize)]
pub struct FrameReport {
    #[serde(flatten)]
    pub metrics: FrameMetrics,
    pub l1: f64,
    pub has_mask: bool,
    /// AP of the optical flow frozen render → ground truth (the motion loss's signal).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub flow_ap: Option<f64>,
}

/// "DispFlow-GS (α=0.1)" or "Deformable-3DGS" from the run's configuration.
pub fn method_name(cfg: &TrainConfig) -> String {
    if cfg.motion_weight > 0.0 {
        use super::config::{MotionFlow, MotionOrder, NormGrad};
        let mut extra = String::new();
        if cfg.motion_order == MotionOrder::Reverse {
            extra += ", reverse order";
        }
        if cfg.motion_norm_grad == NormGrad::Full {
            extra += ", full norm grad";
        }
        if cfg.motion_flow == MotionFlow::Oracle {
            extra += ", oracle flow";
        }
        format!("DispFlow-GS (α={}{extra})", cfg.motion_weight)
    } else {
        "Deformable-3DGS".into()
    }
}

const TABLE_HEADERS: [&str; 7] = [
    "Method",
    "Scene",
    "PSNR ↑",
    "SSIM ↑",
    "LPIPS ↓",
    "MMAP ↑",
    "DRC ↑",
];

fn table_row(r: &EvalReport) -> Vec<String> {
    vec![
        format!("{} [{}]", r.method, r.run),
        r.scene.clone(),
        report::fmt_metric(Some(r.psnr), 2),
        report::fmt_metric(Some(r.ssim), 4),
        report::fmt_metric(r.lpips, 4),
        report::fmt_metric(r.mmap, 4),
        report::fmt_metric(r.drc, 4),
    ]
}

/// The paper-style table (a row per run, metric columns).
pub fn table(reports: &[EvalReport]) -> Table {
    Table {
        headers: TABLE_HEADERS.iter().map(|s| s.to_string()).collect(),
        rows: reports.iter().map(table_row).collect(),
    }
}

/// Runs `eval` over every `--run`; returns the reports (each also written to `DIR/eval/`).
pub fn run_eval(a: &EvalArgs) -> Result<Vec<EvalReport>> {
    if let Some(w) = &a.lpips_weights {
        return Err(invalid(
            w,
            "LPIPS needs its backbone network, which this build does not implement yet; run \
             without --lpips-weights (the LPIPS column then reads n/a)",
        ));
    }
    // Every run is checked before the first (slow) evaluation starts.
    let runs = a
        .run
        .iter()
        .map(|d| open_run(d, a.data.as_deref()))
        .collect::<Result<Vec<_>>>()?;
    let gpu = Gpu::new_default()?;
    eprintln!("device: {}", gpu.info);
    let mut reports = Vec::new();
    for run in &runs {
        let r = eval_one(&gpu, run, !a.no_pictures)?;
        reports.push(r);
    }
    let t = table(&reports).to_markdown();
    if let Some(p) = &a.table {
        write_atomic(p, t.as_bytes())?;
    }
    println!("{t}");
    Ok(reports)
}

fn eval_one(gpu: &Gpu, run: &Run, pictures: bool) -> Result<EvalReport> {
    let (ds, mut tr) = load_trainer(gpu, run)?;
    if tr.val.is_empty() {
        return Err(invalid(&run.data_dir, "the dataset has no test frames"));
    }
    let out = run.dir.join("eval");
    let pb = indicatif::ProgressBar::new(tr.val.len() as u64);
    pb.set_style(
        indicatif::ProgressStyle::with_template(
            "eval {bar:30} {pos}/{len} [{elapsed_precise}<{eta_precise}] {msg}",
        )
        .expect("progress template"),
    );
    pb.set_message(run.dir.display().to_string());
    let mut per = Vec::with_capacity(tr.val.len());
    for i in 0..tr.val.len() {
        let e = tr.evaluate_one(i, pictures)?;
        if pictures {
            if let Some(im) = &e.images {
                let path = out
                    .join("frames")
                    .join(format!("{i:03}_{}.png", super::sanitize(&e.id)));
                report::save_png(&frame_strip(im)?, &path)?;
            }
        }
        per.push(FrameEval { images: None, ..e });
        pb.inc(1);
    }
    pb.finish_and_clear();
    let (mmap, drc) = motion_means(&per);
    let mean = |f: &dyn Fn(&FrameEval) -> f64| {
        let v: Vec<f64> = per.iter().map(f).filter(|x| x.is_finite()).collect();
        v.iter().sum::<f64>() / v.len().max(1) as f64
    };
    let scene = ds
        .root
        .file_name()
        .map_or_else(|| "scene".into(), |s| s.to_string_lossy().into_owned());
    let r = EvalReport {
        run: run.dir.display().to_string(),
        method: method_name(&run.cfg),
        scene,
        dataset: run.data_dir.display().to_string(),
        iterations: run.iterations,
        num_gaussians: tr.n,
        psnr: mean(&|e| e.values.psnr),
        ssim: mean(&|e| e.values.ssim),
        l1: mean(&|e| e.values.l1),
        lpips: None,
        lpips_note: "unavailable: no --lpips-weights given".into(),
        mmap,
        drc,
        flow_mmap: mmap.and(crate::kernels::metrics::mmap(
            per.iter().map(|e| e.scene_ap),
        )),
        device: gpu.info.to_string(),
        per_frame: per
            .iter()
            .map(|e| FrameReport {
                metrics: FrameMetrics::of(e),
                l1: e.values.l1,
                has_mask: e.has_mask,
                flow_ap: e.scene_ap,
            })
            .collect(),
    };
    let json = serde_json::to_string_pretty(&r).expect("report serialises");
    write_atomic(&out.join("metrics.json"), json.as_bytes())?;
    let t = table(std::slice::from_ref(&r)).to_markdown();
    write_atomic(&out.join("table.md"), t.as_bytes())?;
    if pictures {
        report::save_png(&per_frame_plot(&per)?, &out.join("per_frame.png"))?;
        let log = run.dir.join("log.jsonl");
        if log.is_file() {
            report::save_png(&training_plot(&read_log(&log)?)?, &out.join("training.png"))?;
        } else {
            eprintln!(
                "{}: no training log (older run); skipping training.png",
                log.display()
            );
        }
    }
    eprintln!(
        "{}: PSNR {:.2} SSIM {:.4} MMAP {} DRC {} (optical-flow MMAP {}) → {}",
        run.dir.display(),
        r.psnr,
        r.ssim,
        report::fmt_metric(r.mmap, 4),
        report::fmt_metric(r.drc, 4),
        report::fmt_metric(r.flow_mmap, 4),
        out.display()
    );
    Ok(r)
}

/// render | ground truth | error | displacement flow | optical flow (frozen render → ground
/// truth) | motion mask (when present).
pub fn frame_strip(im: &super::FrameImages) -> Result<image::RgbImage> {
    let (w, h) = (im.width, im.height);
    let mut panels = vec![("render", report::rgb_image(&im.render, w, h)?)];
    if !im.gt.is_empty() {
        panels.push(("ground truth", report::rgb_image(&im.gt, w, h)?));
        panels.push(("|error|", report::error_map(&im.render, &im.gt, w, h)?));
    }
    panels.push(("disp. flow", report::heatmap(&im.motion, w, h)?));
    if !im.gt.is_empty() {
        // Black without an earlier time, so every strip of a run has the same panels.
        let zeros = vec![0.0; (w * h) as usize];
        let sm = im.scene_motion.as_ref().unwrap_or(&zeros);
        panels.push(("optical flow", report::heatmap(sm, w, h)?));
    }
    if let Some(m) = &im.mask {
        panels.push(("motion mask", report::mask_image(m, w, h)?));
    }
    let refs: Vec<(&str, &image::RgbImage)> = panels.iter().map(|(l, i)| (*l, i)).collect();
    report::labelled_strip(&refs)
}

fn per_frame_plot(per: &[FrameEval]) -> Result<image::RgbImage> {
    let mut sorted: Vec<&FrameEval> = per.iter().collect();
    sorted.sort_by(|a, b| a.time.total_cmp(&b.time));
    let series = |label: &str, f: &dyn Fn(&FrameEval) -> Option<f64>, c: usize| Series {
        label: label.into(),
        points: sorted
            .iter()
            .filter_map(|e| f(e).map(|v| (e.time as f64, v)))
            .collect(),
        color: PALETTE[c],
    };
    let psnr = Plot {
        title: "test PSNR per frame".into(),
        x_label: "time".into(),
        y_label: "PSNR (dB)".into(),
        series: vec![series("PSNR", &|e| Some(e.values.psnr), 0)],
        width: 640,
        height: 240,
    };
    let motion = Plot {
        title: "motion metrics per frame".into(),
        x_label: "time".into(),
        y_label: "score".into(),
        series: vec![
            series("AP (MMAP)", &|e| e.ap, 1),
            series("DRC", &|e| e.drc, 2),
        ],
        width: 640,
        height: 240,
    };
    report::stacked(&[psnr.render()?, motion.render()?])
}

/// Reads a run's `log.jsonl`, naming the line of a malformed entry.
pub fn read_log(path: &Path) -> Result<Vec<LogLine>> {
    let text = std::fs::read_to_string(path).map_err(|source| Error::Io {
        path: path.display().to_string(),
        source,
    })?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            serde_json::from_str(l).map_err(|e| invalid(path, format!("line {}: {e}", i + 1)))
        })
        .collect()
}

fn training_plot(log: &[LogLine]) -> Result<image::RgbImage> {
    let plot = |title: &str, y: &str, f: &dyn Fn(&LogLine) -> f64, c: usize| Plot {
        title: title.into(),
        x_label: "iteration".into(),
        y_label: y.into(),
        series: vec![Series {
            label: String::new(),
            points: log.iter().map(|l| (l.iteration as f64, f(l))).collect(),
            color: PALETTE[c],
        }],
        width: 640,
        height: 200,
    };
    report::stacked(&[
        plot("training loss", "loss", &|l| l.loss, 0).render()?,
        plot("training-view PSNR", "PSNR (dB)", &|l| l.psnr, 1).render()?,
        plot("Gaussians", "count", &|l| l.num_gaussians as f64, 2).render()?,
    ])
}

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
    /// Put the displacement-flow heatmap (motion since the previous dataset time) beside
    /// each frame.
    #[arg(long)]
    pub flow: bool,
    /// Also write the deformed Gaussians of every frame as standard 3DGS .ply files
    /// (`ply/frame_NNNN.ply`) plus `ply/canonical.ply`.
    #[arg(long)]
    pub ply: bool,
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
    let r = Mat3::from_cols_array_2d(&c.rot).transpose();
    -(r.transpose() * Vec3::from(c.trans))
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
        std::fs::create_dir_all(&dir).map_err(|source| Error::Io {
            path: dir.display().to_string(),
            source,
        })?;
        write_ply(&dir.join("canonical.ply"), &tr.gaussians()?)?;
    }
    let pb = indicatif::ProgressBar::new(views.len() as u64);
    pb.set_style(
        indicatif::ProgressStyle::with_template(
            "render {bar:30} {pos}/{len} [{elapsed_precise}<{eta_precise}]",
        )
        .expect("progress template"),
    );
    let mut written = Vec::new();
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
        let e = tr.render_motion(&v.camera, v.time, prev, None, true)?;
        let im = e.images.expect("images requested");
        let (w, h) = (im.width, im.height);
        let render = report::rgb_image(&im.render, w, h)?;
        let img = if a.flow {
            let heat = report::heatmap(&im.motion, w, h)?;
            let t_label = format!("t={:.3}", v.time);
            report::labelled_strip(&[(t_label.as_str(), &render), ("disp. flow", &heat)])?
        } else {
            render
        };
        let path = out.join(format!("{k:04}.png"));
        report::save_png(&img, &path)?;
        written.push(path);
        if a.ply {
            let g = tr.deformed_gaussians(v.time)?;
            write_ply(&out.join("ply").join(format!("frame_{k:04}.ply")), &g)?;
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    eprintln!(
        "{} frames ({} path) in {}",
        written.len(),
        path_name,
        out.display()
    );
    Ok(written)
}
