// Workgroup-wide exclusive scan of one uint per thread, in shared memory (Hillis–Steele).
// Portable: no subgroup shuffles (lavapipe has none), any subgroup size.
// Requires: local_size_x == WG_SCAN_SIZE, called by every invocation in uniform control flow.
#ifndef WG_SCAN_GLSL
#define WG_SCAN_GLSL

#ifndef WG_SCAN_SIZE
#define WG_SCAN_SIZE 256
#endif

shared uint s_wg_scan[2][WG_SCAN_SIZE];

// Returns the exclusive prefix of `v` over invocations 0..gl_LocalInvocationIndex; `total` gets
// the sum over the workgroup.
uint wg_exclusive_scan(uint v, out uint total) {
    uint tid = gl_LocalInvocationIndex;
    uint cur = 0;
    s_wg_scan[0][tid] = v;
    barrier();
    for (uint off = 1; off < WG_SCAN_SIZE; off <<= 1) {
        uint x = s_wg_scan[cur][tid];
        if (tid >= off) x += s_wg_scan[cur][tid - off];
        s_wg_scan[cur ^ 1][tid] = x;
        cur ^= 1;
        barrier();
    }
    uint inclusive = s_wg_scan[cur][tid];
    total = s_wg_scan[cur][WG_SCAN_SIZE - 1];
    barrier(); // s_wg_scan may be reused by the next call
    return inclusive - v;
}

#endif
