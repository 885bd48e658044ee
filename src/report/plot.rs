//! Line plots (loss / PSNR / metric curves against iteration) drawn straight into an RGB
//! image with the bitmap font, so `eval` needs no plotting library or system fonts.
//!
//! Over 600 lines because axis ticks, labels, legend and clipping belong to one drawing routine;
//! split it when a second plot type arrives.

use image::{Rgb, RgbImage};
use serde::Serialize;

use super::draw::{fill_rect, fill_rect_in, stroke_rect};
use super::text::{draw_text, draw_text_up, fit_text, text_width};
use crate::error::{Error, Result};

/// Distinct series colours (the Tableau 10 hues), all readable on white.
pub const PALETTE: [[u8; 3]; 6] = [
    [31, 119, 180],
    [255, 127, 14],
    [44, 160, 44],
    [214, 39, 40],
    [148, 103, 189],
    [140, 86, 75],
];

/// Narrowest plot that still leaves room for tick labels beside a visible plot area.
pub const MIN_WIDTH: u32 = 120;
/// Lowest plot that still leaves room for the title and x labels around a visible plot area.
pub const MIN_HEIGHT: u32 = 80;

const WHITE: [u8; 3] = [255, 255, 255];
const INK: [u8; 3] = [0, 0, 0];
const TEXT: [u8; 3] = [40, 40, 40];
const GRID: [u8; 3] = [228, 228, 228];
const LEGEND_BORDER: [u8; 3] = [170, 170, 170];

/// Length of the tick marks outside the axes box.
const TICK: i64 = 4;
/// Data never touches the axes box: a line along the data range's edge stays visible.
const INSET: f64 = 4.0;
/// Line thickness in pixels.
const LINE: i64 = 2;
/// Side of the square drawn for an isolated point.
const DOT: i64 = 5;
/// Font glyph height at scale 1.
const FONT: i64 = 8;

/// One curve: points joined in the given order; non-finite points leave a gap.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Series {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    pub color: [u8; 3],
}

/// A line plot of several series on shared axes. Series with empty labels stay out of the
/// legend; no legend is drawn when every label is empty.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Plot {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<Series>,
    pub width: u32,
    pub height: u32,
}

/// A tick-labelled axis covering `lo..=hi`.
struct Axis {
    lo: f64,
    hi: f64,
    ticks: Vec<f64>,
    labels: Vec<String>,
}

fn finite_point(p: &(f64, f64)) -> bool {
    p.0.is_finite() && p.1.is_finite()
}

/// Smallest and largest of `values`, or None when empty.
fn min_max(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values.fold(None, |acc, v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}

/// Widens a zero-width range so that a constant series is drawn inside the axes rather
/// than along their edge.
fn pad_flat(lo: f64, hi: f64) -> (f64, f64) {
    if hi > lo {
        return (lo, hi);
    }
    let pad = if lo == 0.0 { 0.5 } else { 0.1 * lo.abs() };
    (lo - pad, hi + pad)
}

/// Decimal exponent of |v| (v non-zero); the epsilon keeps exact powers of ten from
/// flooring one too low.
fn exp10(v: f64) -> i32 {
    (v.abs().log10() + 1e-9).floor() as i32
}

/// `v` with `decimals` places, trailing zeros dropped, and never "-0".
fn fixed(v: f64, decimals: usize) -> String {
    let mut s = format!("{:.*}", decimals.min(12), v);
    if s.contains('.') {
        s = s.trim_end_matches('0').trim_end_matches('.').to_string();
    }
    if s == "-0" {
        s = "0".into();
    }
    s
}

/// `v` in scientific notation with `digits` mantissa decimals, trailing zeros dropped
/// ("1e-3", "2.5e-3").
fn sci(v: f64, digits: usize) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let s = format!("{:.*e}", digits.min(12), v);
    match s.split_once('e') {
        Some((m, e)) if m.contains('.') => {
            format!("{}e{e}", m.trim_end_matches('0').trim_end_matches('.'))
        }
        _ => s,
    }
}

