#version 460
// dst[i] = src[row_of[i]] for every Gaussian, or the Gaussian's own constant row
// `fixed[i]` where row_of[i] is NO_ROW (a static Gaussian: its time-constant deformation,
// so its displacement between any two times is exactly 0). Writes every row.
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "params.glsl"

layout(local_size_x = 256) in;

layout(push_constant) uniform Push { RowsParams pc; };
layout(std430, binding = 0) readonly buffer RowOf { uint row_of[]; }; // [N]
layout(std430, binding = 1) readonly buffer Src { float src[]; };     // [count, width]
layout(std430, binding = 2) readonly buffer Fixed { float fixed_rows[]; }; // [N, width]
layout(std430, binding = 3) writeonly buffer Dst { float dst[]; };    // [N, width]

const uint NO_ROW = 0xffffffffu;

void main() {
    uint i = gl_GlobalInvocationID.x + gl_GlobalInvocationID.y * gl_NumWorkGroups.x * gl_WorkGroupSize.x;
    if (i >= pc.n) return;
    uint r = row_of[i], o = i * pc.width;
    for (uint c = 0; c < pc.width; ++c)
        dst[o + c] = r == NO_ROW ? fixed_rows[o + c] : src[r * pc.width + c];
}
