//! Instance and device: pick a device, check the features the kernels need, own the allocator.

use std::ffi::{c_void, CStr, CString};
use std::mem::ManuallyDrop;
use std::sync::{Arc, Mutex};

use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};

use crate::error::{Error, Result};

/// Whether to load the Khronos validation layer (with synchronisation validation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Validation {
    Off,
    /// On when `VK_LAYER_KHRONOS_validation` is installed, else off with a note on stderr.
    IfAvailable,
    /// Error when the layer is missing.
    Required,
}

#[derive(Debug, Clone)]
pub struct GpuOptions {
    pub validation: Validation,
    /// Device index or case-insensitive name substring; `None` ranks discrete > integrated >
    /// virtual > CPU (lavapipe).
    pub device: Option<String>,
    /// Fill every new device-local buffer with this word before handing it out (a debugging
    /// aid: a kernel that reads memory nothing wrote then sees it; off = contents undefined).
    pub poison: Option<u32>,
}

impl GpuOptions {
    /// `DISPFLOW_DEVICE=<index|name>` picks the device; `DISPFLOW_VALIDATION=1|required|0`
    /// turns on the validation layer (default off); `DISPFLOW_POISON=<u32, decimal or 0x hex>`
    /// fills new device-local buffers with that word (an unparsable value is ignored with a
    /// note on stderr).
    pub fn from_env() -> Self {
        let validation = match std::env::var("DISPFLOW_VALIDATION").as_deref() {
            Ok("required") => Validation::Required,
            Ok("1") | Ok("on") => Validation::IfAvailable,
            _ => Validation::Off,
        };
        GpuOptions {
            validation,
            device: std::env::var("DISPFLOW_DEVICE")
                .ok()
                .filter(|s| !s.is_empty()),
            poison: std::env::var("DISPFLOW_POISON")
                .ok()
                .and_then(|v| match parse_word(&v) {
                    Some(w) => Some(w),
                    None => {
                        eprintln!("note: DISPFLOW_POISON={v:?} is not a u32 (decimal or 0x hex); not poisoning");
                        None
                    }
                }),
        }
    }
}

fn poison_bits(word: Option<u32>) -> u64 {
    word.map_or(0, |w| 1 << 32 | w as u64)
}

fn parse_word(v: &str) -> Option<u32> {
    let v = v.trim();
    match v.strip_prefix("0x").or_else(|| v.strip_prefix("0X")) {
        Some(hex) => u32::from_str_radix(hex, 16).ok(),
        None => v.parse().ok(),
    }
}

/// What the kernels and the reports need to know about the device.
#[derive(Debug, Clone)]
pub struct DeviceInfo {
    pub name: String,
    pub kind: String,
    pub driver: String,
    pub api_version: String,
    /// Queried, never assumed (lavapipe: 8, NVIDIA: 32, AMD: 64).
    pub subgroup_size: u32,
    pub subgroup_arithmetic: bool,
    pub subgroup_vote: bool,
    pub subgroup_ballot: bool,
    pub subgroup_shuffle: bool,
    pub max_shared_memory: u32,
    pub max_workgroup_invocations: u32,
    pub max_workgroup_count: [u32; 3],
    pub max_storage_buffer_range: u32,
    pub min_storage_buffer_offset_alignment: u64,
    /// Texel-buffer limits (the CPU shape's `imageBuffer` arrays, glsl/include/access.glsl).
    pub max_texel_buffer_elements: u32,
    pub min_texel_buffer_offset_alignment: u64,
    pub max_uniform_buffer_range: u32, // lavapipe: 64 KiB (the register MLP's weight windows)
    pub min_uniform_buffer_offset_alignment: u64,
    pub max_push_constants: u32,
    /// Nanoseconds per timestamp tick; `None` when the compute queue has no timestamps.
    pub timestamp_period_ns: Option<f32>,
    pub float_atomic_add: bool,
    pub shader_float16: bool,
    pub storage_16bit: bool,
    pub validation: bool,
}

impl std::fmt::Display for DeviceInfo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} ({}, {}, Vulkan {})",
            self.name, self.kind, self.driver, self.api_version
        )
    }
}

