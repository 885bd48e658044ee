#version 460
// Blend backward, per-tile accumulation, 8 pixels per invocation, 0 extra feature channels
// (body in blend_bwd_tile.glsl).
#define FEAT 0
#define PX 8
#include "blend_bwd_tile.glsl"
