//! The trainable state on the GPU: canonical Gaussians (parameters, gradients, Adam moments and
//! the buffers densification writes the next generation into) and the deformation MLP
//! (weights, gradients, Adam moments). Passes read and write it through explicit slices; the
//! trainer never reaches into a pass for model data.
//! (Over 600 lines: the Gaussians, the MLP, the nodes and the split are one model whose
//! snapshot, checks and restore must agree field by field.)

use super::deform::{MlpConfig, MlpLayout, TimeEncoding};
use super::dynamic::{DynamicSet, SplitSnapshot};
use super::gaussians::{GaussianLayout, HostGaussians, Section};
use super::nodes::{NodeSnapshot, NodeState};
use super::rows::{Populations, Rows};
use crate::error::{Error, Result};
use crate::kernels::deform::Canonical;
use crate::kernels::raster::SplatInputs;
use crate::vk::{BufSlice, Buffer, Gpu, Recorder};

/// Canonical Gaussians for a fixed capacity (the densification budget), rows `0..n` live.
pub struct GaussianState {
    pub layout: GaussianLayout,
    /// Live Gaussians.
    pub n: u32,
    /// How many of the live rows (the last ones) are transient; ask
    /// [`GaussianState::populations`].
    transients: u32,
    pub params: Buffer,
    pub grads: Buffer,
    pub m: Buffer,
    pub v: Buffer,
    /// Densification writes (params, m, v) of the next generation here; see
    /// [`GaussianState::swap_generation`].
    pub next: [Buffer; 3],
}

impl GaussianState {
    /// Allocates every buffer for `capacity` Gaussians and uploads `init` (moments zeroed).
    pub fn new(gpu: &Gpu, capacity: u32, sh_degree: u32, init: &HostGaussians) -> Result<Self> {
        let layout = GaussianLayout::new(capacity, sh_degree);
        if init.len() > capacity as usize {
            return Err(Error::Capacity {
                what: "Gaussian budget (initial points)",
                capacity: capacity as u64,
                asked: init.len() as u64,
            });
        }
        let bytes = layout.total_floats() * 4;
        let mk = |name: &str| gpu.buffer(name, bytes);
        let s = GaussianState {
            layout,
            n: init.len() as u32,
            transients: init.transient_rows().len(),
            params: mk("gaussian params")?,
            grads: mk("gaussian grads")?,
            m: mk("gaussian adam m")?,
            v: mk("gaussian adam v")?,
            next: [
                mk("gaussian params next")?,
                mk("gaussian adam m next")?,
                mk("gaussian adam v next")?,
            ],
        };
        init.upload(gpu, &layout, &s.params)?;
        let mut rec = Recorder::new(gpu)?;
        rec.fill(s.m.all(), 0);
        rec.fill(s.v.all(), 0);
        rec.finish()?;
        Ok(s)
    }

    /// After densification wrote the next generation (`next`) with `n` Gaussians, the last
    /// `transients` of them transients: make it the current one (the old buffers become the
    /// next scratch).
    pub fn swap_generation(&mut self, n: u32, transients: u32) {
        let [p, m, v] = &mut self.next;
        std::mem::swap(&mut self.params, p);
        std::mem::swap(&mut self.m, m);
        std::mem::swap(&mut self.v, v);
        self.n = n;
        self.transients = transients.min(n);
    }

    /// The live rows by population.
    pub fn populations(&self) -> Populations {
        Populations::split(self.n, self.transients)
    }

    /// Rows of the canonical population (what the deformation runs over).
    pub fn canonical_rows(&self) -> Rows {
        self.populations().canonical
    }

    /// Rows of the transient population.
    pub fn transient_rows(&self) -> Rows {
        self.populations().transient
    }

    /// Appends `g` (all transient: `g.transient_rows()` covers it) after the live rows, with zero
    /// Adam moments. The caller keeps the densification statistics of the new rows at zero.
    pub fn append_transients(&mut self, gpu: &Gpu, g: &HostGaussians) -> Result<()> {
        if !g.populations().canonical.is_empty() {
            return Err(Error::Invalid(
                "append_transients: only transient rows can be appended".into(),
            ));
        }
        if g.is_empty() {
            return Ok(());
        }
        g.upload_at(gpu, &self.layout, &self.params, self.n)?;
        let k = g.len() as u32;
        let mut rec = Recorder::new(gpu)?;
        for s in Section::ALL {
            for b in [&self.m, &self.v] {
                rec.fill(self.layout.rows(b, s, self.n, k), 0);
            }
        }
        rec.finish()?;
        self.n += k;
        self.transients += k;
        Ok(())
    }

