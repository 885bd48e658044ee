//! Twin of `glsl/loss/*`: `(1 − λ)·L1 + λ·(1 − SSIM)` with the 11×11 Gaussian window (σ = 1.5,
//! zero padding), per colour channel, and its gradient wrt the render. Written as a direct 2D
//! window (not separable) in f64, with the gradient by the chain rule through the window
//! statistics μx, E[x²], E[xy].

use crate::kernels::loss::LossValues;

const C1: f64 = 0.01 * 0.01;
const C2: f64 = 0.03 * 0.03;

fn window() -> [[f64; 11]; 11] {
    let g: Vec<f64> = (-5..=5)
        .map(|d: i32| (-(d * d) as f64 / (2.0 * 1.5 * 1.5)).exp())
        .collect();
    let s: f64 = g.iter().sum();
    let mut w = [[0.0; 11]; 11];
    for (i, row) in w.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = g[i] * g[j] / (s * s);
        }
    }
    w
}

/// Loss values and ∂L/∂render ([H·W] × rgba, alpha 0) for `render` against `target`.
pub fn photometric_loss(
    render: &[[f32; 4]],
    target: &[[f32; 4]],
    w: usize,
    h: usize,
    lambda: f64,
) -> (LossValues, Vec<[f64; 4]>) {
    let x: Vec<[f64; 4]> = render.iter().map(|p| p.map(f64::from)).collect();
    let y: Vec<[f64; 4]> = target.iter().map(|p| p.map(f64::from)).collect();
    photometric_loss_f64(&x, &y, w, h, lambda)
}

/// [`photometric_loss`] on f64 images (for finite differences).
pub fn photometric_loss_f64(
    x: &[[f64; 4]],
    y: &[[f64; 4]],
    w: usize,
    h: usize,
    lambda: f64,
) -> (LossValues, Vec<[f64; 4]>) {
    assert_eq!(x.len(), w * h);
    assert_eq!(y.len(), w * h);
    let win = window();
    let n = (3 * w * h) as f64;
    let mut grad = vec![[0.0f64; 4]; w * h];
    let (mut l1, mut se, mut ssim_sum) = (0.0, 0.0, 0.0);
    for c in 0..3 {
        // Window statistics and ∂S/∂(μx, Exx, Exy) per pixel.
        let mut parts = vec![[0.0f64; 3]; w * h];
        for py in 0..h {
            for px in 0..w {
                let (mut mx, mut my, mut exx, mut eyy, mut exy) = (0.0, 0.0, 0.0, 0.0, 0.0);
                for (dy, row) in win.iter().enumerate() {
                    for (dx, wt) in row.iter().enumerate() {
                        let (qx, qy) = (px as i64 + dx as i64 - 5, py as i64 + dy as i64 - 5);
                        if qx < 0 || qy < 0 || qx >= w as i64 || qy >= h as i64 {
                            continue;
                        }
                        let q = qy as usize * w + qx as usize;
                        let (a, b) = (x[q][c], y[q][c]);
                        mx += wt * a;
                        my += wt * b;
                        exx += wt * a * a;
                        eyy += wt * b * b;
                        exy += wt * a * b;
                    }
                }
                let (sxx, syy, sxy) = (exx - mx * mx, eyy - my * my, exy - mx * my);
                let (n1, n2) = (2.0 * mx * my + C1, 2.0 * sxy + C2);
                let (d1, d2) = (mx * mx + my * my + C1, sxx + syy + C2);
                let s = n1 * n2 / (d1 * d2);
                ssim_sum += s;
                let ds = -lambda / n; // ∂L/∂S(p)
                parts[py * w + px] = [
                    ds * s * (2.0 * my / n1 - 2.0 * my / n2 - 2.0 * mx / d1 + 2.0 * mx / d2),
                    ds * (-s / d2),
                    ds * (2.0 * s / n2),
                ];
            }
        }
        // Scatter back through the window: ∂μx(p)/∂x(q) = G, ∂Exx/∂x = 2Gx(q), ∂Exy/∂x = Gy(q).
        for py in 0..h {
            for px in 0..w {
                let [a, b, cc] = parts[py * w + px];
                for (dy, row) in win.iter().enumerate() {
                    for (dx, wt) in row.iter().enumerate() {
                        let (qx, qy) = (px as i64 + dx as i64 - 5, py as i64 + dy as i64 - 5);
                        if qx < 0 || qy < 0 || qx >= w as i64 || qy >= h as i64 {
                            continue;
                        }
                        let q = qy as usize * w + qx as usize;
                        grad[q][c] += wt * (a + 2.0 * x[q][c] * b + y[q][c] * cc);
                    }
                }
            }
        }
        for q in 0..w * h {
            let e = x[q][c] - y[q][c];
            l1 += e.abs();
            se += e * e;
            grad[q][c] += (1.0 - lambda) / n * e.signum() * (e != 0.0) as i32 as f64;
        }
    }
    (LossValues::new(l1 / n, se / n, ssim_sum / n, lambda), grad)
}