/// State shared by everything created from one device; dropped last.
pub(crate) struct Shared {
    _entry: ash::Entry,
    pub(crate) instance: ash::Instance,
    pub(crate) device: ash::Device,
    pub(crate) allocator: ManuallyDrop<Mutex<Allocator>>,
    debug: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    // Boxed so the pointer handed to the debug callback stays put.
    pub(crate) log: Box<Mutex<ValidationLog>>,
}

#[derive(Default)]
pub(crate) struct ValidationLog {
    pub(crate) errors: Vec<String>,
    pub(crate) warnings: usize,
}

impl Drop for Shared {
    fn drop(&mut self) {
        unsafe {
            let _ = self.device.device_wait_idle();
            ManuallyDrop::drop(&mut self.allocator);
            self.device.destroy_device(None);
            if let Some((du, m)) = self.debug.take() {
                du.destroy_debug_utils_messenger(m, None);
            }
            self.instance.destroy_instance(None);
        }
    }
}

/// One Vulkan device with one compute queue. Buffers and pipelines keep it alive.
pub struct Gpu {
    pub(crate) shared: Arc<Shared>,
    pub(crate) queue: Mutex<vk::Queue>,
    pub(crate) queue_family: u32,
    pub(crate) push_desc: ash::khr::push_descriptor::Device,
    pub info: DeviceInfo,
    /// 0: off; else `1 << 32 | word` (see `GpuOptions::poison`; atomic so a test can steer the
    /// shared test device).
    poison: std::sync::atomic::AtomicU64,
    pub(crate) pipelines: super::pipeline::PipelineCache,
}

/// Device memory held by the allocator: live allocations and the blocks reserved for them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemoryUse {
    pub allocations: usize,
    pub allocated_bytes: u64,
    pub reserved_bytes: u64,
}

/// Validation errors reported by any device of the process, ever, including those reported
/// while a device is destroyed (leaked objects), when its own log is already going away.
pub static VALIDATION_ERRORS: std::sync::atomic::AtomicUsize =
    std::sync::atomic::AtomicUsize::new(0);

unsafe extern "system" fn debug_callback(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _ty: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    let msg = if data.is_null() || (*data).p_message.is_null() {
        String::from("(no message)")
    } else {
        CStr::from_ptr((*data).p_message)
            .to_string_lossy()
            .into_owned()
    };
    let log = &*(user as *const Mutex<ValidationLog>);
    if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR) {
        VALIDATION_ERRORS.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
    }
    if let Ok(mut log) = log.lock() {
        if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR) {
            eprintln!("[vulkan validation error] {msg}");
            log.errors.push(msg);
        } else {
            eprintln!("[vulkan validation warning] {msg}");
            log.warnings += 1;
        }
    }
    vk::FALSE
}

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

fn kind_name(t: vk::PhysicalDeviceType) -> (&'static str, u32) {
    match t {
        vk::PhysicalDeviceType::DISCRETE_GPU => ("discrete GPU", 0),
        vk::PhysicalDeviceType::INTEGRATED_GPU => ("integrated GPU", 1),
        vk::PhysicalDeviceType::VIRTUAL_GPU => ("virtual GPU", 2),
        vk::PhysicalDeviceType::CPU => ("CPU", 3),
        _ => ("other", 4),
    }
}

fn version(v: u32) -> String {
    format!(
        "{}.{}.{}",
        vk::api_version_major(v),
        vk::api_version_minor(v),
        vk::api_version_patch(v)
    )
}

