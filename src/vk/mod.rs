//! The thin Vulkan layer: device selection, named buffers, reflected compute pipelines, and a
//! recorder that places barriers where data flows and times every dispatch on the GPU.
//! Nothing here knows about Gaussians.

mod buffer;
mod device;
mod pipeline;
mod recorder;

pub use buffer::{BufSlice, Buffer};
pub use device::{
    list_devices, DeviceInfo, Gpu, GpuOptions, MemoryUse, Validation, VALIDATION_ERRORS,
};
pub use pipeline::ComputePipeline;
pub use recorder::{Recorder, Timings};
