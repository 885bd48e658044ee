//! Command recording with barriers placed where data flows, and GPU timestamps per dispatch.
//!
//! Each dispatch declares its buffers (access from reflection: `readonly` bindings are reads,
//! everything else a write). The recorder remembers what was written and read since the last
//! barrier, and emits one global memory barrier only before a command that reads or overwrites
//! a byte range an earlier command wrote (RAW/WAW), or overwrites a range one read (WAR).
//! Indirect-argument buffers count as reads by the indirect stage.

use ash::vk;
use bytemuck::Pod;

use super::buffer::BufSlice;
use super::device::Gpu;
use super::pipeline::{descriptor_type, ComputePipeline};
use crate::error::Result;

#[derive(Clone, Copy)]
struct Range {
    buf: vk::Buffer,
    start: u64,
    end: u64,
}

impl Range {
    fn of(s: &BufSlice<'_>) -> Range {
        Range {
            buf: s.raw(),
            start: s.offset,
            end: s.offset + s.size,
        }
    }
    fn overlaps(&self, o: &Range) -> bool {
        self.buf == o.buf && self.start < o.end && o.start < self.end
    }
}

/// GPU time of each timed command, in submission order.
#[derive(Debug, Clone, Default)]
pub struct Timings {
    pub entries: Vec<(String, f64)>,
}

impl Timings {
    /// Total milliseconds over all entries.
    pub fn total_ms(&self) -> f64 {
        self.entries.iter().map(|e| e.1).sum()
    }

    /// Milliseconds summed per label, in first-seen order.
    pub fn by_label(&self) -> Vec<(String, f64)> {
        let mut out: Vec<(String, f64)> = Vec::new();
        for (l, ms) in &self.entries {
            match out.iter_mut().find(|e| &e.0 == l) {
                Some(e) => e.1 += ms,
                None => out.push((l.clone(), *ms)),
            }
        }
        out
    }
}

const MAX_TIMED: u32 = 4096;

/// Whether bytes `[offset, offset + size)` can be a view of `texel`-byte texels: the offset on
/// `align`, 1 to `max_texels` whole texels.
fn texel_fits((offset, size): (u64, u64), texel: u64, align: u64, max_texels: u32) -> bool {
    let texels = size / texel;
    offset % align.max(1) == 0 && texels >= 1 && texels <= max_texels as u64
}

/// Bytes of one texel of the formats `imageBuffer` bindings use (build.rs's list).
fn texel_bytes(format: vk::Format) -> u64 {
    match format {
        vk::Format::R32G32B32A32_SFLOAT | vk::Format::R32G32B32A32_UINT => 16,
        vk::Format::R32G32_SFLOAT => 8,
        _ => 4,
    }
}

/// One primary command buffer on the compute queue. `finish()` submits and waits.
pub struct Recorder<'g> {
    gpu: &'g Gpu,
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    written: Vec<Range>,
    read: Vec<Range>,
    queries: Option<vk::QueryPool>,
    labels: Vec<String>,
    zone: String,
    barriers: u32,
    dispatches: u32,
    tracking: bool,
    /// Texel-buffer views made for this command buffer's dispatches.
    views: Vec<vk::BufferView>,
    twin_dispatches: u32,
}

impl<'g> Recorder<'g> {
    /// A recorder without timestamps.
    pub fn new(gpu: &'g Gpu) -> Result<Self> {
        Self::create(gpu, false)
    }

    /// A recorder that writes a timestamp pair around every dispatch (when the queue has
    /// timestamps; otherwise `finish` returns no entries).
    pub fn timed(gpu: &'g Gpu) -> Result<Self> {
        Self::create(gpu, gpu.info.timestamp_period_ns.is_some())
    }

