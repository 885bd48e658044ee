//! Built-in dense optical flow: TV-L1 (Zach, Pock, Bischof 2007, duality-based; the
//! discretisation of Wedel et al. 2009 / OpenCV's `DualTVL1`) with coarse-to-fine warping on a
//! grey pyramid (`glsl/flow/*.comp`). CPU twin: `reference::flow`.
//!
//! Convention: `flow(x)` is in pixels and goes from image `a` to image `b`, `a(x) ≈ b(x + flow(x))`
//! (pixel centres at integer coordinates; x right, y down).
//!
//! Stages, in recording order:
//! 1. `grey`: RGB → `GREY_SCALE · (0.299 r + 0.587 g + 0.114 b)` (intensities in [0, 255], so
//!    λ has its usual literature scale), for `a` (I0) and `b` (I1).
//! 2. `prefilter` (optional, full resolution): `blur_a` binomial blur passes of I0 only (a
//!    sharp photo against a blurry render: σ = √blur_a px), then, with `texture` = β > 0, both
//!    planes become `I − β·S(I)`, `S` = [`TEXTURE_PASSES`] blur passes: the texture part of a
//!    structure–texture split (classically S is a ROF/TV denoising; a Gaussian structure is
//!    the cheap stand-in), which drops the shading a render has not learnt yet.
//! 3. `downsample` per level: 5×5 binomial blur ([1 4 6 4 1]/16 separable, clamped border)
//!    sampled at even pixels; a level is `ceil(w/2) × ceil(h/2)` of the finer one; the pyramid
//!    stops after `levels` levels or when a level's smaller side would drop below `min_size`.
//! 4. Coarse to fine, per level: flow (u) and dual variables (p) start at 0 on the coarsest
//!    level, otherwise `upsample` (bilinear, fine pixel `x` at coarse `x/2`, u × 2);
//!    `gradient` of I1 (central differences, clamped); then `warps` times: `warp` (bilinear,
//!    border-clamped: I1, ∂I1/∂x, ∂I1/∂y at `x + u`, the linearised residual), and `iterations`
//!    times `tvl1`: the point-wise thresholding step (v), `u = v + θ·div p`, and the dual step
//!    `p = (p + τ/θ·∇u) / (1 + τ/θ·|∇u|)` (forward differences, zero at the far border).
//!    The GPU does one iteration per dispatch, ping-ponging (u, p): each invocation recomputes
//!    the new u of its +x and +y neighbours to get ∇u, so an iteration is a single pass.
//!    With `finest` = L > 0 the solve stops after level L and the flow is brought to full
//!    resolution by `upsample` alone (about 4^L times less work on the finest levels).
//! 5. The level-0 flow is copied to the caller's buffer.
//!
//! No median filtering and no stopping criterion (fixed work, no readback). Flat or textureless
//! regions have |∇I1|² = 0: the data step does nothing there (no division; `FLOW_GRAD_EPS`) and
//! the flow is filled in by the TV term, so flat images give exactly zero flow. Images with
//! NaN/Inf are the caller's bug: the output is then undefined (the twin asserts in debug).

use bytemuck::{Pod, Zeroable};

use crate::error::{Error, Result};
use crate::kernels::shape::{Access, DeviceShape};
use crate::shaders;
use crate::vk::{BufSlice, Buffer, ComputePipeline, Gpu, Recorder};

/// Grey levels are scaled to [0, 255] (mirrored as `FLOW_GREY_SCALE` in glsl/flow/flow.glsl).
pub const GREY_SCALE: f32 = 255.0;
/// Below this |∇I1|² the data step leaves v = u (mirrored in glsl/flow/flow.glsl).
pub const FLOW_GRAD_EPS: f32 = 1e-6;
/// Blur passes of the structure S(I) in the texture prefilter (σ = 2 px).
pub const TEXTURE_PASSES: u32 = 4;

