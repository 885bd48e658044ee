#version 460
// Blend backward, whole tile, 3 extra feature channels: blend_bwd_tile_f3.comp with its
// arrays as texel buffers (glsl/include/access.glsl; the CPU shape of kernels::shape::Access).
#define FEAT 3
#define PX 32
#define TEXEL_ACCESS
#include "blend_bwd_tile.glsl"
