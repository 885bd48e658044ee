#version 460
// Coarse → fine level, GPU shape (storage buffers); body and notes in upsample.glsl.
#extension GL_GOOGLE_include_directive : require
#include "upsample.glsl"
