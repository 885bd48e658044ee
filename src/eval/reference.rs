//! `dispflow-vk score-renders`: scores another implementation's test renders with this
//! project's evaluation, so its numbers sit in the same tables as ours (issue 38: the official
//! Deformable-3DGS trained on our scenes). Renders in: a folder of PNGs, one per test frame,
//! in the test split's order (sorted by file name, as the official `render.py` writes
//! `00000.png`, `00001.png`, …). A result out: the sweep cell `cells/<scene>/<variant>/seed<N>/`
//! with `cell.json` (what `sweep report` tables), `metrics.json` with the per-frame rows, and
//! the sweep's `results.jsonl` rewritten.
//!
//! Scores are this project's definitions, on the images as they are (8-bit PNGs for a render
//! saved as one): PSNR and SSIM by the same GPU kernels `eval` runs (11×11 Gaussian window),
//! PSNR inside and outside the dilated motion masks, LPIPS (AlexNet) when weights are given.
//! The ground truth is loaded by this project's loader at `--max-resolution` (box
//! downscaling) on `--background`.

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::data::{self, Dataset, LoadOptions};
use crate::error::{Error, Result};
use crate::kernels::loss::PhotometricLoss;
use crate::results::{cell_files, cell_key, read_cell, write_cell, write_results, CellResult};
use crate::train::checkpoint::write_atomic;
use crate::train::config::Background;
use crate::train::score::lpips::LpipsScorer;
use crate::train::score::regions::{region_psnr, MASK_DILATE_PX};
use crate::vk::{Gpu, Recorder};

#[derive(clap::Args, Debug, Clone)]
pub struct ScoreArgs {
    /// The dataset the renders are of; its test split (D-NeRF: transforms_test.json) gives the
    /// ground truth, in order.
    #[arg(long)]
    pub data: PathBuf,
    /// Folder of the renders: one PNG per test frame; sorted by file name they follow the
    /// split's order. Their size must be the ground truth's at --max-resolution.
    #[arg(long)]
    pub renders: PathBuf,
    /// Largest image side the ground truth is loaded at (box-downscaled by an integer factor)
    /// [default: as stored].
    #[arg(long)]
    pub max_resolution: Option<u32>,
    /// Background the ground truth's transparent pixels are composited on [default: black,
    /// the official code's without --white_background].
    #[arg(long, value_enum)]
    pub background: Option<Background>,
    /// LPIPS (AlexNet) weights in this project's safetensors format; without them the LPIPS
    /// column reads n/a.
    #[arg(long)]
    pub lpips_weights: Option<PathBuf>,
    /// Method name in the tables.
    #[arg(long, default_value = "official Deformable-3DGS")]
    pub method: String,
    /// Variant (row) label in the sweep's tables [default: the method name].
    #[arg(long)]
    pub variant: Option<String>,
    /// Scene name in the sweep's tables [default: the dataset directory's name].
    #[arg(long)]
    pub scene: Option<String>,
    /// Seed the renders' training used.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// The implementation's code revision (recorded with the result).
    #[arg(long)]
    pub commit: Option<String>,
    /// Training iterations the renders come from.
    #[arg(long)]
    pub iterations: u32,
    /// Wall seconds of the training (its seconds per iteration = this / --iterations).
    #[arg(long)]
    pub train_seconds: Option<f64>,
    /// The trained model's PLY, to count its Gaussians (the header's vertex count).
    #[arg(long)]
    pub ply: Option<PathBuf>,
    /// The device the training ran on, as a person reads it.
    #[arg(long, default_value = "")]
    pub device: String,
    /// Sweep directory the result goes into (created if missing).
    #[arg(long)]
    pub out: PathBuf,
}

/// One scored render.
#[derive(Clone, Debug, Serialize)]
pub struct RenderScore {
    pub file: String,
    pub id: String,
    pub time: f32,
    pub psnr: f64,
    pub ssim: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dynamic_psnr: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub static_psnr: Option<f64>,
    /// Share of the frame's pixels inside the dilated motion mask.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub dynamic_share: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lpips: Option<f64>,
}

/// `metrics.json` of a scored folder.
#[derive(Clone, Debug, Serialize)]
pub struct ScoreReport {
    pub method: String,
    pub commit: Option<String>,
    pub renders: String,
    pub dataset: String,
    pub iterations: u32,
    pub psnr: f64,
    pub ssim: f64,
    pub lpips: Option<f64>,
    pub dynamic_psnr: Option<f64>,
    pub static_psnr: Option<f64>,
    pub worst_psnr: f64,
    pub num_gaussians: Option<u32>,
    pub seconds_per_iteration: Option<f64>,
    pub per_frame: Vec<RenderScore>,
}

