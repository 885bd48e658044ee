//! Bitmap text from the public-domain 8x8 font: enough for labels, ticks and legends without
//! needing system fonts (none exist on CI machines).

use font8x8::{UnicodeFonts, BASIC_FONTS};
use image::RgbImage;

use super::draw::fill_rect;

/// Glyph cell size in font pixels; glyphs advance by this much times the scale.
const GLYPH: i64 = 8;

/// The glyph for `c`: printable ASCII as is, everything else as '?' so that unsupported
/// characters stay visible instead of silently vanishing.
fn glyph(c: char) -> [u8; 8] {
    let c = if c == ' ' || c.is_ascii_graphic() {
        c
    } else {
        '?'
    };
    BASIC_FONTS.get(c).unwrap_or([0; 8])
}

/// Width in pixels of `text` drawn at `scale` (saturating at `u32::MAX`).
pub fn text_width(text: &str, scale: u32) -> u32 {
    let w = text.chars().count() as u64 * GLYPH as u64 * scale as u64;
    w.min(u32::MAX as u64) as u32
}

/// `text` cut to at most `max_width` pixels at `scale`, ending in ".." when cut, so that a
/// shortened label is visibly shortened rather than silently wrong.
pub(crate) fn fit_text(text: &str, max_width: i64, scale: u32) -> String {
    let cell = GLYPH * scale.max(1) as i64;
    let fit = (max_width.max(0) / cell) as usize;
    if text.chars().count() <= fit {
        return text.to_string();
    }
    let keep = fit.saturating_sub(2);
    let mut out: String = text.chars().take(keep).collect();
    out.push_str(&"..".chars().take(fit - keep).collect::<String>());
    out
}

/// Draws `text` with its top-left corner at (`x`, `y`), each font pixel a `scale` x `scale`
/// block (scale 0 draws nothing). Anything outside the image is clipped.
pub fn draw_text(img: &mut RgbImage, x: i32, y: i32, text: &str, color: [u8; 3], scale: u32) {
    draw_glyphs(img, x as i64, y as i64, text, color, scale, false);
}

/// Draws `text` rotated a quarter turn counter-clockwise (reading bottom to top), with the
/// bottom-left corner of its first glyph at (`x`, `y`); used for vertical axis labels.
pub(crate) fn draw_text_up(img: &mut RgbImage, x: i64, y: i64, text: &str, color: [u8; 3]) {
    draw_glyphs(img, x, y, text, color, 1, true);
}

fn draw_glyphs(
    img: &mut RgbImage,
    x: i64,
    y: i64,
    text: &str,
    color: [u8; 3],
    scale: u32,
    up: bool,
) {
    let s = scale as i64;
    let cell = GLYPH * s;
    if s == 0 {
        return;
    }
    let (w, h) = (img.width() as i64, img.height() as i64);
    for (i, c) in text.chars().enumerate() {
        let advance = (i as i64).saturating_mul(cell);
        // Origin of this glyph's cell and whether it can still touch the image; once the
        // pen has left the image along the writing direction, later glyphs cannot return.
        let (gx, gy) = if up {
            let gy = y.saturating_sub(advance).saturating_sub(cell);
            if gy.saturating_add(cell) <= 0 {
                break;
            }
            (x, gy)
        } else {
            let gx = x.saturating_add(advance);
            if gx >= w {
                break;
            }
            (gx, y)
        };
        if gx.saturating_add(cell) <= 0 || gy.saturating_add(cell) <= 0 || gx >= w || gy >= h {
            continue;
        }
        let rows = glyph(c);
        for (r, bits) in rows.iter().enumerate() {
            for col in 0..GLYPH {
                // font8x8 stores the leftmost pixel in bit 0.
                if bits & (1 << col) == 0 {
                    continue;
                }
                let r = r as i64;
                let (px, py) = if up {
                    // Rotating counter-clockwise puts glyph rows left to right and glyph
                    // columns bottom to top.
                    (gx + r * s, gy + cell - (col + 1) * s)
                } else {
                    (gx + col * s, gy + r * s)
                };
                fill_rect(img, px, py, s, s, color);
            }
        }
    }
}
