//! What a training run writes besides its model: `log.jsonl` lines (and cutting them back on
//! resume), side-by-side PNGs, the dynamic-mask pictures, and the clean-up of what a killed
//! run leaves behind.

use std::path::Path;

use serde::Serialize;

use super::checkpoint::write_atomic;
use super::Trainer;
use crate::error::{Error, Result};
use crate::eval::run::frame_png;

fn io(path: &Path) -> impl Fn(std::io::Error) -> Error + '_ {
    move |source| Error::Io {
        path: path.display().to_string(),
        source,
    }
}

/// One line of a run's `log.jsonl` (every `log_interval` iterations).
#[derive(Debug, Default, Serialize, serde::Deserialize)]
pub struct LogLine {
    pub iteration: u32,
    pub loss: f64,
    /// PSNR of the training view of that iteration.
    pub psnr: f64,
    pub num_gaussians: u32,
    /// Motion weight α_t in force (0 before the motion term starts).
    pub motion_weight: f32,
    /// GPU milliseconds of the step (only with --verbose, else wall milliseconds).
    pub ms: f64,
    /// Fraction of the Gaussians the deformation runs over (1 while dense).
    #[serde(default = "one")]
    pub dynamic_fraction: f64,
    /// Wall seconds of training so far (steps only; a resumed run continues the count).
    #[serde(default)]
    pub wall_s: f64,
    /// Mean test PSNR of the probe frames (every `test_interval` iterations, else absent).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_psnr: Option<f64>,
    /// The probe's PSNR inside and outside the dilated motion masks (test frames with masks).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_dynamic_psnr: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub test_static_psnr: Option<f64>,
    /// The probe's displacement EPE inside the masks, pixels (scenes with ground-truth flow),
    /// next to the ground-truth flow's mean length there (a motionless model's EPE) and the
    /// median and 99th percentile of the Gaussians' projected motion.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion_epe: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion_gt_px: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion_p50_px: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion_p99_px: Option<f64>,
    /// The worst training-view PSNR since the previous line, and that view's frame id.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worst_psnr: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worst_view: Option<String>,
    /// A collapse confirmed since the previous line (and the rollback it caused).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub collapse: Option<super::collapse::CollapseEvent>,
}

fn one() -> f64 {
    1.0
}

/// Before training: removes what a killed run can leave behind (`*.tmp` files of interrupted
/// atomic writes) and `metrics.json`, the mark of a finished run, which is written again
/// last, so a run killed from here on never looks finished.
pub(crate) fn remove_stale_outputs(out: &Path, fresh: bool) -> Result<()> {
    for dir in [
        out.to_path_buf(),
        out.join("checkpoints"),
        out.join("renders"),
    ] {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            // A fresh run also drops an earlier run's kept checkpoints (`NNNNNN.ckpt`):
            // `signal` would score another run's models.
            let kept = super::checkpoint::is_kept_checkpoint(&p);
            if (p.extension().is_some_and(|x| x == "tmp") || (fresh && kept)) && p.is_file() {
                std::fs::remove_file(&p).map_err(io(&p))?;
            }
        }
    }
    let m = out.join("metrics.json");
    if m.is_file() {
        std::fs::remove_file(&m).map_err(io(&m))?;
    }
    Ok(())
}

/// `wall_s` of the last line of a run's `log.jsonl` (0 without one).
pub(crate) fn last_wall_s(path: &Path) -> f64 {
    std::fs::read_to_string(path)
        .ok()
        .and_then(|t| {
            t.lines()
                .rev()
                .find_map(|l| serde_json::from_str::<LogLine>(l).ok())
        })
        .map_or(0.0, |l| l.wall_s)
}

/// Keeps the lines of a run's `log.jsonl` up to `iteration` (the checkpoint a run resumes
/// from): the resumed run logs the later iterations again, and a line cut short by a kill is
/// dropped. A missing log is created empty.
pub(crate) fn truncate_log(path: &Path, iteration: u32) -> Result<()> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Vec::new(),
        Err(e) => return Err(io(path)(e)),
    };
    let text = String::from_utf8_lossy(&bytes);
    let mut keep = String::new();
    for line in text.split_inclusive('\n') {
        let whole = line.ends_with('\n');
        match serde_json::from_str::<LogLine>(line.trim()) {
            Ok(l) if whole && l.iteration <= iteration => keep.push_str(line),
            _ => break,
        }
    }
    write_atomic(path, keep.as_bytes())
}

/// `renders/dynamic/<frame>.png` per test frame: where the render sees dynamic Gaussians
/// (white) beside the ground-truth motion mask when the dataset has one.
pub fn write_dynamic_masks(tr: &mut Trainer, dir: &Path) -> Result<()> {
    for i in 0..tr.val.len() {
        let (cam, t, id) = (tr.val[i].camera, tr.val[i].time, tr.val[i].id.clone());
        let m = tr.dynamic_mask(&cam, t)?;
        let gray = |v: f32| [v, v, v, 1.0];
        let mask: Vec<[f32; 4]> = m.iter().map(|&v| gray(v)).collect();
        let mut images = vec![&mask[..]];
        let gt: Vec<[f32; 4]>;
        if let Some((_, host)) = &tr.val[i].mask {
            gt = host.iter().map(|&b| gray((b != 0) as u8 as f32)).collect();
            images.push(&gt);
        }
        save_side_by_side(&dir.join(frame_png(i, &id)), cam.width, cam.height, &images)?;
    }
    Ok(())
}

/// Writes images (RGBA f32, alpha ignored) side by side as one 8-bit PNG.
pub fn save_side_by_side(path: &Path, w: u32, h: u32, images: &[&[[f32; 4]]]) -> Result<()> {
    let k = images.len() as u32;
    let img = image::RgbImage::from_fn(w * k, h, |x, y| {
        let p = images[(x / w) as usize][(y * w + x % w) as usize];
        image::Rgb([0, 1, 2].map(|c| (p[c].clamp(0.0, 1.0) * 255.0).round() as u8))
    });
    crate::report::save_png(&img, path)
}
