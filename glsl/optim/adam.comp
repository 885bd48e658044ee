#version 460
// Fused Adam, GPU shape (storage buffers); body and notes in adam.glsl.
#extension GL_GOOGLE_include_directive : require
#include "adam.glsl"