/// Compact labels for evenly spaced ticks: plain decimals for ordinary magnitudes, k/M/G
/// suffixes for large ones, scientific notation for tiny or huge ones. One style per axis
/// so neighbouring labels read alike; the step decides how many decimals are needed.
fn tick_labels(ticks: &[f64], step: f64) -> Vec<String> {
    let max = ticks.iter().fold(0.0f64, |m, t| m.max(t.abs()));
    let decimals = |step: f64| (-exp10(step)).max(0) as usize;
    if max >= 1e12 || (max > 0.0 && max < 1e-2) {
        ticks
            .iter()
            .map(|&t| {
                let digits = if t == 0.0 { 0 } else { exp10(t) - exp10(step) };
                sci(t, digits.max(0) as usize)
            })
            .collect()
    } else if max >= 1e3 {
        let (unit, suffix) = if max >= 1e9 {
            (1e9, "G")
        } else if max >= 1e6 {
            (1e6, "M")
        } else {
            (1e3, "k")
        };
        let d = decimals(step / unit);
        ticks
            .iter()
            .map(|&t| match fixed(t / unit, d) {
                z if z == "0" => z,
                s => s + suffix,
            })
            .collect()
    } else {
        ticks.iter().map(|&t| fixed(t, decimals(step))).collect()
    }
}

/// An axis over `lo..=hi` (lo < hi) with 4-6 ticks at multiples of a 1/2/5 x 10^k step,
/// widened outwards to whole steps so the end ticks sit at the axis ends.
fn nice_axis(lo: f64, hi: f64) -> Axis {
    let span = hi - lo;
    if span.is_finite() && span > 0.0 {
        let base = 10f64.powi(exp10(span));
        let mut best: Option<(i64, f64, f64, f64)> = None;
        for e in [0.01, 0.1, 1.0, 10.0] {
            for m in [1.0, 2.0, 5.0] {
                let step = m * base * e;
                // The tolerance keeps float noise (2.5 / 0.02 = 124.99999...) from adding a
                // whole extra step at either end.
                let (a, b) = ((lo / step + 1e-9).floor(), (hi / step - 1e-9).ceil());
                let n = (b - a) as i64 + 1;
                // Precision loss (huge lo/step) can make the count nonsense; skip such steps.
                if !(2..=20).contains(&n) || !(a * step).is_finite() || !(b * step).is_finite() {
                    continue;
                }
                // The first (smallest) step wins ties, as it wastes less of the axis.
                if best.map_or(true, |(bn, ..)| (n - 5).abs() < (bn - 5).abs()) {
                    best = Some((n, step, a, b));
                }
            }
        }
        if let Some((n, step, a, _)) = best {
            // `+ 0.0` turns -0.0 into 0.0.
            let ticks: Vec<f64> = (0..n).map(|i| (a + i as f64) * step + 0.0).collect();
            let labels = tick_labels(&ticks, step);
            // The end ticks may miss the data by float noise; the axis itself must not.
            return Axis {
                lo: ticks[0].min(lo),
                hi: ticks[ticks.len() - 1].max(hi),
                ticks,
                labels,
            };
        }
    }
    // Ranges too wide or too fine for decimal steps: label just the ends.
    let ticks = vec![lo, hi];
    let labels = ticks.iter().map(|&t| sci(t, 2)).collect();
    Axis {
        lo,
        hi,
        ticks,
        labels,
    }
}

/// Clips the segment a-b to the rectangle [x0, x1] x [y0, y1] (Liang-Barsky); None when it
/// lies outside.
fn clip_segment(
    a: (f64, f64),
    b: (f64, f64),
    (x0, y0, x1, y1): (f64, f64, f64, f64),
) -> Option<((f64, f64), (f64, f64))> {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-dx, a.0 - x0),
        (dx, x1 - a.0),
        (-dy, a.1 - y0),
        (dy, y1 - a.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let t = q / p;
            if p < 0.0 {
                t0 = t0.max(t);
            } else {
                t1 = t1.min(t);
            }
        }
    }
    let at = |t: f64| (a.0 + t * dx, a.1 + t * dy);
    (t0 <= t1).then_some((at(t0), at(t1)))
}

