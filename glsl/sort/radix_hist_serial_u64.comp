#version 460
// Radix sort hist pass, CPU shape, u64 keys (body in radix_hist_serial.glsl).
#define KEY64
#include "radix_hist_serial.glsl"