/// Name and type of every physical device, in enumeration order (for `dispflow-vk devices`).
pub fn list_devices() -> Result<Vec<(String, String)>> {
    let entry = unsafe { ash::Entry::load() }.map_err(|e| Error::Loader(e.to_string()))?;
    let app = vk::ApplicationInfo::default().api_version(vk::API_VERSION_1_2);
    let instance = unsafe {
        entry.create_instance(
            &vk::InstanceCreateInfo::default().application_info(&app),
            None,
        )?
    };
    let out = unsafe {
        let pds = instance.enumerate_physical_devices();
        let out = pds.map(|pds| {
            pds.iter()
                .map(|&pd| {
                    let p = instance.get_physical_device_properties(pd);
                    let name = p
                        .device_name_as_c_str()
                        .unwrap_or(c"?")
                        .to_string_lossy()
                        .into_owned();
                    (name, kind_name(p.device_type).0.to_string())
                })
                .collect()
        });
        instance.destroy_instance(None);
        out?
    };
    Ok(out)
}

impl Gpu {
    /// The word new device-local buffers are filled with, if any (`GpuOptions::poison`).
    pub fn poison(&self) -> Option<u32> {
        let bits = self.poison.load(std::sync::atomic::Ordering::Relaxed);
        (bits != 0).then_some(bits as u32)
    }

    /// Sets or clears `GpuOptions::poison` for the buffers allocated from now on.
    pub fn set_poison(&self, word: Option<u32>) {
        self.poison
            .store(poison_bits(word), std::sync::atomic::Ordering::Relaxed);
    }

    /// Device from `GpuOptions::from_env()`.
    pub fn new_default() -> Result<Gpu> {
        Gpu::new(&GpuOptions::from_env())
    }

    pub fn new(opts: &GpuOptions) -> Result<Gpu> {
        let entry = unsafe { ash::Entry::load() }.map_err(|e| Error::Loader(e.to_string()))?;
        let layers = unsafe { entry.enumerate_instance_layer_properties()? };
        let have_layer = layers
            .iter()
            .any(|l| l.layer_name_as_c_str() == Ok(VALIDATION_LAYER));
        let validate = match opts.validation {
            Validation::Off => false,
            Validation::IfAvailable => {
                if !have_layer {
                    eprintln!("note: VK_LAYER_KHRONOS_validation not installed; running without validation (Debian: apt-get install vulkan-validationlayers)");
                }
                have_layer
            }
            Validation::Required => {
                if !have_layer {
                    return Err(Error::NoDevice(
                        "validation was required but VK_LAYER_KHRONOS_validation is not installed (Debian: apt-get install vulkan-validationlayers)".into(),
                    ));
                }
                true
            }
        };

        let app_name = CString::new("dispflow-vk").unwrap();
        let app = vk::ApplicationInfo::default()
            .application_name(&app_name)
            .api_version(vk::API_VERSION_1_2);
        let layer_ptrs: Vec<*const i8> = if validate {
            vec![VALIDATION_LAYER.as_ptr()]
        } else {
            vec![]
        };
        let ext_ptrs: Vec<*const i8> = if validate {
            vec![ash::ext::debug_utils::NAME.as_ptr()]
        } else {
            vec![]
        };
        // Synchronisation validation is what catches a missing barrier on lavapipe, which runs
        // dispatches in order and would hide it.
        let enables = [vk::ValidationFeatureEnableEXT::SYNCHRONIZATION_VALIDATION];
        let mut features =
            vk::ValidationFeaturesEXT::default().enabled_validation_features(&enables);
        let mut ici = vk::InstanceCreateInfo::default()
            .application_info(&app)
            .enabled_layer_names(&layer_ptrs)
            .enabled_extension_names(&ext_ptrs);
        if validate {
            ici = ici.push_next(&mut features);
        }
        let instance = unsafe { entry.create_instance(&ici, None)? };
        let log: Box<Mutex<ValidationLog>> = Box::default();
        let debug = if validate {
            let du = ash::ext::debug_utils::Instance::new(&entry, &instance);
            let info = vk::DebugUtilsMessengerCreateInfoEXT::default()
                .message_severity(
                    vk::DebugUtilsMessageSeverityFlagsEXT::WARNING
                        | vk::DebugUtilsMessageSeverityFlagsEXT::ERROR,
                )
                .message_type(
                    vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                        | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                        | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
                )
                .pfn_user_callback(Some(debug_callback))
                .user_data(&*log as *const Mutex<ValidationLog> as *mut c_void);
            let m = unsafe { du.create_debug_utils_messenger(&info, None)? };
            Some((du, m))
        } else {
            None
        };
        // open_device destroys the instance (and messenger) itself if it fails.
        Self::open_device(entry, instance, debug, log, validate, opts)
    }

