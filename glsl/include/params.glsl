// Push-constant structs. Each is mirrored by a #[repr(C)] bytemuck struct of the same name in
// src/kernels/ and checked member by member against the reflected SPIR-V (tests/layout.rs).
#ifndef PARAMS_GLSL
#define PARAMS_GLSL

// src/kernels/scan.rs
struct ScanParams {
    uint capacity;   // element capacity of level 0 (the count is clamped to it)
    uint level;      // pyramid level this dispatch works on
    uint num_levels; // levels in the pyramid (the last is scanned by one workgroup)
    uint pad;
};

// src/kernels/radix_sort.rs
struct SortParams {
    uint capacity;   // key capacity (the count is clamped to it)
    uint shift;      // bit offset of this pass's 4-bit digit
    uint digit_mask; // mask applied to the digit (ignores key bits at or above `bits`)
    uint block_keys; // keys per block (SORT_BLOCK, or SORT_SERIAL_BLOCK for the serial shape)
    uint group_blocks; // blocks per workgroup (1, or SORT_SERIAL_LANES: one per invocation)
    uint pad;
};


// src/kernels/mlp.rs: positional encoding of x (and t) into the trunk input rows.
struct MlpEncodeParams {
    uint n;          // Gaussians
    uint x_freqs;    // L of γ(x)
    uint t_freqs;    // L of γ(t)
    uint x0_stride;  // floats per row of x0 (in_dims)
    uint t_to_x0;    // 1: γ(t) goes to x0 after γ(x) (Direct); 0: to enc_t (time net)
    uint t_stride;   // floats per row of enc_t
    uint per_gaussian_time; // 1: t = times[i]; 0: t = time
    float time;
};

// src/kernels/mlp.rs: out[r][out_col + o] = act(b[o] + Σ_k W[o][k] · in[r][k]), in = [A | B].
struct MlpLinearParams {
    uint n;          // rows (Gaussians)
    uint fan_in;     // K (= ka + columns from B)
    uint fan_out;
    uint ka;         // input columns read from A; the rest from B
    uint a_stride;
    uint b_stride;
    uint out_stride;
    uint out_col;
    uint w_off;      // floats into the parameter buffer
    uint b_off;
    uint relu;       // 1: ReLU epilogue
    uint pad;
};

// src/kernels/mlp.rs: d_in[r][out_col + c] (+)= mask · Σ_o dz[r][o] · W[o][col0 + c], c < cols.
struct MlpBwdDataParams {
    uint n;
    uint fan_in;     // weight row length
    uint fan_out;    // K (columns of dz)
    uint cols;       // input columns produced
    uint col0;       // first weight column
    uint dz_stride;
    uint out_stride;
    uint out_col;
    uint mask_stride;// 0: no ReLU mask; else mask = act[r][mask_col + c] > 0
    uint mask_col;
    uint w_off;
    uint accumulate; // 1: add into d_in
};

// src/kernels/mlp.rs: partial[s][o][c] = Σ_{r in chunk s} dz[r][o] · [A | B | 1][r][c].
struct MlpBwdWeightParams {
    uint n;
    uint fan_in;
    uint fan_out;
    uint ka;
    uint a_stride;
    uint b_stride;
    uint dz_stride;
    uint chunk_rows; // rows per partial (multiple of 16)
};

// src/kernels/mlp.rs, register path (linear_rows): for the window of outputs j < count,
//   out[r][out_col + j] (+)= act(bias[j] + Σ_k M[j][k] · in[r][k]) · mask,  in = [A | B],
// M = the uniform-buffer window (row j at m_res + j·fan_in floats), bias at b_res in its own.
struct MlpRowsParams {
    uint n;
    uint fan_in;     // K (= ka + columns from B)
    uint ka;
    uint a_stride;
    uint b_stride;
    uint out_stride;
    uint out_col;    // column of the window's first output
    uint count;      // outputs in this window
    uint m_res;      // floats from the bound window's start to M[0][0] (offset alignment)
    uint b_res;      // same for the bias; has_bias = 0 ignores it
    uint has_bias;
    uint relu;
    uint mask_stride;// 0: no mask; else mask = act[r][mask_col + j] > 0
    uint mask_col;
    uint accumulate; // 1: add into out
    uint pad;
};

