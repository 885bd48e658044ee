//! The passes a training step is made of. Each owns its pipelines and its scratch, allocated
//! once from one [`StepSizes`]; model state comes in as explicit arguments, so the step
//! (`super::step`) reads as a list of pass calls.

pub mod deform;
pub mod motion;
pub mod optim;
pub mod render;
pub mod signal;
pub mod sparsity;

pub use deform::{DeformPass, Slot};
pub use motion::{MotionPair, MotionTerm, SceneMotion};
pub use optim::{AdamPass, DensifyPass};
pub use render::{OverflowWatch, PhotoLoss, RenderPass};
pub use signal::{SceneSignal, SignalConfig};

use crate::kernels::raster::RasterSize;

/// Floats per Gaussian of the per-Gaussian scratch tensors.
pub mod row {
    /// The deformation MLP's output (dx 3, dr 4, ds 3) and its gradient.
    pub const DEFORM: u64 = crate::model::deform::OUT_DIMS as u64;
    /// Drawn means and scales; the displacement δ.
    pub const VEC3: u64 = 3;
    /// Drawn rotations.
    pub const QUAT: u64 = 4;
}

/// What every pass is sized for: the Gaussian budget and the image size.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StepSizes {
    pub capacity: u32,
    pub width: u32,
    pub height: u32,
    pub sh_coeffs: u32,
    /// First guess of tile intersections (grown on overflow).
    pub isect_guess: u32,
}

impl StepSizes {
    pub fn pixels(&self) -> u64 {
        self.width as u64 * self.height as u64
    }

    /// Raster buffers of this size blending `feature_dims` extra channels.
    pub fn raster(&self, feature_dims: u32) -> RasterSize {
        RasterSize {
            max_gaussians: self.capacity,
            width: self.width,
            height: self.height,
            sh_coeffs: self.sh_coeffs,
            feature_dims,
            isect_capacity: self.isect_guess,
        }
    }
}