    /// Opacity logits of live rows `span`.
    pub fn read_opacity(&self, gpu: &Gpu, span: std::ops::Range<u32>) -> Result<Vec<f32>> {
        let k = span.end.saturating_sub(span.start);
        if span.end > self.n || k == 0 {
            return Ok(Vec::new());
        }
        gpu.read(
            self.layout
                .rows(&self.params, Section::Opacity, span.start, k),
        )
    }

    /// Gives live rows `rows` (each inside `span`) the opacity logit `logit` and zero opacity
    /// moments, so the optimiser does not carry them back: a row dropped this way draws
    /// nothing and the next densification prunes it.
    pub fn set_opacity(
        &self,
        gpu: &Gpu,
        span: std::ops::Range<u32>,
        rows: &[u32],
        logit: f32,
    ) -> Result<()> {
        if rows.is_empty() {
            return Ok(());
        }
        if span.end > self.n || rows.iter().any(|r| !span.contains(r)) {
            return Err(Error::Invalid(format!(
                "set_opacity: rows outside {span:?} of {} live",
                self.n
            )));
        }
        let k = span.end - span.start;
        for (buf, value) in [(&self.params, logit), (&self.m, 0.0), (&self.v, 0.0)] {
            let at = self.layout.rows(buf, Section::Opacity, span.start, k);
            let mut x: Vec<f32> = gpu.read(at)?;
            for &r in rows {
                x[(r - span.start) as usize] = value;
            }
            gpu.upload(at, &x)?;
        }
        Ok(())
    }

    /// Rows `0..n` of section `s` of the parameters.
    pub fn param(&self, s: Section) -> BufSlice<'_> {
        self.layout.slice(&self.params, s, self.n)
    }

    /// Rows `0..n` of section `s` of the gradients.
    pub fn grad(&self, s: Section) -> BufSlice<'_> {
        self.layout.slice(&self.grads, s, self.n)
    }

    /// Canonical means, log-scales and quaternions of the parameters.
    pub fn canonical(&self) -> Canonical<'_> {
        Canonical {
            means: self.param(Section::Means),
            log_scales: self.param(Section::LogScales),
            quats: self.param(Section::Quats),
        }
    }

    /// The same sections of the gradients.
    pub fn canonical_grads(&self) -> Canonical<'_> {
        Canonical {
            means: self.grad(Section::Means),
            log_scales: self.grad(Section::LogScales),
            quats: self.grad(Section::Quats),
        }
    }

    /// What the rasteriser reads: the drawn geometry `drawn` (means, scales, quats) with the
    /// canonical opacity and SH sections.
    pub fn splats<'a>(&'a self, drawn: [BufSlice<'a>; 3], sh_degree: u32) -> SplatInputs<'a> {
        SplatInputs {
            n: self.n,
            means: drawn[0],
            scales: drawn[1],
            quats: drawn[2],
            opacity_logits: self.param(Section::Opacity),
            sh_dc: self.param(Section::ShDc),
            sh_rest: self.param(Section::ShRest),
            sh_coeffs: self.layout.sh_coeffs,
            sh_degree,
            features: None,
            opacity_scale: None,
        }
    }

    pub fn download(&self, gpu: &Gpu) -> Result<HostGaussians> {
        HostGaussians::download(gpu, &self.layout, &self.params, self.populations())
    }

    /// Replaces the live Gaussians by `g` (parameters only; moments untouched).
    pub fn upload(&mut self, gpu: &Gpu, g: &HostGaussians, what: &'static str) -> Result<()> {
        if g.sh_coeffs != self.layout.sh_coeffs {
            return Err(Error::Invalid(format!(
                "{what}: the Gaussians carry {} SH coefficients; the configuration expects {}",
                g.sh_coeffs, self.layout.sh_coeffs
            )));
        }
        if g.len() > self.layout.capacity as usize {
            return Err(Error::Capacity {
                what,
                capacity: self.layout.capacity as u64,
                asked: g.len() as u64,
            });
        }
        g.upload(gpu, &self.layout, &self.params)?;
        self.n = g.len() as u32;
        self.transients = g.transient_rows().len();
        Ok(())
    }
}

/// The deformation MLP's trainable state.
pub struct DeformState {
    pub cfg: MlpConfig,
    pub layout: MlpLayout,
    pub params: Buffer,
    pub grads: Buffer,
    pub m: Buffer,
    pub v: Buffer,
}

