//! Which Gaussians the deformation moves: the model's dynamic/static split.
//!
//! DESIGN (issue 15). A *static* Gaussian is drawn with a constant deformation `fixed[i]`
//! (the midrange of D over the probed times) instead of D(x, t): its displacement between any
//! two times, and so its displacement flow, is exactly zero, and the MLP never sees it. Why
//! not D ≡ 0: the MLP's time-constant part is an offset the canonical Gaussian was trained
//! together with; on the built-in scene it is 2.7 px at the median Gaussian (measured), so
//! dropping it would move every static Gaussian. The split is part of the model (checkpoints
//! and exported runs carry it), decided by the motion probe (`train::passes::sparsity`) from
//! the deformation itself: a Gaussian is dynamic when D *varies* by more than a threshold in
//! pixels of some training view over the probed times.
//! `None` = every Gaussian dynamic (the dense path: the warm-up, the dense windows that let a
//! static Gaussian become dynamic again, `--sparsity off`). Counts are learnt on the host
//! when the split is made (a synchronisation point like densification), never inside a step.

use crate::error::{Error, Result};
use crate::kernels::sparse::NO_ROW;
use crate::vk::{BufSlice, Buffer, Gpu};

pub struct DynamicSet {
    capacity: u32,
    /// [capacity] u32, 1 = dynamic (rows 0..n valid while split).
    pub flags: Buffer,
    /// [capacity] u32: the dynamic indices in ascending order (rows 0..count).
    pub idx: Buffer,
    /// [capacity] u32: each Gaussian's row in `idx`, or [`NO_ROW`].
    pub row_of: Buffer,
    /// [1] u32 written by the GPU compaction (read after the classification's submit).
    pub count: Buffer,
    /// [capacity, 10] the constant deformation of each static Gaussian.
    pub fixed: Buffer,
    split: Option<u32>,
    /// Bumped whenever the split changes (the control nodes' KNN depends on it).
    generation: u64,
}

impl DynamicSet {
    /// Buffers for `capacity` Gaussians; starts dense.
    pub fn new(gpu: &Gpu, capacity: u32) -> Result<Self> {
        let rows = |name: &str| gpu.buffer(name, capacity.max(1) as u64 * 4);
        Ok(DynamicSet {
            capacity,
            flags: rows("dynamic flags")?,
            idx: rows("dynamic indices")?,
            row_of: rows("dynamic row of")?,
            count: gpu.buffer("dynamic count", 256)?,
            fixed: gpu.buffer("static deformation", capacity.max(1) as u64 * 40)?,
            split: None,
            generation: 0,
        })
    }

    /// Dynamic Gaussians when split; `None` when every Gaussian runs through the MLP.
    pub fn split(&self) -> Option<u32> {
        self.split
    }

    /// Every Gaussian dynamic again (the dense path).
    pub fn set_dense(&mut self) {
        if self.split.is_some() {
            self.generation += 1;
        }
        self.split = None;
    }

    /// Changes whenever the split does.
    pub fn generation(&self) -> u64 {
        self.generation
    }

    /// After the GPU compaction wrote `idx`, `row_of` and `count`: `count` dynamic Gaussians.
    pub fn set_split(&mut self, count: u32) {
        self.generation += 1;
        self.split = Some(count);
    }

    /// Fraction of the `n` live Gaussians that are dynamic (1 when dense).
    pub fn fraction(&self, n: u32) -> f64 {
        match self.split {
            Some(c) if n > 0 => c as f64 / n as f64,
            Some(_) => 0.0,
            None => 1.0,
        }
    }

    pub fn idx(&self) -> BufSlice<'_> {
        self.idx.all()
    }

    pub fn row_of(&self) -> BufSlice<'_> {
        self.row_of.all()
    }

    pub fn fixed(&self) -> BufSlice<'_> {
        self.fixed.all()
    }

    /// The split of the `n` live Gaussians (`None` when dense), for checkpoints and exports.
    pub fn download(&self, gpu: &Gpu, n: u32) -> Result<Option<SplitSnapshot>> {
        match self.split {
            None => Ok(None),
            Some(_) if n == 0 => Ok(Some(SplitSnapshot::default())),
            Some(_) => Ok(Some(SplitSnapshot {
                flags: gpu.read(self.flags.elems::<u32>(0, n as u64))?,
                fixed: gpu.read(self.fixed.elems::<f32>(0, 10 * n as u64))?,
            })),
        }
    }

    /// Splits as `s` says (a restored checkpoint or a loaded run): uploads the flags, the
    /// static deformations and the compaction. `None` makes the model dense.
    pub fn upload(&mut self, gpu: &Gpu, s: Option<&SplitSnapshot>) -> Result<()> {
        self.generation += 1;
        let Some(s) = s else {
            self.split = None;
            return Ok(());
        };
        s.check()?;
        let flags = &s.flags[..];
        if flags.len() > self.capacity as usize {
            return Err(Error::Capacity {
                what: "dynamic flags",
                capacity: self.capacity as u64,
                asked: flags.len() as u64,
            });
        }
        let (idx, row_of) = compact(flags);
        if !flags.is_empty() {
            gpu.upload(self.flags.elems::<u32>(0, flags.len() as u64), flags)?;
            gpu.upload(self.row_of.elems::<u32>(0, flags.len() as u64), &row_of)?;
            gpu.upload(self.fixed.elems::<f32>(0, s.fixed.len() as u64), &s.fixed)?;
        }
        if !idx.is_empty() {
            gpu.upload(self.idx.elems::<u32>(0, idx.len() as u64), &idx)?;
        }
        self.split = Some(idx.len() as u32);
        Ok(())
    }
}

/// The split on the host: flags (0/1) and the static Gaussians' constant deformation [N,10].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SplitSnapshot {
    pub flags: Vec<u32>,
    pub fixed: Vec<f32>,
}

impl SplitSnapshot {
    /// Refuses flags other than 0/1, a length mismatch or a non-finite static deformation.
    pub fn check(&self) -> Result<()> {
        let n = self.flags.len();
        if self.fixed.len() != 10 * n {
            return Err(Error::Invalid(format!(
                "dynamic split: {} static-deformation floats for {n} Gaussians; expected {}",
                self.fixed.len(),
                10 * n
            )));
        }
        if let Some(i) = self.flags.iter().position(|&f| f > 1) {
            return Err(Error::Invalid(format!(
                "dynamic flag of Gaussian {i} is {}; expected 0 (static) or 1 (dynamic)",
                self.flags[i]
            )));
        }
        if let Some(j) = self.fixed.iter().position(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!(
                "static deformation of Gaussian {} is {}; expected finite values",
                j / 10,
                self.fixed[j]
            )));
        }
        Ok(())
    }
}

/// Host compaction (loading only; training compacts on the GPU): dynamic indices ascending and
/// each Gaussian's row.
fn compact(flags: &[u32]) -> (Vec<u32>, Vec<u32>) {
    let mut idx = Vec::new();
    let mut row_of = vec![NO_ROW; flags.len()];
    for (i, &f) in flags.iter().enumerate() {
        if f != 0 {
            row_of[i] = idx.len() as u32;
            idx.push(i as u32);
        }
    }
    (idx, row_of)
}
