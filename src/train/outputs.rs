//! What a training run writes besides its model: `log.jsonl` lines (and cutting them back on
//! resume), side-by-side PNGs, the dynamic-mask pictures, and the clean-up of what a killed
//! run leaves behind; reading `log.jsonl` back and drawing `training.png`; `dynamic.bin`.

use std::path::Path;

use serde::Serialize;

use super::checkpoint::write_atomic;
use super::Trainer;
use crate::error::{Error, Result};
use crate::model::dynamic::SplitSnapshot;
use crate::report::{self, Plot, Series, PALETTE};

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
    /// Transient Gaussians among `num_gaussians` (with transients on).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transients: Option<u32>,
    /// The collapse guard's probe views (fixed training frames): their mean latest PSNR and
    /// their mean fall below their own best (dB).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_psnr: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub probe_fall_db: Option<f64>,
    /// The worst training-view PSNR since the previous line, and that view's frame id.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worst_psnr: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worst_view: Option<String>,
    /// A collapse confirmed since the previous line (and the rollback it caused).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub collapse: Option<super::collapse::CollapseEvent>,
    /// A densification step since the previous line that removed most of the Gaussians.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prune: Option<super::collapse::PruneEvent>,
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
                std::fs::remove_file(&p).map_err(Error::io(&p))?;
            }
        }
    }
    let m = out.join("metrics.json");
    if m.is_file() {
        std::fs::remove_file(&m).map_err(Error::io(&m))?;
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
        Err(e) => return Err(Error::io(path)(e)),
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

/// Floats per Gaussian in `dynamic.bin`: the flag (0.0 static, 1.0 dynamic), then the
/// static deformation (dx 3, dr 4, ds 3) the Gaussian is drawn with while static.
pub const DYN_ROW: usize = 11;

/// `dynamic.bin`: little-endian f32 rows of [`DYN_ROW`], one per Gaussian of
/// `point_cloud.ply` (the canonical ones; transients are never split), in its order. Absent:
/// every Gaussian dynamic.
pub fn dynamic_bin(s: &SplitSnapshot) -> Vec<u8> {
    let mut v = Vec::with_capacity(DYN_ROW * s.flags.len());
    for (f, row) in s.flags.iter().zip(s.fixed.chunks_exact(10)) {
        v.push(*f as f32);
        v.extend_from_slice(row);
    }
    bytemuck::cast_slice(&v).to_vec()
}

/// `NNN_<id>.png` with the id made file-name safe.
pub fn frame_png(i: usize, id: &str) -> String {
    let safe: String = id
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    format!("{i:03}_{safe}.png")
}

/// Reads a run's `log.jsonl`, naming the line of a malformed entry.
pub fn read_log(path: &Path) -> Result<Vec<LogLine>> {
    let text = std::fs::read_to_string(path).map_err(Error::io(path))?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            serde_json::from_str(l)
                .map_err(|e| Error::Invalid(format!("{}: line {}: {e}", path.display(), i + 1)))
        })
        .collect()
}

/// Loss, training-view PSNR (with the worst view of each interval), Gaussians against
/// iterations, and the test-PSNR probe against training seconds (when the log has it).
pub fn training_plot(log: &[LogLine]) -> Result<image::RgbImage> {
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
    let mut view = plot("training-view PSNR", "PSNR (dB)", &|l| l.psnr, 1);
    if log.iter().any(|l| l.worst_psnr.is_some()) {
        view.series[0].label = "logged view".into();
        view.series.push(Series {
            label: "worst view of the interval".into(),
            points: log
                .iter()
                .filter_map(|l| l.worst_psnr.map(|p| (l.iteration as f64, p)))
                .collect(),
            color: PALETTE[3],
        });
    }
    let mut plots = vec![
        plot("training loss", "loss", &|l| l.loss, 0).render()?,
        view.render()?,
        plot("Gaussians", "count", &|l| l.num_gaussians as f64, 2).render()?,
    ];
    if log.iter().any(|l| l.test_psnr.is_some()) {
        plots.push(crate::train::curve::psnr_time_plot(
            &[(String::new(), log)],
            640,
            200,
        )?);
    }
    if log.iter().any(|l| l.test_dynamic_psnr.is_some()) {
        plots.push(probe_plot(
            "test PSNR by region (probe frames)",
            "PSNR (dB)",
            log,
            &[
                ("whole image", &|l| l.test_psnr),
                ("dynamic (dilated mask)", &|l| l.test_dynamic_psnr),
                ("static", &|l| l.test_static_psnr),
            ],
        )?);
    }
    if log.iter().any(|l| l.motion_epe.is_some()) {
        plots.push(probe_plot(
            "the model's motion against the ground-truth flow (probe frames)",
            "pixels",
            log,
            &[
                ("EPE inside the masks", &|l| l.motion_epe),
                ("ground-truth flow length (EPE of no motion)", &|l| {
                    l.motion_gt_px
                }),
                ("Gaussians' motion p50", &|l| l.motion_p50_px),
                ("Gaussians' motion p99", &|l| l.motion_p99_px),
            ],
        )?);
    }
    report::stacked(&plots)
}

type LogValue<'a> = (&'a str, &'a dyn Fn(&LogLine) -> Option<f64>);

/// Probe values of the log against iterations, a series each.
fn probe_plot(
    title: &str,
    y: &str,
    log: &[LogLine],
    series: &[LogValue<'_>],
) -> Result<image::RgbImage> {
    Plot {
        title: title.into(),
        x_label: "iteration".into(),
        y_label: y.into(),
        series: series
            .iter()
            .enumerate()
            .map(|(c, (label, f))| Series {
                label: label.to_string(),
                points: log
                    .iter()
                    .filter_map(|l| f(l).map(|v| (l.iteration as f64, v)))
                    .collect(),
                color: PALETTE[c % PALETTE.len()],
            })
            .collect(),
        width: 640,
        height: 200,
    }
    .render()
}
