#version 460
// One TV-L1 iteration, GPU shape (storage buffers); body and notes in tvl1.glsl.
#extension GL_GOOGLE_include_directive : require
#include "tvl1.glsl"
