#version 460
// Deformation composition, with the MLP output (body in deform_apply.glsl).
#define USE_DEFORM 1
#extension GL_GOOGLE_include_directive : require
#include "deform_apply.glsl"
