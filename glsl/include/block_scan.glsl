// Exclusive scan of one SCAN_BLOCK-element block held in shared memory, plus `offset`.
#ifndef BLOCK_SCAN_GLSL
#define BLOCK_SCAN_GLSL
#include "wg_scan.glsl"

shared uint s_block[SCAN_BLOCK];

// Loads src[base ..] (zero past n), scans, and writes dst[base ..] (only below n).
// src and dst may be the same buffer: every read lands in shared memory before any write.
#define BLOCK_SCAN(src, dst, base, n, offset)                                   \
    {                                                                           \
        uint tid_ = gl_LocalInvocationIndex;                                    \
        for (uint i = 0; i < SCAN_ITEMS; ++i) {                                 \
            uint idx = (base) + i * SCAN_WG + tid_;                             \
            s_block[i * SCAN_WG + tid_] = idx < (n) ? src[idx] : 0u;            \
        }                                                                       \
        barrier();                                                              \
        uint run_ = 0;                                                          \
        uint vals_[SCAN_ITEMS];                                                 \
        for (uint i = 0; i < SCAN_ITEMS; ++i) {                                 \
            vals_[i] = s_block[tid_ * SCAN_ITEMS + i];                          \
            run_ += vals_[i];                                                   \
        }                                                                       \
        uint total_;                                                            \
        uint pre_ = wg_exclusive_scan(run_, total_) + (offset);                 \
        for (uint i = 0; i < SCAN_ITEMS; ++i) {                                 \
            s_block[tid_ * SCAN_ITEMS + i] = pre_;                              \
            pre_ += vals_[i];                                                   \
        }                                                                       \
        barrier();                                                              \
        for (uint i = 0; i < SCAN_ITEMS; ++i) {                                 \
            uint idx = (base) + i * SCAN_WG + tid_;                             \
            if (idx < (n)) dst[idx] = s_block[i * SCAN_WG + tid_];              \
        }                                                                       \
    }

#endif
