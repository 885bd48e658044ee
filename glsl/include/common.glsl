// Shared constants and helpers. Mirrored in Rust where noted.
#ifndef COMMON_GLSL
#define COMMON_GLSL

// Prefix sum: 256 threads × 8 items = 2048 elements per workgroup (src/kernels/scan.rs: SCAN_BLOCK).
#define SCAN_WG 256
#define SCAN_ITEMS 8
#define SCAN_BLOCK 2048

// Radix sort: 4-bit digits, 256 threads × 8 keys = 2048 keys per block (src/kernels/radix_sort.rs).
#define SORT_WG 256
#define SORT_ITEMS 8
#define SORT_BLOCK 2048
#define SORT_RADIX 16
// The serial shape: one invocation per 256-key block, 8 invocations (lavapipe's SIMD lanes at
// 256 bits) per workgroup, so the lanes of one subgroup walk 8 blocks at once.
#define SORT_SERIAL_BLOCK 256
#define SORT_SERIAL_LANES 8

// Deformation composition (glsl/deform): the drawn scale is exp(min(log_scale, LOG_SCALE_MAX))
// + ds and the log-scale gets no gradient above the clamp. f32 exp overflows from 88.72 on; 44
// is the largest integer whose exp still squares to a finite f32 (the rasteriser uses s²).
// Mirrored in Rust: kernels::deform::LOG_SCALE_MAX.
#define LOG_SCALE_MAX 44.0

#endif
