#version 460
// Radix sort hist pass, u64 keys (body in radix_hist.glsl).
#define KEY64
#include "radix_hist.glsl"
