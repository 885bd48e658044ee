#version 460
// Radix sort hist pass, u32 keys (body in radix_hist.glsl).
#include "radix_hist.glsl"