    fn open_device(
        entry: ash::Entry,
        instance: ash::Instance,
        debug: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
        log: Box<Mutex<ValidationLog>>,
        validate: bool,
        opts: &GpuOptions,
    ) -> Result<Gpu> {
        let cleanup = |instance: &ash::Instance,
                       debug: &Option<(
            ash::ext::debug_utils::Instance,
            vk::DebugUtilsMessengerEXT,
        )>| unsafe {
            if let Some((du, m)) = debug {
                du.destroy_debug_utils_messenger(*m, None);
            }
            instance.destroy_instance(None);
        };
        let picked = Self::pick(&instance, opts);
        let (pd, qf) = match picked {
            Ok(x) => x,
            Err(e) => {
                cleanup(&instance, &debug);
                return Err(e);
            }
        };
        match Self::create_logical(&instance, pd, qf, validate) {
            Ok((device, info)) => {
                let allocator = Allocator::new(&AllocatorCreateDesc {
                    instance: instance.clone(),
                    device: device.clone(),
                    physical_device: pd,
                    debug_settings: Default::default(),
                    buffer_device_address: false,
                    allocation_sizes: Default::default(),
                });
                let allocator = match allocator {
                    Ok(a) => a,
                    Err(e) => {
                        unsafe { device.destroy_device(None) };
                        cleanup(&instance, &debug);
                        return Err(Error::NoDevice(format!("gpu-allocator: {e}")));
                    }
                };
                let queue = unsafe { device.get_device_queue(qf, 0) };
                let push_desc = ash::khr::push_descriptor::Device::new(&instance, &device);
                let shared = Arc::new(Shared {
                    _entry: entry,
                    instance,
                    device,
                    allocator: ManuallyDrop::new(Mutex::new(allocator)),
                    debug,
                    log,
                });
                Ok(Gpu {
                    shared,
                    queue: Mutex::new(queue),
                    queue_family: qf,
                    push_desc,
                    info,
                    poison: std::sync::atomic::AtomicU64::new(poison_bits(opts.poison)),
                    pipelines: Default::default(),
                })
            }
            Err(e) => {
                cleanup(&instance, &debug);
                Err(e)
            }
        }
    }

    /// Physical device and compute queue family: the override if given, else the best kind.
    fn pick(instance: &ash::Instance, opts: &GpuOptions) -> Result<(vk::PhysicalDevice, u32)> {
        let pds = unsafe { instance.enumerate_physical_devices()? };
        if pds.is_empty() {
            return Err(Error::NoDevice(
                "the Vulkan loader found no device; install a driver (Debian: `bash tools/setup.sh` installs Mesa lavapipe)".into(),
            ));
        }
        let mut cands = Vec::new();
        for (i, &pd) in pds.iter().enumerate() {
            let p = unsafe { instance.get_physical_device_properties(pd) };
            let name = p
                .device_name_as_c_str()
                .unwrap_or(c"?")
                .to_string_lossy()
                .into_owned();
            let qfs = unsafe { instance.get_physical_device_queue_family_properties(pd) };
            let qf = qfs
                .iter()
                .position(|q| q.queue_flags.contains(vk::QueueFlags::COMPUTE));
            cands.push((i, pd, name, kind_name(p.device_type).1, qf));
        }
        let list = cands
            .iter()
            .map(|c| format!("{}: {}", c.0, c.2))
            .collect::<Vec<_>>()
            .join(", ");
        let chosen = if let Some(sel) = &opts.device {
            let by_index = sel
                .parse::<usize>()
                .ok()
                .and_then(|i| cands.iter().find(|c| c.0 == i));
            let by_name = || {
                cands
                    .iter()
                    .find(|c| c.2.to_lowercase().contains(&sel.to_lowercase()))
            };
            by_index.or_else(by_name).ok_or_else(|| {
                Error::NoDevice(format!(
                    "DISPFLOW_DEVICE={sel:?} matches no device (have: {list})"
                ))
            })?
        } else {
            cands
                .iter()
                .filter(|c| c.4.is_some())
                .min_by_key(|c| (c.3, c.0))
                .ok_or_else(|| {
                    Error::NoDevice(format!("no device has a compute queue (have: {list})"))
                })?
        };
        let qf = chosen
            .4
            .ok_or_else(|| Error::NoDevice(format!("{} has no compute queue", chosen.2)))?;
        Ok((chosen.1, qf as u32))
    }

