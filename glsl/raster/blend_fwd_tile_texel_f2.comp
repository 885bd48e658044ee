#version 460
// Blend forward, whole tile, 2 extra feature channels: blend_fwd_tile_f2.comp with its
// arrays as texel buffers (glsl/include/access.glsl; the CPU shape of kernels::shape::Access).
#define FEAT 2
#define PX 32
#define TEXEL_ACCESS
#include "blend_fwd_tile.glsl"
