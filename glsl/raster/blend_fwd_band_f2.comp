#version 460
// Blend forward, one subgroup per band of the tile (body in blend_fwd_band.glsl), 2 extra
// feature channels; 8 pixels per invocation, 32 invocations per tile.
#define FEAT 2
#define PX 8
#include "blend_fwd_band.glsl"
