// The blend backward's interface, shared by both variants (blend_bwd.glsl: subgroup atomics;
// blend_bwd_tile.glsl: one coroutine per tile), so the host binds them alike.
#include "access.glsl"
layout(push_constant) uniform Push { BlendParams pc; };
layout(std430, binding = 0) readonly buffer Ranges { uvec2 ranges[]; };
ARR_RO_U(1, uint, r32ui, Ids, ids)
ARR_RO(2, vec4, rgba32f, Splats, splats)
ARR_RO(3, float, r32f, FinalT, final_t)
ARR_RO_U(4, uint, r32ui, NContrib, n_contrib)
ARR_RO(5, vec4, rgba32f, DRgba, d_rgba) // dL/d(rgb, alpha)
ARR_RO(6, float, r32f, DDepth, d_depth)
layout(std430, binding = 7) buffer Grad2d { float grad2d[]; };           // [N, G2D_STRIDE], accumulated
#if FEAT > 0
ARR_RO(8, float, r32f, Feat, feat) // [N,FEAT]
ARR_RO(9, float, r32f, DFeat, d_feat) // [H·W,FEAT]
layout(std430, binding = 10) buffer GradFeat { float grad_feat[]; };     // [N,FEAT], accumulated
#endif
