//! Real spherical harmonics, degrees 0–3, with the sign and ordering conventions of 3DGS's
//! `computeColorFromSH` (and gsplat's `sh_coeffs_to_color`). Twin of `glsl/include/sh.glsl`.
//!
//! Coefficients are band-major: coefficient `k` (0..16) multiplies basis function `k` below, one
//! coefficient per colour channel. The colour is linear in the coefficients, so its gradient wrt
//! coefficient `k` of channel `c` is `basis[k] · d_colour[c]`. The view direction is treated as a
//! constant (detached): no gradient flows into it.

/// Band 0.
pub const C0: f64 = 0.282_094_791_773_878_14;
/// Band 1.
pub const C1: f64 = 0.488_602_511_902_919_9;
/// Band 2.
pub const C2: [f64; 5] = [
    1.092_548_430_592_079_2,
    -1.092_548_430_592_079_2,
    0.315_391_565_252_520_05,
    -1.092_548_430_592_079_2,
    0.546_274_215_296_039_6,
];
/// Band 3.
pub const C3: [f64; 7] = [
    -0.590_043_589_926_643_5,
    2.890_611_442_640_554,
    -0.457_045_799_464_465_8,
    0.373_176_332_590_115_4,
    -0.457_045_799_464_465_8,
    1.445_305_721_320_277,
    -0.590_043_589_926_643_5,
];

/// Number of coefficients used by degree `degree`: `(degree + 1)²`.
pub fn num_coeffs(degree: u32) -> usize {
    ((degree + 1) * (degree + 1)) as usize
}

/// Values of the basis functions at unit direction `dir` for bands `0..=degree` (degree ≤ 3);
/// entries of higher bands are 0. `colour[c] = Σ_k basis[k] · coeff[k][c]` (before the +0.5).
pub fn basis(degree: u32, dir: [f64; 3]) -> [f64; 16] {
    assert!(degree <= 3, "SH degree {degree} > 3");
    let mut b = [0.0; 16];
    b[0] = C0;
    if degree == 0 {
        return b;
    }
    let [x, y, z] = dir;
    b[1] = -C1 * y;
    b[2] = C1 * z;
    b[3] = -C1 * x;
    if degree == 1 {
        return b;
    }
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xy, yz, xz) = (x * y, y * z, x * z);
    b[4] = C2[0] * xy;
    b[5] = C2[1] * yz;
    b[6] = C2[2] * (2.0 * zz - xx - yy);
    b[7] = C2[3] * xz;
    b[8] = C2[4] * (xx - yy);
    if degree == 2 {
        return b;
    }
    b[9] = C3[0] * y * (3.0 * xx - yy);
    b[10] = C3[1] * xy * z;
    b[11] = C3[2] * y * (4.0 * zz - xx - yy);
    b[12] = C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
    b[13] = C3[4] * x * (4.0 * zz - xx - yy);
    b[14] = C3[5] * z * (xx - yy);
    b[15] = C3[6] * x * (xx - 3.0 * yy);
    b
}

/// SH value (no +0.5 offset, no clamp) for one Gaussian: `coeffs` holds at least
/// `num_coeffs(degree)` RGB triples, band-major (`coeffs[k*3 + c]`).
pub fn eval(degree: u32, dir: [f64; 3], coeffs: &[f64]) -> [f64; 3] {
    let b = basis(degree, dir);
    let mut out = [0.0; 3];
    for (k, bk) in b.iter().enumerate().take(num_coeffs(degree)) {
        for c in 0..3 {
            out[c] += bk * coeffs[k * 3 + c];
        }
    }
    out
}

/// Gradient of [`eval`] wrt the coefficients, accumulated into `d_coeffs` (same layout as
/// `coeffs`): `d_coeffs[k*3 + c] += basis[k] · d_value[c]` for `k < num_coeffs(degree)`.
pub fn eval_bwd(degree: u32, dir: [f64; 3], d_value: [f64; 3], d_coeffs: &mut [f64]) {
    let b = basis(degree, dir);
    for (k, bk) in b.iter().enumerate().take(num_coeffs(degree)) {
        for c in 0..3 {
            d_coeffs[k * 3 + c] += bk * d_value[c];
        }
    }
}
