//! Image decoding (PNG), RGBA compositing, box downscaling and undistortion.

use std::path::Path;

use glam::DVec2;

use super::camera::Distortion;
use super::{DataError, DataResult};

/// Row-major `H×W×3` RGB image, values in `[0, 1]` (8-bit code value / 255).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub data: Vec<f32>,
}

impl Image {
    pub fn new(width: u32, height: u32) -> Self {
        Image {
            width,
            height,
            data: vec![0.0; width as usize * height as usize * 3],
        }
    }

    /// RGB at pixel `(x, y)`.
    pub fn pixel(&self, x: u32, y: u32) -> [f32; 3] {
        let i = (y as usize * self.width as usize + x as usize) * 3;
        [self.data[i], self.data[i + 1], self.data[i + 2]]
    }
}

/// Pinhole intrinsics `[fx, fy, cx, cy]` in f64 for resampling.
pub type Intrinsics = [f64; 4];

/// Decodes a PNG file (any bit depth / channel count).
pub(crate) fn decode(path: &Path) -> DataResult<image::DynamicImage> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    image::load_from_memory_with_format(&bytes, image::ImageFormat::Png)
        .map_err(|e| DataError::file(path, format!("unreadable PNG: {e}")))
}

/// Loads a PNG as RGB; RGBA is composited over `background` (`c·a + bg·(1−a)`).
pub(crate) fn load_rgb(path: &Path, background: [f32; 3]) -> DataResult<Image> {
    Ok(load_rgb_alpha(path, background)?.0)
}

/// [`load_rgb`], with the fraction of pixels under half opacity when the PNG has alpha.
pub(crate) fn load_rgb_alpha(
    path: &Path,
    background: [f32; 3],
) -> DataResult<(Image, Option<f32>)> {
    let img = decode(path)?;
    let (width, height) = (img.width(), img.height());
    let has_alpha = img.color().has_alpha();
    let rgba = img.into_rgba32f();
    let mut data = Vec::with_capacity(width as usize * height as usize * 3);
    let mut clear = 0usize;
    for p in rgba.pixels() {
        let a = if has_alpha { p[3].clamp(0.0, 1.0) } else { 1.0 };
        clear += usize::from(a < 0.5);
        for c in 0..3 {
            data.push(p[c].clamp(0.0, 1.0) * a + background[c] * (1.0 - a));
        }
    }
    let clear = has_alpha.then(|| clear as f32 / (width as f32 * height as f32).max(1.0));
    let image = Image {
        width,
        height,
        data,
    };
    Ok((image, clear))
}

/// Loads a PNG as 8-bit grey (the first channel for colour images): `(width, height, values)`.
pub(crate) fn load_gray(path: &Path) -> DataResult<(u32, u32, Vec<u8>)> {
    let img = decode(path)?;
    let (w, h) = (img.width(), img.height());
    let gray = match img {
        image::DynamicImage::ImageLuma8(g) => g.into_raw(),
        other => other.into_rgb8().pixels().map(|p| p[0]).collect(),
    };
    Ok((w, h, gray))
}

/// Box-downscales by an integer factor `f`: output pixel `(i, j)` averages the source block
/// `[i·f, (i+1)·f) × [j·f, (j+1)·f)`; a remainder at the right/bottom is cropped, so the camera
/// intrinsics scale by exactly `1/f`.
pub fn downscale(img: &Image, f: u32) -> Image {
    if f <= 1 {
        return img.clone();
    }
    let data = box_mean(&img.data, img.width, img.height, 3, f);
    Image {
        width: img.width / f,
        height: img.height / f,
        data,
    }
}

fn box_mean(src: &[f32], w: u32, h: u32, ch: usize, f: u32) -> Vec<f32> {
    let (ow, oh) = ((w / f) as usize, (h / f) as usize);
    let f = f as usize;
    let w = w as usize;
    let inv = 1.0 / (f * f) as f32;
    let mut out = vec![0.0f32; ow * oh * ch];
    for oy in 0..oh {
        for ox in 0..ow {
            for dy in 0..f {
                let row = (oy * f + dy) * w;
                for dx in 0..f {
                    let s = (row + ox * f + dx) * ch;
                    for c in 0..ch {
                        out[(oy * ow + ox) * ch + c] += src[s + c];
                    }
                }
            }
            for c in 0..ch {
                out[(oy * ow + ox) * ch + c] *= inv;
            }
        }
    }
    out
}

/// Box-downscales a 0/1 mask: a block is moving when at least half of it is.
pub(crate) fn downscale_mask(mask: &[u8], w: u32, h: u32, f: u32) -> Vec<u8> {
    if f <= 1 {
        return mask.to_vec();
    }
    let as_f: Vec<f32> = mask.iter().map(|&m| m as f32).collect();
    box_mean(&as_f, w, h, 1, f)
        .into_iter()
        .map(|m| u8::from(m >= 0.5))
        .collect()
}