// src/kernels/mlp.rs, register path (linear_bwd_weight_rows): for one window of rows,
//   partial[o][c] (+)= Σ_{r < rows} dz[r0 + r][o] · [A | B | 1][r0 + r][c],
// dz rows from the uniform-buffer window (row r at dz_res + r·dz_stride floats).
struct MlpRowsWeightParams {
    uint r0;
    uint rows;
    uint fan_in;
    uint fan_out;
    uint ka;
    uint a_stride;
    uint b_stride;
    uint dz_stride;
    uint dz_res;
    uint accumulate; // 0 for the first window
    uint pad0;
    uint pad1;
};

// src/kernels/mlp.rs: wt[w_off + c·fan_out + o] = W[o][c] (the backward's weight windows).
struct MlpTransposeParams {
    uint fan_in;
    uint fan_out;
    uint w_off;
    uint pad;
};

// src/kernels/mlp.rs: grad[W, b] (+)= Σ_s partial[s].
struct MlpReduceParams {
    uint count;      // fan_out · (fan_in + 1)
    uint chunks;
    uint fan_in;
    uint w_off;
    uint b_off;
    uint accumulate;
    uint pad0;
    uint pad1;
};

// src/kernels/mlp_fused.rs: whole network per block of rows, activations in shared memory.
struct MlpFusedParams {
    uint n;
    uint depth;
    uint width;
    uint skip;       // layer after whose ReLU the input is concatenated; 0xffffffff: none
    uint x_freqs;
    uint t_freqs;
    uint time_net;   // 1: γ(t) → time net → t_feat; 0: t_feat = γ(t)
    uint hidden;     // time-net hidden width
    uint t_feat;     // time-feature dims
    uint per_gaussian_time;
    float time;
    uint pad;
};

// src/kernels/mlp_fused.rs: f32 → f16 copy of the parameters.
struct MlpConvertParams {
    uint count;
    uint pad0;
    uint pad1;
    uint pad2;
};

// src/kernels/mlp_fused.rs: FMA-throughput probe (register-only FMA chains).
struct FmaPeakParams {
    uint iters;
    float a;
    float b;
    uint pad;
};

// src/kernels/adam.rs: one Adam step on floats [first, first + count) of one buffer.
struct AdamParams {
    uint first;
    uint count;
    uint row_len;    // floats per mask row (mask index = (i − first) / row_len)
    uint use_mask;   // 1: skip rows whose mask word is 0
    float lr;
    float beta1;
    float beta2;
    float eps;
    float bc1;       // 1 − β1^t
    float bc2;       // 1 − β2^t
    uint skip_flags; // (flag, needed) pairs in `skip`; any non-zero flag makes the step a no-op
    uint pad1;
};


// src/kernels/raster.rs — camera and image shared by project, bin and project_bwd.
struct ProjectParams {
    vec4 rot0;        // rows of the world-to-camera rotation (OpenCV: x right, y down, z forward)
    vec4 rot1;
    vec4 rot2;
    vec4 trans_near;  // xyz: p_cam = rot · p + trans; w: near plane
    vec4 intrinsics;  // fx, fy, cx, cy (pixels; pixel centres at +0.5)
    uint width;
    uint height;
    uint tiles_x;
    uint tiles_y;
    uint num_gaussians;
    uint sh_coeffs;   // SH coefficients stored per Gaussian (1, 4, 9, 16)
    uint sh_degree;   // active degree (<= sqrt(sh_coeffs) - 1)
    uint isect_capacity;
    uint opacity_scale; // project/project_bwd: multiply each opacity by op_scale[i] (0: culled)
    uint feat_detach;   // project_bwd: d_op_scale leaves out grad2d slot 12 (the features' share)
    uint splat_extent;  // project: 0 = the 3σ square of `radius`, 1 = opacity_rect (raster.glsl)
    uint pad2;
};