/// TV-L1 settings: the speed/accuracy knob is `levels`, `warps` and `iterations`
/// (work ≈ 4/3 · H·W · warps · iterations).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FlowConfig {
    /// Maximum pyramid levels (≥ 1; level 0 is full resolution). Default 5.
    pub levels: u32,
    /// Smallest allowed side of a pyramid level (≥ 1); coarser levels are dropped. Default 8.
    pub min_size: u32,
    /// Warps (re-linearisations) per level (≥ 1). Default 4.
    pub warps: u32,
    /// TV-L1 iterations per warp. Default 30.
    pub iterations: u32,
    /// Data-term weight λ on [0, 255] intensities (smaller = smoother). Default 0.15.
    pub lambda: f32,
    /// Dual time step τ, in (0, 0.25]. Default 0.25.
    pub tau: f32,
    /// Coupling θ between u and v (> 0). Default 0.3.
    pub theta: f32,
    /// Binomial blur passes on the full-resolution I0 (image `a`) before the pyramid. Default 0.
    pub blur_a: u32,
    /// Structure–texture factor β in [0, 1): both images become `I − β·S(I)`. Default 0 (off).
    pub texture: f32,
    /// Finest level solved (0 = full resolution); must be below the levels the image gets.
    pub finest: u32,
}

impl Default for FlowConfig {
    fn default() -> Self {
        FlowConfig {
            levels: 5,
            min_size: 8,
            warps: 4,
            iterations: 30,
            lambda: 0.15,
            tau: 0.25,
            theta: 0.3,
            blur_a: 0,
            texture: 0.0,
            finest: 0,
        }
    }
}

impl FlowConfig {
    /// Cheapest useful setting: 4 levels, 2 warps, 10 iterations (≈ 1/6 of the default work).
    pub fn fast() -> Self {
        FlowConfig {
            levels: 4,
            warps: 2,
            iterations: 10,
            ..Default::default()
        }
    }

    /// Heavier setting: 5 levels, 6 warps, 50 iterations (≈ 2.5× the default work).
    pub fn accurate() -> Self {
        FlowConfig {
            levels: 5,
            warps: 6,
            iterations: 50,
            ..Default::default()
        }
    }

    /// A preset by name: `fast`, `default`, `accurate`.
    pub fn preset(name: &str) -> Result<Self> {
        match name {
            "fast" => Ok(Self::fast()),
            "default" => Ok(Self::default()),
            "accurate" => Ok(Self::accurate()),
            _ => Err(Error::Invalid(format!(
                "flow preset {name:?}: expected one of fast, default, accurate"
            ))),
        }
    }

    /// Checks the ranges documented on the fields.
    pub fn validate(&self) -> Result<()> {
        let bad = |what: &str| {
            Err(Error::Invalid(format!(
                "flow config: {what} (got {self:?})"
            )))
        };
        if self.levels < 1 || self.levels > 16 {
            return bad("levels must be in 1..=16");
        }
        if self.min_size < 1 {
            return bad("min_size must be >= 1");
        }
        if self.warps < 1 {
            return bad("warps must be >= 1");
        }
        if !(self.lambda.is_finite() && self.lambda > 0.0) {
            return bad("lambda must be finite and > 0");
        }
        if !(self.tau > 0.0 && self.tau <= 0.25) {
            return bad("tau must be in (0, 0.25]");
        }
        if !(self.theta.is_finite() && self.theta > 0.0) {
            return bad("theta must be finite and > 0");
        }
        if !(0.0..1.0).contains(&self.texture) {
            return bad("texture must be in [0, 1)");
        }
        if self.finest >= self.levels {
            return bad("finest must be below levels");
        }
        if self.blur_a > 64 {
            return bad("blur_a must be at most 64 passes");
        }
        Ok(())
    }

    /// `tvl1` dispatches (one per iteration) over the solved levels for an image of this size.
    pub fn iteration_dispatches(&self, width: u32, height: u32) -> u32 {
        let levels = pyramid_dims(self, width, height).len() as u32;
        levels.saturating_sub(self.finest) * self.warps * self.iterations
    }

    /// Prefilter blur passes per flow (both planes counted).
    pub fn prefilter_passes(&self) -> u32 {
        self.blur_a
            + if self.texture > 0.0 {
                2 * TEXTURE_PASSES
            } else {
                0
            }
    }
}

/// Sizes of the pyramid levels, finest first (always at least level 0).
pub fn pyramid_dims(cfg: &FlowConfig, width: u32, height: u32) -> Vec<(u32, u32)> {
    let mut dims = vec![(width, height)];
    while (dims.len() as u32) < cfg.levels {
        let (w, h) = *dims.last().unwrap();
        let (nw, nh) = (w.div_ceil(2), h.div_ceil(2));
        if nw.min(nh) < cfg.min_size.max(1) || (nw, nh) == (w, h) {
            break;
        }
        dims.push((nw, nh));
    }
    dims
}

