// Shared by the loss stages: the 11×11 Gaussian window (σ = 1.5) as a separable 11-tap filter,
// SSIM constants, and the plane layout (planar [plane][H·W] float arrays).
#ifndef LOSS_GLSL
#define LOSS_GLSL

#define SSIM_RADIUS 5
// Pixels per invocation of the CPU-shaped blurs (blur_h_rows, blur_v_rows).
#define BLUR_RUN 16
#define SSIM_C1 (0.01 * 0.01)
#define SSIM_C2 (0.03 * 0.03)
// Partial sums per workgroup: [L1 sum, squared-error sum, SSIM sum, unused].
#define PARTIAL_STRIDE 4

// exp(−d²/(2·1.5²)) normalised over the 11 taps (so the 2D window sums to 1, as in 3DGS).
float gauss_tap(int d) {
    const float w[6] = float[6](0.26601171, 0.21300554, 0.10936069, 0.03600077, 0.00759876, 0.00102838);
    return w[abs(d)];
}

#endif