impl DeformState {
    /// Initialised weights (`seed`); with `zero_head` the head starts at exactly 0, so D = 0
    /// when the warm-up ends and training continues the static model instead of jolting every
    /// Gaussian by a random head (PyTorch-init displacements ~0.1–0.5 scene units, and ds ≫
    /// exp(s) inflates every Gaussian). The head still gets gradients at once.
    pub fn new(gpu: &Gpu, cfg: MlpConfig, seed: u64, zero_head: bool) -> Result<Self> {
        Self::with_gain(gpu, cfg, seed, zero_head, 1.0)
    }

    /// [`Self::new`] with the weights' init bounds scaled by `gain` (see
    /// [`MlpLayout::init_params_gain`]).
    pub fn with_gain(
        gpu: &Gpu,
        cfg: MlpConfig,
        seed: u64,
        zero_head: bool,
        gain: f32,
    ) -> Result<Self> {
        let layout = MlpLayout::new(&cfg)?;
        let mut init = layout.init_params_gain(seed, gain);
        if zero_head {
            let h = layout.head();
            init[h.w_off..h.w_off + h.fan_in * h.fan_out].fill(0.0);
            init[h.b_off..h.b_off + h.fan_out].fill(0.0);
        }
        let zeros = vec![0f32; init.len()];
        Ok(DeformState {
            cfg,
            params: gpu.buffer_from("mlp params", &init)?,
            grads: gpu.buffer_from("mlp grads", &zeros)?,
            m: gpu.buffer_from("mlp adam m", &zeros)?,
            v: gpu.buffer_from("mlp adam v", &zeros)?,
            layout,
        })
    }

    /// Weights on the host.
    pub fn download(&self, gpu: &Gpu) -> Result<Vec<f32>> {
        gpu.read(self.params.all())
    }

    fn check_len(&self, len: usize, what: &str) -> Result<()> {
        if len != self.layout.total {
            return Err(Error::Invalid(format!(
                "{what} hold {len} floats; this configuration's MLP ({}×{}) has {}",
                self.cfg.depth, self.cfg.width, self.layout.total
            )));
        }
        Ok(())
    }
}

/// A run's MLP as its configuration states it: depth, width and the positional encodings'
/// frequency counts (0 = the paper's for the dataset's kind). The trainer's configuration
/// builds it (`TrainConfig::mlp_shape`), so the model never reads the trainer's settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MlpShape {
    pub depth: u32,
    pub width: u32,
    pub x_freqs: u32,
    pub t_freqs: u32,
}

/// The run's MLP: [`mlp_config_for`] (Deformable-3DGS's encodings for the dataset's kind:
/// synthetic scenes γ(t) with L=6 through a time net, real captures γ(t) with L=10) with the
/// frequency counts overridden where `shape` sets them.
pub fn mlp_config_of(synthetic: bool, shape: MlpShape) -> MlpConfig {
    let mut m = mlp_config_for(synthetic, shape.depth, shape.width);
    if shape.x_freqs > 0 {
        m.x_freqs = shape.x_freqs;
    }
    if shape.t_freqs > 0 {
        m.time = match m.time {
            TimeEncoding::Direct { .. } => TimeEncoding::Direct {
                freqs: shape.t_freqs,
            },
            TimeEncoding::TimeNet { hidden, out, .. } => TimeEncoding::TimeNet {
                freqs: shape.t_freqs,
                hidden,
                out,
            },
        };
    }
    m
}

pub fn mlp_config_for(synthetic: bool, depth: u32, width: u32) -> MlpConfig {
    let base = if synthetic {
        MlpConfig::synthetic()
    } else {
        MlpConfig::real()
    };
    let time = match base.time {
        TimeEncoding::TimeNet { freqs, out, .. } => TimeEncoding::TimeNet {
            freqs,
            hidden: width,
            out,
        },
        t => t,
    };
    MlpConfig {
        depth,
        width,
        skip: (depth >= 3).then_some(depth / 2).filter(|&s| s + 1 < depth),
        x_freqs: base.x_freqs,
        time,
    }
}

/// Everything that is trained: canonical Gaussians and the deformation network.
pub struct Model {
    pub gaussians: GaussianState,
    pub deform: DeformState,
    /// Which Gaussians the deformation moves (all, until the first classification).
    pub dynamic: DynamicSet,
    /// The control nodes when the deformation field is `nodes` (the MLP then runs at them).
    pub nodes: Option<NodeState>,
    /// How the transient rows are drawn (the temporal stage's constants).
    pub transient: TransientShape,
}

