#version 460
// Deformation composition, D ≡ 0 (no MLP-output gradient bound) (body in deform_apply_bwd.glsl).
#define USE_DEFORM 0
#extension GL_GOOGLE_include_directive : require
#include "deform_apply_bwd.glsl"
