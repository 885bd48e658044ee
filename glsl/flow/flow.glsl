// Shared helpers of the TV-L1 flow stages (src/kernels/flow.rs; twin: src/reference/flow.rs).
#ifndef FLOW_GLSL
#define FLOW_GLSL

#define FLOW_GREY_SCALE 255.0  // kernels::flow::GREY_SCALE
#define FLOW_GRAD_EPS 1e-6     // kernels::flow::FLOW_GRAD_EPS

// Bilinear weights and corner indices at continuous pixel coordinates q, clamped to the
// w×h image (border replicate). Returns (i00, i10, i01, i11) and writes the fractions to f.
uvec4 flow_bilinear(vec2 q, uint w, uint h, out vec2 f) {
    q = clamp(q, vec2(0.0), vec2(float(w - 1u), float(h - 1u)));
    uint x0 = min(uint(floor(q.x)), w - 1u), y0 = min(uint(floor(q.y)), h - 1u);
    uint x1 = min(x0 + 1u, w - 1u), y1 = min(y0 + 1u, h - 1u);
    f = q - vec2(float(x0), float(y0));
    return uvec4(y0 * w + x0, y0 * w + x1, y1 * w + x0, y1 * w + x1);
}

#define FLOW_LERP2(a00, a10, a01, a11, f) \
    (((a00) * (1.0 - (f).x) + (a10) * (f).x) * (1.0 - (f).y) + ((a01) * (1.0 - (f).x) + (a11) * (f).x) * (f).y)

#endif
