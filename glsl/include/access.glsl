// Per-element arrays as storage buffers (GPU shape) or, with TEXEL_ACCESS defined before the
// include, as storage texel buffers (the CPU shape, kernels::shape's `Access`). Why: llvmpipe
// 22.3 compiles a storage-buffer load or store whose address differs between lanes into a loop
// over the 8 lanes with a bounds-check branch per component, while an image load is one gather
// per vector (the TV-L1 iteration ran 3.4× faster on lavapipe through images). The buffer
// expansion is token for token the declaration and indexing it replaces, so GPU shapes compile
// to the same SPIR-V as before.
//
// Declare:  ARR_RO(binding, type, format, Block, name)   (also ARR_WO, ARR_RW; ARR_RO_U for
//           uint arrays, read with LDU1; ARR_WO_U written with STU1)
//           e.g. ARR_RO(0, vec4, rgba32f, Warp, warp)
// Access:   LD4/LD2/LD1(name, i) for vec4/vec2/float; ST4/ST2/ST1(name, i, v).
// A texel binding must start 16-byte aligned (the recorder asserts it); indices are elements.
#ifndef ACCESS_GLSL
#define ACCESS_GLSL

#ifdef TEXEL_ACCESS
#define ARR_RO(b, T, fmt, Block, name) layout(binding = b, fmt) readonly uniform imageBuffer name;
#define ARR_WO(b, T, fmt, Block, name) layout(binding = b, fmt) writeonly uniform imageBuffer name;
#define ARR_RW(b, T, fmt, Block, name) layout(binding = b, fmt) uniform imageBuffer name;
#define ARR_RO_U(b, T, fmt, Block, name) layout(binding = b, fmt) readonly uniform uimageBuffer name;
#define ARR_WO_U(b, T, fmt, Block, name) layout(binding = b, fmt) writeonly uniform uimageBuffer name;
#define LD4(name, i) imageLoad(name, int(i))
#define LD2(name, i) imageLoad(name, int(i)).xy
#define LD1(name, i) imageLoad(name, int(i)).x
#define LDU1(name, i) imageLoad(name, int(i)).x
#define ST4(name, i, v) imageStore(name, int(i), v)
#define ST2(name, i, v) imageStore(name, int(i), vec4(v, 0.0, 0.0))
#define ST1(name, i, v) imageStore(name, int(i), vec4(v, 0.0, 0.0, 0.0))
#define STU1(name, i, v) imageStore(name, int(i), uvec4(v, 0u, 0u, 0u))
#else
#define ARR_RO(b, T, fmt, Block, name) layout(std430, binding = b) readonly buffer Block { T name[]; };
#define ARR_WO(b, T, fmt, Block, name) layout(std430, binding = b) writeonly buffer Block { T name[]; };
#define ARR_RW(b, T, fmt, Block, name) layout(std430, binding = b) buffer Block { T name[]; };
#define ARR_RO_U(b, T, fmt, Block, name) layout(std430, binding = b) readonly buffer Block { T name[]; };
#define ARR_WO_U(b, T, fmt, Block, name) layout(std430, binding = b) writeonly buffer Block { T name[]; };
#define LD4(name, i) name[i]
#define LD2(name, i) name[i]
#define LD1(name, i) name[i]
#define LDU1(name, i) name[i]
#define ST4(name, i, v) name[i] = v
#define ST2(name, i, v) name[i] = v
#define ST1(name, i, v) name[i] = v
#define STU1(name, i, v) name[i] = v
#endif

#endif
