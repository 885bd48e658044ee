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