/// Pixel geometry of the axes box and the data-to-pixel mapping.
struct Frame {
    /// Axes box, half-open: x0..x1, y0..y1.
    x0: i64,
    y0: i64,
    x1: i64,
    y1: i64,
    x: Axis,
    y: Axis,
}

impl Frame {
    fn px(&self, v: f64) -> f64 {
        let (a, b) = (self.x0 as f64 + INSET, (self.x1 - 1) as f64 - INSET);
        a + (v - self.x.lo) / (self.x.hi - self.x.lo) * (b - a)
    }
    fn py(&self, v: f64) -> f64 {
        let (a, b) = ((self.y1 - 1) as f64 - INSET, self.y0 as f64 + INSET);
        a + (v - self.y.lo) / (self.y.hi - self.y.lo) * (b - a)
    }
    /// Inside the box, excluding its 1-px outline.
    fn inner(&self) -> (i64, i64, i64, i64) {
        (self.x0 + 1, self.y0 + 1, self.x1 - 1, self.y1 - 1)
    }
}

fn draw_line(img: &mut RgbImage, f: &Frame, a: (f64, f64), b: (f64, f64), color: [u8; 3]) {
    let clip = f.inner();
    let bounds = (
        clip.0 as f64,
        clip.1 as f64,
        clip.2 as f64 - 1.0,
        clip.3 as f64 - 1.0,
    );
    if ![a.0, a.1, b.0, b.1].iter().all(|v| v.is_finite()) {
        return;
    }
    let Some((a, b)) = clip_segment(a, b, bounds) else {
        return;
    };
    // Clipping bounds the step count by the box size.
    let n = (b.0 - a.0).abs().max((b.1 - a.1).abs()).ceil().max(1.0) as i64;
    for i in 0..=n {
        let t = i as f64 / n as f64;
        let (x, y) = (a.0 + t * (b.0 - a.0), a.1 + t * (b.1 - a.1));
        // Centre the LINE x LINE brush on the exact position.
        let half = LINE as f64 / 2.0;
        let (bx, by) = ((x - half + 0.5).floor(), (y - half + 0.5).floor());
        fill_rect_in(img, clip, bx as i64, by as i64, LINE, LINE, color);
    }
}

fn draw_series(img: &mut RgbImage, f: &Frame, s: &Series) {
    let pts = &s.points;
    let clip = f.inner();
    for (i, p) in pts.iter().enumerate() {
        if !finite_point(p) {
            continue;
        }
        let here = (f.px(p.0), f.py(p.1));
        match pts.get(i + 1).filter(|q| finite_point(q)) {
            Some(q) => draw_line(img, f, here, (f.px(q.0), f.py(q.1)), s.color),
            None => {
                // A point with no finite neighbour would be invisible as a line; give it a dot.
                let isolated = i == 0 || !finite_point(&pts[i - 1]);
                if isolated && here.0.is_finite() && here.1.is_finite() {
                    let (x, y) = (here.0.round() as i64, here.1.round() as i64);
                    fill_rect_in(img, clip, x - DOT / 2, y - DOT / 2, DOT, DOT, s.color);
                }
            }
        }
    }
}

/// Draws every `stride`-th label so that neighbours never overlap; `spacing` is the pixel
/// distance between ticks and `extent` the largest label extent along the axis.
fn label_stride(spacing: f64, extent: f64) -> usize {
    if spacing <= 0.0 || !spacing.is_finite() {
        return 1;
    }
    ((extent / spacing).ceil() as usize).max(1)
}

