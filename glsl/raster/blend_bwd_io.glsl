// The blend backward's interface, shared by both variants (blend_bwd.glsl: subgroup atomics;
// blend_bwd_tile.glsl: one coroutine per tile), so the host binds them alike.
layout(push_constant) uniform Push { BlendParams pc; };
layout(std430, binding = 0) readonly buffer Ranges { uvec2 ranges[]; };
layout(std430, binding = 1) readonly buffer Ids { uint ids[]; };
layout(std430, binding = 2) readonly buffer Splats { vec4 splats[]; };
layout(std430, binding = 3) readonly buffer FinalT { float final_t[]; };
layout(std430, binding = 4) readonly buffer NContrib { uint n_contrib[]; };
layout(std430, binding = 5) readonly buffer DRgba { vec4 d_rgba[]; };    // dL/d(rgb, alpha)
layout(std430, binding = 6) readonly buffer DDepth { float d_depth[]; };
layout(std430, binding = 7) buffer Grad2d { float grad2d[]; };           // [N, G2D_STRIDE], accumulated
#if FEAT > 0
layout(std430, binding = 8) readonly buffer Feat { float feat[]; };      // [N,FEAT]
layout(std430, binding = 9) readonly buffer DFeat { float d_feat[]; };   // [H·W,FEAT]
layout(std430, binding = 10) buffer GradFeat { float grad_feat[]; };     // [N,FEAT], accumulated
#endif
