#version 460
// Blend backward, per-tile accumulation (body in blend_bwd_tile.glsl), 6 extra feature channels (Gaussian flow);
// 32 pixels per invocation: 8 invocations, one lavapipe coroutine per tile.
#define FEAT 6
#define PX 32
#include "blend_bwd_tile.glsl"
