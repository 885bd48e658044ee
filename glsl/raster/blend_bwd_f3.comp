#version 460
// Blend backward with 3 extra feature channels (body in blend_bwd.glsl).
#define FEAT 3
#include "blend_bwd.glsl"
