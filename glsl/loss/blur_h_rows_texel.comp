#version 460
// blur_h for CPU devices, texel arrays: its arrays are texel buffers (glsl/include/access.glsl).
#extension GL_GOOGLE_include_directive : require
#define TEXEL_ACCESS
#include "blur_h_rows.glsl"
