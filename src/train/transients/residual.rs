//! Which pixels of a render are wrong enough to spawn from: the per-pixel error, the
//! threshold (at least `min_error` and [`RELATIVE_ERROR`] times the frame's median) and the
//! frame's localized residual. Spawning and the tracker apply the same rule.

/// What a render gets wrong, in one pass over its errors: the localized residual (the summed
/// error of the pixels [`worst_pixels`] would spawn from; 0 when the frame is wrong everywhere
/// alike, or right everywhere) and the share of those pixels where the render draws nothing
/// (coverage 1 − T, its alpha, under one half: an object missing from the model there, rather
/// than one drawn wrong; 0 when no pixel is over the threshold), and the share of those pixels
/// whose true colour the render draws nowhere near ([`explained`]: an object the model lacks
/// at this time, where a misplaced or mis-shaded one is drawn close by).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrameResidual {
    pub sum: f64,
    /// The frame's pixels.
    pub pixels: usize,
    pub uncovered: f64,
    pub unexplained: f64,
}

impl FrameResidual {
    /// The localized residual per pixel of the frame.
    pub fn per_pixel(&self) -> f64 {
        self.sum / self.pixels.max(1) as f64
    }
}

/// [`FrameResidual`] of a `width`-wide render against its ground truth.
pub fn frame_residual(
    render: &[[f32; 4]],
    gt: &[[f32; 4]],
    width: u32,
    min_error: f32,
) -> FrameResidual {
    let err = pixel_errors(render, gt);
    let thr = threshold(&err, min_error);
    let (mut sum, mut over, mut bare, mut lost) = (0.0f64, 0usize, 0usize, 0usize);
    for (i, (&e, r)) in err.iter().zip(render).enumerate() {
        if e >= thr {
            sum += e as f64;
            over += 1;
            bare += (r[3] < 0.5) as usize;
            lost += !explained(render, width, i, &gt[i]) as usize;
        }
    }
    let share = |k: usize| {
        if over == 0 {
            0.0
        } else {
            k as f64 / over as f64
        }
    };
    FrameResidual {
        sum,
        pixels: render.len(),
        uncovered: share(bare),
        unexplained: share(lost),
    }
}

/// How far from a wrong pixel (in pixels, each way) the render may draw its true colour for
/// the pixel to count as explained: an object drawn a few pixels off, or a shading error of a
/// drawn surface, is found there; one the model does not hold at this time is not.
pub const EXPLAINED_REACH: usize = 6;
/// The mean absolute RGB difference under which a render pixel draws the true colour.
pub const EXPLAINED_COLOUR: f32 = 0.1;

/// Whether the render draws `truth` (RGB) within [`EXPLAINED_REACH`] pixels of pixel `i`.
pub fn explained(render: &[[f32; 4]], width: u32, i: usize, truth: &[f32; 4]) -> bool {
    let w = width.max(1) as usize;
    let h = render.len() / w;
    let (x, y) = (i % w, i / w);
    let xs = x.saturating_sub(EXPLAINED_REACH)..(x + EXPLAINED_REACH + 1).min(w);
    (y.saturating_sub(EXPLAINED_REACH)..(y + EXPLAINED_REACH + 1).min(h)).any(|yy| {
        render[yy * w + xs.start..yy * w + xs.end].iter().any(|r| {
            let d = (r[0] - truth[0]).abs() + (r[1] - truth[1]).abs() + (r[2] - truth[2]).abs();
            d < 3.0 * EXPLAINED_COLOUR
        })
    })
}

/// The error a pixel needs to spawn: at least `min_error` and [`RELATIVE_ERROR`] times the
/// frame's median.
pub fn threshold(err: &[f32], min_error: f32) -> f32 {
    min_error.max(RELATIVE_ERROR * median(err))
}

