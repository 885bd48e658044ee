#version 460
// Radix sort scatter pass, u32 keys (body in radix_scatter.glsl).
#include "radix_scatter.glsl"
