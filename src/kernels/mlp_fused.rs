//! The deformation MLP's second implementation: one fused forward kernel per block of rows
//! (`glsl/mlp/fused_fwd.comp`, f32, 16 rows per workgroup) and its fp16-storage variant
//! (`fused_fwd_f16.comp`, 32 rows, weights converted by `to_f16.comp`). Activations live in
//! shared memory only, so nothing is stored per Gaussian: this is the forward for evaluations
//! without gradient. Also the FMA-throughput probe used by the GEMM microbenchmark.

use bytemuck::{Pod, Zeroable};

use crate::error::{Error, Result};
use crate::kernels::mlp::MlpTime;
use crate::model::deform::{MlpConfig, MlpLayout, TimeEncoding};
use crate::shaders;
use crate::vk::{BufSlice, Buffer, ComputePipeline, Gpu, Recorder};

/// Mirrors `MlpFusedParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct MlpFusedParams {
    pub n: u32,
    pub depth: u32,
    pub width: u32,
    pub skip: u32,
    pub x_freqs: u32,
    pub t_freqs: u32,
    pub time_net: u32,
    pub hidden: u32,
    pub t_feat: u32,
    pub per_gaussian_time: u32,
    pub time: f32,
    pub pad: u32,
}

/// Mirrors `MlpConvertParams` in glsl/include/params.glsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct MlpConvertParams {
    pub count: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

/// Mirrors `FmaPeakParams` in glsl/include/params.glsl.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct FmaPeakParams {
    pub iters: u32,
    pub a: f32,
    pub b: f32,
    pub pad: u32,
}

/// Largest width / time-net hidden width and trunk input of the fused kernels (shared memory).
pub const FUSED_MAX_WIDTH: u32 = 256;
pub const FUSED_MAX_IN: usize = 128;

/// Storage precision of the fused forward.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Precision {
    F32,
    /// f16 weights and activations, f32 arithmetic.
    F16,
}

/// Fused forward for one configuration: pipelines plus the layer table (fan_in, fan_out,
/// w_off, b_off per Linear) in a small device buffer.
pub struct MlpFused {
    pub layout: MlpLayout,
    pub precision: Precision,
    fwd: ComputePipeline,
    convert: Option<ComputePipeline>,
    table: Buffer,
    dummy: Buffer,
}

/// Rows per workgroup of each variant (mirrors ROWS in the .comp files).
fn rows(p: Precision) -> u32 {
    match p {
        Precision::F32 => 16,
        Precision::F16 => 32,
    }
}

impl MlpFused {
    /// Fails with a message naming the limit when the configuration does not fit shared
    /// memory, or the feature when fp16 is asked for on a device without it.
    pub fn new(gpu: &Gpu, cfg: &MlpConfig, precision: Precision) -> Result<Self> {
        let layout = MlpLayout::new(cfg)?;
        let hidden = match cfg.time {
            TimeEncoding::TimeNet { hidden, .. } => hidden,
            _ => 0,
        };
        if cfg.width > FUSED_MAX_WIDTH || hidden > FUSED_MAX_WIDTH || cfg.in_dims() > FUSED_MAX_IN {
            return Err(Error::Invalid(format!(
                "fused MLP forward: width {} / time-net hidden {hidden} must be ≤ {FUSED_MAX_WIDTH} and in_dims {} ≤ {FUSED_MAX_IN} (shared memory); use the layer-wise kernels::mlp::Mlp",
                cfg.width,
                cfg.in_dims()
            )));
        }
        if precision == Precision::F16 && !(gpu.info.shader_float16 && gpu.info.storage_16bit) {
            return Err(Error::MissingFeature {
                device: gpu.info.name.clone(),
                feature: "shaderFloat16 + storageBuffer16BitAccess",
                why:
                    "the fp16 MLP forward stores weights and activations as f16; use Precision::F32",
            });
        }
        let table: Vec<u32> = layout
            .linears
            .iter()
            .flat_map(|l| [l.fan_in, l.fan_out, l.w_off, l.b_off].map(|v| v as u32))
            .collect();
        let (fwd, convert) = match precision {
            Precision::F32 => (gpu.pipeline(&shaders::mlp::FUSED_FWD)?, None),
            Precision::F16 => (
                gpu.pipeline(&shaders::mlp::FUSED_FWD_F16)?,
                Some(gpu.pipeline(&shaders::mlp::TO_F16)?),
            ),
        };
        Ok(MlpFused {
            precision,
            fwd,
            convert,
            table: gpu.buffer_from("mlp layer table", &table)?,
            dummy: gpu.buffer("mlp fused no times", 16)?,
            layout,
        })
    }