fn invalid(path: &Path, why: impl std::fmt::Display) -> Error {
    Error::Invalid(format!("{}: {why}", path.display()))
}

/// The PNG files of `dir`, sorted by name.
/// The PSNR a pixel-identical frame scores (∞ otherwise: JSON has no infinity, and a mean
/// over frames needs a finite value). Scoring a run's own ground-truth PNGs, the check that the
/// two pipelines load the same frames, gives exactly this.
pub const PSNR_CAP: f64 = 100.0;

pub fn render_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let rd = std::fs::read_dir(dir).map_err(|e| invalid(dir, format!("cannot read: {e}")))?;
    let mut v: Vec<PathBuf> = rd
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")))
        .collect();
    v.sort();
    Ok(v)
}

/// The vertex count in a PLY header.
pub fn ply_vertex_count(path: &Path) -> Result<u32> {
    let bytes = std::fs::read(path).map_err(|e| invalid(path, format!("cannot read: {e}")))?;
    let head = &bytes[..bytes.len().min(4096)];
    let text = String::from_utf8_lossy(head);
    text.lines()
        .take_while(|l| *l != "end_header")
        .find_map(|l| l.strip_prefix("element vertex "))
        .and_then(|n| n.trim().parse().ok())
        .ok_or_else(|| invalid(path, "no \"element vertex N\" line in the PLY header"))
}

/// Scores every render of `a.renders` against `ds`'s test frames.
pub fn score_folder(gpu: &Gpu, a: &ScoreArgs, ds: &Dataset) -> Result<Vec<RenderScore>> {
    let files = render_files(&a.renders)?;
    if files.len() != ds.val.len() {
        return Err(invalid(
            &a.renders,
            format!(
                "{} PNG files; the test split of {} has {} frames (one render per frame, in order)",
                files.len(),
                ds.root.display(),
                ds.val.len()
            ),
        ));
    }
    let loss = PhotometricLoss::new(gpu)?;
    let mut lp = match &a.lpips_weights {
        Some(w) => Some(LpipsScorer::open(gpu, w)?),
        None => None,
    };
    let bg = match a.background {
        Some(Background::White) => [1.0; 3],
        _ => [0.0; 3],
    };
    let mut out = Vec::with_capacity(files.len());
    let mut bufs = None;
    for (f, frame) in files.iter().zip(&ds.val) {
        let (w, h) = (frame.image.width, frame.image.height);
        let img = crate::data::image::load_rgb(f, bg)?;
        if (img.width, img.height) != (w, h) {
            return Err(invalid(
                f,
                format!(
                    "{}×{} pixels; test frame {} is {w}×{h} at this --max-resolution",
                    img.width, img.height, frame.id
                ),
            ));
        }
        let rgba = |d: &[f32]| -> Vec<[f32; 4]> {
            d.chunks_exact(3).map(|p| [p[0], p[1], p[2], 1.0]).collect()
        };
        let (render, gt) = (rgba(&img.data), rgba(&frame.image.data));
        if bufs
            .as_ref()
            .map_or(true, |b: &crate::kernels::loss::LossBuffers| {
                (b.width, b.height) != (w, h)
            })
        {
            bufs = Some(loss.buffers(gpu, w, h)?);
        }
        let b = bufs.as_mut().expect("made above");
        let r_buf = gpu.buffer_from("scored render", &render)?;
        let g_buf = gpu.buffer_from("scored ground truth", &gt)?;
        let d_buf = gpu.buffer("scored render gradient", (w * h) as u64 * 16)?;
        let mut rec = Recorder::new(gpu)?;
        loss.record(&mut rec, b, r_buf.all(), g_buf.all(), d_buf.all(), 0.2);
        rec.finish()?;
        let v = b.values(gpu)?;
        let regions = frame
            .mask
            .as_ref()
            .filter(|m| m.iter().any(|&x| x != 0))
            .map(|m| region_psnr(&render, &gt, m, w, h, MASK_DILATE_PX));
        let lpips = match lp.as_mut() {
            Some(s) => Some(s.score(gpu, (w, h), r_buf.all(), g_buf.all())?),
            None => None,
        };
        out.push(RenderScore {
            file: f
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            id: frame.id.clone(),
            time: frame.time,
            psnr: v.psnr.min(PSNR_CAP),
            ssim: v.ssim,
            dynamic_psnr: regions.and_then(|r| r.dynamic).map(|p| p.min(PSNR_CAP)),
            static_psnr: regions.and_then(|r| r.static_).map(|p| p.min(PSNR_CAP)),
            dynamic_share: regions.and_then(|r| r.dynamic_share),
            lpips,
        });
    }
    Ok(out)
}

