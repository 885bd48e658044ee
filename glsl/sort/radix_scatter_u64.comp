#version 460
// Radix sort scatter pass, u64 keys (body in radix_scatter.glsl).
#define KEY64
#include "radix_scatter.glsl"
