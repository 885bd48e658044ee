#version 460
// Fused whole-network forward with fp16 storage: weights from an f16 copy of the parameters
// (mlp/to_f16), activations in shared memory as f16, products and sums in f32. 32 rows per
// workgroup: shared memory 32 × (128 + 256) × 2 = 24 KiB. Stored activations saturate at
// ±65504 (f16 max) instead of overflowing to infinity.
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_shader_explicit_arithmetic_types_float16 : require
#extension GL_EXT_shader_16bit_storage : require
#include "common.glsl"
#include "params.glsl"

#define ROWS 32
#define ACT float16_t
#define STORE_ACT(v) float16_t(clamp((v), -65504.0, 65504.0))
layout(std430, binding = 0) readonly buffer Params { float16_t params[]; };
#define W_AT(i) float(params[i])

#include "fused_fwd.glsl"
