#version 460
// Register-blocked Linear for CPU devices, texel arrays: its arrays are texel buffers (glsl/include/access.glsl).
#extension GL_GOOGLE_include_directive : require
#define TEXEL_ACCESS
#include "linear_rows.glsl"
