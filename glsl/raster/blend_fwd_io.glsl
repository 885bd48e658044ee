// The blend forward's interface, shared by both variants (blend_fwd.glsl: shared-memory
// batches; blend_fwd_tile.glsl: one coroutine per tile), so the host binds them alike.
layout(push_constant) uniform Push { BlendParams pc; };
layout(std430, binding = 0) readonly buffer Ranges { uvec2 ranges[]; };
layout(std430, binding = 1) readonly buffer Ids { uint ids[]; };         // sorted Gaussian ids
layout(std430, binding = 2) readonly buffer Splats { vec4 splats[]; };
layout(std430, binding = 3) writeonly buffer OutRgba { vec4 out_rgba[]; }; // rgb + alpha
layout(std430, binding = 4) writeonly buffer OutDepth { float out_depth[]; }; // Σ w z
layout(std430, binding = 5) writeonly buffer FinalT { float final_t[]; };
layout(std430, binding = 6) writeonly buffer NContrib { uint n_contrib[]; };
#if FEAT > 0
layout(std430, binding = 7) readonly buffer Feat { float feat[]; };         // [N,FEAT]
layout(std430, binding = 8) writeonly buffer OutFeat { float out_feat[]; }; // [H·W,FEAT]
#endif
// The overflow word (meta[64] of bin_total, bound alone, last); a blend ORs OVERFLOW_WALK_CUT
// into it. Bindings stay dense: 7 without the feature pair.
#if FEAT > 0
layout(std430, binding = 9) buffer Overflow { uint overflow_word; };
#else
layout(std430, binding = 7) buffer Overflow { uint overflow_word; };
#endif
