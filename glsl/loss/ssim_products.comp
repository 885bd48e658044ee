#version 460
// SSIM products, GPU shape (storage buffers); body and notes in ssim_products.glsl.
#extension GL_GOOGLE_include_directive : require
#include "ssim_products.glsl"
