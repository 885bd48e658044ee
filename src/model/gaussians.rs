//! Canonical Gaussians: parameter sections in one buffer (so one Adam pass with per-section
//! learning rates covers them), their gradients and Adam moments in the same layout, and the
//! host-side copy used for initialisation, checkpoints and exports.

use super::rows::{Populations, Rows};
use crate::error::{Error, Result};
use crate::vk::{BufSlice, Buffer, Gpu};

/// The per-Gaussian parameter sections, in buffer order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Section {
    /// Canonical means [N,3].
    Means,
    /// Log scales [N,3] (scale = exp).
    LogScales,
    /// Quaternions [N,4] (w, x, y, z; normalised where used).
    Quats,
    /// Opacity logits [N] (opacity = sigmoid).
    Opacity,
    /// SH DC band [N,3].
    ShDc,
    /// SH bands 1.. [N, sh_coeffs − 1, 3].
    ShRest,
    /// Transients' time centre c [N] (rows of the canonical population: unused).
    TimeCentre,
    /// Transients' log temporal width τ [N] (σ = exp τ, floored where used).
    TimeLogWidth,
    /// Transients' velocity v [N,3] (world units per unit of time).
    Velocity,
}

impl Section {
    pub const ALL: [Section; 9] = [
        Section::Means,
        Section::LogScales,
        Section::Quats,
        Section::Opacity,
        Section::ShDc,
        Section::ShRest,
        Section::TimeCentre,
        Section::TimeLogWidth,
        Section::Velocity,
    ];

    /// The transients' own sections (learnt for rows of the transient population only).
    pub const TEMPORAL: [Section; 3] = [
        Section::TimeCentre,
        Section::TimeLogWidth,
        Section::Velocity,
    ];
}

/// Where each section lives in a buffer of `capacity` Gaussians. Sections start on 64-float
/// (256-byte) boundaries so each can be bound on its own on any device.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GaussianLayout {
    pub capacity: u32,
    /// SH coefficients per Gaussian: (max degree + 1)².
    pub sh_coeffs: u32,
}

impl GaussianLayout {
    pub fn new(capacity: u32, sh_degree: u32) -> Self {
        GaussianLayout {
            capacity,
            sh_coeffs: (sh_degree + 1).pow(2),
        }
    }

    /// Floats per Gaussian in `s`.
    pub fn row_len(&self, s: Section) -> u32 {
        match s {
            Section::Means | Section::LogScales | Section::ShDc | Section::Velocity => 3,
            Section::Quats => 4,
            Section::Opacity | Section::TimeCentre | Section::TimeLogWidth => 1,
            Section::ShRest => 3 * (self.sh_coeffs - 1),
        }
    }

    /// First float of `s`.
    pub fn offset(&self, s: Section) -> u64 {
        let mut off = 0u64;
        for t in Section::ALL {
            if t == s {
                return off;
            }
            off += (self.capacity as u64 * self.row_len(t) as u64).next_multiple_of(64);
        }
        unreachable!()
    }

    /// Floats in the whole buffer.
    pub fn total_floats(&self) -> u64 {
        let last = Section::Velocity;
        (self.offset(last) + self.capacity as u64 * self.row_len(last) as u64).max(1)
    }

    /// Floats of one Gaussian over all sections.
    pub fn floats_per_gaussian(&self) -> u32 {
        Section::ALL.iter().map(|&s| self.row_len(s)).sum()
    }

    /// The first `n` rows of section `s` of `buf` (at least one float, so it can be bound).
    pub fn slice<'a>(&self, buf: &'a Buffer, s: Section, n: u32) -> BufSlice<'a> {
        self.rows(buf, s, 0, n)
    }

    /// Rows `first..first + n` of section `s` of `buf` (at least one float).
    pub fn rows<'a>(&self, buf: &'a Buffer, s: Section, first: u32, n: u32) -> BufSlice<'a> {
        let row = self.row_len(s) as u64;
        let floats = (n as u64 * row).max(1);
        buf.slice((self.offset(s) + first as u64 * row) * 4, floats * 4)
    }
}