/// The temporal stage's constants of a model (see `kernels::temporal`): σ's floor, the cull
/// threshold, and the time range a transient's largest weight is taken over.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TransientShape {
    pub log_floor: f32,
    pub cutoff: f32,
    pub t_range: [f32; 2],
}

impl Default for TransientShape {
    fn default() -> Self {
        TransientShape {
            log_floor: (0.02f32).ln(),
            cutoff: 0.01,
            t_range: [0.0, 1.0],
        }
    }
}

/// What a model was built for that its blobs do not show: MLP depth and width (the parameter
/// count alone is ambiguous) and the Gaussian budget (buffer capacity; densification stops at
/// it, so it shapes the run). Recorded in checkpoints so that resuming under another
/// configuration is refused by name.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ModelShape {
    pub mlp_depth: u32,
    pub mlp_width: u32,
    pub budget: u32,
    /// Control nodes of the `nodes` field (0: the MLP field) and their K; absent from
    /// checkpoints written before the field existed (they are MLP-field runs).
    #[serde(default)]
    pub nodes: u32,
    #[serde(default)]
    pub knn: u32,
}

/// The model's part of a checkpoint (parameters and Adam moments; the trainer adds its
/// densification statistics and the iteration).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ModelSnapshot {
    pub shape: ModelShape,
    pub gaussians: HostGaussians,
    pub gauss_m: HostGaussians,
    pub gauss_v: HostGaussians,
    pub mlp_params: Vec<f32>,
    pub mlp_m: Vec<f32>,
    pub mlp_v: Vec<f32>,
    /// The dynamic/static split when the model is split; `None` when dense.
    pub dynamic: Option<SplitSnapshot>,
    /// The control nodes once placed (`nodes` field after the warm-up).
    pub nodes: Option<NodeSnapshot>,
}

/// One named array of a snapshot, as checkpoints store it.
pub struct Blob<'a> {
    pub name: String,
    pub data: &'a [f32],
    /// Floats per Gaussian for per-Gaussian arrays (to name the Gaussian of a bad value).
    pub row: Option<usize>,
    /// Never negative (Adam second moments, densification statistics).
    pub non_negative: bool,
}

impl Blob<'_> {
    /// Refuses a non-finite (or, for second moments, negative) value, naming the blob and
    /// the element.
    pub fn check_values(&self) -> Result<()> {
        let bad = |x: f32| !x.is_finite() || (self.non_negative && x < 0.0);
        let Some(i) = self.data.iter().position(|&x| bad(x)) else {
            return Ok(());
        };
        let at = match self.row {
            Some(r) if r > 0 => format!("element {i} (Gaussian {})", i / r),
            _ => format!("element {i}"),
        };
        let want = if self.non_negative {
            "finite values >= 0"
        } else {
            "finite values"
        };
        Err(Error::Invalid(format!(
            "blob {}: {at} is {}; expected {want} (the run had diverged when it was saved)",
            self.name, self.data[i]
        )))
    }
}

/// The per-Gaussian blobs of `g`, named `prefix` + section.
pub fn gaussian_blobs<'a>(prefix: &str, g: &'a HostGaussians, non_negative: bool) -> Vec<Blob<'a>> {
    let rest = 3 * (g.sh_coeffs as usize).saturating_sub(1);
    [
        ("means", g.means.as_flattened(), 3),
        ("log_scales", g.log_scales.as_flattened(), 3),
        ("quats", g.quats.as_flattened(), 4),
        ("opacity", &g.opacity[..], 1),
        ("sh_dc", g.sh_dc.as_flattened(), 3),
        ("sh_rest", &g.sh_rest[..], rest),
    ]
    .into_iter()
    .chain(
        (g.populations().temporal() && g.time.len() == g.len())
            .then(|| {
                [
                    ("time", g.time.as_flattened(), 2),
                    ("velocity", g.velocity.as_flattened(), 3),
                ]
            })
            .into_iter()
            .flatten(),
    )
    .map(|(k, data, row)| Blob {
        name: format!("{prefix}{k}"),
        data,
        row: Some(row),
        non_negative,
    })
    .collect()
}

