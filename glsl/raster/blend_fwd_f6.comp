#version 460
// Blend forward with 6 extra feature channels (Gaussian flow) (body in blend_fwd.glsl).
#define FEAT 6
#include "blend_fwd.glsl"
