#version 460
// Blend backward, per-tile accumulation, 8 pixels per invocation, 3 extra feature channels
// (body in blend_bwd_tile.glsl).
#define FEAT 3
#define PX 8
#include "blend_bwd_tile.glsl"
