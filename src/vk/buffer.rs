//! Named buffers through gpu-allocator, with staging upload and readback.

use std::sync::Arc;

use ash::vk;
use bytemuck::Pod;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

use super::device::{Gpu, Shared};
use super::recorder::Recorder;
use crate::error::{Error, Result};

/// A buffer usable as storage, uniform, indirect-args, copy source and copy destination.
/// Every buffer is named (the name shows in allocation errors and validation messages).
pub struct Buffer {
    shared: Arc<Shared>,
    pub(crate) raw: vk::Buffer,
    alloc: Option<Allocation>,
    size: u64,
    name: String,
}

/// A byte range of a buffer, as bound to a shader or copied.
#[derive(Clone, Copy)]
pub struct BufSlice<'a> {
    pub buf: &'a Buffer,
    pub offset: u64,
    pub size: u64,
}

impl<'a> BufSlice<'a> {
    pub(crate) fn raw(&self) -> vk::Buffer {
        self.buf.raw
    }
}

impl std::fmt::Debug for BufSlice<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}[{}..{}]",
            self.buf.name,
            self.offset,
            self.offset + self.size
        )
    }
}

impl Buffer {
    pub fn size(&self) -> u64 {
        self.size
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// The whole buffer.
    pub fn all(&self) -> BufSlice<'_> {
        BufSlice {
            buf: self,
            offset: 0,
            size: self.size,
        }
    }

    /// Bytes `[offset, offset + size)`.
    pub fn slice(&self, offset: u64, size: u64) -> BufSlice<'_> {
        assert!(
            offset + size <= self.size,
            "slice {offset}+{size} out of buffer {:?} ({} bytes)",
            self.name,
            self.size
        );
        BufSlice {
            buf: self,
            offset,
            size,
        }
    }

    /// Elements `[first, first + count)` of a buffer of `T`.
    pub fn elems<T>(&self, first: u64, count: u64) -> BufSlice<'_> {
        let s = std::mem::size_of::<T>() as u64;
        self.slice(first * s, count * s)
    }

    /// Contents of a host-visible buffer (`Gpu::host_buffer`) as `T`s. Call after the command
    /// buffer that wrote it finished.
    pub fn read_mapped<T: Pod>(&self) -> Vec<T> {
        let n = self.size as usize / std::mem::size_of::<T>();
        bytemuck::pod_collect_to_vec(&self.mapped()[..n * std::mem::size_of::<T>()])
    }

    fn mapped_mut(&mut self) -> &mut [u8] {
        self.alloc
            .as_mut()
            .and_then(|a| a.mapped_slice_mut())
            .expect("buffer is not host-visible")
    }

    fn mapped(&self) -> &[u8] {
        self.alloc
            .as_ref()
            .and_then(|a| a.mapped_slice())
            .expect("buffer is not host-visible")
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        unsafe { self.shared.device.destroy_buffer(self.raw, None) };
        if let Some(a) = self.alloc.take() {
            let _ = self.shared.allocator.lock().unwrap().free(a);
        }
    }
}

const USAGE: vk::BufferUsageFlags = vk::BufferUsageFlags::from_raw(
    vk::BufferUsageFlags::STORAGE_BUFFER.as_raw()
        | vk::BufferUsageFlags::UNIFORM_BUFFER.as_raw()
        | vk::BufferUsageFlags::STORAGE_TEXEL_BUFFER.as_raw()
        | vk::BufferUsageFlags::INDIRECT_BUFFER.as_raw()
        | vk::BufferUsageFlags::TRANSFER_SRC.as_raw()
        | vk::BufferUsageFlags::TRANSFER_DST.as_raw(),
);

