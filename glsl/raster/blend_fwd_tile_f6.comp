#version 460
// Blend forward, pixels in registers (body in blend_fwd_tile.glsl), 6 extra feature channels (Gaussian flow);
// 32 pixels per invocation: 8 invocations, one lavapipe coroutine per tile.
#define FEAT 6
#define PX 32
#include "blend_fwd_tile.glsl"
