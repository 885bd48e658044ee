//! Frames on the GPU: the kernels' camera, the time, the target image and (evaluation frames)
//! the motion mask; training frames of the oracle ablation also carry their scene flow.

use crate::data::{Dataset, Frame};
use crate::error::{Error, Result};
use crate::kernels::raster::Camera;
use crate::vk::{Buffer, Gpu};

/// A frame on the GPU: raster camera, time and the target image as [H·W] vec4.
pub struct GpuFrame {
    pub id: String,
    pub camera: Camera,
    pub time: f32,
    pub target: Buffer,
    /// Motion mask as [H·W] u32 (moving = 1) with its host copy, when the dataset has one.
    pub mask: Option<(Buffer, Vec<u8>)>,
    /// The latest earlier time of any frame in the dataset (the MMAP/DRC predecessor `t−1`).
    pub prev_time: Option<f32>,
    /// Ground-truth scene flow [H·W] vec2 (training frames, oracle motion flow only).
    pub gt_flow: Option<Buffer>,
    /// Test frames of scenes with ground-truth flow: the next time of any frame in the dataset
    /// and the host copy of the flow towards it (`H×W×2` pixels under this frame's camera),
    /// what the displacement EPE probe scores the model's motion against.
    pub next_flow: Option<(f32, Vec<f32>)>,
}

/// The kernels' camera of a loaded (OpenCV, glam) camera; `near` is the projection's cut.
pub fn kernel_camera(c: &crate::data::camera::Camera, near: f32) -> Camera {
    let r = c.rotation;
    Camera {
        rot: [
            r.row(0).to_array(),
            r.row(1).to_array(),
            r.row(2).to_array(),
        ],
        trans: c.translation.to_array(),
        fx: c.fx,
        fy: c.fy,
        cx: c.cx,
        cy: c.cy,
        width: c.width,
        height: c.height,
        near,
    }
}

/// The near cut of a dataset: half its near bound (0.01 without one).
pub fn near_of(data: &Dataset) -> f32 {
    data.near_far.map_or(0.01, |(n, _)| (0.5 * n).max(1e-3))
}

/// Uploads a frame; `times` (of every frame) give its predecessor. Only evaluation frames
/// (`with_mask`) carry their motion mask: training never reads it.
pub fn upload_frame(
    gpu: &Gpu,
    f: &Frame,
    near: f32,
    times: &[f32],
    with_mask: bool,
) -> Result<GpuFrame> {
    let px = (f.image.width * f.image.height) as usize;
    if f.image.data.len() != 3 * px {
        return Err(Error::Invalid(format!(
            "{}: image holds {} values, expected {}",
            f.image_path.display(),
            f.image.data.len(),
            3 * px
        )));
    }
    let rgba: Vec<[f32; 4]> = f
        .image
        .data
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2], 1.0])
        .collect();
    let mask = match with_mask {
        true => gpu_mask(gpu, f)?,
        false => None,
    };
    Ok(GpuFrame {
        id: f.id.clone(),
        camera: kernel_camera(&f.camera, near),
        time: f.time,
        target: gpu.buffer_from(&format!("target {}", f.id), &rgba)?,
        mask,
        gt_flow: None,
        next_flow: match (with_mask, &f.flow) {
            (true, Some(flow)) if flow.len() == 2 * px => times
                .iter()
                .copied()
                .filter(|&t| t > f.time)
                .reduce(f32::min)
                .map(|t| (t, flow.clone())),
            _ => None,
        },
        prev_time: times
            .iter()
            .copied()
            .filter(|&t| t < f.time)
            .reduce(f32::max),
    })
}

/// Checks that a dataset can be trained (training frames exist, one image size) and returns
/// that size.
pub fn check_dataset(data: &Dataset) -> Result<(u32, u32)> {
    let Some(first) = data.train.first() else {
        return Err(Error::Invalid(format!(
            "{}: the dataset has no training frames",
            data.root.display()
        )));
    };
    let (w, h) = (first.camera.width, first.camera.height);
    if let Some(f) = data
        .frames()
        .find(|f| (f.camera.width, f.camera.height) != (w, h))
    {
        return Err(Error::Invalid(format!(
            "{}: frame {} is {}×{}, the first training frame {w}×{h}: all frames must share one size",
            data.root.display(),
            f.id,
            f.camera.width,
            f.camera.height
        )));
    }
    Ok((w, h))
}

/// Uploads the training frames (no masks) and the test frames (with masks).
pub fn upload_splits(gpu: &Gpu, data: &Dataset) -> Result<(Vec<GpuFrame>, Vec<GpuFrame>)> {
    let near = near_of(data);
    let times: Vec<f32> = data.frames().map(|f| f.time).collect();
    let up = |fs: &[Frame], masks| {
        fs.iter()
            .map(|f| upload_frame(gpu, f, near, &times, masks))
            .collect::<Result<Vec<_>>>()
    };
    Ok((up(&data.train, false)?, up(&data.val, true)?))
}

/// The frame's motion mask on the GPU ([H·W] u32, moving = 1) with its host copy.
fn gpu_mask(gpu: &Gpu, f: &Frame) -> Result<Option<(Buffer, Vec<u8>)>> {
    let px = (f.image.width * f.image.height) as usize;
    match f.mask.as_ref() {
        Some(m) if m.len() == px => {
            let words: Vec<u32> = m.iter().map(|&v| (v != 0) as u32).collect();
            Ok(Some((
                gpu.buffer_from(&format!("mask {}", f.id), &words)?,
                m.clone(),
            )))
        }
        Some(m) if !m.is_empty() => Err(Error::Invalid(format!(
            "{}: motion mask holds {} values, expected {px}",
            f.image_path.display(),
            m.len()
        ))),
        _ => Ok(None),
    }
}

/// Attaches each training frame's motion mask, when the dataset has one (probes that score
/// training views; training itself never reads masks).
pub fn attach_masks(gpu: &Gpu, frames: &mut [GpuFrame], data: &Dataset) -> Result<()> {
    for (g, f) in frames.iter_mut().zip(&data.train) {
        g.mask = gpu_mask(gpu, f)?;
    }
    Ok(())
}

/// Attaches each training frame's ground-truth scene flow (the oracle ablation), or says which
/// frame has none.
pub fn attach_gt_flow(gpu: &Gpu, frames: &mut [GpuFrame], data: &Dataset) -> Result<()> {
    for (g, f) in frames.iter_mut().zip(&data.train) {
        let px = (f.camera.width * f.camera.height) as usize;
        let flow = f.flow.as_ref().filter(|v| v.len() == 2 * px).ok_or_else(|| {
            Error::Invalid(format!(
                "config field motion_flow: oracle needs ground-truth scene flow ({} has none; synthetic scenes from `dispflow-vk data gen` do)",
                f.image_path.display()
            ))
        })?;
        g.gt_flow = Some(gpu.buffer_from(&format!("gt flow {}", f.id), flow)?);
    }
    Ok(())
}

/// 3DGS's camera extent: 1.1 × the largest distance of a camera centre from their mean.
pub fn camera_extent(frames: &[Frame]) -> f32 {
    let centres: Vec<glam::Vec3> = frames.iter().map(|f| f.camera.centre()).collect();
    let mean = centres.iter().copied().sum::<glam::Vec3>() / centres.len().max(1) as f32;
    let r = centres
        .iter()
        .map(|c| c.distance(mean))
        .fold(0.0f32, f32::max);
    1.1 * r.max(1e-3)
}
