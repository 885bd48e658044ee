//! The scene motion a motion step learns from (issue 16): the source's flow photo → render
//! (v1, t2), optionally corrected by the flow photo → render (v1, t1) (the apparent motion of
//! reconstruction error alone) and weighted per pixel by how well the render at t1 matches
//! the photo (`kernels::dispflow::scene_signal`). Direct order only: the reverse order's
//! reconstruction error sits in a render the step does not draw.

use super::motion::{MotionPair, SceneMotion};
use crate::error::{Error, Result};
use crate::kernels::dispflow::{DispFlow, SignalIo};
use crate::vk::{BufSlice, Buffer, Gpu, Recorder};

/// How the scene motion is made robust to a half-trained render.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SignalConfig {
    /// Subtract the flow photo → render (v1, t1) (one more flow per motion step).
    pub residual: bool,
    /// Confidence scale σ: pixels weigh `exp(−mean|photo − render(v1, t1)| / σ)` in the
    /// motion L1; 0 = every pixel weighs 1.
    pub sigma: f32,
    /// Motion-mask filtering: scene motion shorter than this (pixels) becomes 0; 0 = off.
    pub mask_px: f32,
}

impl SignalConfig {
    /// The `scene_signal` kernel runs (else the source writes the scene motion directly).
    pub fn corrects(&self) -> bool {
        self.residual || self.sigma > 0.0 || self.mask_px > 0.0
    }

    pub fn validate(&self) -> Result<()> {
        if !(self.sigma.is_finite() && self.sigma >= 0.0) {
            return Err(Error::Invalid(format!(
                "config field motion_confidence: {}; expected a finite σ ≥ 0 (0 = off)",
                self.sigma
            )));
        }
        if !(self.mask_px.is_finite() && self.mask_px >= 0.0) {
            return Err(Error::Invalid(format!(
                "config field scene_motion.mask_px: {}; expected a finite length ≥ 0 (0 = off)",
                self.mask_px
            )));
        }
        Ok(())
    }
}

/// A scene-motion source with its correction, and the buffers it fills.
pub struct SceneSignal {
    source: Box<dyn SceneMotion>,
    cfg: SignalConfig,
    kernel: DispFlow,
    pixels: u32,
    /// The source's flow photo → render (v1, t2) when it is corrected afterwards.
    raw: Option<Buffer>,
    /// The flow photo → render (v1, t1) (residual correction only).
    resid: Option<Buffer>,
    flow: Buffer,
    conf: Option<Buffer>,
}

impl SceneSignal {
    pub fn new(
        gpu: &Gpu,
        source: Box<dyn SceneMotion>,
        cfg: SignalConfig,
        pixels: u64,
    ) -> Result<Self> {
        cfg.validate()?;
        let corrects = cfg.corrects();
        let buf = |name: &str, on: bool| on.then(|| gpu.buffer(name, pixels * 8)).transpose();
        Ok(SceneSignal {
            raw: buf("scene flow before correction", corrects)?,
            resid: buf("residual flow photo to render t1", cfg.residual)?,
            flow: gpu.buffer("scene flow", pixels * 8)?,
            // Written whenever the kernel runs (all ones without σ); read only with σ > 0.
            conf: corrects
                .then(|| gpu.buffer("scene flow confidence", pixels * 4))
                .transpose()?,
            kernel: DispFlow::new(gpu)?,
            pixels: pixels as u32,
            source,
            cfg,
        })
    }

    /// Records the scene motion of `pair` (`pair.from` the photo); `render_t1` is the render
    /// at (v1, t1) the residual and the confidence compare the photo with.
    pub fn record(&self, rec: &mut Recorder<'_>, pair: &MotionPair<'_>, render_t1: BufSlice<'_>) {
        let Some(raw) = &self.raw else {
            self.source.record(rec, pair, self.flow.all());
            return;
        };
        self.source.record(rec, pair, raw.all());
        if let Some(resid) = &self.resid {
            let at_t1 = MotionPair {
                to: render_t1,
                ..*pair
            };
            self.source.record(rec, &at_t1, resid.all());
        }
        let conf = self
            .conf
            .as_ref()
            .expect("allocated whenever the kernel runs");
        let io = SignalIo {
            flow_t2: raw.all(),
            // Never read without the residual: the raw flow fills the binding.
            flow_t1: self.resid.as_ref().unwrap_or(raw).all(),
            photo: pair.from,
            render_t1,
            scene: self.flow.all(),
            conf: conf.all(),
        };
        let c = &self.cfg;
        self.kernel
            .scene_signal(rec, self.pixels, c.residual, c.sigma, c.mask_px, &io);
    }

    /// The scene motion ([H·W] vec2, pixels) of the last `record`.
    pub fn flow(&self) -> BufSlice<'_> {
        self.flow.all()
    }

    /// Per-pixel confidence ([H·W] f32) of the last `record`, when σ > 0.
    pub fn confidence(&self) -> Option<BufSlice<'_>> {
        self.conf
            .as_ref()
            .filter(|_| self.cfg.sigma > 0.0)
            .map(|c| c.all())
    }

    pub fn source_name(&self) -> &str {
        self.source.name()
    }

    pub fn config(&self) -> SignalConfig {
        self.cfg
    }
}
