#version 460
// The control-node blend over NODES_KMAX slots (any K; body in nodes_lbs.glsl).
#define NODES_KLOOP NODES_KMAX
#include "nodes_lbs.glsl"
