//! The control-node deformation field's state (docs/nodes.md): node positions and log-radii
//! (trained by Adam), their gradients and moments, and the KNN scratch that ties every
//! Gaussian to its nearest nodes. Nodes are placed on the host by farthest-point sampling of
//! the canonical means when the deformation starts (a synchronisation point like
//! densification, never inside a step).

use std::cell::Cell;

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::kernels::nodes::{check_shape, NO_NODE};
use crate::vk::{BufSlice, Buffer, Gpu};

/// Which deformation field drives the Gaussians.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FieldKind {
    /// Deformable-3DGS: the MLP at every (dynamic) Gaussian.
    #[default]
    Mlp,
    /// SC-GS: the MLP at a few hundred control nodes, blended into every Gaussian.
    Nodes,
}

/// `[deform_field]` of a training configuration.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FieldConfig {
    pub kind: FieldKind,
    /// Control nodes (at most the Gaussian count when placed).
    pub nodes: u32,
    /// Nearest nodes blended per Gaussian (1..=8).
    pub knn: u32,
    /// Recompute the KNN every this many iterations (and after every densification and change
    /// of the dynamic split); 0 = only then.
    pub knn_every: u32,
    /// Adam rate of the node log-radii (positions use the Gaussian means' rate).
    pub radius_lr: f64,
}

impl Default for FieldConfig {
    fn default() -> Self {
        FieldConfig {
            kind: FieldKind::Mlp,
            nodes: 512,
            knn: 4,
            knn_every: 100,
            radius_lr: 1e-3,
        }
    }
}

impl FieldConfig {
    pub fn validate(&self) -> Result<()> {
        check_shape(self.nodes, self.knn)?;
        if !(self.radius_lr.is_finite() && self.radius_lr >= 0.0) {
            return Err(Error::Invalid(format!(
                "deform_field.radius_lr = {}: expected a finite value >= 0",
                self.radius_lr
            )));
        }
        Ok(())
    }
}

pub struct NodeState {
    pub cfg: FieldConfig,
    /// Placed nodes (0 until the deformation starts).
    pub m: u32,
    /// [4·cfg.nodes] positions [0, 3M), log-radii [3M, 4M) — packed for the placed M.
    pub params: Buffer,
    pub grads: Buffer,
    pub adam_m: Buffer,
    pub adam_v: Buffer,
    /// [capacity, K] u32: each Gaussian's nearest nodes (model state, so a resumed run blends
    /// with exactly the KNN the uninterrupted one had).
    pub knn: Buffer,
    /// (Gaussian count, dynamic-split generation) the KNN was computed for; `None`: stale
    /// (placement, densification, every `knn_every` steps). Cells: the passes that blend
    /// refresh it through `&Model`.
    pub knn_for: Cell<Option<(u32, u64)>>,
    /// Bumped at every KNN update (the training pass re-sorts its gather lists on a change).
    pub knn_epoch: Cell<u64>,
}

impl NodeState {
    pub fn new(gpu: &Gpu, cfg: FieldConfig, capacity: u32) -> Result<Self> {
        cfg.validate()?;
        let bytes = 4 * cfg.nodes as u64 * 4;
        let mk = |name: &str| gpu.buffer(name, bytes);
        Ok(NodeState {
            params: mk("node params")?,
            grads: mk("node grads")?,
            adam_m: mk("node adam m")?,
            adam_v: mk("node adam v")?,
            knn: gpu.buffer("node knn", capacity.max(1) as u64 * cfg.knn as u64 * 4)?,
            cfg,
            m: 0,
            knn_for: Cell::new(None),
            knn_epoch: Cell::new(0),
        })
    }

    pub fn placed(&self) -> bool {
        self.m > 0
    }

