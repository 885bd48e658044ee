#version 460
// Deformation composition, with the MLP-output gradient (body in deform_apply_bwd.glsl).
#define USE_DEFORM 1
#extension GL_GOOGLE_include_directive : require
#include "deform_apply_bwd.glsl"