fn draw_legend(img: &mut RgbImage, f: &Frame, series: &[Series]) {
    let entries: Vec<&Series> = series.iter().filter(|s| !s.label.is_empty()).collect();
    if entries.is_empty() {
        return;
    }
    const PAD: i64 = 5;
    const ROW: i64 = 12;
    const SWATCH: i64 = 14;
    let label_w = entries
        .iter()
        .map(|s| text_width(&s.label, 1) as i64)
        .max()
        .unwrap_or(0);
    let w = PAD + SWATCH + 5 + label_w + PAD;
    let h = 2 * PAD + ROW * entries.len() as i64 - (ROW - FONT);
    let margin = 6;
    let (l, r) = (f.x0 + margin, f.x1 - margin - w);
    let (t, b) = (f.y0 + margin, f.y1 - margin - h);
    // Put the box in the corner that hides the fewest curve pixels, preferring top right.
    let candidates = [(r, t), (l, t), (r, b), (l, b)];
    let covered = |&(x, y): &(i64, i64)| {
        let mut n = 0usize;
        for py in y.max(0)..(y + h).min(img.height() as i64) {
            for px in x.max(0)..(x + w).min(img.width() as i64) {
                let c = img.get_pixel(px as u32, py as u32).0;
                if c != WHITE && c != GRID {
                    n += 1;
                }
            }
        }
        n
    };
    // A legend larger than the box would hide the data it explains; leave it out.
    if w > f.x1 - f.x0 - 2 * margin || h > f.y1 - f.y0 - 2 * margin {
        return;
    }
    let (x, y) = candidates
        .iter()
        .copied()
        .min_by_key(covered)
        .unwrap_or((r, t));
    fill_rect(img, x, y, w, h, WHITE);
    stroke_rect(img, x, y, w, h, LEGEND_BORDER);
    for (i, s) in entries.iter().enumerate() {
        let ty = y + PAD + ROW * i as i64;
        fill_rect(img, x + PAD, ty + 3, SWATCH, LINE, s.color);
        draw_text(
            img,
            clamp_i32(x + PAD + SWATCH + 5),
            clamp_i32(ty),
            &s.label,
            s.color,
            1,
        );
    }
}

fn clamp_i32(v: i64) -> i32 {
    v.clamp(i32::MIN as i64, i32::MAX as i64) as i32
}

