#version 460
// Weight and bias gradients on the register path (CPU devices): one invocation per input
// column c (column fan_in is the constant 1: the bias) and block of OB outputs, walking the
// rows of one uniform-buffer window of dz. Each input value is one per-lane load reused for OB
// outputs; each dz value is a uniform-index load (a broadcast on llvmpipe). Windows run as
// successive dispatches adding into one partial [fan_out][fan_in + 1] in a fixed order
// (deterministic); mlp/reduce_grad moves it into the gradient buffer.
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#include "common.glsl"
#include "params.glsl"

#define OB 32

layout(local_size_x = 64) in;

layout(push_constant) uniform Push { MlpRowsWeightParams pc; };
layout(std140, binding = 0) uniform Dz { vec4 dz4[4096]; };
layout(std430, binding = 1) readonly buffer InA { float in_a[]; };
layout(std430, binding = 2) readonly buffer InB { float in_b[]; };
layout(std430, binding = 3) buffer Partial { float partial[]; };

float dz_at(uint i) { return dz4[i >> 2][i & 3]; }

void main() {
    uint c = gl_GlobalInvocationID.x;
    uint cols = pc.fan_in + 1;
    if (c >= cols) return;
    uint o0 = gl_WorkGroupID.y * OB;
    float acc[OB];
    [[unroll]] for (uint j = 0; j < OB; ++j) acc[j] = 0.0;
    // Outputs past fan_out read output fan_out − 1 (inside the row) and are never stored.
    uint oc[OB];
    [[unroll]] for (uint j = 0; j < OB; ++j) oc[j] = min(o0 + j, pc.fan_out - 1);
    for (uint r = 0; r < pc.rows; ++r) {
        uint g = pc.r0 + r;
        float x = c < pc.ka ? in_a[g * pc.a_stride + c]
                : (c < pc.fan_in ? in_b[g * pc.b_stride + c - pc.ka] : 1.0);
        uint row = pc.dz_res + r * pc.dz_stride;
        [[unroll]] for (uint j = 0; j < OB; ++j) acc[j] += dz_at(row + oc[j]) * x;
    }
    [[unroll]] for (uint j = 0; j < OB; ++j) {
        if (o0 + j >= pc.fan_out) continue;
        uint e = (o0 + j) * cols + c;
        partial[e] = pc.accumulate != 0 ? partial[e] + acc[j] : acc[j];
    }
}
