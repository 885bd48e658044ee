#version 460
// Blend forward in bands (body in blend_fwd_tile.glsl), 3 extra feature channels; 8 pixels
// per invocation, 32 invocations per tile, splats that miss a band's rows stepped over.
#define FEAT 3
#define PX 8
#define STEP_OVER
#include "blend_fwd_tile.glsl"
