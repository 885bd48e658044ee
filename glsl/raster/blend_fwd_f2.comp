#version 460
// Blend forward with 2 extra feature channels (body in blend_fwd.glsl).
#define FEAT 2
#include "blend_fwd.glsl"