/// Mirrors `FlowParams` in glsl/include/params.glsl (checked by tests/layout.rs). One struct
/// for every flow stage; each stage documents which fields it reads.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct FlowParams {
    pub width: u32,
    pub height: u32,
    pub src_width: u32,
    pub src_height: u32,
    pub off0: u32,
    pub off1: u32,
    pub off2: u32,
    pub off3: u32,
    pub lambda_theta: f32,
    pub theta: f32,
    pub tau_theta: f32,
    /// prefilter: 0 = dst = blur(src); β = dst = dst − β·blur(src).
    pub mix: f32,
}

/// A dense optical-flow estimator recorded into a command buffer. Object safe, so a learned
/// estimator can sit behind `Box<dyn FlowEstimator>` next to the built-in TV-L1.
pub trait FlowEstimator {
    /// Short name (for tables and logs).
    fn name(&self) -> &str;

    /// Scratch for one image size, allocated once and reused by every `record` of that size.
    fn scratch(&self, gpu: &Gpu, width: u32, height: u32) -> Result<FlowScratch>;

    /// Records the flow from `a` to `b` (both [H·W] vec4 RGB in [0,1], alpha ignored) into
    /// `flow` ([H·W] vec2, pixels, `a(x) ≈ b(x + flow(x))`). `s` comes from `self.scratch`.
    fn record(
        &self,
        rec: &mut Recorder<'_>,
        s: &FlowScratch,
        a: BufSlice<'_>,
        b: BufSlice<'_>,
        flow: BufSlice<'_>,
    );
}

/// Scratch of one estimator for one image size (named device buffers, owned by the estimator
/// that made it).
pub struct FlowScratch {
    pub width: u32,
    pub height: u32,
    estimator: String,
    /// Level sizes, finest first.
    dims: Vec<(u32, u32)>,
    /// Float offset of each level's (I0, I1) planes in `pyr`.
    offsets: Vec<(u32, u32)>,
    pyr: Buffer,
    grad: Buffer,
    warp: Buffer,
    u: [Buffer; 2],
    p: [Buffer; 2],
    /// Prefilter ping-pong planes ([H·W] f32; 4 bytes when no prefilter is configured).
    tmp: [Buffer; 2],
}

impl FlowScratch {
    /// Every device buffer of the scratch (e.g. to fill them with noise in tests).
    pub fn buffers(&self) -> Vec<&Buffer> {
        let [u0, u1] = &self.u;
        let [p0, p1] = &self.p;
        let [t0, t1] = &self.tmp;
        vec![&self.pyr, &self.grad, &self.warp, u0, u1, p0, p1, t0, t1]
    }

    /// Pyramid level sizes, finest first.
    pub fn levels(&self) -> &[(u32, u32)] {
        &self.dims
    }
}

/// The built-in TV-L1 estimator: its configuration and pipelines.
pub struct TvL1Flow {
    pub cfg: FlowConfig,
    grey: ComputePipeline,
    downsample: ComputePipeline,
    gradient: ComputePipeline,
    warp: ComputePipeline,
    tvl1: ComputePipeline,
    upsample: ComputePipeline,
    prefilter: ComputePipeline,
}

impl TvL1Flow {
    /// The estimator in the device's array-access shape ([`Access`]).
    pub fn new(gpu: &Gpu, cfg: FlowConfig) -> Result<Self> {
        Self::with_access(gpu, cfg, Access::for_device(&gpu.info))
    }

    /// The estimator with its warp, iteration and upsampling stages in `access`'s shape.
    pub fn with_access(gpu: &Gpu, cfg: FlowConfig, access: Access) -> Result<Self> {
        cfg.validate()?;
        use shaders::flow as f;
        Ok(TvL1Flow {
            cfg,
            grey: gpu.pipeline(&f::GREY)?,
            downsample: gpu.pipeline(&f::DOWNSAMPLE)?,
            gradient: gpu.pipeline(&f::GRADIENT)?,
            warp: gpu.pipeline(access.pick(&f::WARP, &f::WARP_TEXEL))?,
            tvl1: gpu.pipeline(access.pick(&f::TVL1, &f::TVL1_TEXEL))?,
            upsample: gpu.pipeline(access.pick(&f::UPSAMPLE, &f::UPSAMPLE_TEXEL))?,
            prefilter: gpu.pipeline(&f::PREFILTER)?,
        })
    }
}

