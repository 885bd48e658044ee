// Register-blocked Linear for CPU-like devices (lavapipe). Measured there (see the MLP bench):
// every SSBO or shared-memory load is a per-lane loop with bounds checks, while a uniform-
// buffer load at a uniform index is one scalar load + broadcast. So one invocation owns R rows,
// loads each row's input once into a private array, and takes the matrix M (a window of
// outputs of W, or of Wᵀ for the input gradient) from a uniform buffer, reusing every
// broadcast weight for R rows and every input for all outputs of the window.
// Serves the forward (bias + ReLU) and the input gradient (ReLU mask, accumulate).
// Body of linear_rows.comp (storage buffers) and linear_rows_texel.comp (texel buffers, glsl/include/access.glsl).
#ifndef LINEAR_ROWS_GLSL
#define LINEAR_ROWS_GLSL
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#include "common.glsl"
#include "params.glsl"
#include "access.glsl"

#define R 8      // rows per invocation
#define OB 8     // outputs per register block (8 × 8 at 32 invocations: 7–9 % faster than
                 // 4 × 4 at 64, and still two workgroups at 512 rows; docs/measurements.md)
#define KMAX 512 // largest fan_in (checked on the host)

layout(local_size_x = 32) in;

layout(push_constant) uniform Push { MlpRowsParams pc; };
// Declared at the 64 KiB every device allows; the host binds at most maxUniformBufferRange.
layout(std140, binding = 0) uniform Mat { vec4 m4[4096]; };
layout(std140, binding = 1) uniform Bias { vec4 b4[4096]; };
ARR_RO(2, float, r32f, InA, in_a)
ARR_RO(3, float, r32f, InB, in_b)
ARR_RO(4, float, r32f, Act, act)
ARR_RW(5, float, r32f, Out, out_)

float m_at(uint i) { return m4[i >> 2][i & 3]; }
float b_at(uint i) { return b4[i >> 2][i & 3]; }

void main() {
    uint g = gl_WorkGroupID.x + gl_WorkGroupID.y * gl_NumWorkGroups.x;
    uint r0 = (g * 32 + gl_LocalInvocationIndex) * R;
    if (r0 >= pc.n) return;
    float xs[R][KMAX];
    [[unroll]] for (uint i = 0; i < R; ++i) {
        uint r = min(r0 + i, pc.n - 1); // tail rows repeat the last row; never stored
        for (uint k = 0; k < pc.ka; ++k) xs[i][k] = LD1(in_a, r * pc.a_stride + k);
        for (uint k = pc.ka; k < pc.fan_in; ++k) xs[i][k] = LD1(in_b, r * pc.b_stride + k - pc.ka);
    }
    for (uint j0 = 0; j0 < pc.count; j0 += OB) {
        float acc[R][OB];
        [[unroll]] for (uint j = 0; j < OB; ++j) {
            float b = (pc.has_bias != 0 && j0 + j < pc.count) ? b_at(pc.b_res + j0 + j) : 0.0;
            [[unroll]] for (uint i = 0; i < R; ++i) acc[i][j] = b;
        }
        // Rows of M past `count` are read as row count−1 (in the window) and never stored.
        uint mrow[OB];
        [[unroll]] for (uint j = 0; j < OB; ++j) mrow[j] = pc.m_res + min(j0 + j, pc.count - 1) * pc.fan_in;
        for (uint k = 0; k < pc.fan_in; ++k) {
            [[unroll]] for (uint j = 0; j < OB; ++j) {
                float w = m_at(mrow[j] + k);
                [[unroll]] for (uint i = 0; i < R; ++i) acc[i][j] += w * xs[i][k];
            }
        }
        [[unroll]] for (uint i = 0; i < R; ++i) {
            uint r = r0 + i;
            if (r >= pc.n) continue;
            [[unroll]] for (uint j = 0; j < OB; ++j) {
                if (j0 + j >= pc.count) continue;
                float v = pc.relu != 0 ? max(acc[i][j], 0.0) : acc[i][j];
                if (pc.mask_stride != 0 && !(LD1(act, r * pc.mask_stride + pc.mask_col + j0 + j) > 0.0)) v = 0.0;
                uint o = r * pc.out_stride + pc.out_col + j0 + j;
                ST1(out_, o, pc.accumulate != 0 ? LD1(out_, o) + v : v);
            }
        }
    }
}

#endif
