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

// src/kernels/deform.rs — canonical Gaussians + deformation → what the rasteriser draws.
struct DeformParams {
    uint n;
    uint use_deform;  // 0 during warm-up (D ≡ 0): the MLP output is not read
    uint pad0;
    uint pad1;
};