// src/kernels/binning.rs — depth-first binning: bin_depth_keys, bin_depth_counts,
// bin_emit_depth.
struct BinParams {
    uint tiles_x;
    uint tiles_y;
    uint num_gaussians;
    uint isect_capacity;
};

// src/kernels/raster.rs — per-tile α-blending, forward and backward.
struct BlendParams {
    vec4 background;  // rgb; w unused
    uint width;
    uint height;
    uint tiles_x;
    uint tiles_y;
    float alpha_max;  // 0.99 as in 3DGS (gsplat: 0.999)
    uint num_gaussians;
    uint abs_grad;    // blend_bwd: also accumulate Σ|∂L/∂mean2d| per pixel into slots 10-11
    uint feat_op;     // blend_bwd: also accumulate the feature channels' share of slot 5 into slot 12
    uint pick;        // CPU blends, which tiles a kernel draws: 0 all, 1 the bands', 2 the rest
    uint band_list_max;  // the longest list the band kernels walk (BAND_LIST_MAX)
    uint band_cover_max; // the bands take a tile when its sampled splats cover at most this
                         // many eighths of a band each, on average (blend_pick.glsl)
    // The picked backward's cost model (blend_bwd_pick.comp), in eighths of one pixel
    // evaluation per lane: per splat a band evaluates, per splat a band walks, and per splat
    // of the whole tile's walk.
    uint pick_band_splat;
    uint pick_band_step;
    uint pick_whole_splat;
    uint pad0;
    uint pad1;
};

// src/kernels/loss.rs — photometric loss 0.8·L1 + 0.2·(1 − SSIM) and its gradient.
struct LossParams {
    uint width;
    uint height;
    uint planes;        // planes the blur passes work on
    uint pad0;
    float lambda_ssim;  // weight of (1 − SSIM); L1 gets 1 − lambda_ssim
    float inv_count;    // 1 / (3 · width · height)
    uint pad1;
    uint pad2;
};

// src/kernels/deform.rs — canonical Gaussians + deformation → what the rasteriser draws.
struct DeformParams {
    uint n;
    uint pad0;  // D ≡ 0 is a separate stage (deform_static*), not a flag
    uint pad1;
    uint pad2;
};

// src/kernels/temporal.rs — transient (time-local) Gaussians: rows [first, n).
struct TemporalParams {
    uint n;           // rows: every live Gaussian
    uint first;       // first transient row (rows below: the canonical population)
    float t;          // the time drawn (t1 of a displacement)
    float log_floor;  // ln σ_floor: σ = exp(max(τ, log_floor))
    float cutoff;     // opacity factors below: culled (w = 0)
    float t2;         // displacement: the pair's time, δ = v·(t2 − t)
    float t_lo;       // peak: the time range of the largest weight
    float t_hi;
};

// src/kernels/check.rs — non-finite counts of one buffer range into a slot.
struct CheckParams {
    uint first;   // the range's first float
    uint count;   // its length in floats
    uint slot;    // where the count (counts[slot]) and the first bad index (counts[slots + slot]) go
    uint slots;
};

// src/kernels/densify.rs — per-view densification statistics (after every backward pass).
struct DensifyStatsParams {
    uint num_gaussians;
    uint width;         // image size: ∂L/∂ndc = ∂L/∂pixel · (W/2, H/2)
    uint height;
    uint skip_flags;    // (flag, needed) pairs in `skip`; any non-zero flag: add nothing
    uint abs_grad;      // the statistic: 0 = ‖Σ ∂L/∂ndc‖, 1 = ‖Σ |∂L/∂ndc|‖ (slots 10-11)
    uint pad0;
    uint pad1;
    uint pad2;
};

