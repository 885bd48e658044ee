//! `dispflow-vk eval`: reopen a trained run directory (its `config.toml`, `metrics.json`,
//! `point_cloud.ply`, `deform.bin`), score it on the test split and draw what a person wants
//! to look at.

use std::path::{Path, PathBuf};

use crate::data::{self, Dataset};
use crate::error::{Error, Result};
use crate::model::deform::MlpLayout;
use crate::model::dynamic::SplitSnapshot;
use crate::model::gaussians::HostGaussians;
use crate::model::nodes::FieldKind;
use crate::model::state::{gaussian_blobs, mlp_config_of};
use crate::report::{self, Plot, Series, PALETTE};
use crate::train::checkpoint::{read_ply, write_atomic};
use crate::train::config::TrainConfig;
use crate::train::metrics::{table, Report, ReportContext};
use crate::train::outputs::{frame_png, read_log, training_plot, LogLine, DYN_ROW};
use crate::train::score::lpips::{self, LpipsScorer};
use crate::train::score::{FrameEval, FrameImages};
use crate::train::Trainer;
use crate::vk::Gpu;

/// A trained run as written by `dispflow-vk train`.
pub struct Run {
    pub dir: PathBuf,
    pub cfg: TrainConfig,
    pub data_dir: PathBuf,
    pub iterations: u32,
    pub gaussians: HostGaussians,
    pub mlp: Vec<f32>,
    /// The dynamic/static split (`dynamic.bin`); `None`: all dynamic.
    pub dynamic: Option<SplitSnapshot>,
    /// The control nodes (`nodes.bin`, [4M] f32) of a nodes-field run; `None` for the MLP field.
    pub nodes: Option<Vec<f32>>,
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
    let text = std::fs::read_to_string(&metrics_path).map_err(Error::io(&metrics_path))?;
    let m: serde_json::Value = serde_json::from_str(&text).map_err(|e| {
        invalid(
            &metrics_path,
            format!("{e}; expected the JSON object `dispflow-vk train` writes when it finishes"),
        )
    })?;
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
    let ply = need("point_cloud.ply")?;
    let mut gaussians = read_ply(&ply)?;
    if gaussians.populations().temporal() {
        return Err(invalid(
            &ply,
            "holds transient Gaussians; a run writes them to transients.ply",
        ));
    }
    // The transient Gaussians (a run with `transient.mode = on`), after the canonical ones.
    let tply = dir.join("transients.ply");
    if tply.is_file() {
        let t = read_ply(&tply)?;
        if t.sh_coeffs != gaussians.sh_coeffs || !t.canonical_rows().is_empty() {
            return Err(invalid(
                &tply,
                "expected transient Gaussians with point_cloud.ply's SH coefficients",
            ));
        }
        gaussians.append(&t);
    }
    let coeffs = (cfg.sh_degree + 1).pow(2);
    if gaussians.sh_coeffs != coeffs {
        return Err(invalid(
            &ply,
            format!(
                "{} SH coefficients per Gaussian; config.toml's sh_degree = {} needs {coeffs}",
                gaussians.sh_coeffs, cfg.sh_degree
            ),
        ));
    }
    if gaussians.len() > cfg.densify.budget as usize {
        return Err(invalid(
            &ply,
            format!(
                "{} Gaussians; config.toml's densify.budget is {}",
                gaussians.len(),
                cfg.densify.budget
            ),
        ));
    }
    for b in gaussian_blobs("", &gaussians, false) {
        let row = b.row.unwrap_or(1).max(1);
        if let Some(i) = b.data.iter().position(|v| !v.is_finite()) {
            return Err(invalid(
                &ply,
                format!(
                    "Gaussian {}: {} holds {}; expected finite values (a run that diverged)",
                    i / row,
                    b.name,
                    b.data[i]
                ),
            ));
        }
    }
    let weights = need("deform.bin")?;
    let bytes = std::fs::read(&weights).map_err(Error::io(&weights))?;
    // The MLP's size follows from config.toml and the dataset's kind (its time encoding).
    let synthetic = data::detect_format(&data_dir)? == data::Format::Blender;
    let floats = MlpLayout::new(&mlp_config_of(synthetic, cfg.mlp_shape()))?.total;
    if bytes.len() != floats * 4 {
        return Err(invalid(
            &weights,
            format!(
                "{} bytes; config.toml's {}×{} deformation MLP for this dataset is {floats} f32 \
                 ({} bytes): truncated, or from another run",
                bytes.len(),
                cfg.mlp_depth,
                cfg.mlp_width,
                floats * 4
            ),
        ));
    }
    let mlp: Vec<f32> = bytemuck::pod_collect_to_vec(&bytes);
    if let Some(i) = mlp.iter().position(|v| !v.is_finite()) {
        return Err(invalid(
            &weights,
            format!(
                "weight {i} is {}; expected finite weights (a run that diverged)",
                mlp[i]
            ),
        ));
    }
    let dyn_path = dir.join("dynamic.bin");
    let dynamic = if dyn_path.is_file() {
        let b = std::fs::read(&dyn_path).map_err(Error::io(&dyn_path))?;
        // One row per canonical Gaussian (point_cloud.ply's; transients are never split).
        let canonical = gaussians.canonical_rows().len() as usize;
        let want = 4 * DYN_ROW * canonical;
        if b.len() != want {
            return Err(invalid(
                &dyn_path,
                format!(
                    "{} bytes; point_cloud.ply's {canonical} Gaussians need {want} ({DYN_ROW} \
                     f32 each)",
                    b.len(),
                ),
            ));
        }
        let v: Vec<f32> = bytemuck::pod_collect_to_vec(&b);
        let mut s = SplitSnapshot::default();
        for (i, row) in v.chunks_exact(DYN_ROW).enumerate() {
            s.flags.push(match row[0] {
                0.0 => 0,
                1.0 => 1,
                f => {
                    return Err(invalid(
                        &dyn_path,
                        format!("Gaussian {i}: flag {f}; expected 0 (static) or 1 (dynamic)"),
                    ))
                }
            });
            s.fixed.extend_from_slice(&row[1..]);
        }
        s.check().map_err(|e| invalid(&dyn_path, e))?;
        Some(s)
    } else {
        None
    };
    let nodes_path = dir.join("nodes.bin");
    let nodes = match cfg.deform_field.kind {
        FieldKind::Nodes if nodes_path.is_file() => {
            let b = std::fs::read(&nodes_path).map_err(Error::io(&nodes_path))?;
            let max = cfg.deform_field.nodes as usize;
            if b.len() % 16 != 0 || b.is_empty() || b.len() > 16 * max {
                return Err(invalid(
                    &nodes_path,
                    format!(
                        "{} bytes; expected 16 per control node (position, log-radius) for 1 to \
                         {max} nodes (config.toml's deform_field.nodes)",
                        b.len()
                    ),
                ));
            }
            Some(bytemuck::pod_collect_to_vec(&b))
        }
        // A nodes run stopped during the warm-up: no node was placed yet.
        _ => None,
    };
    Ok(Run {
        dir: dir.to_path_buf(),
        cfg,
        data_dir,
        iterations,
        gaussians,
        mlp,
        dynamic,
        nodes,
    })
}

