//! LPIPS weight files and per-frame scoring for `eval --lpips-weights FILE`.
//!
//! # Weight file format (`dispflow-lpips`, version 1)
//!
//! A [safetensors](https://github.com/huggingface/safetensors) file with the metadata
//! `format = "dispflow-lpips"`, `version = "1"`, `net = "alex"` and these tensors (f32, f16 or
//! bf16, read as f32), named and shaped as in the reference `lpips` package v0.1:
//!
//! | tensor | shape | source |
//! |---|---|---|
//! | `conv1.weight`, `conv1.bias` | [64, 3, 11, 11], [64] | torchvision AlexNet `features.0` |
//! | `conv2.weight`, `conv2.bias` | [192, 64, 5, 5], [192] | `features.3` |
//! | `conv3.weight`, `conv3.bias` | [384, 192, 3, 3], [384] | `features.6` |
//! | `conv4.weight`, `conv4.bias` | [256, 384, 3, 3], [256] | `features.8` |
//! | `conv5.weight`, `conv5.bias` | [256, 256, 3, 3], [256] | `features.10` |
//! | `lin1.weight` … `lin5.weight` | [1, C, 1, 1] (C = 64, 192, 384, 256, 256) | lpips `alex.pth` `lin0…lin4.model.1.weight` |
//!
//! `tools/lpips_weights.py` writes it from the two PyTorch files; the engine never downloads
//! anything. Other tensors in the file are ignored.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use safetensors::{Dtype, SafeTensors};

use crate::error::{Error, Result};
use crate::kernels::lpips::{Lpips, LpipsBuffers, LpipsWeights, ALEXNET};
use crate::testing::Noise;
use crate::vk::{BufSlice, Buffer, Gpu, Recorder};

pub const FORMAT: &str = "dispflow-lpips";
pub const FORMAT_VERSION: &str = "1";

/// Name and shape of every tensor the file must hold, in packing order.
pub fn tensor_specs() -> Vec<(String, Vec<usize>)> {
    let mut v = Vec::new();
    for (i, s) in ALEXNET.iter().enumerate() {
        let (o, c, k) = (s.cout as usize, s.cin as usize, s.ksize as usize);
        v.push((format!("conv{}.weight", i + 1), vec![o, c, k, k]));
        v.push((format!("conv{}.bias", i + 1), vec![o]));
    }
    for (i, s) in ALEXNET.iter().enumerate() {
        v.push((
            format!("lin{}.weight", i + 1),
            vec![1, s.cout as usize, 1, 1],
        ));
    }
    v
}

fn bad_tensor(path: &Path, tensor: &str, why: impl std::fmt::Display) -> Error {
    Error::Invalid(format!(
        "{}: LPIPS weights: tensor `{tensor}`: {why}",
        path.display()
    ))
}

/// Reads and checks a weight file: every tensor present, shaped as the table above, finite.
pub fn load_weights(path: &Path) -> Result<LpipsWeights> {
    let bytes = std::fs::read(path).map_err(|e| {
        Error::Invalid(format!(
            "{}: cannot read the LPIPS weights ({e}); convert them with tools/lpips_weights.py",
            path.display()
        ))
    })?;
    parse_weights(path, &bytes)
}