// src/kernels/densify.rs — densify step (grow, mark, count, write). Thresholds arrive
// pre-transformed by the host (log / logit space) so the kernels only compare f32 values.
struct DensifyParams {
    uint num_gaussians;       // originals: rows of the source buffers
    uint capacity;            // output row budget (>= num_gaussians)
    uint row_len;             // write: floats per row of the bound section
    uint section;             // write: 0 plain copy, 1 means (split: sample), 2 log scales (split: shrink)
    uint seed;
    uint iteration;
    uint screen_prune;        // 1: also prune by screen size and world size (max_screen_size > 0)
    uint pad0;
    float grad_threshold;     // on the average ‖∂L/∂ndc‖ (compared as accum >= thr · denom)
    float log_dense_scale;    // ln(percent_dense · extent): clone if max log-scale <=, split if >
    float min_opacity_logit;  // logit(min_opacity): prune a row whose logit is below
    float max_screen_size;    // pixels: prune a row whose max radius is above
    float log_max_world_size; // ln(max_world_size): prune a row whose max log-scale is above
    float pad1;
    float pad2;
    float pad3;
};

// src/kernels/densify.rs — opacity reset (every 3000 iterations).
struct OpacityResetParams {
    uint num_gaussians;
    float reset_logit;        // logit(0.01): logits above it are lowered to it
    uint pad0;
    uint pad1;
};

// src/kernels/dispflow.rs — the displacement-flow motion term of DispFlow-GS.
struct DispFlowParams {
    uint n;           // Gaussians (displacement stages) or pixels (motion L1)
    float weight;     // α_t of the motion term (motion L1)
    uint conf;        // motion L1: 1 = weight each pixel by the confidence binding
    uint pad1;
};

// src/kernels/dispflow.rs — scene_signal (residual correction and confidence of the scene motion)
struct SceneSignalParams {
    uint n;           // pixels
    uint residual;    // 1: subtract flow(photo → render(v1, t1))
    float sigma;      // confidence scale on the mean |photo − render(v1, t1)|; 0 = off (c = 1)
    float mask_px;    // motion-mask filtering: |s| below this (pixels) becomes 0; 0 = off
};

// src/kernels/dispflow.rs — camera_flow (indirect scene motion: pair flow − camera flow).
// The relative pose v1 → v2 is composed on the host (in f64): y = M·x_cam1 + m.
struct CameraFlowParams {
    vec4 rel0;        // rows of M = R2·R1ᵀ, w: m = t2 − M·t1
    vec4 rel1;
    vec4 rel2;
    vec4 intr_a;      // fx, fy, cx, cy of v1
    vec4 intr_b;      // of v2
    uint width;
    uint height;
    float min_alpha;  // below this render alpha the depth is not trusted
    uint subtract;    // 0: the raw pair flow (no decomposition)
    float near_b;     // v2's near plane
    uint pad0;
    uint pad1;
    uint pad2;
};

// src/kernels/gflow.rs — Gaussian flow (features, their backward, the vector L1)
struct GFlowParams {
    uint n;           // Gaussians (feature stages) or pixels (L1)
    uint width;       // image width (L1: the pixel coordinates)
    float weight;     // α_t (L1)
    uint conf;        // L1: 1 = weight each pixel by the confidence binding
};

// src/kernels/flow.rs — TV-L1 optical flow stages (one struct for all; each stage says which
// fields it reads). Offsets are in floats into the grey pyramid buffer.
struct FlowParams {
    uint width;         // this level (or the output level)
    uint height;
    uint src_width;     // downsample: finer level; upsample: coarser level
    uint src_height;
    uint off0;          // I0 plane (downsample: source I0)
    uint off1;          // I1 plane (downsample: source I1)
    uint off2;          // downsample: destination I0
    uint off3;          // downsample: destination I1
    float lambda_theta; // λ·θ: threshold of the data step
    float theta;        // θ
    float tau_theta;    // τ/θ: dual step
    float mix;          // prefilter: 0 = dst = blur(src); β = dst = dst − β·blur(src)
};

