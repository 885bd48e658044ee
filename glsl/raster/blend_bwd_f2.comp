#version 460
// Blend backward with 2 extra feature channels (body in blend_bwd.glsl).
#define FEAT 2
#include "blend_bwd.glsl"