/// Host copy of the canonical Gaussians (f32, the GPU's layout per section).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct HostGaussians {
    pub sh_coeffs: u32,
    pub means: Vec<[f32; 3]>,
    pub log_scales: Vec<[f32; 3]>,
    pub quats: Vec<[f32; 4]>,
    pub opacity: Vec<f32>,
    pub sh_dc: Vec<[f32; 3]>,
    /// [N, sh_coeffs − 1, 3] flattened per Gaussian.
    pub sh_rest: Vec<f32>,
    /// How many of the rows (the last ones) are transient Gaussians (time-local; see
    /// `kernels::temporal`); set when building, ask [`HostGaussians::populations`].
    pub transients: usize,
    /// Per row (c, τ): time centre and log temporal width; empty = zeros (no transients).
    pub time: Vec<[f32; 2]>,
    /// Per row velocity; empty = zeros.
    pub velocity: Vec<[f32; 3]>,
}

/// SH DC coefficient giving colour `c` (colour = C0·dc + 0.5).
pub fn rgb_to_sh_dc(c: f32) -> f32 {
    (c - 0.5) / 0.282_094_8
}

pub fn inverse_sigmoid(p: f32) -> f32 {
    (p / (1.0 - p)).ln()
}

impl HostGaussians {
    pub fn len(&self) -> usize {
        self.means.len()
    }

    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// 3DGS initialisation from points: isotropic log-scale from the mean squared distance to
    /// the 3 nearest neighbours (grid-accelerated), identity rotation, opacity 0.1, DC colour
    /// from the point colour (grey when none), higher bands zero.
    pub fn from_points(
        points: &[[f32; 3]],
        colors: Option<&[[f32; 3]]>,
        sh_degree: u32,
    ) -> Result<Self> {
        if let Some(i) = points.iter().position(|p| p.iter().any(|v| !v.is_finite())) {
            return Err(Error::Invalid(format!(
                "initial point {i} is not finite: {:?}",
                points[i]
            )));
        }
        let sh_coeffs = (sh_degree + 1).pow(2);
        let d2 = knn3_mean_sq_dist(points);
        let n = points.len();
        Ok(HostGaussians {
            sh_coeffs,
            means: points.to_vec(),
            log_scales: d2.iter().map(|&d| [0.5 * d.max(1e-7).ln(); 3]).collect(),
            quats: vec![[1.0, 0.0, 0.0, 0.0]; n],
            opacity: vec![inverse_sigmoid(0.1); n],
            sh_dc: (0..n)
                .map(|i| colors.map_or([0.0; 3], |c| c[i].map(rgb_to_sh_dc)))
                .collect(),
            sh_rest: vec![0.0; n * 3 * (sh_coeffs as usize - 1)],
            ..Default::default()
        })
    }

    /// The rows by population.
    pub fn populations(&self) -> Populations {
        Populations::split(self.len() as u32, self.transients.min(self.len()) as u32)
    }

    /// Rows of the canonical population.
    pub fn canonical_rows(&self) -> Rows {
        self.populations().canonical
    }

    /// Rows of the transient population (after the canonical ones).
    pub fn transient_rows(&self) -> Rows {
        self.populations().transient
    }

    /// The temporal sections, zeros where empty.
    pub fn time_or_zeros(&self) -> Vec<[f32; 2]> {
        if self.time.len() == self.len() {
            self.time.clone()
        } else {
            vec![[0.0; 2]; self.len()]
        }
    }

    pub fn velocity_or_zeros(&self) -> Vec<[f32; 3]> {
        if self.velocity.len() == self.len() {
            self.velocity.clone()
        } else {
            vec![[0.0; 3]; self.len()]
        }
    }