// src/kernels/motion.rs — magnitude of a per-pixel vector field and its normalisation over the
// image (forward and backward). Quantile positions come from the host (they depend only on n).
struct MotionNormParams {
    uint n;           // pixels (H·W)
    uint channels;    // 2 or 3 floats per pixel, interleaved [H·W, C]
    uint mode;        // 0 min-max, 1 max-abs, 2 z-score, 3 IQR
    uint groups;      // partial-result slots of the per-pixel passes (groups_x · rows)
    uint groups_x;    // workgroups along x of the per-pixel grid (2D beyond 65535)
    float eps;        // flat map: denominator below eps (absolute, magnitude units)
    uint q25_lo;      // sorted position floor(q·(n − 1)) of q25, q50, q75
    uint q50_lo;
    uint q75_lo;
    float q25_frac;   // q·(n − 1) − floor(q·(n − 1))
    float q50_frac;
    float q75_frac;
    uint detach;      // backward: 1 = statistics held constant (no gradient through min/max…)
};

// src/kernels/metrics.rs — per-pixel passes of MMAP (keys, AP terms) and DRC.
struct MetricsParams {
    uint n;           // pixels (H·W)
    uint groups_x;    // workgroups along x of the per-pixel grid
    uint groups;      // partial-sum slots (groups_x · rows)
    uint pad;
};

// src/kernels/lpips.rs — LPIPS (AlexNet backbone): input scaling, conv + ReLU, max-pool, and the
// per-stage normalise → squared difference → learned 1×1 weights → spatial mean.
struct LpipsInputParams {
    uint width;
    uint height;
    uint pad0;
    uint pad1;
    vec4 shift;       // the reference package's ScalingLayer shift (rgb, unused)
    vec4 scale;       // and scale: x' = (x − shift) / scale on x ∈ [−1, 1]
};

struct LpipsConvParams {
    uint in_w;
    uint in_h;
    uint out_w;
    uint out_h;
    uint cin;
    uint cout;
    uint ksize;       // square kernel side
    uint stride;
    uint pad;         // zero padding on every side
    uint w_off;       // weight [cout][cin][k][k] offset (floats) in the weight buffer
    uint b_off;       // bias [cout] offset
    uint pad0;
};

struct LpipsPoolParams {
    uint in_w;
    uint in_h;
    uint out_w;
    uint out_h;
    uint planes;      // batch · channels
    uint pad0;
    uint pad1;
    uint pad2;
};

struct LpipsDiffParams {
    uint width;
    uint height;
    uint channels;
    uint lin_off;     // 1×1 linear weights [channels] offset in the weight buffer
    float inv_count;  // 1 / (width · height): the spatial mean
    uint sum_off;     // first partial-sum slot of this stage
    uint pad0;
    uint pad1;
};

// src/kernels/sparse.rs: one sample of the motion probe (D at one time over every Gaussian).
struct ProbeParams {
    uint n;             // Gaussians
    uint num_cams;      // training cameras (>= 1)
    uint first;         // 1: the first sample (the running maximum starts here)
    uint last;          // 1: the last sample (midrange and pixels are written)
    float near;         // distances to a camera are clamped to at least this (scene units)
    uint pad0;
    uint pad1;
    uint pad2;
};

// src/kernels/sparse.rs: the dynamic flags from the probe's pixels.
struct FlagParams {
    uint n;
    float threshold_px; // apparent motion (pixels) above which a Gaussian is dynamic
    uint pad0;
    uint pad1;
};

// src/kernels/sparse.rs: compaction of the dynamic set and row gather/expand.
struct RowsParams {
    uint n;     // rows processed (Gaussians for compact/expand, dynamic rows for gather)
    uint width; // floats per row
    uint pad0;
    uint pad1;
};

// src/kernels/nodes.rs — the control-node deformation field (KNN, blend, gather).
struct NodesParams {
    uint n;          // rows: Gaussians (knn, lbs dense), dynamic rows (lbs indexed), pairs (ranges)
    uint m;          // control nodes
    uint k;          // nearest nodes per Gaussian (<= NODES_KMAX)
    uint flags;      // knn: 1 = split (static Gaussians get no nodes); lbs: 1 = rows through idx;
                     // gather: 1 = add the node-parameter gradients instead of writing them
};

#endif