fn mean_of(v: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let s: Vec<f64> = v.flatten().filter(|x| x.is_finite()).collect();
    (!s.is_empty()).then(|| s.iter().sum::<f64>() / s.len() as f64)
}

/// The whole command: scores the folder and writes the sweep cell; returns its result.
pub fn run_score(a: &ScoreArgs) -> Result<CellResult> {
    if a.iterations == 0 {
        return Err(Error::Invalid(
            "--iterations 0: expected the training iterations the renders come from".into(),
        ));
    }
    let opts = LoadOptions {
        max_size: a.max_resolution.filter(|&m| m > 0),
        background: match a.background {
            Some(Background::White) => [1.0; 3],
            _ => [0.0; 3],
        },
        // No initial points are used: the fewest random ones.
        points: data::PointsPreference::Random,
        random_points: 1,
        ..LoadOptions::default()
    };
    let ds = data::load(&a.data, &opts)?;
    let gpu = Gpu::new_default()?;
    let per = score_folder(&gpu, a, &ds)?;
    let gaussians = match &a.ply {
        Some(p) => Some(ply_vertex_count(p)?),
        None => None,
    };
    let spi = a.train_seconds.map(|s| s / a.iterations as f64);
    let report = ScoreReport {
        method: a.method.clone(),
        commit: a.commit.clone(),
        renders: a.renders.display().to_string(),
        dataset: a.data.display().to_string(),
        iterations: a.iterations,
        psnr: mean_of(per.iter().map(|p| Some(p.psnr))).unwrap_or(f64::NAN),
        ssim: mean_of(per.iter().map(|p| Some(p.ssim))).unwrap_or(f64::NAN),
        lpips: mean_of(per.iter().map(|p| p.lpips)),
        dynamic_psnr: mean_of(per.iter().map(|p| p.dynamic_psnr)),
        static_psnr: mean_of(per.iter().map(|p| p.static_psnr)),
        worst_psnr: per.iter().map(|p| p.psnr).fold(f64::INFINITY, f64::min),
        num_gaussians: gaussians,
        seconds_per_iteration: spi,
        per_frame: per,
    };
    let scene = a.scene.clone().unwrap_or_else(|| {
        a.data
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "scene".into())
    });
    let variant = a.variant.clone().unwrap_or_else(|| a.method.clone());
    let key = cell_key(&scene, &variant, a.seed);
    let dir = a.out.join("cells").join(&key);
    std::fs::create_dir_all(&dir).map_err(|e| invalid(&dir, format!("cannot create: {e}")))?;
    let metrics = serde_json::to_string_pretty(&report).expect("report serialises");
    write_atomic(&dir.join("metrics.json"), metrics.as_bytes())?;
    let rel = dir
        .strip_prefix(&a.out)
        .unwrap_or(&dir)
        .display()
        .to_string();
    let result = CellResult {
        cell: key,
        scene,
        variant,
        seed: a.seed,
        args: Vec::new(),
        config_toml: String::new(),
        config: serde_json::json!({
            "implementation": a.method,
            "commit": a.commit,
            "iterations": a.iterations,
            "max_resolution": a.max_resolution.unwrap_or(0),
        }),
        method: a.method.clone(),
        device: a.device.clone(),
        iterations: a.iterations,
        num_gaussians: gaussians.unwrap_or(0),
        psnr: report.psnr,
        ssim: report.ssim,
        lpips: report.lpips,
        dynamic_psnr: report.dynamic_psnr,
        static_psnr: report.static_psnr,
        mmap: None,
        drc: None,
        ms_per_step: spi.map(|s| s * 1e3),
        train_seconds: a.train_seconds,
        cell_seconds: a.train_seconds.unwrap_or(0.0),
        jobs: 1,
        run: rel,
        strip: None,
        status: None,
        status_note: None,
    };
    write_cell(&dir, &result)?;
    // results.jsonl: the sweep's cells, this one included.
    let all = cell_files(&a.out)
        .iter()
        .map(|f| read_cell(f))
        .collect::<Result<Vec<_>>>()?;
    write_results(&a.out, &all)?;
    println!(
        "{}: PSNR {:.2} dB (dynamic {}, static {}, worst frame {:.2}), SSIM {:.4} over {} renders → {}",
        result.cell,
        report.psnr,
        report
            .dynamic_psnr
            .map_or("n/a".into(), |v| format!("{v:.2}")),
        report
            .static_psnr
            .map_or("n/a".into(), |v| format!("{v:.2}")),
        report.worst_psnr,
        report.ssim,
        report.per_frame.len(),
        dir.display()
    );
    Ok(result)
}
