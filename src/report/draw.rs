//! Clipped pixel primitives shared by the text, strip and plot drawing. Coordinates are i64
//! so that offsets computed from any i32/u32 input cannot overflow before clipping.

use image::{Rgb, RgbImage};

/// Fills the `w` x `h` rectangle at (`x`, `y`), clipped to `clip` (x0, y0, x1, y1; half-open)
/// and to the image.
pub(crate) fn fill_rect_in(
    img: &mut RgbImage,
    clip: (i64, i64, i64, i64),
    x: i64,
    y: i64,
    w: i64,
    h: i64,
    color: [u8; 3],
) {
    let x0 = x.max(clip.0).max(0);
    let y0 = y.max(clip.1).max(0);
    let x1 = x.saturating_add(w).min(clip.2).min(img.width() as i64);
    let y1 = y.saturating_add(h).min(clip.3).min(img.height() as i64);
    for py in y0..y1 {
        for px in x0..x1 {
            img.put_pixel(px as u32, py as u32, Rgb(color));
        }
    }
}

/// Fills a rectangle clipped only to the image.
pub(crate) fn fill_rect(img: &mut RgbImage, x: i64, y: i64, w: i64, h: i64, color: [u8; 3]) {
    fill_rect_in(img, (0, 0, i64::MAX, i64::MAX), x, y, w, h, color);
}

/// Outlines a rectangle with a 1-px border.
pub(crate) fn stroke_rect(img: &mut RgbImage, x: i64, y: i64, w: i64, h: i64, color: [u8; 3]) {
    fill_rect(img, x, y, w, 1, color);
    fill_rect(img, x, y + h - 1, w, 1, color);
    fill_rect(img, x, y, 1, h, color);
    fill_rect(img, x + w - 1, y, 1, h, color);
}