    /// Bytes of the f16 parameter copy this variant needs (0 for f32).
    pub fn f16_params_bytes(&self) -> u64 {
        match self.precision {
            Precision::F32 => 0,
            Precision::F16 => (self.layout.total as u64 * 2).next_multiple_of(4),
        }
    }

    /// F16 only: converts `params` (f32) into `params16` (f16); record after every update of
    /// the parameters and before [`MlpFused::forward`].
    pub fn convert_params(
        &self,
        rec: &mut Recorder<'_>,
        params: BufSlice<'_>,
        params16: BufSlice<'_>,
    ) {
        let conv = self
            .convert
            .as_ref()
            .expect("convert_params is for Precision::F16");
        let count = self.layout.total as u32;
        assert!(params.size >= count as u64 * 4 && params16.size >= count as u64 * 2);
        let pc = MlpConvertParams {
            count,
            ..Default::default()
        };
        rec.dispatch_threads(conv, &pc, &[params, params16], [count, 1, 1]);
    }

    /// Forward of `n` Gaussians: `xyz` [N][3], `out` [N][10]. `params` is the f32 parameter
    /// buffer (F32) or its f16 copy from [`MlpFused::convert_params`] (F16).
    pub fn forward(
        &self,
        rec: &mut Recorder<'_>,
        n: u32,
        xyz: BufSlice<'_>,
        time: MlpTime<'_>,
        params: BufSlice<'_>,
        out: BufSlice<'_>,
    ) {
        let cfg = &self.layout.cfg;
        let elem = if self.precision == Precision::F16 {
            2
        } else {
            4
        };
        assert!(
            params.size >= self.layout.total as u64 * elem,
            "params {params:?} too small"
        );
        assert!(xyz.size >= n as u64 * 12 && out.size >= n as u64 * 40);
        let (per_g, t, times) = match time {
            MlpTime::Batch(t) => (0, t, self.dummy.all()),
            MlpTime::PerGaussian(s) => {
                assert!(s.size >= n as u64 * 4);
                (1, 0.0, s)
            }
        };
        let (time_net, hidden) = match cfg.time {
            TimeEncoding::TimeNet { hidden, .. } => (1, hidden),
            _ => (0, 0),
        };
        let pc = MlpFusedParams {
            n,
            depth: cfg.depth,
            width: cfg.width,
            skip: cfg.skip.unwrap_or(u32::MAX),
            x_freqs: cfg.x_freqs,
            t_freqs: cfg.t_freqs(),
            time_net,
            hidden,
            t_feat: cfg.t_feat_dims() as u32,
            per_gaussian_time: per_g,
            time: t,
            pad: 0,
        };
        let blocks = n.div_ceil(rows(self.precision));
        let gx = blocks.clamp(1, 65535);
        let outer = rec.set_zone("mlp fused");
        rec.dispatch(
            &self.fwd,
            &pc,
            &[params, self.table.all(), xyz, times, out],
            [gx, blocks.div_ceil(gx), 1],
        );
        rec.set_zone(&outer);
    }
}

/// The FMA-throughput probe: `groups` workgroups of 256 invocations, `iters` rounds of 16 FMA.
/// Returns the FLOP it performs.
pub struct FmaPeak {
    pipe: ComputePipeline,
}

impl FmaPeak {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        Ok(FmaPeak {
            pipe: gpu.pipeline(&shaders::mlp::FMA_PEAK)?,
        })
    }

    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        out: BufSlice<'_>,
        groups: u32,
        iters: u32,
    ) -> f64 {
        assert!(out.size >= groups as u64 * 256 * 4);
        let pc = FmaPeakParams {
            iters,
            a: 0.999,
            b: 1e-3,
            pad: 0,
        };
        rec.dispatch(&self.pipe, &pc, &[out], [groups, 1, 1]);
        groups as f64 * 256.0 * iters as f64 * 32.0
    }
}