impl Plot {
    /// Draws the plot at `width` x `height` on white: title, axes box with nice ticks and
    /// grid, axis labels, the curves and a legend. Errors only for a size below
    /// [`MIN_WIDTH`] x [`MIN_HEIGHT`]; any point values are accepted.
    pub fn render(&self) -> Result<RgbImage> {
        if self.width < MIN_WIDTH || self.height < MIN_HEIGHT {
            return Err(Error::Invalid(format!(
                "plot {:?}: {}x{} is smaller than the minimum {MIN_WIDTH}x{MIN_HEIGHT}",
                self.title, self.width, self.height
            )));
        }
        let (w, h) = (self.width as i64, self.height as i64);
        let mut img = RgbImage::from_pixel(self.width, self.height, Rgb(WHITE));

        let finite = || {
            self.series
                .iter()
                .flat_map(|s| s.points.iter())
                .filter(|p| finite_point(p))
        };
        let has_data = finite().next().is_some();
        let (xlo, xhi) = min_max(finite().map(|p| p.0)).unwrap_or((0.0, 1.0));
        let (ylo, yhi) = min_max(finite().map(|p| p.1)).unwrap_or((0.0, 1.0));
        let (xlo, xhi) = pad_flat(xlo, xhi);
        let (ylo, yhi) = pad_flat(ylo, yhi);
        let (x_axis, y_axis) = (nice_axis(xlo, xhi), nice_axis(ylo, yhi));

        // Layout: title band on top, y label and y tick labels on the left, x tick labels
        // and x label below.
        let title_scale = if !self.title.is_empty()
            && self.height >= 240
            && text_width(&self.title, 2) as i64 + 16 <= w
        {
            2
        } else {
            1
        };
        let top = if self.title.is_empty() {
            10
        } else {
            FONT * title_scale + 12
        };
        let y_label_w = y_axis
            .labels
            .iter()
            .map(|l| text_width(l, 1) as i64)
            .max()
            .unwrap_or(0);
        let left = 6 + if self.y_label.is_empty() { 0 } else { FONT + 6 } + y_label_w + 4 + TICK;
        let last_x_label = x_axis.labels.last().map_or(0, |l| text_width(l, 1) as i64);
        let right = (last_x_label / 2 + 6).max(12);
        let bottom = TICK + 4 + FONT + if self.x_label.is_empty() { 0 } else { 6 + FONT } + 6;
        // Long labels on a small canvas could leave no box at all; keep a sliver and let
        // clipping cut the rest rather than fail.
        let x0 = left.min(w - 16);
        let y0 = top.min(h - 16);
        let frame = Frame {
            x0,
            y0,
            x1: (w - right).max(x0 + 12),
            y1: (h - bottom).max(y0 + 12),
            x: x_axis,
            y: y_axis,
        };
        let f = &frame;

        for &t in &f.x.ticks {
            let x = f.px(t).round() as i64;
            fill_rect_in(&mut img, f.inner(), x, f.y0, 1, f.y1 - f.y0, GRID);
        }
        for &t in &f.y.ticks {
            let y = f.py(t).round() as i64;
            fill_rect_in(&mut img, f.inner(), f.x0, y, f.x1 - f.x0, 1, GRID);
        }
        for s in &self.series {
            draw_series(&mut img, f, s);
        }
        stroke_rect(&mut img, f.x0, f.y0, f.x1 - f.x0, f.y1 - f.y0, INK);

        let x_spacing =
            f.x.ticks
                .get(1)
                .map_or(0.0, |&t| f.px(t) - f.px(f.x.ticks[0]));
        let x_extent =
            f.x.labels
                .iter()
                .map(|l| text_width(l, 1) as f64)
                .fold(0.0, f64::max);
        let x_stride = label_stride(x_spacing, x_extent + 6.0);
        for (i, (&t, label)) in f.x.ticks.iter().zip(&f.x.labels).enumerate() {
            let x = f.px(t).round() as i64;
            fill_rect(&mut img, x, f.y1, 1, TICK, INK);
            if i % x_stride == 0 {
                let lx = x - text_width(label, 1) as i64 / 2;
                draw_text(
                    &mut img,
                    clamp_i32(lx),
                    clamp_i32(f.y1 + TICK + 3),
                    label,
                    TEXT,
                    1,
                );
            }
        }
        let y_spacing =
            f.y.ticks
                .get(1)
                .map_or(0.0, |&t| f.py(f.y.ticks[0]) - f.py(t));
        let y_stride = label_stride(y_spacing, FONT as f64 + 4.0);
        for (i, (&t, label)) in f.y.ticks.iter().zip(&f.y.labels).enumerate() {
            let y = f.py(t).round() as i64;
            fill_rect(&mut img, f.x0 - TICK, y, TICK, 1, INK);
            if i % y_stride == 0 {
                let lx = f.x0 - TICK - 3 - text_width(label, 1) as i64;
                draw_text(&mut img, clamp_i32(lx), clamp_i32(y - 3), label, TEXT, 1);
            }
        }

        if has_data {
            draw_legend(&mut img, f, &self.series);
        } else {
            let msg = "no data";
            let mx = (f.x0 + f.x1 - text_width(msg, 1) as i64) / 2;
            let my = (f.y0 + f.y1 - FONT) / 2;
            draw_text(&mut img, clamp_i32(mx), clamp_i32(my), msg, TEXT, 1);
        }

        let title = fit_text(&self.title, w - 4, title_scale as u32);
        let tw = text_width(&title, title_scale as u32) as i64;
        draw_text(
            &mut img,
            clamp_i32((w - tw) / 2),
            6,
            &title,
            INK,
            title_scale as u32,
        );
        // Axis labels may overhang the box a little but not leave the image.
        let x_label = fit_text(&self.x_label, w - 4, 1);
        let xl = text_width(&x_label, 1) as i64;
        let xl_x = ((f.x0 + f.x1 - xl) / 2).clamp(2, (w - xl - 2).max(2));
        draw_text(
            &mut img,
            clamp_i32(xl_x),
            clamp_i32(f.y1 + TICK + 4 + FONT + 6),
            &x_label,
            TEXT,
            1,
        );
        let y_label = fit_text(&self.y_label, h - 4, 1);
        let yl = text_width(&y_label, 1) as i64;
        let yl_y = ((f.y0 + f.y1 + yl) / 2).clamp((yl + 2).min(h - 2), h - 2);
        draw_text_up(&mut img, 6, yl_y, &y_label, TEXT);
        Ok(img)
    }
}

