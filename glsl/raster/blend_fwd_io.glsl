// The blend forward's interface, shared by both variants (blend_fwd.glsl: shared-memory
// batches; blend_fwd_tile.glsl: one coroutine per tile), so the host binds them alike.
#include "access.glsl"
layout(push_constant) uniform Push { BlendParams pc; };
layout(std430, binding = 0) readonly buffer Ranges { uvec2 ranges[]; };
ARR_RO_U(1, uint, r32ui, Ids, ids) // sorted Gaussian ids
ARR_RO(2, vec4, rgba32f, Splats, splats)
ARR_WO(3, vec4, rgba32f, OutRgba, out_rgba) // rgb + alpha
ARR_WO(4, float, r32f, OutDepth, out_depth) // Σ w z
ARR_WO(5, float, r32f, FinalT, final_t)
ARR_WO_U(6, uint, r32ui, NContrib, n_contrib)
#if FEAT > 0
ARR_RO(7, float, r32f, Feat, feat) // [N,FEAT]
ARR_WO(8, float, r32f, OutFeat, out_feat) // [H·W,FEAT]
#endif
// The overflow word (meta[64] of bin_total, bound alone, last); a blend ORs OVERFLOW_WALK_CUT
// into it. Bindings stay dense: 7 without the feature pair.
#if FEAT > 0
layout(std430, binding = 9) buffer Overflow { uint overflow_word; };
#else
layout(std430, binding = 7) buffer Overflow { uint overflow_word; };
#endif
