#version 460
// Deformation composition, D ≡ 0 (no MLP output bound) (body in deform_apply.glsl).
#define USE_DEFORM 0
#extension GL_GOOGLE_include_directive : require
#include "deform_apply.glsl"
