//! Compute pipelines built from the reflected shader table (no layout written by hand).

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use ash::vk;

use super::device::{Gpu, Shared};
use crate::error::Result;
use crate::shaders::{BindingInfo, ShaderInfo};

/// A compute pipeline whose descriptor layout (push descriptors, set 0), push-constant range and
/// workgroup size come from the SPIR-V reflection in the shader table. Shared: every wrapper
/// asking its device for the same shader gets the same Vulkan objects ([`PipelineCache`]).
pub struct ComputePipeline {
    pub info: &'static ShaderInfo,
    pub(crate) pipeline: vk::Pipeline,
    pub(crate) layout: vk::PipelineLayout,
    /// The storage-buffer twin of a texel-buffer stage (`ShaderInfo::buffer_twin`).
    pub(crate) twin: Option<Box<ComputePipeline>>,
    _objects: Arc<PipelineObjects>,
}

impl ComputePipeline {
    pub fn workgroup_size(&self) -> [u32; 3] {
        self.info.workgroup_size
    }

    /// The Vulkan pipeline handle (tests check two wrappers share one).
    pub fn raw(&self) -> vk::Pipeline {
        self.pipeline
    }
}

/// The Vulkan objects of one shader's pipeline, destroyed with their last user.
struct PipelineObjects {
    shared: Arc<Shared>,
    pipeline: vk::Pipeline,
    layout: vk::PipelineLayout,
    set_layout: vk::DescriptorSetLayout,
}

impl Drop for PipelineObjects {
    fn drop(&mut self) {
        let d = &self.shared.device;
        unsafe {
            d.destroy_pipeline(self.pipeline, None);
            d.destroy_pipeline_layout(self.layout, None);
            d.destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

/// A device's pipelines by shader, built on first use: a pipeline depends on its shader alone
/// (no specialisation constants), and building one is not cheap (lavapipe: ~25 ms of SPIR-V
/// to NIR for each, its shader cache notwithstanding; a rasteriser's ~40 took ~1 s, so every
/// `Trainer::new` or `Rasterizer::new` after the first paid it again).
#[derive(Default)]
pub(crate) struct PipelineCache(Mutex<HashMap<&'static str, Arc<PipelineObjects>>>);

impl Gpu {
    /// The pipeline of `info`: the device's own if it built one already, else a new one.
    /// A texel-buffer stage comes with its storage-buffer twin's pipeline.
    pub fn pipeline(&self, info: &'static ShaderInfo) -> Result<ComputePipeline> {
        let objects = {
            let mut cache = self.pipelines.0.lock().unwrap_or_else(|e| e.into_inner());
            match cache.get(info.name) {
                Some(o) => o.clone(),
                None => {
                    let o = Arc::new(self.build_pipeline(info)?);
                    cache.insert(info.name, o.clone());
                    o
                }
            }
        };
        let twin = match info.buffer_twin {
            Some(t) => Some(Box::new(self.pipeline(t)?)),
            None => None,
        };
        Ok(ComputePipeline {
            info,
            pipeline: objects.pipeline,
            layout: objects.layout,
            twin,
            _objects: objects,
        })
    }

    fn build_pipeline(&self, info: &'static ShaderInfo) -> Result<PipelineObjects> {
        let d = self.device();
        let bindings: Vec<_> = info
            .bindings
            .iter()
            .map(|b| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b.binding)
                    .descriptor_type(descriptor_type(b))
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        let set_layout = unsafe {
            d.create_descriptor_set_layout(
                &vk::DescriptorSetLayoutCreateInfo::default()
                    .flags(vk::DescriptorSetLayoutCreateFlags::PUSH_DESCRIPTOR_KHR)
                    .bindings(&bindings),
                None,
            )?
        };
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::COMPUTE)
            .offset(0)
            .size(info.push_constant_size)];
        let set_layouts = [set_layout];
        let mut pli = vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts);
        if info.push_constant_size > 0 {
            pli = pli.push_constant_ranges(&ranges);
        }
        let layout = unsafe { d.create_pipeline_layout(&pli, None)? };
        let words: Vec<u32> = bytemuck::pod_collect_to_vec(info.spirv);
        let module = unsafe {
            d.create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&words), None)?
        };
        let stage = vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(module)
            .name(c"main");
        let ci = [vk::ComputePipelineCreateInfo::default()
            .stage(stage)
            .layout(layout)];
        let res = unsafe { d.create_compute_pipelines(vk::PipelineCache::null(), &ci, None) };
        unsafe { d.destroy_shader_module(module, None) };
        let pipeline = res.map_err(|(_, e)| e)?[0];
        Ok(PipelineObjects {
            shared: self.shared.clone(),
            pipeline,
            layout,
            set_layout,
        })
    }
}

/// The descriptor type of a reflected binding.
pub(crate) fn descriptor_type(b: &BindingInfo) -> vk::DescriptorType {
    if b.texel_format != 0 {
        vk::DescriptorType::STORAGE_TEXEL_BUFFER
    } else if b.uniform {
        vk::DescriptorType::UNIFORM_BUFFER
    } else {
        vk::DescriptorType::STORAGE_BUFFER
    }
}
