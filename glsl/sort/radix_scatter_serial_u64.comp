#version 460
// Radix sort scatter pass, CPU shape, u64 keys (body in radix_scatter_serial.glsl).
#define KEY64
#include "radix_scatter_serial.glsl"
