#version 460
// Blend forward with 0 extra feature channels (body in blend_fwd.glsl).
#define FEAT 0
#include "blend_fwd.glsl"