/// [`load_weights`] on bytes already read (`path` only names them in errors).
pub fn parse_weights(path: &Path, bytes: &[u8]) -> Result<LpipsWeights> {
    let hint = "expected a safetensors file written by tools/lpips_weights.py";
    let file_err =
        |why: String| Error::Invalid(format!("{}: LPIPS weights: {why}", path.display()));
    let (_, meta) = SafeTensors::read_metadata(bytes)
        .map_err(|e| file_err(format!("not a safetensors file ({e:?}); {hint}")))?;
    let info = meta.metadata().clone().unwrap_or_default();
    let field = |k: &str| info.get(k).map(String::as_str);
    if field("format") != Some(FORMAT) || field("version") != Some(FORMAT_VERSION) {
        return Err(file_err(format!(
            "metadata format/version is {:?}/{:?}, expected \"{FORMAT}\"/\"{FORMAT_VERSION}\"; \
             {hint}",
            field("format").unwrap_or("(none)"),
            field("version").unwrap_or("(none)")
        )));
    }
    if field("net") != Some("alex") {
        return Err(file_err(format!(
            "metadata net is {:?}; only the AlexNet backbone (\"alex\") is implemented",
            field("net").unwrap_or("(none)")
        )));
    }
    let st = SafeTensors::deserialize(bytes)
        .map_err(|e| file_err(format!("corrupt safetensors file ({e:?}); {hint}")))?;
    let mut got: Vec<Vec<f32>> = Vec::new();
    for (name, shape) in tensor_specs() {
        let t = st.tensor(&name).map_err(|_| {
            bad_tensor(
                path,
                &name,
                format!("missing; expected shape {shape:?}; {hint}"),
            )
        })?;
        if t.shape() != shape.as_slice() {
            return Err(bad_tensor(
                path,
                &name,
                format!("shape {:?}, expected {shape:?}", t.shape()),
            ));
        }
        let data = t.data();
        let vals: Vec<f32> = match t.dtype() {
            Dtype::F32 => data
                .chunks_exact(4)
                .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .collect(),
            Dtype::F16 => data
                .chunks_exact(2)
                .map(|b| half::f16::from_le_bytes([b[0], b[1]]).to_f32())
                .collect(),
            Dtype::BF16 => data
                .chunks_exact(2)
                .map(|b| half::bf16::from_le_bytes([b[0], b[1]]).to_f32())
                .collect(),
            d => {
                return Err(bad_tensor(
                    path,
                    &name,
                    format!("dtype {d:?}, expected F32, F16 or BF16"),
                ))
            }
        };
        if let Some(i) = vals.iter().position(|v| !v.is_finite()) {
            return Err(bad_tensor(
                path,
                &name,
                format!("element {i} is {}; expected finite weights", vals[i]),
            ));
        }
        got.push(vals);
    }
    let conv_w = std::array::from_fn(|i| got[2 * i].as_slice());
    let conv_b = std::array::from_fn(|i| got[2 * i + 1].as_slice());
    let lin = std::array::from_fn(|i| got[10 + i].as_slice());
    Ok(LpipsWeights::pack(conv_w, conv_b, lin))
}

/// A weight file's bytes (f32) holding `w`, e.g. for tests; `skip`/`patch` let a test drop or
/// alter one tensor (name, new shape, new values).
pub fn to_safetensors(
    w: &LpipsWeights,
    skip: Option<&str>,
    patch: Option<(&str, Vec<usize>, Vec<f32>)>,
) -> Vec<u8> {
    let mut tensors: Vec<(String, Vec<usize>, Vec<u8>)> = Vec::new();
    let packed: Vec<&[f32]> = (0..5)
        .flat_map(|i| [w.conv_weight(i), w.conv_bias(i)])
        .chain((0..5).map(|i| w.lin_weight(i)))
        .collect();
    for ((name, shape), vals) in tensor_specs().into_iter().zip(packed) {
        if skip == Some(name.as_str()) {
            continue;
        }
        let (shape, vals) = match &patch {
            Some((n, s, v)) if *n == name => (s.clone(), v.as_slice()),
            _ => (shape, vals),
        };
        tensors.push((name, shape, bytemuck::cast_slice(vals).to_vec()));
    }
    let views: Vec<(String, safetensors::tensor::TensorView<'_>)> = tensors
        .iter()
        .map(|(n, s, b)| {
            let v = safetensors::tensor::TensorView::new(Dtype::F32, s.clone(), b)
                .expect("shape matches the data");
            (n.clone(), v)
        })
        .collect();
    let meta: HashMap<String, String> = [
        ("format", FORMAT),
        ("version", FORMAT_VERSION),
        ("net", "alex"),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v.to_string()))
    .collect();
    safetensors::serialize(views, Some(meta)).expect("serialise LPIPS weights")
}

