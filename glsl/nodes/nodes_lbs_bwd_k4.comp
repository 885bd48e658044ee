#version 460
// The control-node blend backward over 4 slots, for K <= 4 (body in nodes_lbs_bwd.glsl): on
// llvmpipe a masked slot costs what a used one does, so at the default K = 4 the 8-slot
// loop spends half its time on nothing (docs/measurements.md, stop 71).
#define NODES_KLOOP 4
#include "nodes_lbs_bwd.glsl"
