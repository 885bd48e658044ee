//! Side-by-side labelled panels (render | ground truth | error | motion ...) and PNG output.

use std::io::Cursor;
use std::path::Path;

use image::{ImageFormat, RgbImage};

use super::text::{draw_text, fit_text, text_width};
use crate::error::{Error, Result};

/// Dark gap between panels, in pixels.
pub const GAP: u32 = 2;
/// Height of the label band above each panel, in pixels (8-px text plus 2 px above and below).
pub const LABEL_BAND: u32 = 12;

const BACKGROUND: [u8; 3] = [24, 24, 24];
const LABEL_COLOR: [u8; 3] = [235, 235, 235];

/// Places `panels` left to right, [`GAP`] pixels apart on a dark background, each under a
/// [`LABEL_BAND`]-pixel band holding its label (centred; cut to the panel width when too
/// long). All panels must have the same height.
pub fn labelled_strip(panels: &[(&str, &RgbImage)]) -> Result<RgbImage> {
    let Some((first_label, first)) = panels.first() else {
        return Err(Error::Invalid("labelled_strip: no panels".into()));
    };
    let height = first.height();
    let mut width: u64 = 0;
    for (i, (label, img)) in panels.iter().enumerate() {
        if img.height() != height {
            return Err(Error::Invalid(format!(
                "labelled_strip: panel {label:?} is {} px high, panel {first_label:?} is {height}",
                img.height()
            )));
        }
        width += img.width() as u64 + if i > 0 { GAP as u64 } else { 0 };
    }
    let total_height = height as u64 + LABEL_BAND as u64;
    if width > u32::MAX as u64 || total_height > u32::MAX as u64 {
        return Err(Error::Invalid(format!(
            "labelled_strip: {width}x{total_height} output is too large"
        )));
    }
    // The background shows through as the gaps and the label bands.
    let mut out = RgbImage::from_pixel(width as u32, total_height as u32, image::Rgb(BACKGROUND));
    let mut x: i64 = 0;
    for (label, img) in panels {
        let pw = img.width();
        // Cut long labels to the panel so one cannot run into its neighbour's band.
        let shown = fit_text(label, pw as i64, 1);
        let tx = x + (pw.saturating_sub(text_width(&shown, 1)) / 2) as i64;
        draw_text(
            &mut out,
            tx.min(i32::MAX as i64) as i32,
            ((LABEL_BAND - 8) / 2) as i32,
            &shown,
            LABEL_COLOR,
            1,
        );
        image::imageops::replace(&mut out, *img, x, LABEL_BAND as i64);
        x += pw as i64 + GAP as i64;
    }
    Ok(out)
}

/// Writes `img` as a PNG at `path`, creating the parent directory. The bytes go to
/// `path.with_extension("png.tmp")` first and are renamed into place, so a reader never sees
/// a half-written file.
pub fn save_png(img: &RgbImage, path: &Path) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(Error::io(dir))?;
    }
    let mut bytes = Vec::new();
    img.write_to(&mut Cursor::new(&mut bytes), ImageFormat::Png)
        .map_err(|e| Error::io(path)(std::io::Error::other(e)))?;
    let tmp = path.with_extension("png.tmp");
    std::fs::write(&tmp, &bytes).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::io(&tmp)(e)
    })?;
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::io(path)(e)
    })
}