/// Loads the run's dataset and a trainer holding its model.
pub fn load_trainer<'g>(gpu: &'g Gpu, run: &Run) -> Result<(Dataset, Trainer<'g>)> {
    let ds = data::load(&run.data_dir, &run.cfg.load_options())?;
    let mut tr = Trainer::new(gpu, &run.cfg, &ds)?;
    tr.load_model(&run.gaussians, &run.mlp, run.iterations)
        .map_err(|e| invalid(&run.dir, format!("the saved model does not load: {e}")))?;
    tr.model.dynamic.upload(gpu, run.dynamic.as_ref())?;
    if let (Some(ns), Some(p)) = (tr.model.nodes.as_mut(), &run.nodes) {
        let nodes = run.dir.join("nodes.bin");
        ns.upload(gpu, p, None).map_err(|e| invalid(&nodes, e))?;
    }
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
    /// LPIPS (AlexNet) weights in dispflow-vk's safetensors format (convert the reference
    /// package's files with tools/lpips_weights.py). Fills the LPIPS column and per-frame
    /// values; without it the column reads "n/a" (never a made-up number).
    #[arg(long)]
    pub lpips_weights: Option<PathBuf>,
    /// Where the combined table of several runs goes [default: print it only].
    #[arg(long)]
    pub table: Option<PathBuf>,
    /// Where a PNG of every run's test PSNR against training seconds goes (one curve per run,
    /// from each run's log.jsonl; runs trained before the probe existed have no curve).
    #[arg(long)]
    pub curves: Option<PathBuf>,
    /// Skip the PNG strips and plots (metrics and tables only).
    #[arg(long)]
    pub no_pictures: bool,
}

