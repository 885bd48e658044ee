#version 460
// Deformation composition backward, added to the gradients already there (a second render of
// the step; body in deform_apply_bwd.glsl).
#define USE_DEFORM 1
#define ACCUM 1
#extension GL_GOOGLE_include_directive : require
#include "deform_apply_bwd.glsl"
