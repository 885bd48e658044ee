#version 460
// One TV-L1 iteration, CPU shape: its arrays are texel buffers (glsl/include/access.glsl).
#extension GL_GOOGLE_include_directive : require
#define TEXEL_ACCESS
#include "tvl1.glsl"