    fn create_logical(
        instance: &ash::Instance,
        pd: vk::PhysicalDevice,
        qf: u32,
        validate: bool,
    ) -> Result<(ash::Device, DeviceInfo)> {
        let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
        let mut driver = vk::PhysicalDeviceDriverProperties::default();
        let mut props2 = vk::PhysicalDeviceProperties2::default()
            .push_next(&mut subgroup)
            .push_next(&mut driver);
        unsafe { instance.get_physical_device_properties2(pd, &mut props2) };
        let p = props2.properties;
        let name = p
            .device_name_as_c_str()
            .unwrap_or(c"?")
            .to_string_lossy()
            .into_owned();
        let driver_name = driver
            .driver_info_as_c_str()
            .unwrap_or(c"")
            .to_string_lossy()
            .into_owned();
        let driver_id = driver
            .driver_name_as_c_str()
            .unwrap_or(c"")
            .to_string_lossy()
            .into_owned();

        let exts = unsafe { instance.enumerate_device_extension_properties(pd)? };
        let has_ext = |n: &CStr| exts.iter().any(|e| e.extension_name_as_c_str() == Ok(n));
        let missing = |feature: &'static str, why: &'static str| Error::MissingFeature {
            device: name.clone(),
            feature,
            why,
        };
        if p.api_version < vk::API_VERSION_1_2 {
            return Err(missing(
                "Vulkan 1.2",
                "the kernels are compiled for the Vulkan 1.2 environment",
            ));
        }
        if !has_ext(ash::khr::push_descriptor::NAME) {
            return Err(missing(
                "VK_KHR_push_descriptor",
                "every dispatch binds its buffers with push descriptors (no descriptor pools)",
            ));
        }
        let mut atomic = vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default();
        let mut f12 = vk::PhysicalDeviceVulkan12Features::default();
        let mut f11 = vk::PhysicalDeviceVulkan11Features::default();
        let has_atomic_ext = has_ext(ash::ext::shader_atomic_float::NAME);
        {
            let mut f2 = vk::PhysicalDeviceFeatures2::default()
                .push_next(&mut f12)
                .push_next(&mut f11);
            if has_atomic_ext {
                f2 = f2.push_next(&mut atomic);
            }
            unsafe { instance.get_physical_device_features2(pd, &mut f2) };
        }
        if !has_atomic_ext || atomic.shader_buffer_float32_atomic_add == vk::FALSE {
            return Err(missing(
                "VK_EXT_shader_atomic_float (shaderBufferFloat32AtomicAdd)",
                "gradient accumulation in the rasteriser backward pass adds floats atomically",
            ));
        }
        let qfp = unsafe { instance.get_physical_device_queue_family_properties(pd) };
        let ts_bits = qfp[qf as usize].timestamp_valid_bits;

        // Enable exactly what is used; optional features only where present.
        let mut en_atomic = vk::PhysicalDeviceShaderAtomicFloatFeaturesEXT::default()
            .shader_buffer_float32_atomic_add(true);
        let mut en12 = vk::PhysicalDeviceVulkan12Features::default()
            .shader_float16(f12.shader_float16 == vk::TRUE)
            .shader_int8(f12.shader_int8 == vk::TRUE)
            .storage_buffer8_bit_access(f12.storage_buffer8_bit_access == vk::TRUE);
        let mut en11 = vk::PhysicalDeviceVulkan11Features::default()
            .storage_buffer16_bit_access(f11.storage_buffer16_bit_access == vk::TRUE);
        let mut en2 = vk::PhysicalDeviceFeatures2::default()
            .push_next(&mut en_atomic)
            .push_next(&mut en12)
            .push_next(&mut en11);
        let dev_exts = [
            ash::khr::push_descriptor::NAME.as_ptr(),
            ash::ext::shader_atomic_float::NAME.as_ptr(),
        ];
        let prio = [1.0f32];
        let qci = [vk::DeviceQueueCreateInfo::default()
            .queue_family_index(qf)
            .queue_priorities(&prio)];
        let dci = vk::DeviceCreateInfo::default()
            .queue_create_infos(&qci)
            .enabled_extension_names(&dev_exts)
            .push_next(&mut en2);
        let device = unsafe { instance.create_device(pd, &dci, None)? };

        let ops = subgroup.supported_operations;
        let info = DeviceInfo {
            kind: kind_name(p.device_type).0.to_string(),
            driver: if driver_name.is_empty() {
                driver_id
            } else {
                format!("{driver_id} {driver_name}")
            },
            api_version: version(p.api_version),
            subgroup_size: subgroup.subgroup_size,
            subgroup_arithmetic: ops.contains(vk::SubgroupFeatureFlags::ARITHMETIC),
            subgroup_vote: ops.contains(vk::SubgroupFeatureFlags::VOTE),
            subgroup_ballot: ops.contains(vk::SubgroupFeatureFlags::BALLOT),
            subgroup_shuffle: ops.contains(vk::SubgroupFeatureFlags::SHUFFLE),
            max_shared_memory: p.limits.max_compute_shared_memory_size,
            max_workgroup_invocations: p.limits.max_compute_work_group_invocations,
            max_workgroup_count: p.limits.max_compute_work_group_count,
            max_storage_buffer_range: p.limits.max_storage_buffer_range,
            min_storage_buffer_offset_alignment: p.limits.min_storage_buffer_offset_alignment,
            max_texel_buffer_elements: p.limits.max_texel_buffer_elements,
            min_texel_buffer_offset_alignment: p.limits.min_texel_buffer_offset_alignment,
            max_uniform_buffer_range: p.limits.max_uniform_buffer_range,
            min_uniform_buffer_offset_alignment: p.limits.min_uniform_buffer_offset_alignment,
            max_push_constants: p.limits.max_push_constants_size,
            timestamp_period_ns: (ts_bits > 0 && p.limits.timestamp_period > 0.0)
                .then_some(p.limits.timestamp_period),
            float_atomic_add: true,
            shader_float16: f12.shader_float16 == vk::TRUE,
            storage_16bit: f11.storage_buffer16_bit_access == vk::TRUE,
            validation: validate,
            name,
        };
        Ok((device, info))
    }

