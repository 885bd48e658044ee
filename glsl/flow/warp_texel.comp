#version 460
// Warp terms of I1 at x + u, CPU shape: its arrays are texel buffers (glsl/include/access.glsl).
#extension GL_GOOGLE_include_directive : require
#define TEXEL_ACCESS
#include "warp.glsl"
