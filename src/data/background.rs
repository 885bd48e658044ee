//! `--background auto`: the background colour a scene's transparent pixels agree on, decided
//! from the images' alpha before they are composited (issue 57).
//!
//! A D-NeRF scene (one object, every view mostly clear) and an image set without alpha get
//! black, the official Deformable-3DGS rule for blender scenes (`-w` for white). A scene whose
//! views disagree about what is transparent, as mujoco-scene5's floor (98 % clear from above,
//! opaque from the side), is composited on the colour that surface has where it is opaque: the
//! mean colour of the opaque pixels of the mostly opaque views, rounded to black or white (the
//! two backgrounds the renderer takes). Composited on anything else, the floor is one colour in
//! some views and another in the rest, and the model hides what moves over it behind a layer
//! of background-coloured Gaussians.

use std::path::Path;

use rayon::prelude::*;

use super::blender::{read_transforms, val_split_name, CLEAR_VIEW, OPAQUE_VIEW};
use super::{detect_format, image as img, DataResult, Format};

/// What `auto` chose and why (printed by `train`, recorded in `metrics.json`).
#[derive(Clone, Debug, PartialEq)]
pub struct BackgroundPick {
    pub white: bool,
    pub reason: String,
}

impl BackgroundPick {
    pub fn colour(&self) -> [f32; 3] {
        if self.white {
            [1.0; 3]
        } else {
            [0.0; 3]
        }
    }

    pub fn name(&self) -> &'static str {
        if self.white {
            "white"
        } else {
            "black"
        }
    }
}

/// One view's transparency: the fraction of pixels under half opacity and the summed colour
/// and count of the others.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ViewAlpha {
    pub clear: f32,
    pub opaque_sum: [f64; 3],
    pub opaque: u64,
}

/// Reads every train and validation image of the dataset at `dir` and picks its background.
pub fn pick_background(dir: &Path) -> DataResult<BackgroundPick> {
    if detect_format(dir)? != Format::Blender {
        return Ok(BackgroundPick {
            white: false,
            reason: "the images carry no alpha (nerfies format): black".into(),
        });
    }
    let mut frames = read_transforms(dir, "train")?;
    if let Some(s) = val_split_name(dir) {
        frames.extend(read_transforms(dir, s)?);
    }
    let views: Vec<(String, Option<ViewAlpha>)> = frames
        .par_iter()
        .map(|f| Ok((f.file_path.clone(), view_alpha(&f.image)?)))
        .collect::<DataResult<_>>()?;
    let views: Vec<(&str, ViewAlpha)> = views
        .iter()
        .filter_map(|(n, v)| v.map(|v| (n.as_str(), v)))
        .collect();
    Ok(decide(&views))
}

/// The alpha statistics of one PNG (`None` without an alpha channel).
pub fn view_alpha(path: &Path) -> DataResult<Option<ViewAlpha>> {
    let im = img::decode(path)?;
    if !im.color().has_alpha() {
        return Ok(None);
    }
    let rgba = im.into_rgba32f();
    let mut v = ViewAlpha::default();
    let mut clear = 0u64;
    for p in rgba.pixels() {
        if p[3] < 0.5 {
            clear += 1;
        } else {
            v.opaque += 1;
            for c in 0..3 {
                v.opaque_sum[c] += p[c].clamp(0.0, 1.0) as f64;
            }
        }
    }
    v.clear = clear as f32 / (clear + v.opaque).max(1) as f32;
    Ok(Some(v))
}

/// The rule, on the views' statistics (pure, unit-tested).
pub fn decide(views: &[(&str, ViewAlpha)]) -> BackgroundPick {
    let black = |reason: String| BackgroundPick {
        white: false,
        reason,
    };
    let (Some(most), Some(least)) = (
        views.iter().max_by(|a, b| a.1.clear.total_cmp(&b.1.clear)),
        views.iter().min_by(|a, b| a.1.clear.total_cmp(&b.1.clear)),
    ) else {
        return black("the images carry no alpha: black".into());
    };
    let range = format!(
        "{:.0}–{:.0} % of each view transparent",
        100.0 * least.1.clear,
        100.0 * most.1.clear
    );
    if !(most.1.clear >= CLEAR_VIEW && least.1.clear <= OPAQUE_VIEW) {
        return black(format!(
            "the views agree on what is transparent ({range}): black, the official rule for \
             blender scenes"
        ));
    }
    let (mut sum, mut n) = ([0.0f64; 3], 0u64);
    for (_, v) in views.iter().filter(|v| v.1.clear <= OPAQUE_VIEW) {
        (0..3).for_each(|c| sum[c] += v.opaque_sum[c]);
        n += v.opaque;
    }
    let mean = sum.map(|s| s / n.max(1) as f64);
    let grey = (mean[0] + mean[1] + mean[2]) / 3.0;
    let white = grey >= 0.5;
    BackgroundPick {
        white,
        reason: format!(
            "views disagree about what is transparent ({} {:.0} %, {} {:.0} %): a surface some \
             views see through is ({:.2}, {:.2}, {:.2}) where opaque, nearer {}",
            most.0,
            100.0 * most.1.clear,
            least.0,
            100.0 * least.1.clear,
            mean[0],
            mean[1],
            mean[2],
            if white { "white" } else { "black" }
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn view(clear: f32, colour: f64) -> ViewAlpha {
        let opaque = ((1.0 - clear) * 1000.0) as u64;
        ViewAlpha {
            clear,
            opaque_sum: [colour * opaque as f64; 3],
            opaque,
        }
    }

    #[test]
    fn a_white_floor_seen_through_from_above_picks_white() {
        let p = decide(&[("top", view(0.98, 0.2)), ("side", view(0.22, 0.9))]);
        assert!(p.white, "{}", p.reason);
        assert!(p.reason.contains("top 98 %"), "{}", p.reason);
    }

    #[test]
    fn a_dark_floor_picks_black_and_agreeing_views_pick_black() {
        assert!(!decide(&[("top", view(0.98, 0.9)), ("side", view(0.22, 0.1))]).white);
        // An object on a clear background (D-NeRF): every view mostly clear.
        let p = decide(&[("a", view(0.95, 0.9)), ("b", view(0.62, 0.9))]);
        assert!(!p.white && p.reason.contains("agree"), "{}", p.reason);
        // Opaque everywhere (a floor opaque from every view).
        assert!(!decide(&[("a", view(0.45, 0.9)), ("b", view(0.005, 0.9))]).white);
        assert!(!decide(&[]).white);
    }
}