impl FlowEstimator for TvL1Flow {
    fn name(&self) -> &str {
        "tvl1"
    }

    fn scratch(&self, gpu: &Gpu, width: u32, height: u32) -> Result<FlowScratch> {
        if width == 0 || height == 0 {
            return Err(Error::Invalid(format!(
                "flow scratch: image size {width}×{height} must be at least 1×1"
            )));
        }
        let hw = width as u64 * height as u64;
        // The largest binding (p: 16 B per pixel) must fit lavapipe's 128 MiB storage range.
        if hw * 16 > 128 << 20 {
            return Err(Error::Capacity {
                what: "flow scratch pixels (16 B each per binding, 128 MiB limit)",
                capacity: (128 << 20) / 16,
                asked: hw,
            });
        }
        let dims = pyramid_dims(&self.cfg, width, height);
        if self.cfg.finest as usize >= dims.len() {
            return Err(Error::Invalid(format!(
                "flow config: finest = {} but a {width}×{height} image gets {} pyramid levels \
                 (levels {}, min_size {}); finest must be below that",
                self.cfg.finest,
                dims.len(),
                self.cfg.levels,
                self.cfg.min_size
            )));
        }
        let mut offsets = Vec::new();
        let mut off = 0u64;
        for &(w, h) in &dims {
            let n = w as u64 * h as u64;
            offsets.push((off as u32, (off + n) as u32));
            off += 2 * n;
        }
        Ok(FlowScratch {
            width,
            height,
            estimator: self.name().to_string(),
            dims,
            offsets,
            pyr: gpu.buffer("flow grey pyramid", off * 4)?,
            grad: gpu.buffer("flow I1 gradient", hw * 8)?,
            warp: gpu.buffer("flow warp terms", hw * 16)?,
            u: [
                gpu.buffer("flow u ping", hw * 8)?,
                gpu.buffer("flow u pong", hw * 8)?,
            ],
            p: [
                gpu.buffer("flow p ping", hw * 16)?,
                gpu.buffer("flow p pong", hw * 16)?,
            ],
            tmp: {
                let bytes = if self.cfg.prefilter_passes() > 0 {
                    hw * 4
                } else {
                    4
                };
                [
                    gpu.buffer("flow prefilter ping", bytes)?,
                    gpu.buffer("flow prefilter pong", bytes)?,
                ]
            },
        })
    }

    fn record(
        &self,
        rec: &mut Recorder<'_>,
        s: &FlowScratch,
        a: BufSlice<'_>,
        b: BufSlice<'_>,
        flow: BufSlice<'_>,
    ) {
        let (w, h) = (s.width, s.height);
        let hw = w as u64 * h as u64;
        assert_eq!(
            s.estimator,
            self.name(),
            "flow scratch of another estimator"
        );
        assert_eq!(
            s.dims,
            pyramid_dims(&self.cfg, w, h),
            "flow scratch made for another pyramid"
        );
        assert!(
            a.size >= hw * 16 && b.size >= hw * 16 && flow.size >= hw * 8,
            "flow record: a {a:?}, b {b:?} must hold {hw} vec4, flow {flow:?} {hw} vec2"
        );
        let cfg = &self.cfg;
        let pc = |(lw, lh): (u32, u32)| FlowParams {
            width: lw,
            height: lh,
            lambda_theta: cfg.lambda * cfg.theta,
            theta: cfg.theta,
            tau_theta: cfg.tau / cfg.theta,
            ..Default::default()
        };
        let (o0, o1) = s.offsets[0];
        rec.dispatch_threads(
            &self.grey,
            &FlowParams {
                off0: o0,
                off1: o1,
                ..pc((w, h))
            },
            &[a, b, s.pyr.all()],
            [w, h, 1],
        );
        self.record_prefilter(rec, s);
        for l in 1..s.dims.len() {
            let (sw, sh) = s.dims[l - 1];
            let (so0, so1) = s.offsets[l - 1];
            let (do0, do1) = s.offsets[l];
            rec.dispatch_threads(
                &self.downsample,
                &FlowParams {
                    src_width: sw,
                    src_height: sh,
                    off0: so0,
                    off1: so1,
                    off2: do0,
                    off3: do1,
                    ..pc(s.dims[l])
                },
                &[s.pyr.all()],
                [s.dims[l].0, s.dims[l].1, 2],
            );
        }
        let top = s.dims.len() - 1;
        let (tw, th) = s.dims[top];
        let top_px = tw as u64 * th as u64;
        rec.fill(s.u[0].slice(0, top_px * 8), 0);
        rec.fill(s.p[0].slice(0, top_px * 16), 0);
        let mut cur = 0usize;
        let finest = cfg.finest as usize;
        for l in (finest..=top).rev() {
            let d = s.dims[l];
            let (lo0, lo1) = s.offsets[l];
            if l < top {
                cur = self.record_upsample(rec, s, l, cur);
            }
            let lp = FlowParams {
                off0: lo0,
                off1: lo1,
                ..pc(d)
            };
            rec.dispatch_threads(
                &self.gradient,
                &lp,
                &[s.pyr.all(), s.grad.all()],
                [d.0, d.1, 1],
            );
            for _ in 0..cfg.warps {
                rec.dispatch_threads(
                    &self.warp,
                    &lp,
                    &[s.pyr.all(), s.grad.all(), s.u[cur].all(), s.warp.all()],
                    [d.0, d.1, 1],
                );
                for _ in 0..cfg.iterations {
                    rec.dispatch_threads(
                        &self.tvl1,
                        &lp,
                        &[
                            s.warp.all(),
                            s.u[cur].all(),
                            s.p[cur].all(),
                            s.u[1 - cur].all(),
                            s.p[1 - cur].all(),
                        ],
                        [d.0, d.1, 1],
                    );
                    cur = 1 - cur;
                }
            }
        }
        // Levels below `finest`: bilinear upsampling only.
        for l in (0..finest).rev() {
            cur = self.record_upsample(rec, s, l, cur);
        }
        rec.copy(
            s.u[cur].slice(0, hw * 8),
            flow.buf.slice(flow.offset, hw * 8),
        );
    }
}