    fn create(gpu: &'g Gpu, timed: bool) -> Result<Self> {
        let d = gpu.device();
        let pool = unsafe {
            d.create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .queue_family_index(gpu.queue_family)
                    .flags(vk::CommandPoolCreateFlags::TRANSIENT),
                None,
            )?
        };
        let mut rec = Recorder {
            gpu,
            pool,
            cmd: vk::CommandBuffer::null(),
            written: Vec::new(),
            read: Vec::new(),
            queries: None,
            labels: Vec::new(),
            zone: String::new(),
            barriers: 0,
            dispatches: 0,
            tracking: true,
            views: Vec::new(),
            twin_dispatches: 0,
        };
        rec.cmd = unsafe {
            d.allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(pool)
                    .level(vk::CommandBufferLevel::PRIMARY)
                    .command_buffer_count(1),
            )?[0]
        };
        unsafe {
            d.begin_command_buffer(
                rec.cmd,
                &vk::CommandBufferBeginInfo::default()
                    .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
            )?
        };
        if timed {
            let qp = unsafe {
                d.create_query_pool(
                    &vk::QueryPoolCreateInfo::default()
                        .query_type(vk::QueryType::TIMESTAMP)
                        .query_count(2 * MAX_TIMED),
                    None,
                )?
            };
            unsafe { d.cmd_reset_query_pool(rec.cmd, qp, 0, 2 * MAX_TIMED) };
            rec.queries = Some(qp);
        }
        Ok(rec)
    }

    pub fn gpu(&self) -> &'g Gpu {
        self.gpu
    }

    /// Prefix for the timing labels of the following commands (e.g. `"sort"`); `""` clears it.
    /// Returns the zone it replaces, which a kernel family that names its own zone restores
    /// when it is done, so the caller's later kernels keep the caller's zone.
    pub fn set_zone(&mut self, zone: &str) -> String {
        std::mem::replace(&mut self.zone, zone.to_string())
    }

    /// Barriers emitted so far (for tests and reports).
    pub fn barrier_count(&self) -> u32 {
        self.barriers
    }

    /// Dispatches recorded so far.
    pub fn dispatch_count(&self) -> u32 {
        self.dispatches
    }

    /// Turns automatic barriers off. Only for the test proving that synchronisation validation
    /// catches a missing barrier; never in real work.
    #[doc(hidden)]
    pub fn disable_hazard_tracking_for_tests(&mut self) {
        self.tracking = false;
    }

    /// Makes sure the next command sees `reads`/`writes` safely with respect to earlier ones.
    fn hazard(&mut self, reads: &[Range], writes: &[Range]) {
        let raw_waw = reads
            .iter()
            .chain(writes)
            .any(|r| self.written.iter().any(|w| w.overlaps(r)));
        let war = writes
            .iter()
            .any(|w| self.read.iter().any(|r| r.overlaps(w)));
        if (raw_waw || war) && self.tracking {
            self.barrier();
        }
        self.read.extend_from_slice(reads);
        self.written.extend_from_slice(writes);
    }

    /// A full compute/transfer/indirect memory barrier. Normally placed by the hazard tracker;
    /// public for the rare case of a dependency the tracker cannot see.
    pub fn barrier(&mut self) {
        let mb = vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(
                vk::AccessFlags::SHADER_READ
                    | vk::AccessFlags::SHADER_WRITE
                    | vk::AccessFlags::TRANSFER_READ
                    | vk::AccessFlags::TRANSFER_WRITE
                    | vk::AccessFlags::INDIRECT_COMMAND_READ
                    | vk::AccessFlags::UNIFORM_READ,
            );
        unsafe {
            self.gpu.device().cmd_pipeline_barrier(
                self.cmd,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::COMPUTE_SHADER
                    | vk::PipelineStageFlags::TRANSFER
                    | vk::PipelineStageFlags::DRAW_INDIRECT,
                vk::DependencyFlags::empty(),
                &[mb],
                &[],
                &[],
            )
        };
        self.written.clear();
        self.read.clear();
        self.barriers += 1;
    }

    fn time_begin(&mut self, label: &str) -> Option<u32> {
        let qp = self.queries?;
        let i = self.labels.len() as u32;
        if i >= MAX_TIMED {
            return None;
        }
        self.labels.push(if self.zone.is_empty() {
            label.to_string()
        } else {
            format!("{}/{label}", self.zone)
        });
        unsafe {
            self.gpu.device().cmd_write_timestamp(
                self.cmd,
                vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                qp,
                2 * i,
            )
        };
        Some(i)
    }

    fn time_end(&mut self, i: Option<u32>) {
        if let (Some(i), Some(qp)) = (i, self.queries) {
            unsafe {
                self.gpu.device().cmd_write_timestamp(
                    self.cmd,
                    vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                    qp,
                    2 * i + 1,
                )
            };
        }
    }

    /// Whether `s` can be a texel view of `format` on this device: its offset on the texel
    /// alignment, and 1 to `maxTexelBufferElements` whole texels.
    fn texel_fits(&self, s: &BufSlice<'_>, format: vk::Format) -> bool {
        let info = &self.gpu.info;
        texel_fits(
            (s.offset, s.size),
            texel_bytes(format),
            info.min_texel_buffer_offset_alignment,
            info.max_texel_buffer_elements,
        )
    }

    /// `p`, or its storage-buffer twin when one of `bindings` cannot be a texel view of `p`
    /// (the same results; only the CPU shape's speed is lost).
    fn runnable<'p>(
        &mut self,
        p: &'p ComputePipeline,
        bindings: &[BufSlice<'_>],
    ) -> &'p ComputePipeline {
        let Some(twin) = &p.twin else { return p };
        let fits = (p.info.bindings.iter().zip(bindings)).all(|(b, s)| {
            b.texel_format == 0 || self.texel_fits(s, vk::Format::from_raw(b.texel_format))
        });
        if fits {
            p
        } else {
            self.twin_dispatches += 1;
            twin
        }
    }

    /// Dispatches of a texel-buffer stage that ran its storage-buffer twin instead.
    pub fn twin_dispatch_count(&self) -> u32 {
        self.twin_dispatches
    }

    /// A view of `s` as texels of `format`, over the whole texels the slice holds (`runnable`
    /// checked that it fits).
    fn texel_view(&self, s: &BufSlice<'_>, format: vk::Format) -> vk::BufferView {
        assert!(
            self.texel_fits(s, format),
            "texel-buffer binding {s:?} as {format:?}"
        );
        let texels = s.size / texel_bytes(format);
        unsafe {
            self.gpu
                .device()
                .create_buffer_view(
                    &vk::BufferViewCreateInfo::default()
                        .buffer(s.raw())
                        .format(format)
                        .offset(s.offset)
                        .range(texels * texel_bytes(format)),
                    None,
                )
                .expect("vkCreateBufferView")
        }
    }

    fn bind<P: Pod>(
        &mut self,
        p: &ComputePipeline,
        pc: &P,
        bindings: &[BufSlice<'_>],
    ) -> Vec<Range> {
        let info = p.info;
        assert_eq!(
            bindings.len(),
            info.bindings.len(),
            "{}: expects {} bindings, got {}",
            info.name,
            info.bindings.len(),
            bindings.len()
        );
        assert!(
            info.push_constant_size == 0
                || std::mem::size_of::<P>() as u32 == info.push_constant_size,
            "{}: push-constant struct is {} bytes, the shader's {} ({})",
            info.name,
            std::mem::size_of::<P>(),
            info.push_constant_size,
            info.push_constant_struct
        );
        let infos: Vec<vk::DescriptorBufferInfo> = bindings
            .iter()
            .map(|b| {
                vk::DescriptorBufferInfo::default()
                    .buffer(b.raw())
                    .offset(b.offset)
                    .range(b.size)
            })
            .collect();
        // Texel buffers read through a view; the views live until the recorder is dropped
        // (after `finish` waited for the command buffer).
        let views: Vec<vk::BufferView> = info
            .bindings
            .iter()
            .zip(bindings)
            .map(|(b, s)| {
                if b.texel_format == 0 {
                    return vk::BufferView::null();
                }
                let view = self.texel_view(s, vk::Format::from_raw(b.texel_format));
                self.views.push(view);
                view
            })
            .collect();
        let writes: Vec<vk::WriteDescriptorSet> = info
            .bindings
            .iter()
            .zip(&infos)
            .zip(&views)
            .map(|((b, bi), view)| {
                let w = vk::WriteDescriptorSet::default()
                    .dst_binding(b.binding)
                    .descriptor_type(descriptor_type(b));
                if b.texel_format != 0 {
                    w.texel_buffer_view(std::slice::from_ref(view))
                } else {
                    w.buffer_info(std::slice::from_ref(bi))
                }
            })
            .collect();
        let mut reads = Vec::new();
        let mut wr = Vec::new();
        for (b, s) in info.bindings.iter().zip(bindings) {
            if b.readonly {
                reads.push(Range::of(s));
            } else {
                wr.push(Range::of(s));
            }
        }
        self.hazard(&reads, &wr);
        let d = self.gpu.device();
        unsafe {
            d.cmd_bind_pipeline(self.cmd, vk::PipelineBindPoint::COMPUTE, p.pipeline);
            self.gpu.push_desc.cmd_push_descriptor_set(
                self.cmd,
                vk::PipelineBindPoint::COMPUTE,
                p.layout,
                0,
                &writes,
            );
            if info.push_constant_size > 0 {
                d.cmd_push_constants(
                    self.cmd,
                    p.layout,
                    vk::ShaderStageFlags::COMPUTE,
                    0,
                    bytemuck::bytes_of(pc),
                );
            }
        }
        reads
    }

    /// Dispatches `groups` workgroups.
    pub fn dispatch<P: Pod>(
        &mut self,
        p: &ComputePipeline,
        pc: &P,
        bindings: &[BufSlice<'_>],
        groups: [u32; 3],
    ) {
        let p = self.runnable(p, bindings);
        self.bind(p, pc, bindings);
        let lim = self.gpu.info.max_workgroup_count;
        assert!(
            groups.iter().zip(lim).all(|(g, l)| *g <= l),
            "{}: {groups:?} workgroups exceed the device limit {lim:?}",
            p.info.name
        );
        let t = self.time_begin(p.info.name.rsplit('/').next().unwrap());
        if groups.iter().all(|&g| g > 0) {
            unsafe {
                self.gpu
                    .device()
                    .cmd_dispatch(self.cmd, groups[0], groups[1], groups[2])
            };
        }
        self.time_end(t);
        self.dispatches += 1;
    }

    /// Dispatches enough workgroups to cover `threads` invocations (workgroup size from reflection).
    pub fn dispatch_threads<P: Pod>(
        &mut self,
        p: &ComputePipeline,
        pc: &P,
        bindings: &[BufSlice<'_>],
        threads: [u32; 3],
    ) {
        let wg = p.workgroup_size();
        let groups = [0, 1, 2].map(|i| threads[i].div_ceil(wg[i]));
        self.dispatch(p, pc, bindings, groups);
    }

    /// One invocation per row for `rows` rows, in workgroups of the reflected width: a 2D grid
    /// (x up to 65 535 groups, the rest in y); the shader's row is
    /// `gl_GlobalInvocationID.x + gl_GlobalInvocationID.y · gl_NumWorkGroups.x · gl_WorkGroupSize.x`.
    pub fn dispatch_rows<P: Pod>(
        &mut self,
        p: &ComputePipeline,
        pc: &P,
        bindings: &[BufSlice<'_>],
        rows: u32,
    ) {
        let groups = rows.div_ceil(p.workgroup_size()[0]);
        let gx = groups.clamp(1, self.gpu.info.max_workgroup_count[0].min(65_535));
        self.dispatch(p, pc, bindings, [gx, groups.div_ceil(gx).max(1), 1]);
    }

    /// Dispatches with the workgroup count read from `args` (three u32) on the GPU, so a count
    /// computed by an earlier dispatch never travels to the host.
    pub fn dispatch_indirect<P: Pod>(
        &mut self,
        p: &ComputePipeline,
        pc: &P,
        bindings: &[BufSlice<'_>],
        args: BufSlice<'_>,
    ) {
        assert!(
            args.size >= 12 && args.offset % 4 == 0,
            "{}: bad indirect args {args:?}",
            p.info.name
        );
        let a = Range::of(&args.buf.slice(args.offset, 12));
        // The args are read by the indirect stage before the shader runs.
        self.hazard(&[a], &[]);
        let p = self.runnable(p, bindings);
        self.bind(p, pc, bindings);
        let t = self.time_begin(p.info.name.rsplit('/').next().unwrap());
        unsafe {
            self.gpu
                .device()
                .cmd_dispatch_indirect(self.cmd, args.raw(), args.offset)
        };
        self.time_end(t);
        self.dispatches += 1;
    }

    /// Copies `src` to `dst` (equal sizes).
    pub fn copy(&mut self, src: BufSlice<'_>, dst: BufSlice<'_>) {
        assert_eq!(src.size, dst.size, "copy {src:?} -> {dst:?}");
        self.hazard(&[Range::of(&src)], &[Range::of(&dst)]);
        let region = vk::BufferCopy {
            src_offset: src.offset,
            dst_offset: dst.offset,
            size: src.size,
        };
        unsafe {
            self.gpu
                .device()
                .cmd_copy_buffer(self.cmd, src.raw(), dst.raw(), &[region])
        };
    }

    /// Fills `dst` (size a multiple of 4) with the 32-bit pattern `value`.
    pub fn fill(&mut self, dst: BufSlice<'_>, value: u32) {
        self.hazard(&[], &[Range::of(&dst)]);
        unsafe {
            self.gpu
                .device()
                .cmd_fill_buffer(self.cmd, dst.raw(), dst.offset, dst.size, value)
        };
    }

    /// Writes a few words from the host inline in the command stream (at most 64 KiB).
    pub fn update(&mut self, dst: BufSlice<'_>, words: &[u32]) {
        let bytes = (words.len() * 4) as u64;
        assert!(
            bytes <= dst.size && bytes <= 65536 && !words.is_empty(),
            "update {dst:?}"
        );
        let r = Range {
            buf: dst.raw(),
            start: dst.offset,
            end: dst.offset + bytes,
        };
        self.hazard(&[], &[r]);
        unsafe {
            self.gpu.device().cmd_update_buffer(
                self.cmd,
                dst.raw(),
                dst.offset,
                bytemuck::cast_slice(words),
            )
        };
    }

    /// Submits, waits, and returns the GPU time of every timed dispatch.
    pub fn finish(mut self) -> Result<Timings> {
        let d = self.gpu.device();
        // Make every write visible to the host (readback through mapped memory).
        let mb = vk::MemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ);
        unsafe {
            d.cmd_pipeline_barrier(
                self.cmd,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &[mb],
                &[],
                &[],
            );
            d.end_command_buffer(self.cmd)?;
            let fence = d.create_fence(&vk::FenceCreateInfo::default(), None)?;
            let cmds = [self.cmd];
            let submit = [vk::SubmitInfo::default().command_buffers(&cmds)];
            let res = {
                let q = self.gpu.queue.lock().unwrap();
                d.queue_submit(*q, &submit, fence)
            }
            .and_then(|_| d.wait_for_fences(&[fence], true, u64::MAX));
            d.destroy_fence(fence, None);
            res?;
        }
        let mut t = Timings::default();
        if let (Some(qp), Some(period)) = (self.queries, self.gpu.info.timestamp_period_ns) {
            let n = self.labels.len();
            if n > 0 {
                let mut raw = vec![0u64; 2 * n];
                unsafe {
                    d.get_query_pool_results(qp, 0, &mut raw, vk::QueryResultFlags::TYPE_64)?
                };
                for (i, l) in self.labels.drain(..).enumerate() {
                    let ticks = raw[2 * i + 1].wrapping_sub(raw[2 * i]);
                    t.entries.push((l, ticks as f64 * period as f64 * 1e-6));
                }
            }
        }
        Ok(t)
    }
}

impl Drop for Recorder<'_> {
    fn drop(&mut self) {
        let d = self.gpu.device();
        unsafe {
            if let Some(qp) = self.queries.take() {
                d.destroy_query_pool(qp, None);
            }
            d.destroy_command_pool(self.pool, None);
            for v in self.views.drain(..) {
                d.destroy_buffer_view(v, None);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::texel_fits;

    #[test]
    fn a_binding_is_a_texel_view_only_on_the_alignment_with_whole_texels_in_range() {
        assert!(texel_fits((32, 64), 16, 16, 1 << 27));
        assert!(!texel_fits((16, 64), 16, 64, 1 << 27), "off the alignment");
        assert!(!texel_fits((0, 8), 16, 16, 1 << 27), "no whole texel");
        assert!(
            !texel_fits((0, 80), 16, 16, 4),
            "more texels than the device allows"
        );
        assert!(
            texel_fits((0, 70), 16, 16, 4),
            "a partial last texel is left out"
        );
    }
}
