#version 460
// Fused Adam, CPU shape: its arrays are texel buffers (glsl/include/access.glsl).
#extension GL_GOOGLE_include_directive : require
#define TEXEL_ACCESS
#include "adam.glsl"