/// Stacks images top to bottom; all must be equally wide (as plots rendered at one width
/// are). An empty list is an error.
pub fn stacked(plots: &[RgbImage]) -> Result<RgbImage> {
    let Some(first) = plots.first() else {
        return Err(Error::Invalid("stacked: no images".into()));
    };
    let width = first.width();
    let mut height: u64 = 0;
    for (i, p) in plots.iter().enumerate() {
        if p.width() != width {
            return Err(Error::Invalid(format!(
                "stacked: image {i} is {} px wide, image 0 is {width}",
                p.width()
            )));
        }
        height += p.height() as u64;
    }
    let height = u32::try_from(height)
        .map_err(|_| Error::Invalid(format!("stacked: total height {height} is too large")))?;
    let mut out = RgbImage::new(width, height);
    let mut y: i64 = 0;
    for p in plots {
        image::imageops::replace(&mut out, p, 0, y);
        y += p.height() as i64;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn labels(lo: f64, hi: f64) -> Vec<String> {
        nice_axis(lo, hi).labels
    }

    #[test]
    fn nice_ticks_count_and_steps() {
        for (lo, hi) in [
            (0.0, 1.0),
            (0.05, 1.05),
            (2.5, 2.6),
            (-3.0, 7.0),
            (0.0, 600.0),
            (20.0, 21.5),
            (1e-4, 9e-4),
            (-1e9, 3e9),
            (0.0, 0.0123),
        ] {
            let a = nice_axis(lo, hi);
            let n = a.ticks.len();
            assert!((4..=6).contains(&n), "{lo}..{hi}: {n} ticks {:?}", a.labels);
            assert!(a.lo <= lo && a.hi >= hi, "{lo}..{hi} not covered");
            let step = a.ticks[1] - a.ticks[0];
            let mantissa = step / 10f64.powi(exp10(step));
            assert!(
                [1.0, 2.0, 5.0].iter().any(|m| (mantissa - m).abs() < 1e-6),
                "{lo}..{hi}: step {step}"
            );
        }
    }

    #[test]
    fn compact_tick_labels() {
        assert_eq!(labels(0.0, 1.0), ["0", "0.2", "0.4", "0.6", "0.8", "1"]);
        assert_eq!(labels(0.0, 600.0), ["0", "200", "400", "600"]);
        assert_eq!(labels(0.0, 1500.0), ["0", "0.5k", "1k", "1.5k"]);
        assert_eq!(labels(1e-3, 4e-3), ["1e-3", "2e-3", "3e-3", "4e-3"]);
        assert_eq!(labels(0.0, 2e-3), ["0", "5e-4", "1e-3", "1.5e-3", "2e-3"]);
        assert_eq!(labels(-10.0, 10.0), ["-10", "-5", "0", "5", "10"]);
        assert_eq!(labels(0.0, 2e6), ["0", "0.5M", "1M", "1.5M", "2M"]);
        assert!(labels(0.0, 2e12)
            .iter()
            .all(|l| l == "0" || l.contains('e')));
    }
}