impl ModelSnapshot {
    /// Every array with its checkpoint name: the Gaussians (`means`, …), their Adam moments
    /// (`m.means`, …, `v.means`, …) and the MLP's (`mlp_params`, `mlp_m`, `mlp_v`).
    pub fn blobs(&self) -> Vec<Blob<'_>> {
        let mut b = gaussian_blobs("", &self.gaussians, false);
        b.extend(gaussian_blobs("m.", &self.gauss_m, false));
        b.extend(gaussian_blobs("v.", &self.gauss_v, true));
        for (name, data, non_negative) in [
            ("mlp_params", &self.mlp_params, false),
            ("mlp_m", &self.mlp_m, false),
            ("mlp_v", &self.mlp_v, true),
        ] {
            b.push(Blob {
                name: name.into(),
                data,
                row: None,
                non_negative,
            });
        }
        if let Some(n) = &self.nodes {
            for (name, data, non_negative) in [
                ("node_params", &n.params, false),
                ("node_m", &n.m, false),
                ("node_v", &n.v, true),
            ] {
                b.push(Blob {
                    name: name.into(),
                    data,
                    row: None,
                    non_negative,
                });
            }
        }
        b
    }
}

impl Model {
    /// The configuration this model was built for.
    pub fn shape(&self) -> ModelShape {
        ModelShape {
            mlp_depth: self.deform.cfg.depth,
            mlp_width: self.deform.cfg.width,
            budget: self.gaussians.layout.capacity,
            nodes: self.nodes.as_ref().map_or(0, |n| n.cfg.nodes),
            knn: self.nodes.as_ref().map_or(0, |n| n.cfg.knn),
        }
    }

    /// Reads parameters and moments back.
    pub fn checkpoint(&self, gpu: &Gpu) -> Result<ModelSnapshot> {
        let g = &self.gaussians;
        let d = &self.deform;
        Ok(ModelSnapshot {
            shape: self.shape(),
            gaussians: g.download(gpu)?,
            gauss_m: HostGaussians::download(gpu, &g.layout, &g.m, g.populations())?,
            gauss_v: HostGaussians::download(gpu, &g.layout, &g.v, g.populations())?,
            mlp_params: gpu.read(d.params.all())?,
            mlp_m: gpu.read(d.m.all())?,
            mlp_v: gpu.read(d.v.all())?,
            dynamic: self.dynamic.download(gpu, g.canonical_rows().len())?,
            nodes: match &self.nodes {
                // The KNN covers the canonical rows (what the deformation blends), not the
                // transients after them.
                Some(n) if n.placed() => {
                    Some(n.download(gpu, g.canonical_rows().len(), self.dynamic.generation())?)
                }
                _ => None,
            },
        })
    }

    /// Why snapshot `s` cannot be restored into this model (another configuration, arrays
    /// that disagree, non-finite values), naming the setting or the blob; `Ok` when it can.
    pub fn check_snapshot(&self, s: &ModelSnapshot) -> Result<()> {
        let layout = &self.gaussians.layout;
        let cfg = &self.deform.cfg;
        let mismatch = |m: String| Err(Error::Invalid(m));
        let degree = |coeffs: u32| (coeffs as f64).sqrt() as u32 - 1;
        for (name, g) in [("", &s.gaussians), ("m.", &s.gauss_m), ("v.", &s.gauss_v)] {
            if g.sh_coeffs != layout.sh_coeffs {
                return mismatch(format!(
                    "SH degree: the checkpoint's {name}Gaussians have degree {} ({} coefficients); \
                     this configuration has sh_degree = {}",
                    degree(g.sh_coeffs.max(1)),
                    g.sh_coeffs,
                    degree(layout.sh_coeffs)
                ));
            }
        }
        let (have, want) = (s.shape, self.shape());
        if (have.mlp_depth, have.mlp_width) != (want.mlp_depth, want.mlp_width) {
            return mismatch(format!(
                "deformation MLP: the checkpoint's is {}×{} (depth×width); this configuration \
                 has mlp_depth = {}, mlp_width = {}",
                have.mlp_depth, have.mlp_width, want.mlp_depth, want.mlp_width
            ));
        }
        if (have.nodes, have.knn) != (want.nodes, want.knn) {
            let field = |nodes: u32, knn: u32| match nodes {
                0 => "the MLP field (deform_field.kind = mlp)".to_string(),
                m => format!("{m} control nodes with K = {knn} (deform_field.kind = nodes)"),
            };
            return mismatch(format!(
                "deformation field: the checkpoint's run had {}; this configuration has {}",
                field(have.nodes, have.knn),
                field(want.nodes, want.knn)
            ));
        }
        if s.nodes.is_some() && self.nodes.is_none() {
            return mismatch("blob node_params: this configuration has no control nodes".into());
        }
        if have.budget != want.budget {
            return mismatch(format!(
                "Gaussian budget: the checkpoint's run had densify.budget = {}; this \
                 configuration has {}",
                have.budget, want.budget
            ));
        }
        let n = s.gaussians.len();
        if n > layout.capacity as usize {
            return Err(Error::Capacity {
                what: "Gaussian budget (checkpoint)",
                capacity: layout.capacity as u64,
                asked: n as u64,
            });
        }
        let node_floats = s.nodes.as_ref().map_or(0, |v| v.params.len());
        if node_floats % 4 != 0 || node_floats > 4 * want.nodes as usize {
            return mismatch(format!(
                "blob node_params: {node_floats} floats; expected 4 per node for at most {} nodes",
                want.nodes
            ));
        }
        for b in s.blobs() {
            let want_len = match b.row {
                _ if b.name.starts_with("node_") => node_floats,
                Some(r) => n * r,
                None => self.deform.layout.total,
            };
            if b.data.len() != want_len {
                let what = if b.row.is_some() {
                    format!("{n} Gaussians need {want_len}")
                } else {
                    format!(
                        "this configuration's {}×{} MLP for this dataset kind has {want_len} \
                         (a run on a dataset of another kind?)",
                        cfg.depth, cfg.width
                    )
                };
                return mismatch(format!("blob {}: {} floats; {what}", b.name, b.data.len()));
            }
            b.check_values()?;
        }
        if let Some(d) = &s.dynamic {
            // The split covers the canonical rows (transients never go through D).
            let c = s.gaussians.canonical_rows().len();
            if d.flags.len() != c as usize {
                return mismatch(format!(
                    "blob dynamic: {} flags; {c} canonical Gaussians need {c}",
                    d.flags.len()
                ));
            }
            d.check()?;
        }
        Ok(())
    }

