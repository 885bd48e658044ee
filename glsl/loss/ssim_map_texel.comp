#version 460
// SSIM map and its partial maps, CPU shape: its arrays are texel buffers (glsl/include/access.glsl).
#extension GL_GOOGLE_include_directive : require
#define TEXEL_ACCESS
#include "ssim_map.glsl"
