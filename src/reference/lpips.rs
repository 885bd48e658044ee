//! Twin of `glsl/lpips/*` (see `kernels::lpips`): the same stages on the same inputs in f64,
//! written as direct loops over the reference package's definitions (no implicit GEMM).

use rayon::prelude::*;

use crate::error::Result;
use crate::kernels::lpips::{pool_out, ConvSpec, LpipsWeights, Plan, ALEXNET, SCALE, SHIFT};

/// `lpips_input`: [2][3][H·W] network input of two RGBA images (clamped to [0, 1]).
pub fn lpips_input(img0: &[[f32; 4]], img1: &[[f32; 4]], w: usize, h: usize) -> Vec<f64> {
    assert!(img0.len() >= w * h && img1.len() >= w * h);
    let hw = w * h;
    let mut out = vec![0.0; 6 * hw];
    for (b, img) in [img0, img1].into_iter().enumerate() {
        for p in 0..hw {
            for c in 0..3 {
                let v = (img[p][c] as f64).clamp(0.0, 1.0) * 2.0 - 1.0;
                out[(3 * b + c) * hw + p] = (v - SHIFT[c] as f64) / SCALE[c] as f64;
            }
        }
    }
    out
}

/// `conv`: convolution + bias + ReLU of `batch` planar images [batch][cin][in_h][in_w]
/// (zero padding); returns [batch][cout][out_h][out_w].
#[allow(clippy::too_many_arguments)] // the layer's shape, each one named
pub fn conv(
    src: &[f64],
    batch: usize,
    in_w: usize,
    in_h: usize,
    s: &ConvSpec,
    weight: &[f32],
    bias: &[f32],
    out_w: usize,
    out_h: usize,
) -> Vec<f64> {
    let (cin, cout, k) = (s.cin as usize, s.cout as usize, s.ksize as usize);
    let (stride, pad) = (s.stride as i64, s.pad as i64);
    assert!(src.len() >= batch * cin * in_w * in_h);
    assert!(weight.len() >= cout * cin * k * k && bias.len() >= cout);
    let mut out = vec![0.0; batch * cout * out_w * out_h];
    out.par_chunks_mut(out_w * out_h)
        .enumerate()
        .for_each(|(plane, o)| {
            let (b, co) = (plane / cout, plane % cout);
            for oy in 0..out_h {
                for ox in 0..out_w {
                    let mut acc = bias[co] as f64;
                    for ci in 0..cin {
                        let base = (b * cin + ci) * in_w * in_h;
                        for ky in 0..k {
                            let iy = oy as i64 * stride - pad + ky as i64;
                            if iy < 0 || iy >= in_h as i64 {
                                continue;
                            }
                            for kx in 0..k {
                                let ix = ox as i64 * stride - pad + kx as i64;
                                if ix < 0 || ix >= in_w as i64 {
                                    continue;
                                }
                                let wt = weight[((co * cin + ci) * k + ky) * k + kx] as f64;
                                acc += wt * src[base + iy as usize * in_w + ix as usize];
                            }
                        }
                    }
                    o[oy * out_w + ox] = acc.max(0.0);
                }
            }
        });
    out
}

/// `max_pool`: 3×3, stride 2, no padding, floor size, of `planes` planar images.
pub fn max_pool(src: &[f64], planes: usize, in_w: usize, in_h: usize) -> Vec<f64> {
    let (ow, oh) = (
        pool_out(in_w as u32).expect("pool input ≥ 3") as usize,
        pool_out(in_h as u32).expect("pool input ≥ 3") as usize,
    );
    let mut out = vec![0.0; planes * ow * oh];
    for z in 0..planes {
        for y in 0..oh {
            for x in 0..ow {
                let mut m = f64::NEG_INFINITY;
                for dy in 0..3 {
                    for dx in 0..3 {
                        m = m.max(src[z * in_w * in_h + (2 * y + dy) * in_w + 2 * x + dx]);
                    }
                }
                out[(z * oh + y) * ow + x] = m;
            }
        }
    }
    out
}

/// `lpips_diff`: spatial mean over the `w`×`h` pixels of Σ_c lin_c · (f0_c/(‖f0‖+ε) −
/// f1_c/(‖f1‖+ε))² for features [2][C][h][w] (ε = 1e-10, as the reference).
pub fn lpips_diff(feats: &[f64], channels: usize, w: usize, h: usize, lin: &[f32]) -> f64 {
    let hw = w * h;
    assert!(feats.len() >= 2 * channels * hw && lin.len() >= channels);
    let other = channels * hw;
    let mut total = 0.0;
    for p in 0..hw {
        let n0 = (0..channels)
            .map(|c| feats[c * hw + p].powi(2))
            .sum::<f64>();
        let n1 = (0..channels)
            .map(|c| feats[other + c * hw + p].powi(2))
            .sum::<f64>();
        let (d0, d1) = (n0.sqrt() + 1e-10, n1.sqrt() + 1e-10);
        for c in 0..channels {
            let e = feats[c * hw + p] / d0 - feats[other + c * hw + p] / d1;
            total += lin[c] as f64 * e * e;
        }
    }
    total / hw as f64
}

/// Per-stage LPIPS values (relu1…relu5) of two `w`×`h` RGBA images; LPIPS is their sum.
pub fn lpips(
    wts: &LpipsWeights,
    img0: &[[f32; 4]],
    img1: &[[f32; 4]],
    w: usize,
    h: usize,
) -> Result<[f64; 5]> {
    let plan = Plan::new(w as u32, h as u32)?;
    let mut x = lpips_input(img0, img1, w, h);
    let (mut cw, mut ch) = (w, h);
    let mut stages = [0.0; 5];
    for (i, s) in ALEXNET.iter().enumerate() {
        if s.pool_before {
            x = max_pool(&x, 2 * s.cin as usize, cw, ch);
        }
        let (iw, ih) = plan.conv_in[i];
        let (ow, oh) = plan.conv_out[i];
        let (iw, ih, ow, oh) = (iw as usize, ih as usize, ow as usize, oh as usize);
        x = conv(
            &x,
            2,
            iw,
            ih,
            s,
            wts.conv_weight(i),
            wts.conv_bias(i),
            ow,
            oh,
        );
        stages[i] = lpips_diff(&x, s.cout as usize, ow, oh, wts.lin_weight(i));
        (cw, ch) = (ow, oh);
    }
    Ok(stages)
}
