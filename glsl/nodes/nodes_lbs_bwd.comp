#version 460
// The control-node blend backward over NODES_KMAX slots (any K; body in nodes_lbs_bwd.glsl).
#define NODES_KLOOP NODES_KMAX
#include "nodes_lbs_bwd.glsl"
