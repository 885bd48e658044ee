#version 460
// Blend backward, per-tile accumulation (body in blend_bwd_tile.glsl), 0 extra feature channels;
// 32 pixels per invocation: 8 invocations, one lavapipe coroutine per tile.
#define FEAT 0
#define PX 32
#include "blend_bwd_tile.glsl"
