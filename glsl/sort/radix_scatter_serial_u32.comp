#version 460
// Radix sort scatter pass, CPU shape, u32 keys (body in radix_scatter_serial.glsl).
#include "radix_scatter_serial.glsl"