/// Box-downscales a 2-channel flow field (pixels) and divides it by `f` (approximate on motion
/// boundaries, where a block mixes moving and static pixels).
pub(crate) fn downscale_flow(flow: &[f32], w: u32, h: u32, f: u32) -> Vec<f32> {
    if f <= 1 {
        return flow.to_vec();
    }
    box_mean(flow, w, h, 2, f)
        .into_iter()
        .map(|v| v / f as f32)
        .collect()
}

/// For output pixel `(i, j)` of the pinhole camera `k`, the continuous source position in the
/// distorted image (pixel-centre convention `i + 0.5`).
fn source_position(k: Intrinsics, dist: &Distortion, i: usize, j: usize) -> DVec2 {
    let [fx, fy, cx, cy] = k;
    let x = (i as f64 + 0.5 - cx) / fx;
    let y = (j as f64 + 0.5 - cy) / fy;
    let d = dist.distort(DVec2::new(x, y));
    DVec2::new(fx * d.x + dist.skew * d.y + cx, fy * d.y + cy)
}

/// Undistorts an image to the pinhole camera with the same intrinsics `k` (same size): each
/// output pixel's ray is pushed through the forward distortion and the source is sampled
/// bilinearly. Source positions outside the image are filled with `background`; positions within
/// the outer half-pixel are edge-clamped.
pub fn undistort(img: &Image, k: Intrinsics, dist: &Distortion, background: [f32; 3]) -> Image {
    use rayon::prelude::*;
    if dist.is_identity() {
        return img.clone();
    }
    let (w, h) = (img.width as usize, img.height as usize);
    let mut out = vec![0.0f32; w * h * 3];
    out.par_chunks_mut(w * 3).enumerate().for_each(|(j, row)| {
        for i in 0..w {
            let s = source_position(k, dist, i, j);
            let px = &mut row[i * 3..i * 3 + 3];
            if !(s.x >= 0.0 && s.y >= 0.0 && s.x <= w as f64 && s.y <= h as f64) {
                px.copy_from_slice(&background);
                continue;
            }
            let fx = (s.x - 0.5).clamp(0.0, (w - 1) as f64);
            let fy = (s.y - 0.5).clamp(0.0, (h - 1) as f64);
            let (x0, y0) = (fx.floor() as usize, fy.floor() as usize);
            let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
            let (ax, ay) = ((fx - x0 as f64) as f32, (fy - y0 as f64) as f32);
            for (c, out) in px.iter_mut().enumerate() {
                let at = |x: usize, y: usize| img.data[(y * w + x) * 3 + c];
                let top = at(x0, y0) * (1.0 - ax) + at(x1, y0) * ax;
                let bot = at(x0, y1) * (1.0 - ax) + at(x1, y1) * ax;
                *out = top * (1.0 - ay) + bot * ay;
            }
        }
    });
    Image {
        width: img.width,
        height: img.height,
        data: out,
    }
}

/// Undistorts a per-pixel field with `ch` channels by nearest sampling (masks, flows); outside
/// the source → `fill`.
pub(crate) fn undistort_nearest<T: Copy + Send + Sync>(
    src: &[T],
    ch: usize,
    w: u32,
    h: u32,
    k: Intrinsics,
    dist: &Distortion,
    fill: T,
) -> Vec<T> {
    if dist.is_identity() {
        return src.to_vec();
    }
    let (w, h) = (w as usize, h as usize);
    let mut out = vec![fill; w * h * ch];
    for j in 0..h {
        for i in 0..w {
            let s = source_position(k, dist, i, j);
            if s.x >= 0.0 && s.y >= 0.0 && s.x < w as f64 && s.y < h as f64 {
                let (x, y) = (s.x as usize, s.y as usize);
                out[(j * w + i) * ch..(j * w + i + 1) * ch]
                    .copy_from_slice(&src[(y * w + x) * ch..(y * w + x + 1) * ch]);
            }
        }
    }
    out
}

/// Writes an 8-bit RGB PNG from `[0,1]` floats.
pub(crate) fn save_rgb(path: &Path, w: u32, h: u32, rgb: &[f32]) -> DataResult<()> {
    let bytes: Vec<u8> = rgb
        .iter()
        .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
        .collect();
    image::save_buffer_with_format(
        path,
        &bytes,
        w,
        h,
        image::ExtendedColorType::Rgb8,
        image::ImageFormat::Png,
    )
    .map_err(|e| DataError::file(path, format!("cannot write PNG: {e}")))
}

/// Writes an 8-bit grey PNG.
pub(crate) fn save_gray(path: &Path, w: u32, h: u32, v: &[u8]) -> DataResult<()> {
    image::save_buffer_with_format(
        path,
        v,
        w,
        h,
        image::ExtendedColorType::L8,
        image::ImageFormat::Png,
    )
    .map_err(|e| DataError::file(path, format!("cannot write PNG: {e}")))
}
