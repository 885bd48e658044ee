#version 460
// Register-blocked Linear for CPU devices, storage buffers; body and notes in linear_rows.glsl.
#extension GL_GOOGLE_include_directive : require
#include "linear_rows.glsl"