    /// Restores parameters and moments written by [`Model::checkpoint`] of a model with the
    /// same configuration. Everything is checked ([`Model::check_snapshot`]) before the first
    /// upload, so a refused snapshot leaves the model as it was.
    pub fn restore(&mut self, gpu: &Gpu, s: &ModelSnapshot) -> Result<()> {
        self.check_snapshot(s)?;
        let g = &mut self.gaussians;
        g.upload(gpu, &s.gaussians, "Gaussian budget (checkpoint)")?;
        s.gauss_m.upload(gpu, &g.layout, &g.m)?;
        s.gauss_v.upload(gpu, &g.layout, &g.v)?;
        let d = &self.deform;
        gpu.upload(d.params.all(), &s.mlp_params)?;
        gpu.upload(d.m.all(), &s.mlp_m)?;
        gpu.upload(d.v.all(), &s.mlp_v)?;
        self.dynamic.upload(gpu, s.dynamic.as_ref())?;
        if let Some(nodes) = self.nodes.as_mut() {
            match &s.nodes {
                Some(v) => {
                    let n = self.gaussians.canonical_rows().len();
                    let generation = self.dynamic.generation();
                    nodes.restore(gpu, v, n, generation)?
                }
                None => nodes.clear(),
            }
        }
        Ok(())
    }

    /// Replaces the parameters by a trained model (a run's `point_cloud.ply` and `deform.bin`),
    /// refusing non-finite values and mismatched shapes.
    pub fn load(&mut self, gpu: &Gpu, g: &HostGaussians, mlp: &[f32]) -> Result<()> {
        self.deform.check_len(mlp.len(), "deformation weights")?;
        let rest = 3 * (g.sh_coeffs as usize).saturating_sub(1);
        let finite = |v: &[f32]| v.iter().all(|x| x.is_finite());
        if let Some(i) = (0..g.len()).find(|&i| {
            !(finite(&g.means[i])
                && finite(&g.log_scales[i])
                && finite(&g.quats[i])
                && g.opacity[i].is_finite()
                && finite(&g.sh_dc[i])
                && finite(g.sh_rest.get(i * rest..(i + 1) * rest).unwrap_or(&[])))
        }) {
            return Err(Error::Invalid(format!(
                "Gaussian {i} has a non-finite parameter"
            )));
        }
        if !finite(mlp) {
            return Err(Error::Invalid(
                "deformation weights contain a non-finite value".into(),
            ));
        }
        self.gaussians
            .upload(gpu, g, "Gaussian budget (loaded model)")?;
        gpu.upload(self.deform.params.all(), mlp)?;
        Ok(())
    }
}
