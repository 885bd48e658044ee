#version 460
// ∂L/∂render, GPU shape (storage buffers); body and notes in loss_grad.glsl.
#extension GL_GOOGLE_include_directive : require
#include "loss_grad.glsl"