    pub(crate) fn device(&self) -> &ash::Device {
        &self.shared.device
    }

    /// Validation errors reported since the last call (empty when validation is off).
    pub fn take_validation_errors(&self) -> Vec<String> {
        std::mem::take(&mut self.shared.log.lock().unwrap().errors)
    }

    /// An error listing the validation errors reported since the last take (device creation
    /// included), or `Ok` when there were none or validation is off.
    pub fn check_validation(&self, what: &str) -> Result<()> {
        let errors = self.take_validation_errors();
        if errors.is_empty() {
            return Ok(());
        }
        Err(Error::Validation {
            what: what.to_string(),
            count: errors.len(),
            messages: errors.join("\n"),
        })
    }

    /// Device memory the allocator holds now.
    pub fn memory_use(&self) -> MemoryUse {
        let r = self.shared.allocator.lock().unwrap().generate_report();
        MemoryUse {
            allocations: r.allocations.len(),
            allocated_bytes: r.total_allocated_bytes,
            reserved_bytes: r.total_capacity_bytes,
        }
    }

    /// Validation warnings seen so far.
    pub fn validation_warnings(&self) -> usize {
        self.shared.log.lock().unwrap().warnings
    }

    pub fn wait_idle(&self) -> Result<()> {
        unsafe { self.device().device_wait_idle()? };
        Ok(())
    }
}
