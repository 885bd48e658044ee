#version 460
// Blend backward, one subgroup per band of the tile (body in blend_bwd_band.glsl), 3 extra
// feature channels; 8 pixels per invocation, 32 invocations per tile.
#define FEAT 3
#define PX 8
#include "blend_bwd_band.glsl"
