// Shared by glsl/metrics/*.comp.
#ifndef METRICS_GLSL
#define METRICS_GLSL

#define METRICS_WG 256

// Linear workgroup index of a 2D grid of `groups_x` columns.
uint metrics_group(uint groups_x) {
    return gl_WorkGroupID.y * groups_x + gl_WorkGroupID.x;
}

#endif