/// Random weights with AlexNet's shapes (Kaiming-uniform-like scale, positive 1×1 weights like
/// the trained ones): for benchmarks and tests that need no reference values.
pub fn random_weights(seed: u64) -> LpipsWeights {
    let mut noise = Noise::new(seed);
    let mut uni = |n: usize, bound: f32| -> Vec<f32> {
        (0..n)
            .map(|_| (noise.next_u32() as f32 / u32::MAX as f32 * 2.0 - 1.0) * bound)
            .collect()
    };
    let mut ws = Vec::new();
    let mut bs = Vec::new();
    let mut ls = Vec::new();
    for s in &ALEXNET {
        let fan_in = (s.cin * s.ksize * s.ksize) as usize;
        let bound = 1.0 / (fan_in as f32).sqrt();
        ws.push(uni(
            s.cout as usize * fan_in,
            bound * 3f32.sqrt() * 2f32.sqrt(),
        ));
        bs.push(uni(s.cout as usize, bound));
        ls.push(
            uni(s.cout as usize, 1.0)
                .iter()
                .map(|v| v.abs() * 0.1)
                .collect::<Vec<f32>>(),
        );
    }
    LpipsWeights::pack(
        std::array::from_fn(|i| ws[i].as_slice()),
        std::array::from_fn(|i| bs[i].as_slice()),
        std::array::from_fn(|i| ls[i].as_slice()),
    )
}

/// LPIPS on the GPU with one set of weights; scratch is allocated per image size on first use.
pub struct LpipsScorer {
    pub source: PathBuf,
    kernels: Lpips,
    weights: LpipsWeights,
    gpu_weights: Buffer,
    bufs: Option<LpipsBuffers>,
}

impl LpipsScorer {
    /// Loads and checks `path` (see the module docs) and uploads the weights.
    pub fn open(gpu: &Gpu, path: &Path) -> Result<Self> {
        let weights = load_weights(path)?;
        let mut s = Self::new(gpu, weights)?;
        s.source = path.to_path_buf();
        Ok(s)
    }

    pub fn new(gpu: &Gpu, weights: LpipsWeights) -> Result<Self> {
        Ok(LpipsScorer {
            source: PathBuf::new(),
            kernels: Lpips::new(gpu)?,
            gpu_weights: gpu.buffer_from("lpips weights", &weights.data)?,
            weights,
            bufs: None,
        })
    }

    /// Scratch for `width`×`height`, reused while the size stays.
    fn bufs(&mut self, gpu: &Gpu, width: u32, height: u32) -> Result<&LpipsBuffers> {
        let fits = self
            .bufs
            .as_ref()
            .is_some_and(|b| (b.plan.width, b.plan.height) == (width, height));
        if !fits {
            self.bufs = None; // free the old size first
            self.bufs = Some(self.kernels.buffers(gpu, width, height)?);
        }
        Ok(self.bufs.as_ref().expect("just made"))
    }

    /// Records the distance of two [H·W] RGBA images into `rec` (read with [`Self::value`]).
    pub fn record(
        &mut self,
        rec: &mut Recorder<'_>,
        size: (u32, u32),
        img0: BufSlice<'_>,
        img1: BufSlice<'_>,
    ) -> Result<()> {
        self.bufs(rec.gpu(), size.0, size.1)?;
        let b = self.bufs.as_ref().expect("made above");
        let w = self.gpu_weights.all();
        self.kernels.record(rec, b, w, &self.weights, img0, img1);
        Ok(())
    }

    /// Per-stage values of the last recorded pair (after its submit).
    pub fn stage_values(&self, gpu: &Gpu) -> Result<[f64; 5]> {
        match &self.bufs {
            Some(b) => b.stage_values(gpu),
            None => Err(Error::Invalid("LPIPS: nothing recorded yet".into())),
        }
    }

    /// LPIPS of the last recorded pair.
    pub fn value(&self, gpu: &Gpu) -> Result<f64> {
        Ok(self.stage_values(gpu)?.iter().sum())
    }

    /// LPIPS of two [H·W] RGBA images on the GPU (one submit).
    pub fn score(
        &mut self,
        gpu: &Gpu,
        size: (u32, u32),
        img0: BufSlice<'_>,
        img1: BufSlice<'_>,
    ) -> Result<f64> {
        let mut rec = Recorder::new(gpu)?;
        self.record(&mut rec, size, img0, img1)?;
        rec.finish()?;
        self.value(gpu)
    }

    pub fn weights(&self) -> &LpipsWeights {
        &self.weights
    }
}