    /// Rows `range` as their own Gaussians (transient rows stay transient).
    pub fn rows(&self, range: std::ops::Range<usize>) -> HostGaussians {
        let r = 3 * (self.sh_coeffs as usize).saturating_sub(1);
        let first_t = self.transient_rows().start as usize;
        let (time, vel) = (self.time_or_zeros(), self.velocity_or_zeros());
        let transient = range.start.max(first_t)..range.end.max(first_t);
        let temporal = !transient.is_empty();
        HostGaussians {
            sh_coeffs: self.sh_coeffs,
            means: self.means[range.clone()].to_vec(),
            log_scales: self.log_scales[range.clone()].to_vec(),
            quats: self.quats[range.clone()].to_vec(),
            opacity: self.opacity[range.clone()].to_vec(),
            sh_dc: self.sh_dc[range.clone()].to_vec(),
            sh_rest: self.sh_rest[range.start * r..range.end * r].to_vec(),
            transients: transient.len(),
            time: if temporal {
                time[range.clone()].to_vec()
            } else {
                Vec::new()
            },
            velocity: if temporal {
                vel[range].to_vec()
            } else {
                Vec::new()
            },
        }
    }

    /// The canonical rows and the transient rows.
    pub fn split_transients(&self) -> (HostGaussians, HostGaussians) {
        let p = self.populations();
        (
            self.rows(p.canonical.range()),
            self.rows(p.transient.range()),
        )
    }

    /// `other`'s rows appended after these (transients stay last: `other`'s canonical rows
    /// go before this one's transients only when this one has none).
    pub fn append(&mut self, other: &HostGaussians) {
        assert_eq!(self.sh_coeffs, other.sh_coeffs, "append: SH layouts differ");
        assert!(
            !self.populations().temporal() || other.canonical_rows().is_empty(),
            "append: canonical rows after transients"
        );
        let (time, vel) = (self.time_or_zeros(), self.velocity_or_zeros());
        self.time = time;
        self.velocity = vel;
        self.time.extend(other.time_or_zeros());
        self.velocity.extend(other.velocity_or_zeros());
        self.means.extend_from_slice(&other.means);
        self.log_scales.extend_from_slice(&other.log_scales);
        self.quats.extend_from_slice(&other.quats);
        self.opacity.extend_from_slice(&other.opacity);
        self.sh_dc.extend_from_slice(&other.sh_dc);
        self.sh_rest.extend_from_slice(&other.sh_rest);
        self.transients += other.transients;
    }

    /// Writes the Gaussians into rows 0..N of the sections of `buf` (laid out by `layout`).
    pub fn upload(&self, gpu: &Gpu, layout: &GaussianLayout, buf: &Buffer) -> Result<()> {
        self.upload_at(gpu, layout, buf, 0)
    }

    /// Writes the Gaussians into rows `first..first + N` of the sections of `buf`.
    pub fn upload_at(
        &self,
        gpu: &Gpu,
        layout: &GaussianLayout,
        buf: &Buffer,
        first: u32,
    ) -> Result<()> {
        if first as usize + self.len() > layout.capacity as usize
            || self.sh_coeffs != layout.sh_coeffs
        {
            return Err(Error::Capacity {
                what: "Gaussian buffer (capacity, SH coefficients)",
                capacity: layout.capacity as u64,
                asked: first as u64 + self.len() as u64,
            });
        }
        if self.is_empty() {
            return Ok(());
        }
        let n = self.len() as u32;
        let at = |s| layout.rows(buf, s, first, n);
        gpu.upload(at(Section::Means), &self.means)?;
        gpu.upload(at(Section::LogScales), &self.log_scales)?;
        gpu.upload(at(Section::Quats), &self.quats)?;
        gpu.upload(at(Section::Opacity), &self.opacity)?;
        gpu.upload(at(Section::ShDc), &self.sh_dc)?;
        if layout.sh_coeffs > 1 {
            gpu.upload(at(Section::ShRest), &self.sh_rest)?;
        }
        let time = self.time_or_zeros();
        let c: Vec<f32> = time.iter().map(|t| t[0]).collect();
        let tau: Vec<f32> = time.iter().map(|t| t[1]).collect();
        gpu.upload(at(Section::TimeCentre), &c)?;
        gpu.upload(at(Section::TimeLogWidth), &tau)?;
        gpu.upload(at(Section::Velocity), &self.velocity_or_zeros())?;
        Ok(())
    }

