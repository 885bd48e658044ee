#version 460
// blur_h for CPU devices, storage buffers; body and notes in blur_h_rows.glsl.
#extension GL_GOOGLE_include_directive : require
#include "blur_h_rows.glsl"
