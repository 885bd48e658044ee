// Shared shape of the layer-wise tiled GEMMs: a 64×64 output tile per 256-thread workgroup,
// 4×4 outputs per thread (rows ty + 16i, columns tx + 16j), K in steps of 16 through shared
// memory (2 × 16 × 65 floats = 8.3 KB; the +1 pad avoids bank conflicts).
#ifndef GEMM_GLSL
#define GEMM_GLSL

#define GEMM_BM 64
#define GEMM_BN 64
#define GEMM_BK 16

shared float s_a[GEMM_BK][GEMM_BM + 1];
shared float s_b[GEMM_BK][GEMM_BN + 1];

// Row tiles may exceed 65535 workgroups: they run over y and z.
uint gemm_row_tile() {
    return gl_WorkGroupID.y + gl_WorkGroupID.z * gl_NumWorkGroups.y;
}

// acc[i][j] += Σ_kk s_a[kk][ty + 16i] · s_b[kk][tx + 16j].
#define GEMM_TILE_FMA(acc, tx, ty)                                   \
    for (uint kk = 0; kk < GEMM_BK; ++kk) {                          \
        float a_[4], b_[4];                                          \
        for (uint i = 0; i < 4; ++i) a_[i] = s_a[kk][(ty) + 16 * i]; \
        for (uint j = 0; j < 4; ++j) b_[j] = s_b[kk][(tx) + 16 * j]; \
        for (uint i = 0; i < 4; ++i)                                 \
            for (uint j = 0; j < 4; ++j) acc[i][j] += a_[i] * b_[j]; \
    }

#endif