impl Gpu {
    fn make_buffer(&self, name: &str, bytes: u64, location: MemoryLocation) -> Result<Buffer> {
        // Zero-sized bindings are invalid in Vulkan; an empty capacity still gets 16 bytes.
        let size = bytes.max(16).next_multiple_of(4);
        let dev = self.device();
        let raw = unsafe {
            dev.create_buffer(
                &vk::BufferCreateInfo::default()
                    .size(size)
                    .usage(USAGE)
                    .sharing_mode(vk::SharingMode::EXCLUSIVE),
                None,
            )?
        };
        let requirements = unsafe { dev.get_buffer_memory_requirements(raw) };
        let alloc = self
            .shared
            .allocator
            .lock()
            .unwrap()
            .allocate(&AllocationCreateDesc {
                name,
                requirements,
                location,
                linear: true,
                allocation_scheme: AllocationScheme::GpuAllocatorManaged,
            });
        let alloc = match alloc {
            Ok(a) => a,
            Err(source) => {
                unsafe { dev.destroy_buffer(raw, None) };
                return Err(Error::Alloc {
                    name: name.to_string(),
                    bytes: size,
                    source,
                });
            }
        };
        unsafe { dev.bind_buffer_memory(raw, alloc.memory(), alloc.offset())? };
        Ok(Buffer {
            shared: self.shared.clone(),
            raw,
            alloc: Some(alloc),
            size,
            name: name.to_string(),
        })
    }

    /// Device-local buffer of `bytes` bytes (contents undefined; `GpuOptions::poison` fills it).
    pub fn buffer(&self, name: &str, bytes: u64) -> Result<Buffer> {
        let b = self.make_buffer(name, bytes, MemoryLocation::GpuOnly)?;
        if let Some(word) = self.poison() {
            let mut rec = Recorder::new(self)?;
            rec.fill(b.all(), word);
            rec.finish()?;
        }
        Ok(b)
    }

    /// Host-visible buffer for results read every step without an extra submit: copy into it at
    /// the end of a command buffer, then `read_mapped` after `finish`.
    pub fn host_buffer(&self, name: &str, bytes: u64) -> Result<Buffer> {
        self.make_buffer(name, bytes, MemoryLocation::GpuToCpu)
    }

    /// Device-local buffer holding `data`.
    pub fn buffer_from<T: Pod>(&self, name: &str, data: &[T]) -> Result<Buffer> {
        let b = self.buffer(name, std::mem::size_of_val(data) as u64)?;
        if !data.is_empty() {
            self.upload(b.all(), data)?;
        }
        Ok(b)
    }

    /// Copies `data` to the start of `dst` through a staging buffer (waits for completion).
    pub fn upload<T: Pod>(&self, dst: BufSlice<'_>, data: &[T]) -> Result<()> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        assert!(
            bytes.len() as u64 <= dst.size,
            "upload of {} bytes into {dst:?}",
            bytes.len()
        );
        if bytes.is_empty() {
            return Ok(());
        }
        let mut staging = self.make_buffer(
            "staging upload",
            bytes.len() as u64,
            MemoryLocation::CpuToGpu,
        )?;
        staging.mapped_mut()[..bytes.len()].copy_from_slice(bytes);
        let mut rec = Recorder::new(self)?;
        rec.copy(
            staging.slice(0, bytes.len() as u64),
            dst.buf.slice(dst.offset, bytes.len() as u64),
        );
        rec.finish()?;
        Ok(())
    }

    /// Reads `src` back as `T`s through a staging buffer (waits for completion).
    pub fn read<T: Pod>(&self, src: BufSlice<'_>) -> Result<Vec<T>> {
        let n = src.size as usize / std::mem::size_of::<T>();
        let bytes = (n * std::mem::size_of::<T>()) as u64;
        if n == 0 {
            return Ok(Vec::new());
        }
        let staging = self.make_buffer("staging readback", bytes, MemoryLocation::GpuToCpu)?;
        let mut rec = Recorder::new(self)?;
        rec.copy(src.buf.slice(src.offset, bytes), staging.slice(0, bytes));
        rec.finish()?;
        Ok(bytemuck::pod_collect_to_vec(
            &staging.mapped()[..bytes as usize],
        ))
    }
}
