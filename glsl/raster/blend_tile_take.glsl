// The batch's splat k, taken from the lane that loaded it (a uniform-index shuffle): a, con,
// col and f[FEAT]. Included in the whole-tile walks of blend_fwd_tile.glsl and
// blend_bwd_tile.glsl, which load a_l, n_l, c_l and f_l one list entry per lane.
vec4 a = subgroupShuffle(a_l, k);
vec3 con = subgroupShuffle(n_l, k).xyz;
vec3 col = subgroupShuffle(c_l, k).rgb;
#if FEAT > 0
float f[FEAT];
for (int c = 0; c < FEAT; ++c) f[c] = subgroupShuffle(f_l[c], k);
#endif
