#version 460
// SSIM map and its partial maps, GPU shape (storage buffers); body and notes in ssim_map.glsl.
#extension GL_GOOGLE_include_directive : require
#include "ssim_map.glsl"
