#version 460
// ∂L/∂render, CPU shape: its arrays are texel buffers (glsl/include/access.glsl).
#extension GL_GOOGLE_include_directive : require
#define TEXEL_ACCESS
#include "loss_grad.glsl"
