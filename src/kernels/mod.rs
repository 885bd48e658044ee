//! One host wrapper per GLSL stage family: `#[repr(C)]` params mirrored in
//! `glsl/include/params.glsl`, pipelines built once, `record()` taking explicit buffers.

pub mod adam;
pub mod binning;
pub mod check;
pub mod deform;
pub mod densify;
pub mod dispflow;
pub mod flow;
pub mod gflow;
pub mod loss;
pub mod lpips;
pub mod metrics;
pub mod mlp;
pub mod mlp_fused;
pub mod mlp_rows;
pub mod motion;
pub mod nodes;
pub mod radix_sort;
pub mod raster;
pub mod scan;
pub mod shape;
pub mod sparse;
pub mod temporal;

/// (Rust struct name, size in bytes, [(field, byte offset)]) of one push-constant struct.
pub type ParamLayout = (&'static str, usize, Vec<(&'static str, usize)>);

/// The layout of every push-constant struct, for the reflection test that compares them with
/// the SPIR-V.
pub fn param_layouts() -> Vec<ParamLayout> {
    macro_rules! layout {
        ($t:ty, $($f:ident),*) => {
            (last_ident(stringify!($t)), std::mem::size_of::<$t>(), vec![$((stringify!($f), std::mem::offset_of!($t, $f))),*])
        };
    }
    vec![
        layout!(dispflow::DispFlowParams, n, weight, conf, pad1),
        layout!(dispflow::SceneSignalParams, n, residual, sigma, mask_px),
        layout!(gflow::GFlowParams, n, width, weight, conf),
        layout!(
            dispflow::CameraFlowParams,
            rel0,
            rel1,
            rel2,
            intr_a,
            intr_b,
            width,
            height,
            min_alpha,
            subtract,
            near_b,
            pad0,
            pad1,
            pad2
        ),
        layout!(deform::DeformParams, n, pad0, pad1, pad2),
        layout!(
            sparse::ProbeParams,
            n,
            num_cams,
            first,
            last,
            near,
            pad0,
            pad1,
            pad2
        ),
        layout!(sparse::FlagParams, n, threshold_px, pad0, pad1),
        layout!(sparse::RowsParams, n, width, pad0, pad1),
        layout!(nodes::NodesParams, n, m, k, flags),
        layout!(check::CheckParams, first, count, slot, slots),
        layout!(
            temporal::TemporalParams,
            n,
            first,
            t,
            log_floor,
            cutoff,
            t2,
            t_lo,
            t_hi
        ),
        layout!(
            densify::DensifyStatsParams,
            num_gaussians,
            width,
            height,
            skip_flags,
            abs_grad,
            pad0,
            pad1,
            pad2
        ),
        layout!(
            densify::DensifyParams,
            num_gaussians,
            capacity,
            row_len,
            section,
            seed,
            iteration,
            screen_prune,
            pad0,
            grad_threshold,
            log_dense_scale,
            min_opacity_logit,
            max_screen_size,
            log_max_world_size,
            pad1,
            pad2,
            pad3
        ),
        layout!(
            densify::OpacityResetParams,
            num_gaussians,
            reset_logit,
            pad0,
            pad1
        ),
        layout!(
            loss::LossParams,
            width,
            height,
            planes,
            pad0,
            lambda_ssim,
            inv_count,
            pad1,
            pad2
        ),
        layout!(
            flow::FlowParams,
            width,
            height,
            src_width,
            src_height,
            off0,
            off1,
            off2,
            off3,
            lambda_theta,
            theta,
            tau_theta,
            mix
        ),
        layout!(scan::ScanParams, capacity, level, num_levels, pad),
        layout!(
            radix_sort::SortParams,
            capacity,
            shift,
            digit_mask,
            block_keys,
            group_blocks,
            pad
        ),
        layout!(
            binning::BinParams,
            tiles_x,
            tiles_y,
            num_gaussians,
            isect_capacity
        ),
        layout!(
            raster::ProjectParams,
            rot0,
            rot1,
            rot2,
            trans_near,
            intrinsics,
            width,
            height,
            tiles_x,
            tiles_y,
            num_gaussians,
            sh_coeffs,
            sh_degree,
            isect_capacity,
            opacity_scale,
            feat_detach,
            splat_extent,
            pad2
        ),
        layout!(
            raster::BlendParams,
            background,
            width,
            height,
            tiles_x,
            tiles_y,
            alpha_max,
            num_gaussians,
            abs_grad,
            feat_op,
            pick,
            band_list_max,
            band_cover_max,
            pick_band_splat,
            pick_band_step,
            pick_whole_splat,
            pad0,
            pad1
        ),
        layout!(
            mlp::MlpEncodeParams,
            n,
            x_freqs,
            t_freqs,
            x0_stride,
            t_to_x0,
            t_stride,
            per_gaussian_time,
            time
        ),
        layout!(
            mlp::MlpLinearParams,
            n,
            fan_in,
            fan_out,
            ka,
            a_stride,
            b_stride,
            out_stride,
            out_col,
            w_off,
            b_off,
            relu,
            pad
        ),
        layout!(
            mlp::MlpBwdDataParams,
            n,
            fan_in,
            fan_out,
            cols,
            col0,
            dz_stride,
            out_stride,
            out_col,
            mask_stride,
            mask_col,
            w_off,
            accumulate
        ),
        layout!(
            mlp::MlpBwdWeightParams,
            n,
            fan_in,
            fan_out,
            ka,
            a_stride,
            b_stride,
            dz_stride,
            chunk_rows
        ),
        layout!(
            mlp::MlpReduceParams,
            count,
            chunks,
            fan_in,
            w_off,
            b_off,
            accumulate,
            pad0,
            pad1
        ),
        layout!(
            mlp_rows::MlpRowsParams,
            n,
            fan_in,
            ka,
            a_stride,
            b_stride,
            out_stride,
            out_col,
            count,
            m_res,
            b_res,
            has_bias,
            relu,
            mask_stride,
            mask_col,
            accumulate,
            pad
        ),
        layout!(mlp_rows::MlpTransposeParams, fan_in, fan_out, w_off, pad),
        layout!(
            mlp_rows::MlpRowsWeightParams,
            r0,
            rows,
            fan_in,
            fan_out,
            ka,
            a_stride,
            b_stride,
            dz_stride,
            dz_res,
            accumulate,
            pad0,
            pad1
        ),
        layout!(
            mlp_fused::MlpFusedParams,
            n,
            depth,
            width,
            skip,
            x_freqs,
            t_freqs,
            time_net,
            hidden,
            t_feat,
            per_gaussian_time,
            time,
            pad
        ),
        layout!(mlp_fused::MlpConvertParams, count, pad0, pad1, pad2),
        layout!(mlp_fused::FmaPeakParams, iters, a, b, pad),
        layout!(
            adam::AdamParams,
            first,
            count,
            row_len,
            use_mask,
            lr,
            beta1,
            beta2,
            eps,
            bc1,
            bc2,
            skip_flags,
            pad1
        ),
        layout!(
            motion::MotionNormParams,
            n,
            channels,
            mode,
            groups,
            groups_x,
            eps,
            q25_lo,
            q50_lo,
            q75_lo,
            q25_frac,
            q50_frac,
            q75_frac,
            detach
        ),
        layout!(metrics::MetricsParams, n, groups_x, groups, pad),
        layout!(
            lpips::LpipsInputParams,
            width,
            height,
            pad0,
            pad1,
            shift,
            scale
        ),
        layout!(
            lpips::LpipsConvParams,
            in_w,
            in_h,
            out_w,
            out_h,
            cin,
            cout,
            ksize,
            stride,
            pad,
            w_off,
            b_off,
            pad0
        ),
        layout!(
            lpips::LpipsPoolParams,
            in_w,
            in_h,
            out_w,
            out_h,
            planes,
            pad0,
            pad1,
            pad2
        ),
        layout!(
            lpips::LpipsDiffParams,
            width,
            height,
            channels,
            lin_off,
            inv_count,
            sum_off,
            pad0,
            pad1
        ),
    ]
}

fn last_ident(path: &'static str) -> &'static str {
    path.rsplit("::").next().unwrap_or(path).trim()
}
