#version 460
// blur_v for CPU devices, storage buffers; body and notes in blur_v_rows.glsl.
#extension GL_GOOGLE_include_directive : require
#include "blur_v_rows.glsl"
