#version 460
// Blend backward with 6 extra feature channels (Gaussian flow) (body in blend_bwd.glsl).
#define FEAT 6
#include "blend_bwd.glsl"
