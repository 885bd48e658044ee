#version 460
// nodes_lbs.comp with its arrays as texel buffers (glsl/include/access.glsl; the CPU shape of
// kernels::shape::Access).
#define NODES_KLOOP NODES_KMAX
#define TEXEL_ACCESS
#include "nodes_lbs.glsl"
