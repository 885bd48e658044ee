//! PSNR inside and outside a frame's motion mask: what shows a moving object drawn as a smear,
//! a ghost or not at all, which whole-image PSNR hides behind a well-fitted static background.
//!
//! The mask is dilated by [`MASK_DILATE_PX`] (a disc) before it splits the image, so a ghost
//! drawn beside the object, where the ground truth is background, counts as dynamic. Computed
//! on the host from the render and the ground truth the evaluation already holds: a few
//! hundred thousand pixels per test frame, once per evaluation.

/// Dilation radius of the motion mask, pixels (at the evaluated resolution).
pub const MASK_DILATE_PX: u32 = 3;

/// PSNR of the pixels in the dilated mask and of the rest; `None` where a region is empty.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RegionPsnr {
    pub dynamic: Option<f64>,
    pub static_: Option<f64>,
    /// Share of the image's pixels inside the dilated mask (`None` for an empty image): a
    /// frame's dynamic PSNR is a mean over this many pixels, so frames are compared knowing
    /// how much of each one moves.
    pub dynamic_share: Option<f64>,
}

/// `mask` (`w·h`, nonzero = moving) dilated by a disc of radius `r` pixels: a pixel is set when
/// a set pixel lies within Euclidean distance `r` of it.
pub fn dilate(mask: &[u8], w: u32, h: u32, r: u32) -> Vec<bool> {
    let (w, h, r) = (w as i64, h as i64, r as i64);
    assert_eq!(mask.len() as i64, w * h, "mask size");
    let offsets: Vec<(i64, i64)> = (-r..=r)
        .flat_map(|dy| (-r..=r).map(move |dx| (dx, dy)))
        .filter(|(dx, dy)| dx * dx + dy * dy <= r * r)
        .collect();
    let mut out = vec![false; mask.len()];
    for y in 0..h {
        for x in 0..w {
            if mask[(y * w + x) as usize] == 0 {
                continue;
            }
            for &(dx, dy) in &offsets {
                let (u, v) = (x + dx, y + dy);
                if (0..w).contains(&u) && (0..h).contains(&v) {
                    out[(v * w + u) as usize] = true;
                }
            }
        }
    }
    out
}

/// PSNR over the RGB channels (alpha ignored, as the photometric loss) of `render` against
/// `gt` inside the mask dilated by `dilate_px` and outside it. A perfect region reads +∞.
pub fn region_psnr(
    render: &[[f32; 4]],
    gt: &[[f32; 4]],
    mask: &[u8],
    w: u32,
    h: u32,
    dilate_px: u32,
) -> RegionPsnr {
    assert!(
        render.len() == mask.len() && gt.len() == mask.len(),
        "region_psnr: image and mask sizes differ"
    );
    let inside = dilate(mask, w, h, dilate_px);
    // (squared-error sum, pixel count) per region: [static, dynamic].
    let mut acc = [(0.0f64, 0u64); 2];
    for ((r, g), &m) in render.iter().zip(gt).zip(&inside) {
        let se: f64 = (0..3).map(|c| (r[c] as f64 - g[c] as f64).powi(2)).sum();
        let a = &mut acc[m as usize];
        a.0 += se;
        a.1 += 1;
    }
    let psnr =
        |(se, n): (f64, u64)| (n > 0).then(|| crate::kernels::loss::psnr(se / (3 * n) as f64));
    let total = acc[0].1 + acc[1].1;
    RegionPsnr {
        dynamic: psnr(acc[1]),
        static_: psnr(acc[0]),
        dynamic_share: (total > 0).then(|| acc[1].1 as f64 / total as f64),
    }
}