/// Runs `eval` over every `--run`; returns the reports (each also written to `DIR/eval/`).
pub fn run_eval(a: &EvalArgs) -> Result<Vec<Report>> {
    // A bad weight file fails before any run is opened or evaluated.
    let lpips_weights = match &a.lpips_weights {
        Some(p) => Some((p.clone(), lpips::load_weights(p)?)),
        None => None,
    };
    // Every run is checked before the first (slow) evaluation starts.
    let runs = a
        .run
        .iter()
        .map(|d| open_run(d, a.data.as_deref()))
        .collect::<Result<Vec<_>>>()?;
    let gpu = Gpu::new_default()?;
    eprintln!("device: {}", gpu.info);
    let mut lpips = match lpips_weights {
        Some((path, w)) => {
            let mut s = LpipsScorer::new(&gpu, w)?;
            s.source = path;
            Some(s)
        }
        None => None,
    };
    let mut reports = Vec::new();
    for run in &runs {
        let r = eval_one(&gpu, run, !a.no_pictures, lpips.as_mut())?;
        reports.push(r);
    }
    if let Some(p) = &a.curves {
        let logs = runs
            .iter()
            .map(|r| read_log(&r.dir.join("log.jsonl")))
            .collect::<Result<Vec<_>>>()?;
        let labelled: Vec<(String, &[LogLine])> = reports
            .iter()
            .zip(&logs)
            .map(|(r, l)| (format!("{} [{}]", r.method, r.run), &l[..]))
            .collect();
        report::save_png(
            &crate::train::curve::psnr_time_plot(&labelled, 800, 400)?,
            p,
        )?;
    }
    let t = table(&reports).to_markdown();
    if let Some(p) = &a.table {
        write_atomic(p, t.as_bytes())?;
    }
    println!("{t}");
    gpu.check_validation("eval")?;
    Ok(reports)
}

fn eval_one(
    gpu: &Gpu,
    run: &Run,
    pictures: bool,
    mut lpips: Option<&mut LpipsScorer>,
) -> Result<Report> {
    let (ds, mut tr) = load_trainer(gpu, run)?;
    if tr.val.is_empty() {
        return Err(invalid(&run.data_dir, "the dataset has no test frames"));
    }
    let out = run.dir.join("eval");
    let pb = report::progress(tr.val.len() as u64, "eval");
    pb.set_message(run.dir.display().to_string());
    let mut per = Vec::with_capacity(tr.val.len());
    for i in 0..tr.val.len() {
        let mut e = tr.evaluate_one(i, pictures)?;
        if let Some(s) = lpips.as_deref_mut() {
            e.lpips = Some(tr.lpips_one(i, s).map_err(|err| {
                invalid(&s.source, format!("LPIPS of test frame {:?}: {err}", e.id))
            })?);
        }
        if let Some(mut im) = e.images.take() {
            let (cam, t) = (tr.val[i].camera, tr.val[i].time);
            im.dynamic = Some(tr.dynamic_mask(&cam, t)?);
            let path = out.join("frames").join(frame_png(i, &e.id));
            report::save_png(&frame_strip(&im)?, &path)?;
        }
        per.push(e);
        pb.inc(1);
    }
    pb.finish_and_clear();
    let scene = ds
        .root
        .file_name()
        .map_or_else(|| "scene".into(), |s| s.to_string_lossy().into_owned());
    let ctx = ReportContext {
        run: run.dir.display().to_string(),
        scene,
        dataset: run.data_dir.display().to_string(),
        device: gpu.info.to_string(),
        iterations: run.iterations,
        num_gaussians: tr.n(),
    };
    let mut r = Report::new(&run.cfg, ctx, per);
    if let Some(s) = &lpips {
        r.set_lpips(&s.source);
    }
    // With --no-pictures no PNG has created the directory yet.
    std::fs::create_dir_all(&out).map_err(Error::io(&out))?;
    write_atomic(&out.join("metrics.json"), r.to_json().as_bytes())?;
    let t = table(std::slice::from_ref(&r)).to_markdown();
    write_atomic(&out.join("table.md"), t.as_bytes())?;
    if pictures {
        report::save_png(&per_frame_plot(&r.per_frame)?, &out.join("per_frame.png"))?;
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
        "{}: PSNR {:.2} (dynamic {}, static {}) SSIM {:.4} MMAP {} DRC {} (optical-flow MMAP {}) → {}",
        run.dir.display(),
        r.psnr,
        report::fmt_metric(r.dynamic_psnr, 2),
        report::fmt_metric(r.static_psnr, 2),
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
pub fn frame_strip(im: &FrameImages) -> Result<image::RgbImage> {
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
    if let Some(d) = &im.dynamic {
        panels.push(("dynamic", grey_image(d, w, h)?));
    }
    let refs: Vec<(&str, &image::RgbImage)> = panels.iter().map(|(l, i)| (*l, i)).collect();
    report::labelled_strip(&refs)
}

/// Values in [0, 1] as a grey picture (white = 1).
pub fn grey_image(v: &[f32], w: u32, h: u32) -> Result<image::RgbImage> {
    let px: Vec<[f32; 4]> = v.iter().map(|&x| [x, x, x, 1.0]).collect();
    report::rgb_image(&px, w, h)
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
        series: vec![
            series("PSNR", &|e| Some(e.psnr), 0),
            series("dynamic (dilated mask)", &|e| e.dynamic_psnr, 3),
            series("static", &|e| e.static_psnr, 4),
        ],
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