pub fn pixel_errors(render: &[[f32; 4]], gt: &[[f32; 4]]) -> Vec<f32> {
    render
        .iter()
        .zip(gt)
        .map(|(r, g)| ((r[0] - g[0]).abs() + (r[1] - g[1]).abs() + (r[2] - g[2]).abs()) / 3.0)
        .collect()
}

fn median(v: &[f32]) -> f32 {
    if v.is_empty() {
        return 0.0;
    }
    let mut s = v.to_vec();
    let m = s.len() / 2;
    *s.select_nth_unstable_by(m, f32::total_cmp).1
}

/// How much worse than the frame's median error a pixel must be to spawn: a transient is for
/// a local failure (an object missing, ghosted, misplaced), not for a view the model gets wrong
/// everywhere.
pub const RELATIVE_ERROR: f32 = 3.0;

/// Pixels whose mean absolute RGB error is at least `min_error` and [`RELATIVE_ERROR`] times
/// the frame's median, at most one per `cell`×`cell` block (its worst), the `k` worst of those;
/// and the side of the cells. `render`, `gt`: [H·W] RGBA.
pub fn worst_pixels(
    render: &[[f32; 4]],
    gt: &[[f32; 4]],
    width: u32,
    height: u32,
    min_error: f32,
    k: usize,
) -> (Vec<(u32, u32, f32)>, u32) {
    let err = pixel_errors(render, gt);
    let min_error = threshold(&err, min_error);
    let over = err.iter().filter(|&&e| e >= min_error).count();
    if over == 0 || k == 0 {
        return (Vec::new(), 1);
    }
    // Cells sized so the region holds about k of them: the picks spread over all of it.
    let cell = ((over as f64 / k as f64).sqrt().ceil() as u32).max(1);
    let (cw, ch) = (width.div_ceil(cell), height.div_ceil(cell));
    let mut best: Vec<Option<(u32, u32, f32)>> = vec![None; (cw * ch) as usize];
    for y in 0..height {
        for x in 0..width {
            let e = err[(y * width + x) as usize];
            if e.is_nan() || e < min_error {
                continue;
            }
            let c = &mut best[((y / cell) * cw + x / cell) as usize];
            if c.map_or(true, |b| e > b.2) {
                *c = Some((x, y, e));
            }
        }
    }
    let mut picks: Vec<(u32, u32, f32)> = best.into_iter().flatten().collect();
    picks.sort_by(|a, b| b.2.total_cmp(&a.2).then((a.1, a.0).cmp(&(b.1, b.0))));
    picks.truncate(k);
    (picks, cell)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_residual_is_local() {
        let gt = vec![[0.0f32; 4]; 100];
        let mut r = gt.clone();
        r[7] = [0.9; 4];
        r[8] = [0.6; 4];
        assert!((frame_residual(&r, &gt, 10, 0.1).sum - 1.5).abs() < 1e-6);
        // Wrong everywhere alike: nothing local.
        assert_eq!(
            frame_residual(&vec![[0.5f32; 4]; 100], &gt, 10, 0.1).sum,
            0.0
        );
    }

    #[test]
    fn uncovered_counts_the_wrong_pixels_the_render_leaves_bare() {
        let gt = vec![[0.0f32, 0.0, 0.0, 1.0]; 100];
        let mut r = gt.clone();
        // Four wrong pixels: three drawn by nothing (alpha 0.1), one drawn wrong (0.9).
        for (i, a) in [(3, 0.1), (4, 0.1), (5, 0.1), (6, 0.9)] {
            r[i] = [0.9, 0.9, 0.9, a];
        }
        // A right pixel left bare does not count.
        r[50][3] = 0.0;
        assert!((frame_residual(&r, &gt, 10, 0.1).uncovered - 0.75).abs() < 1e-12);
        assert_eq!(
            frame_residual(&gt, &gt, 10, 0.1),
            FrameResidual {
                pixels: 100,
                ..Default::default()
            },
            "nothing wrong"
        );
    }

    #[test]
    fn unexplained_counts_the_wrong_pixels_whose_colour_is_drawn_nowhere_near() {
        // A 40×20 grey frame; the truth holds a red square (an object) and a blue one.
        let (w, h) = (40usize, 20usize);
        let grey = [0.5f32, 0.5, 0.5, 1.0];
        let mut gt = vec![grey; w * h];
        let mut r = gt.clone();
        let square = |img: &mut Vec<[f32; 4]>, x0: usize, y0: usize, c: [f32; 4]| {
            for y in y0..y0 + 3 {
                for x in x0..x0 + 3 {
                    img[y * w + x] = c;
                }
            }
        };
        let (red, blue) = ([0.9f32, 0.1, 0.1, 1.0], [0.1f32, 0.1, 0.9, 1.0]);
        square(&mut gt, 2, 2, red);
        square(&mut gt, 30, 10, blue);
        // The render draws the red square 4 pixels off (misplaced: explained) and no blue one.
        square(&mut r, 6, 2, red);
        let f = frame_residual(&r, &gt, w as u32, 0.1);
        // Wrong: the true red square's 9 pixels, the 9 the render draws red on grey (their
        // grey is drawn next door) and the 9 blue ones.
        let err = pixel_errors(&r, &gt);
        let wrong: Vec<usize> = (0..w * h).filter(|&i| err[i] >= 0.1).collect();
        assert_eq!(
            wrong.len(),
            27,
            "9 true red, 9 drawn red, 9 true blue pixels"
        );
        assert!(
            (f.unexplained - 9.0 / 27.0).abs() < 1e-12,
            "only the blue square is drawn nowhere near: {}",
            f.unexplained
        );
        assert!(
            explained(&r, w as u32, 2 * w + 2, &gt[2 * w + 2]),
            "red 4 px away"
        );
        assert!(!explained(&r, w as u32, 10 * w + 30, &gt[10 * w + 30]));
        // A red pixel just past the reach no longer explains the truth at (2, 2).
        let mut far = vec![grey; w * h];
        far[2 * w + 2 + EXPLAINED_REACH + 1] = red;
        assert!(!explained(&far, w as u32, 2 * w + 2, &red));
        far[2 * w + 2 + EXPLAINED_REACH] = red;
        assert!(explained(&far, w as u32, 2 * w + 2, &red));
        // Nothing wrong: nothing unexplained.
        assert_eq!(frame_residual(&gt, &gt, w as u32, 0.1).unexplained, 0.0);
    }

    #[test]
    fn worst_pixels_spread_over_the_wrong_region() {
        let (w, h) = (16u32, 8u32);
        let gt = vec![[0.0f32; 4]; (w * h) as usize];
        let mut r = gt.clone();
        // A wrong 8×4 block, error growing with x.
        for y in 2..6 {
            for x in 4..12 {
                r[(y * w + x) as usize] = [0.2 + 0.01 * x as f32; 4];
            }
        }
        let (p, cell) = worst_pixels(&r, &gt, w, h, 0.1, 8);
        assert_eq!(cell, 2, "32 pixels over the threshold, 8 picks: 2×2 cells");
        assert_eq!(p.len(), 8);
        assert!(p
            .iter()
            .all(|&(x, y, _)| (4..12).contains(&x) && (2..6).contains(&y)));
        // No two picks in one cell, worst first.
        for (i, a) in p.iter().enumerate() {
            for b in &p[i + 1..] {
                assert!((a.0 / 2, a.1 / 2) != (b.0 / 2, b.1 / 2));
            }
        }
        assert!(p.windows(2).all(|w| w[0].2 >= w[1].2));
        assert!(worst_pixels(&gt, &gt, w, h, 0.1, 8).0.is_empty());
        // Wrong everywhere: nothing stands out of the frame's median, nothing spawns.
        let all = vec![[0.5f32; 4]; (w * h) as usize];
        assert!(worst_pixels(&all, &gt, w, h, 0.1, 8).0.is_empty());
    }
}
