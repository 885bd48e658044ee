// Weight and bias gradients on the register path (CPU devices): one invocation per C input
// columns (column fan_in is the constant 1: the bias) and block of OB outputs, walking the
// rows of one uniform-buffer window of dz. On llvmpipe a uniform-buffer load costs about as
// much as a per-lane loop (about 20 cycles measured, a dozen FMAs), so each dz value feeds C
// columns' FMAs and each input value (one per-lane load) OB outputs. C = 4 cut this kernel by
// about a fifth (docs/measurements.md, "The MLP weight gradient, four columns per invocation").
// Every accumulator sums its rows in row order, as with one column per invocation.
// Windows run as successive dispatches adding into one partial [fan_out][fan_in + 1] in a
// fixed order (deterministic); mlp/reduce_grad moves it into the gradient buffer.
// Body of linear_bwd_weight_rows.comp (storage buffers) and linear_bwd_weight_rows_texel.comp (texel buffers, glsl/include/access.glsl).
#ifndef LINEAR_BWD_WEIGHT_ROWS_GLSL
#define LINEAR_BWD_WEIGHT_ROWS_GLSL
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#include "common.glsl"
#include "params.glsl"
#include "access.glsl"

#define OB 32
#define C 4 // input columns per invocation: each dz load feeds C FMAs

layout(local_size_x = 64) in;

layout(push_constant) uniform Push { MlpRowsWeightParams pc; };
layout(std140, binding = 0) uniform Dz { vec4 dz4[4096]; };
ARR_RO(1, float, r32f, InA, in_a)
ARR_RO(2, float, r32f, InB, in_b)
ARR_RW(3, float, r32f, Partial, partial)

float dz_at(uint i) { return dz4[i >> 2][i & 3]; }

void main() {
    uint c0 = gl_GlobalInvocationID.x * C;
    uint cols = pc.fan_in + 1;
    if (c0 >= cols) return;
    uint o0 = gl_WorkGroupID.y * OB;
    float acc[C][OB];
    [[unroll]] for (uint ci = 0; ci < C; ++ci)
        [[unroll]] for (uint j = 0; j < OB; ++j) acc[ci][j] = 0.0;
    // Outputs past fan_out read output fan_out − 1 (inside the row) and are never stored.
    uint oc[OB];
    [[unroll]] for (uint j = 0; j < OB; ++j) oc[j] = min(o0 + j, pc.fan_out - 1);
    for (uint r = 0; r < pc.rows; ++r) {
        uint g = pc.r0 + r;
        float x[C];
        [[unroll]] for (uint ci = 0; ci < C; ++ci) {
            uint c = c0 + ci;
            x[ci] = c < pc.ka ? LD1(in_a, g * pc.a_stride + c)
                  : (c < pc.fan_in ? LD1(in_b, g * pc.b_stride + c - pc.ka) : 1.0);
        }
        uint row = pc.dz_res + r * pc.dz_stride;
        [[unroll]] for (uint j = 0; j < OB; ++j) {
            float d = dz_at(row + oc[j]);
            [[unroll]] for (uint ci = 0; ci < C; ++ci) acc[ci][j] += d * x[ci];
        }
    }
    [[unroll]] for (uint ci = 0; ci < C; ++ci) {
        uint c = c0 + ci;
        if (c >= cols) continue;
        [[unroll]] for (uint j = 0; j < OB; ++j) {
            if (o0 + j >= pc.fan_out) continue;
            uint e = (o0 + j) * cols + c;
            ST1(partial, e, pc.accumulate != 0 ? LD1(partial, e) + acc[ci][j] : acc[ci][j]);
        }
    }
}

#endif
