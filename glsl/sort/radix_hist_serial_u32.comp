#version 460
// Radix sort hist pass, CPU shape, u32 keys (body in radix_hist_serial.glsl).
#include "radix_hist_serial.glsl"
