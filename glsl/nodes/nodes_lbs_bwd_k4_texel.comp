#version 460
// nodes_lbs_bwd_k4.comp with its arrays as texel buffers (glsl/include/access.glsl; the CPU shape of
// kernels::shape::Access).
#define NODES_KLOOP 4
#define TEXEL_ACCESS
#include "nodes_lbs_bwd.glsl"
