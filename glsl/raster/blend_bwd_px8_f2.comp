#version 460
// Blend backward, per-tile accumulation, 8 pixels per invocation, 2 extra feature channels
// (body in blend_bwd_tile.glsl).
#define FEAT 2
#define PX 8
#include "blend_bwd_tile.glsl"
