//! Twin of `glsl/dispflow/*`. Generic over the float type: f32 is what the GPU stores (bit for
//! bit), f64 is what the whole-step twin (`reference::step`) composes.

use std::ops::Sub;

use crate::kernels::raster::Camera;

/// δ_i = dx_i(t2) − dx_i(t1) from [N,10] MLP outputs.
pub fn displacement<T: Copy + Sub<Output = T>>(out_t1: &[T], out_t2: &[T]) -> Vec<T> {
    out_t1
        .chunks_exact(10)
        .zip(out_t2.chunks_exact(10))
        .flat_map(|(a, b)| [b[0] - a[0], b[1] - a[1], b[2] - a[2]])
        .collect()
}

/// (updated ∂L/∂out(t1), ∂L/∂out(t2)) from ∂L/∂δ.
pub fn displacement_bwd<T: Copy + Default + Sub<Output = T>>(
    d_delta: &[T],
    d_out_t1: &[T],
) -> (Vec<T>, Vec<T>) {
    let mut d1 = d_out_t1.to_vec();
    let mut d2 = vec![T::default(); d_out_t1.len()];
    for (i, g) in d_delta.chunks_exact(3).enumerate() {
        for a in 0..3 {
            d1[10 * i + a] = d1[10 * i + a] - g[a];
            d2[10 * i + a] = g[a];
        }
    }
    (d1, d2)
}

/// ((1/N) Σ c·|m_scene − m_disp|, ∂(weight · that)/∂m_disp), c ≡ 1 without `conf`; zeros
/// when `skip` (degenerate map).
pub fn motion_l1<T: Copy + Into<f64>>(
    m_disp: &[T],
    m_scene: &[T],
    conf: Option<&[T]>,
    weight: f64,
    skip: bool,
) -> (f64, Vec<f64>) {
    let n = m_disp.len().max(1) as f64;
    if skip {
        return (0.0, vec![0.0; m_disp.len()]);
    }
    let mut sum = 0.0;
    let g = m_disp
        .iter()
        .zip(m_scene)
        .enumerate()
        .map(|(i, (&a, &b))| {
            let c = conf.map_or(1.0, |c| c[i].into());
            let e = a.into() - b.into();
            sum += c * e.abs();
            weight
                * c
                * if e > 0.0 {
                    1.0
                } else if e < 0.0 {
                    -1.0
                } else {
                    0.0
                }
                / n
        })
        .collect();
    (sum / n, g)
}

/// Twin of `scene_signal`: (scene motion `flow_t2 − residual·flow_t1`, 0 where shorter than
/// `mask_px`; confidence `exp(−mean_rgb|photo − render_t1| / sigma)`, 1 when `sigma` = 0);
/// non-finite → (0, 0).
pub fn scene_signal(
    flow_t2: &[[f32; 2]],
    flow_t1: &[[f32; 2]],
    photo: &[[f32; 4]],
    render_t1: &[[f32; 4]],
    residual: bool,
    sigma: f64,
    mask_px: f64,
) -> (Vec<[f64; 2]>, Vec<f64>) {
    let mut scene = Vec::with_capacity(flow_t2.len());
    let mut conf = Vec::with_capacity(flow_t2.len());
    for p in 0..flow_t2.len() {
        let r = if residual { flow_t1[p] } else { [0.0; 2] };
        let mut s = [0, 1].map(|k| flow_t2[p][k] as f64 - r[k] as f64);
        if s[0].hypot(s[1]) < mask_px {
            s = [0.0; 2];
        }
        let c = if sigma > 0.0 {
            let e: f64 = (0..3)
                .map(|k| (photo[p][k] as f64 - render_t1[p][k] as f64).abs())
                .sum::<f64>()
                / 3.0;
            (-e / sigma).exp()
        } else {
            1.0
        };
        let ok = s.iter().all(|v| v.is_finite()) && c.is_finite();
        scene.push(if ok { s } else { [0.0; 2] });
        conf.push(if ok { c } else { 0.0 });
    }
    (scene, conf)
}

/// Twin of `camera_flow`: the pair flow minus the camera flow of the depth `depth / alpha`
/// reprojected from `a` into `b` at pixel centres; 0 where alpha < `min_alpha`, the depth is
/// not positive and finite, the point is behind `b`'s near plane or anything is not finite.
/// `subtract` = false passes the flow through (non-finite → 0).
pub fn camera_flow(
    a: &Camera,
    b: &Camera,
    flow: &[[f32; 2]],
    rgba: &[[f32; 4]],
    depth: &[f32],
    min_alpha: f64,
    subtract: bool,
) -> Vec<[f64; 2]> {
    let w = a.width as usize;
    let f64s = |v: [f32; 3]| v.map(|x| x as f64);
    (0..flow.len())
        .map(|p| {
            let mut f = flow[p].map(|v| v as f64);
            let mut ok = f.iter().all(|v| v.is_finite());
            if subtract {
                let px = [(p % w) as f64 + 0.5, (p / w) as f64 + 0.5];
                let al = rgba[p][3] as f64;
                let z = depth[p] as f64 / al;
                let xc = [
                    (px[0] - a.cx as f64) / a.fx as f64 * z,
                    (px[1] - a.cy as f64) / a.fy as f64 * z,
                    z,
                ];
                let d = [0, 1, 2].map(|k| xc[k] - a.trans[k] as f64);
                let ra = a.rot.map(f64s);
                let xw = [0, 1, 2].map(|j| (0..3).map(|k| ra[k][j] * d[k]).sum::<f64>());
                let rb = b.rot.map(f64s);
                let y = [0, 1, 2]
                    .map(|k| (0..3).map(|j| rb[k][j] * xw[j]).sum::<f64>() + b.trans[k] as f64);
                let q = [
                    b.fx as f64 * y[0] / y[2] + b.cx as f64,
                    b.fy as f64 * y[1] / y[2] + b.cy as f64,
                ];
                ok = ok && al >= min_alpha && z > 0.0 && z.is_finite() && y[2] > b.near as f64;
                f = [f[0] - (q[0] - px[0]), f[1] - (q[1] - px[1])];
                ok = ok && f.iter().all(|v| v.is_finite());
            }
            if ok {
                f
            } else {
                [0.0; 2]
            }
        })
        .collect()
}