    /// Positions [M,3] (the MLP's input rows) and the whole parameter block [4M].
    pub fn positions(&self) -> BufSlice<'_> {
        self.params.elems::<f32>(0, 3 * self.m as u64)
    }

    pub fn param_block(&self) -> BufSlice<'_> {
        self.params.elems::<f32>(0, 4 * self.m as u64)
    }

    pub fn grad_block(&self) -> BufSlice<'_> {
        self.grads.elems::<f32>(0, 4 * self.m as u64)
    }

    /// The KNN must be recomputed before the next blend.
    pub fn invalidate_knn(&self) {
        self.knn_for.set(None);
    }

    /// Records that the KNN now holds what (`n`, `generation`) needs.
    pub fn knn_updated(&self, n: u32, generation: u64) {
        self.knn_for.set(Some((n, generation)));
        self.knn_epoch.set(self.knn_epoch.get() + 1);
    }

    /// The live Gaussians' KNN rows [n·K].
    pub fn knn_rows(&self, n: u32) -> BufSlice<'_> {
        self.knn.elems::<u32>(0, n as u64 * self.cfg.knn as u64)
    }

    /// Places the nodes by farthest-point sampling of `means` and uploads them (moments zeroed).
    /// A non-finite mean is passed over (the Gaussian draws nothing; the collapse guard's
    /// parameter check retires it at its next probe): as the farthest point it would become a
    /// node, and every node a NaN.
    pub fn place(&mut self, gpu: &Gpu, means: &[[f32; 3]]) -> Result<()> {
        let finite: Vec<[f32; 3]> = means
            .iter()
            .filter(|m| m.iter().all(|v| v.is_finite()))
            .copied()
            .collect();
        let means = &finite[..];
        if means.is_empty() {
            return Err(Error::Invalid(
                "control nodes: no Gaussians with finite means to place them on".into(),
            ));
        }
        let (picks, cover) = farthest_points(means, self.cfg.nodes as usize);
        let m = picks.len();
        let rho = cover.max(1e-6).ln();
        let mut p = vec![0f32; 4 * m];
        for (j, &i) in picks.iter().enumerate() {
            p[3 * j..3 * j + 3].copy_from_slice(&means[i]);
            p[3 * m + j] = rho;
        }
        self.upload(gpu, &p, None)
    }

    /// Node parameters (and moments) on the host: `[4M]` each, and the KNN of the `n`
    /// canonical Gaussians when it is current for them under split generation `generation`
    /// (a stale one is left out: the next blend recomputes it, as a resumed run then must).
    pub fn download(&self, gpu: &Gpu, n: u32, generation: u64) -> Result<NodeSnapshot> {
        let rd = |b: &Buffer| gpu.read::<f32>(b.elems::<f32>(0, 4 * self.m as u64));
        let knn = match self.knn_for.get() {
            Some(f) if f == (n, generation) && n > 0 => gpu.read::<u32>(self.knn_rows(n))?,
            _ => Vec::new(),
        };
        Ok(NodeSnapshot {
            params: rd(&self.params)?,
            m: rd(&self.adam_m)?,
            v: rd(&self.adam_v)?,
            knn,
        })
    }

    /// Restores a checkpoint's nodes; its KNN (when present) is taken as current for `n`
    /// Gaussians under split generation `generation`.
    pub fn restore(&mut self, gpu: &Gpu, s: &NodeSnapshot, n: u32, generation: u64) -> Result<()> {
        self.upload(gpu, &s.params, Some((&s.m, &s.v)))?;
        if s.knn.is_empty() {
            return Ok(());
        }
        let k = self.cfg.knn as usize;
        if s.knn.len() != n as usize * k {
            return Err(Error::Invalid(format!(
                "blob node_knn: {} entries; {n} canonical Gaussians with deform_field.knn = {k} need {}",
                s.knn.len(),
                n as usize * k
            )));
        }
        if let Some(i) = s.knn.iter().position(|&j| j != NO_NODE && j >= self.m) {
            return Err(Error::Invalid(format!(
                "blob node_knn: entry {i} names node {}; the checkpoint has {} nodes",
                s.knn[i], self.m
            )));
        }
        gpu.upload(self.knn_rows(n), &s.knn)?;
        self.knn_updated(n, generation);
        Ok(())
    }

    /// Uploads `params` [4M] (and moments, or zeros), making M = len/4.
    pub fn upload(
        &mut self,
        gpu: &Gpu,
        params: &[f32],
        moments: Option<(&[f32], &[f32])>,
    ) -> Result<()> {
        let m = params.len() / 4;
        if params.len() % 4 != 0 || m == 0 || m > self.cfg.nodes as usize {
            return Err(Error::Invalid(format!(
                "control nodes: {} floats; expected 4 per node for 1..={} nodes (deform_field.nodes)",
                params.len(),
                self.cfg.nodes
            )));
        }
        if let Some(i) = params.iter().position(|v| !v.is_finite()) {
            return Err(Error::Invalid(format!(
                "control node {} has a non-finite parameter",
                if i < 3 * m { i / 3 } else { i - 3 * m }
            )));
        }
        let zeros = vec![0f32; params.len()];
        let (mm, vv) = moments.unwrap_or((&zeros, &zeros));
        gpu.upload(self.params.elems::<f32>(0, params.len() as u64), params)?;
        gpu.upload(self.adam_m.elems::<f32>(0, params.len() as u64), mm)?;
        gpu.upload(self.adam_v.elems::<f32>(0, params.len() as u64), vv)?;
        self.m = m as u32;
        self.invalidate_knn();
        Ok(())
    }

    /// Back to unplaced (a restored checkpoint from before the deformation started).
    pub fn clear(&mut self) {
        self.m = 0;
        self.invalidate_knn();
    }
}

