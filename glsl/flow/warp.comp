#version 460
// Warp terms of I1 at x + u, GPU shape (storage buffers); body and notes in warp.glsl.
#extension GL_GOOGLE_include_directive : require
#include "warp.glsl"
