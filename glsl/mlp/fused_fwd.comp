#version 460
// Fused whole-network forward, f32 (see fused_fwd.glsl). 16 rows per workgroup:
// shared memory 16 × (128 + 256) × 4 = 24 KiB (lavapipe has 32 KiB).
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

#define ROWS 16
#define ACT float
#define STORE_ACT(v) (v)
layout(std430, binding = 0) readonly buffer Params { float params[]; };
#define W_AT(i) params[i]

#include "fused_fwd.glsl"