impl TvL1Flow {
    /// `upsample` of (u, p) from level `l + 1` into level `l`, ping-pong slot `cur` → the
    /// returned one.
    fn record_upsample(
        &self,
        rec: &mut Recorder<'_>,
        s: &FlowScratch,
        l: usize,
        cur: usize,
    ) -> usize {
        let ((cw, ch), d) = (s.dims[l + 1], s.dims[l]);
        let p = FlowParams {
            width: d.0,
            height: d.1,
            src_width: cw,
            src_height: ch,
            ..Default::default()
        };
        let bufs = [
            s.u[cur].all(),
            s.p[cur].all(),
            s.u[1 - cur].all(),
            s.p[1 - cur].all(),
        ];
        rec.dispatch_threads(&self.upsample, &p, &bufs, [d.0, d.1, 1]);
        1 - cur
    }

    /// The full-resolution prefilters of the grey planes (stage 2): `blur_a` passes on I0,
    /// then the texture split of both planes.
    fn record_prefilter(&self, rec: &mut Recorder<'_>, s: &FlowScratch) {
        let (w, h) = (s.width, s.height);
        let hw = w as u64 * h as u64;
        let (o0, o1) = s.offsets[0];
        let pass = |rec: &mut Recorder<'_>, src: BufSlice<'_>, dst: (&Buffer, u32), mix: f32| {
            let p = FlowParams {
                width: w,
                height: h,
                off2: dst.1,
                mix,
                ..Default::default()
            };
            rec.dispatch_threads(&self.prefilter, &p, &[src, dst.0.all()], [w, h, 1]);
        };
        // `n` blur passes of the plane at `off`: copied out, ping-ponged, and the last pass
        // writes the plane back (`mix` = 0) or subtracts β times it (the texture split).
        let chain = |rec: &mut Recorder<'_>, off: u32, n: u32, mix: f32| {
            rec.copy(
                s.pyr.slice(off as u64 * 4, hw * 4),
                s.tmp[0].slice(0, hw * 4),
            );
            let mut cur = 0;
            for k in 0..n {
                let src = s.tmp[cur].all();
                if k + 1 == n {
                    pass(rec, src, (&s.pyr, off), mix);
                } else {
                    pass(rec, src, (&s.tmp[1 - cur], 0), 0.0);
                    cur = 1 - cur;
                }
            }
        };
        if self.cfg.blur_a > 0 {
            chain(rec, o0, self.cfg.blur_a, 0.0);
        }
        if self.cfg.texture > 0.0 {
            for off in [o0, o1] {
                chain(rec, off, TEXTURE_PASSES, self.cfg.texture);
            }
        }
    }
}
