#version 460
// Blend forward with 3 extra feature channels (body in blend_fwd.glsl).
#define FEAT 3
#include "blend_fwd.glsl"
