//! Per-pixel maps as 8-bit RGB images: scalar heat maps, binary masks, render-vs-ground-truth
//! error, and plain colour renders.

use image::{Rgb, RgbImage};

use crate::error::{Error, Result};

/// Mean absolute RGB error drawn at full colormap brightness; larger errors saturate.
/// A quarter of the colour range is already a glaring mistake, so the scale spends its
/// resolution on the errors that training actually leaves.
pub const ERROR_FULL_SCALE: f32 = 0.25;

/// Colour for NaN: mid grey sits outside INFERNO's black-purple-orange-yellow path, so
/// undefined pixels cannot be mistaken for any value.
const NAN_GREY: [u8; 3] = [128, 128, 128];

/// Checks that `len` values describe a `width` x `height` image.
fn check_len(what: &str, len: usize, width: u32, height: u32) -> Result<()> {
    // u32 x u32 always fits in u64, so the product cannot overflow.
    let expected = width as u64 * height as u64;
    if expected != len as u64 {
        return Err(Error::Invalid(format!(
            "{what}: {len} values for a {width}x{height} image (expected {expected})"
        )));
    }
    Ok(())
}

/// INFERNO colour of `t`, clamped to [0, 1]; NaN is grey.
fn inferno(t: f32) -> [u8; 3] {
    if t.is_nan() {
        return NAN_GREY;
    }
    colorous::INFERNO
        .eval_continuous(t.clamp(0.0, 1.0) as f64)
        .into_array()
}

/// Builds an image from a row-major per-pixel colour function.
fn from_index(width: u32, height: u32, f: impl Fn(usize) -> [u8; 3]) -> RgbImage {
    RgbImage::from_fn(width, height, |x, y| {
        Rgb(f(y as usize * width as usize + x as usize))
    })
}

/// Row-major `values` in [0, 1] (clamped; NaN drawn mid grey) as an INFERNO heat map:
/// black is no motion, bright yellow the most.
pub fn heatmap(values: &[f32], width: u32, height: u32) -> Result<RgbImage> {
    check_len("heatmap", values.len(), width, height)?;
    Ok(from_index(width, height, |i| inferno(values[i])))
}

/// Row-major binary mask: non-zero white, zero black.
pub fn mask_image(mask: &[u8], width: u32, height: u32) -> Result<RgbImage> {
    check_len("mask_image", mask.len(), width, height)?;
    Ok(from_index(width, height, |i| {
        if mask[i] != 0 {
            [255; 3]
        } else {
            [0; 3]
        }
    }))
}

/// Per-pixel mean absolute RGB error between `render` and `gt` (alpha ignored), drawn with
/// the heat-map colours; [`ERROR_FULL_SCALE`] or more is full brightness.
pub fn error_map(
    render: &[[f32; 4]],
    gt: &[[f32; 4]],
    width: u32,
    height: u32,
) -> Result<RgbImage> {
    check_len("error_map render", render.len(), width, height)?;
    check_len("error_map ground truth", gt.len(), width, height)?;
    Ok(from_index(width, height, |i| {
        let (r, g) = (render[i], gt[i]);
        let err = ((r[0] - g[0]).abs() + (r[1] - g[1]).abs() + (r[2] - g[2]).abs()) / 3.0;
        inferno(err / ERROR_FULL_SCALE)
    }))
}

/// Row-major RGBA in [0, 1] as 8-bit RGB (clamped, rounded; NaN becomes 0, alpha dropped).
pub fn rgb_image(pixels: &[[f32; 4]], width: u32, height: u32) -> Result<RgbImage> {
    check_len("rgb_image", pixels.len(), width, height)?;
    // `as u8` saturates and maps NaN to 0, so no value can panic here.
    let to_u8 = |v: f32| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    Ok(from_index(width, height, |i| {
        let p = pixels[i];
        [to_u8(p[0]), to_u8(p[1]), to_u8(p[2])]
    }))
}