/// Node parameters and Adam moments, `[4M]` each (positions then log-radii), and the KNN
/// `[N·K]` (empty when it was stale).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NodeSnapshot {
    pub params: Vec<f32>,
    pub m: Vec<f32>,
    pub v: Vec<f32>,
    pub knn: Vec<u32>,
}

/// Farthest-point sampling: the first pick is the point nearest the centroid, each next one
/// the point farthest from every pick (ties → lower index), until m picks or every point sits
/// on one. Returns the picks and
/// the covering radius (the largest distance of a point to its nearest pick).
pub fn farthest_points(pts: &[[f32; 3]], m: usize) -> (Vec<usize>, f32) {
    let n = pts.len();
    let d2 =
        |a: &[f32; 3], b: &[f64; 3]| -> f64 { (0..3).map(|k| (a[k] as f64 - b[k]).powi(2)).sum() };
    let mut c = [0f64; 3];
    for p in pts {
        for k in 0..3 {
            c[k] += p[k] as f64 / n as f64;
        }
    }
    let argmax = |v: &[f64]| {
        let mut best = 0;
        for (i, &x) in v.iter().enumerate() {
            if x > v[best] {
                best = i;
            }
        }
        best
    };
    let to_centre: Vec<f64> = pts.iter().map(|p| -d2(p, &c)).collect();
    let mut picks = vec![argmax(&to_centre)];
    let as64 = |p: &[f32; 3]| p.map(|x| x as f64);
    let first = as64(&pts[picks[0]]);
    let mut near: Vec<f64> = pts.iter().map(|p| d2(p, &first)).collect();
    while picks.len() < m.min(n) {
        let i = argmax(&near);
        if near[i] == 0.0 {
            break; // every point sits on a pick: more would be coincident copies
        }
        let q = as64(&pts[i]);
        picks.push(i);
        for (d, p) in near.iter_mut().zip(pts) {
            *d = d.min(d2(p, &q));
        }
    }
    let cover = near.iter().copied().fold(0.0, f64::max).sqrt() as f32;
    (picks, cover)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn farthest_points_spreads_and_covers() {
        // A line of 11 points: centre first, then the two ends, then the quarter points.
        let pts: Vec<[f32; 3]> = (0..11).map(|i| [i as f32, 0.0, 0.0]).collect();
        let (p, cover) = farthest_points(&pts, 3);
        assert_eq!(p, vec![5, 0, 10]);
        assert!((cover - 2.0).abs() < 1e-6, "{cover}"); // 2, 3, 7, 8 are 2 from a pick
        let (all, c) = farthest_points(&pts, 50);
        assert_eq!(all.len(), 11);
        assert_eq!(c, 0.0);
        // Coincident points: one pick covers them all.
        let same = vec![[1.0f32, 2.0, 3.0]; 5];
        let (p, c) = farthest_points(&same, 3);
        assert_eq!((p.len(), c), (1, 0.0));
    }
}
