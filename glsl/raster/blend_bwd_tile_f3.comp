#version 460
// Blend backward, per-tile accumulation (body in blend_bwd_tile.glsl), 3 extra feature channels;
// 32 pixels per invocation: 8 invocations, one lavapipe coroutine per tile.
#define FEAT 3
#define PX 32
#include "blend_bwd_tile.glsl"
