// Push-constant structs. Each is mirrored by a #[repr(C)] bytemuck struct of the same name in
// src/kernels/ and checked member by member against the reflected SPIR-V (tests/layout.rs).
#ifndef PARAMS_GLSL
#define PARAMS_GLSL

// src/kernels/scan.rs
struct ScanParams {
    uint capacity;   // element capacity of level 0 (the count is clamped to it)
    uint level;      // pyramid level this dispatch works on
    uint num_levels; // levels in the pyramid (the last is scanned by one workgroup)
    uint pad;
};

// src/kernels/radix_sort.rs
struct SortParams {
    uint capacity;   // key capacity (the count is clamped to it)
    uint shift;      // bit offset of this pass's 4-bit digit
    uint digit_mask; // mask applied to the digit (ignores key bits at or above `bits`)
    uint pad;
};

#endif

// src/kernels/raster.rs — camera and image shared by project, bin and project_bwd.
struct ProjectParams {
    vec4 rot0;        // rows of the world-to-camera rotation (OpenCV: x right, y down, z forward)
    vec4 rot1;
    vec4 rot2;
    vec4 trans_near;  // xyz: p_cam = rot · p + trans; w: near plane
    vec4 intrinsics;  // fx, fy, cx, cy (pixels; pixel centres at +0.5)
    uint width;
    uint height;
    uint tiles_x;
    uint tiles_y;
    uint num_gaussians;
    uint sh_coeffs;   // SH coefficients stored per Gaussian (1, 4, 9, 16)
    uint sh_degree;   // active degree (<= sqrt(sh_coeffs) - 1)
    uint isect_capacity;
};

// src/kernels/raster.rs — per-tile α-blending, forward and backward.
struct BlendParams {
    vec4 background;  // rgb; w unused
    uint width;
    uint height;
    uint tiles_x;
    uint tiles_y;
    float alpha_max;  // 0.99 as in 3DGS (gsplat: 0.999)
    uint num_gaussians;
    uint pad0;
    uint pad1;
};

// src/kernels/loss.rs — photometric loss 0.8·L1 + 0.2·(1 − SSIM) and its gradient.
struct LossParams {
    uint width;
    uint height;
    uint planes;        // planes the blur passes work on
    uint pad0;
    float lambda_ssim;  // weight of (1 − SSIM); L1 gets 1 − lambda_ssim
    float inv_count;    // 1 / (3 · width · height)
    uint pad1;
    uint pad2;
};

// src/kernels/densify.rs — per-view densification statistics (after every backward pass).
struct DensifyStatsParams {
    uint num_gaussians;
    uint width;         // image size: ∂L/∂ndc = ∂L/∂pixel · (W/2, H/2)
    uint height;
    uint pad;
};

// src/kernels/densify.rs — densify step (grow, mark, count, write). Thresholds arrive
// pre-transformed by the host (log / logit space) so the kernels only compare f32 values.
struct DensifyParams {
    uint num_gaussians;       // originals: rows of the source buffers
    uint capacity;            // output row budget (>= num_gaussians)
    uint row_len;             // write: floats per row of the bound section
    uint section;             // write: 0 plain copy, 1 means (split: sample), 2 log scales (split: shrink)
    uint seed;
    uint iteration;
    uint screen_prune;        // 1: also prune by screen size and world size (max_screen_size > 0)
    uint pad0;
    float grad_threshold;     // on the average ‖∂L/∂ndc‖ (compared as accum >= thr · denom)
    float log_dense_scale;    // ln(percent_dense · extent): clone if max log-scale <=, split if >
    float min_opacity_logit;  // logit(min_opacity): prune a row whose logit is below
    float max_screen_size;    // pixels: prune a row whose max radius is above
    float log_max_world_size; // ln(max_world_size): prune a row whose max log-scale is above
    float pad1;
    float pad2;
    float pad3;
};

// src/kernels/densify.rs — opacity reset (every 3000 iterations).
struct OpacityResetParams {
    uint num_gaussians;
    float reset_logit;        // logit(0.01): logits above it are lowered to it
    uint pad0;
    uint pad1;
};
