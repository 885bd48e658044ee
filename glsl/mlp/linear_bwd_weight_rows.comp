#version 460
// Weight gradient for CPU devices, storage buffers; body and notes in linear_bwd_weight_rows.glsl.
#extension GL_GOOGLE_include_directive : require
#include "linear_bwd_weight_rows.glsl"
