//! The library's error type. Every variant says what was expected and where.

use std::path::Path;

use ash::vk as avk;

pub type Result<T, E = Error> = std::result::Result<T, E>;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("Vulkan call failed: {0}")]
    Vulkan(#[from] avk::Result),
    #[error("cannot load the Vulkan library (libvulkan.so.1): {0}; install the Vulkan loader and a driver (Debian: `bash tools/setup.sh`, or apt-get install mesa-vulkan-drivers)")]
    Loader(String),
    #[error("no usable Vulkan device: {0}")]
    NoDevice(String),
    #[error("device {device:?} lacks the required feature {feature}: {why}")]
    MissingFeature {
        device: String,
        feature: &'static str,
        why: &'static str,
    },
    #[error("GPU memory allocation {name:?} ({bytes} bytes) failed: {source}")]
    Alloc {
        name: String,
        bytes: u64,
        #[source]
        source: gpu_allocator::AllocationError,
    },
    #[error("{what}: capacity {capacity} exceeded (asked for {asked})")]
    Capacity {
        what: &'static str,
        capacity: u64,
        asked: u64,
    },
    #[error("invalid argument: {0}")]
    Invalid(String),
    /// A rasteriser blend could not walk a tile's whole splat list (the device ends long
    /// shader loops: llvmpipe after 65 535 iterations of one invocation). Growing buffers
    /// cannot help; the render is wrong and nothing learns from it.
    #[error("{what}: a 16×16 tile holds more splats than this Vulkan device lets one shader invocation walk (lavapipe/llvmpipe ends every loop after 65 535 iterations, silently), so the render was cut and is discarded; use fewer or smaller Gaussians per tile (a lower --budget, a larger image) or a GPU")]
    TileWalkCut { what: String },
    #[error("{count} Vulkan validation error(s) during {what} (a bug in dispflow-vk; please report it):\n{messages}")]
    Validation {
        what: String,
        count: usize,
        messages: String,
    },
    #[error(transparent)]
    Data(#[from] crate::data::DataError),
    #[error("{path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
}

impl Error {
    /// For `map_err`: an I/O failure on `path` as an [`Error::Io`] that names it
    /// (`.map_err(Error::io(&path))?`, or `Error::io(&path)(e)` for an error in hand).
    pub fn io(path: &Path) -> impl FnOnce(std::io::Error) -> Error + '_ {
        move |source| Error::Io {
            path: path.display().to_string(),
            source,
        }
    }
}