    /// Reads the live rows `rows` of `buf` (the transients' temporal sections are read only
    /// when there are any).
    pub fn download(
        gpu: &Gpu,
        layout: &GaussianLayout,
        buf: &Buffer,
        rows: Populations,
    ) -> Result<Self> {
        let n = rows.len();
        let temporal = rows.temporal();
        if n == 0 {
            return Ok(HostGaussians {
                sh_coeffs: layout.sh_coeffs,
                ..Default::default()
            });
        }
        Ok(HostGaussians {
            sh_coeffs: layout.sh_coeffs,
            means: gpu.read(layout.slice(buf, Section::Means, n))?,
            log_scales: gpu.read(layout.slice(buf, Section::LogScales, n))?,
            quats: gpu.read(layout.slice(buf, Section::Quats, n))?,
            opacity: gpu.read(layout.slice(buf, Section::Opacity, n))?,
            sh_dc: gpu.read(layout.slice(buf, Section::ShDc, n))?,
            sh_rest: if layout.sh_coeffs > 1 {
                gpu.read(layout.slice(buf, Section::ShRest, n))?
            } else {
                Vec::new()
            },
            transients: rows.transient.len() as usize,
            time: if temporal {
                let c: Vec<f32> = gpu.read(layout.slice(buf, Section::TimeCentre, n))?;
                let tau: Vec<f32> = gpu.read(layout.slice(buf, Section::TimeLogWidth, n))?;
                c.into_iter().zip(tau).map(|(a, b)| [a, b]).collect()
            } else {
                Vec::new()
            },
            velocity: if temporal {
                gpu.read(layout.slice(buf, Section::Velocity, n))?
            } else {
                Vec::new()
            },
        })
    }
}

/// Mean squared distance of each point to its 3 nearest neighbours (as 3DGS's `distCUDA2`),
/// with a uniform grid so 10^5 points take milliseconds, not a quadratic scan.
pub fn knn3_mean_sq_dist(p: &[[f32; 3]]) -> Vec<f32> {
    let n = p.len();
    if n < 2 {
        return vec![1e-4; n];
    }
    let mut lo = [f32::MAX; 3];
    let mut hi = [f32::MIN; 3];
    for q in p {
        for a in 0..3 {
            lo[a] = lo[a].min(q[a]);
            hi[a] = hi[a].max(q[a]);
        }
    }
    // About 2 points per cell.
    let extent: Vec<f32> = (0..3).map(|a| (hi[a] - lo[a]).max(1e-6)).collect();
    let vol: f32 = extent.iter().product();
    let cell = (vol / (n as f32 / 2.0)).cbrt().max(1e-6);
    let dims: Vec<i64> = extent
        .iter()
        .map(|e| ((e / cell).ceil() as i64).clamp(1, 1024))
        .collect();
    let key = |q: &[f32; 3]| -> [i64; 3] {
        [0, 1, 2].map(|a| (((q[a] - lo[a]) / cell) as i64).clamp(0, dims[a] - 1))
    };
    let mut grid: std::collections::HashMap<[i64; 3], Vec<usize>> =
        std::collections::HashMap::new();
    for (i, q) in p.iter().enumerate() {
        grid.entry(key(q)).or_default().push(i);
    }
    use rayon::prelude::*;
    p.par_iter()
        .enumerate()
        .map(|(i, q)| {
            let k = key(q);
            let mut best = [f32::MAX; 3];
            let mut r = 1i64;
            loop {
                for dx in -r..=r {
                    for dy in -r..=r {
                        for dz in -r..=r {
                            if let Some(v) = grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                                for &j in v {
                                    if j == i {
                                        continue;
                                    }
                                    let d: f32 = (0..3).map(|a| (p[j][a] - q[a]).powi(2)).sum();
                                    if d < best[2] {
                                        best[2] = d;
                                        best.sort_by(|a, b| a.total_cmp(b));
                                    }
                                }
                            }
                        }
                    }
                }
                // Exact once the searched cube's inner radius covers the third distance.
                let covered = (r as f32 * cell).powi(2);
                if (best[2] <= covered) || r > dims.iter().copied().max().unwrap() {
                    break;
                }
                r += 1;
            }
            let found: Vec<f32> = best.iter().copied().filter(|d| *d < f32::MAX).collect();
            found.iter().sum::<f32>() / found.len().max(1) as f32
        })
        .collect()
}
