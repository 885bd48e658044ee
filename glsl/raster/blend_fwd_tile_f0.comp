#version 460
// Blend forward, pixels in registers (body in blend_fwd_tile.glsl), no extra feature channels;
// 32 pixels per invocation: 8 invocations, one lavapipe coroutine per tile.
#define FEAT 0
#define PX 32
#include "blend_fwd_tile.glsl"
