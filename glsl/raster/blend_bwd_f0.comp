#version 460
// Blend backward with 0 extra feature channels (body in blend_bwd.glsl).
#define FEAT 0
#include "blend_bwd.glsl"
