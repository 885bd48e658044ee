//! The deformation pass: D(x, t) by the MLP and its composition with the canonical Gaussians,
//! forward and backward, over one or more time slots (a DispFlow step evaluates D at t1 and t2).
//!
//! When the model is split into dynamic and static Gaussians (`model.dynamic`), the MLP runs
//! over the dynamic rows only: their means are gathered into a compact batch, the MLP's
//! compact output is expanded back into Gaussian order with the static ones' constant
//! deformation in between (so the composition, δ and everything downstream are unchanged,
//! and a static Gaussian's δ is exactly 0), and the backward gathers
//! the output gradients of the same rows. The dense path is the code that ran before.
//!
//! The model's transient Gaussians (its last rows, `model.gaussians.transient_rows()`) are not
//! deformed: the MLP, the nodes and the composition run over the canonical rows only, and the
//! temporal stage (`kernels::temporal`) draws the transient rows at the slot's time and writes
//! every row's opacity factor (1 for canonical rows), which the slot's splats carry.

use std::cell::Cell;

use super::{row, StepSizes};
use crate::error::Result;
use crate::kernels::deform::{DeformApply, Drawn};
use crate::kernels::mlp::{Mlp, MlpBuffers, MlpTime};
use crate::kernels::nodes::{BlendInputs, NodeBuffers, NodeKernels};
use crate::kernels::raster::SplatInputs;
use crate::kernels::sparse::SparseKernels;
use crate::kernels::temporal::{Temporal, TemporalGrads, TemporalInputs, TemporalParams};
use crate::model::deform::MlpConfig;
use crate::model::gaussians::Section;
use crate::model::nodes::{FieldConfig, NodeState};
use crate::model::rows::Rows;
use crate::model::state::Model;
use crate::train::population::Population;
use crate::vk::{BufSlice, Buffer, Gpu, Recorder};

/// A time slot of the pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    /// The rendered time t1 (or the evaluated time).
    T1 = 0,
    /// The pair's time t2 (or the evaluated time's predecessor).
    T2 = 1,
}

/// Scratch of one time: MLP activations, its output and gradient [N,10], the drawn geometry.
struct SlotBuffers {
    mlp: MlpBuffers,
    out: Buffer,
    d_out: Option<Buffer>,
    drawn: [Buffer; 3],
    /// The MLP's output and output gradient over the dynamic rows only (split model).
    compact_out: Buffer,
    compact_d_out: Option<Buffer>,
    /// The MLP's output at the control nodes [M,10] and its gradient (nodes field).
    node_out: Option<Buffer>,
    node_d_out: Option<Buffer>,
    /// Every row's opacity factor at the slot's time [N] (transients' temporal weights).
    op_scale: Buffer,
}

/// The control-node field's kernels and the backward's scratch.
struct NodeField {
    kernels: NodeKernels,
    bufs: NodeBuffers,
    /// The model's KNN epoch the sorted gather lists were built for.
    pairs_for: Cell<Option<u64>>,
}

pub struct DeformPass {
    mlp: Mlp,
    apply: DeformApply,
    temporal: Temporal,
    rows: SparseKernels,
    /// The dynamic Gaussians' canonical means, gathered (split model).
    compact_means: Buffer,
    slots: Vec<SlotBuffers>,
    nodes: Option<NodeField>,
}

impl DeformPass {
    /// `slots` time slots (1 or 2); `backward`: also the MLP-output gradients; `field`: the
    /// control-node field's settings when the model has nodes.
    pub fn new(
        gpu: &Gpu,
        cfg: &MlpConfig,
        field: Option<&FieldConfig>,
        s: &StepSizes,
        slots: usize,
        backward: bool,
    ) -> Result<Self> {
        let mlp = Mlp::new(gpu, cfg)?;
        let cap = s.capacity as u64;
        let slots = (0..slots)
            .map(|k| {
                let name = |what: &str| format!("{what} (time slot {k})");
                let rows = |what: &str, floats: u64| gpu.buffer(&name(what), cap * floats * 4);
                let node_rows = |what: &str| {
                    let m = field.map_or(0, |f| f.nodes as u64);
                    gpu.buffer(&name(what), m * row::DEFORM * 4)
                };
                Ok(SlotBuffers {
                    mlp: mlp.buffers(gpu, s.capacity)?,
                    out: rows("deformation", row::DEFORM)?,
                    d_out: backward
                        .then(|| rows("deformation grads", row::DEFORM))
                        .transpose()?,
                    drawn: [
                        rows("drawn means", row::VEC3)?,
                        rows("drawn scales", row::VEC3)?,
                        rows("drawn quats", row::QUAT)?,
                    ],
                    compact_out: rows("dynamic deformation", row::DEFORM)?,
                    compact_d_out: backward
                        .then(|| rows("dynamic deformation grads", row::DEFORM))
                        .transpose()?,
                    node_out: field.map(|_| node_rows("node transforms")).transpose()?,
                    node_d_out: field
                        .filter(|_| backward)
                        .map(|_| node_rows("node transform grads"))
                        .transpose()?,
                    op_scale: rows("opacity factors", 1)?,
                })
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(DeformPass {
            mlp,
            apply: DeformApply::new(gpu)?,
            temporal: Temporal::new(gpu)?,
            rows: SparseKernels::new(gpu)?,
            compact_means: gpu.buffer("dynamic means", cap * row::VEC3 * 4)?,
            slots,
            nodes: field
                .map(|f| -> Result<NodeField> {
                    let kernels = NodeKernels::for_capacity(gpu, s.capacity)?;
                    Ok(NodeField {
                        bufs: kernels.buffers(gpu, s.capacity, f.nodes, f.knn)?,
                        kernels,
                        pairs_for: Cell::new(None),
                    })
                })
                .transpose()?,
        })
    }

    /// The placed control nodes and this pass's field, when the model blends nodes.
    fn node_field<'a>(&'a self, model: &'a Model) -> Option<(&'a NodeField, &'a NodeState)> {
        let ns = model.nodes.as_ref()?;
        Some((
            self.nodes
                .as_ref()
                .expect("a pass built for the nodes field"),
            ns,
        ))
    }

    /// Recomputes the model's KNN when it is stale (placement, densification, a new split,
    /// every `knn_every` steps: the trainer invalidates it) — only then, so a resumed run
    /// blends with exactly the KNN the uninterrupted one had.
    pub fn ensure_knn(&self, rec: &mut Recorder<'_>, model: &Model) {
        let Some((f, ns)) = self.node_field(model).filter(|(_, ns)| ns.placed()) else {
            return;
        };
        let (g, d) = (&model.gaussians, &model.dynamic);
        let n = g.canonical_rows().len();
        if ns.knn_for.get() == Some((n, d.generation())) {
            return;
        }
        let means = g.param(Section::Means);
        let row_of = d.split().map(|_| d.row_of());
        let (m, k) = (ns.m, ns.cfg.knn);
        let nodes = ns.param_block();
        (f.kernels).record_knn(rec, ns.knn_rows(n), n, m, k, means, nodes, row_of);
        ns.knn_updated(n, d.generation());
    }

    /// Rebuilds the gather's per-node pair lists when the model's KNN changed.
    fn ensure_pairs(&self, rec: &mut Recorder<'_>, model: &Model, f: &NodeField, ns: &NodeState) {
        let epoch = Some(ns.knn_epoch.get());
        if f.pairs_for.get() == epoch {
            return;
        }
        f.pairs_for.set(epoch);
        let n = model.gaussians.canonical_rows().len();
        (f.kernels).record_pairs(rec, &f.bufs, ns.knn_rows(n), n, ns.m);
    }

    fn blend_inputs<'a>(&'a self, model: &'a Model, ns: &'a NodeState, k: Slot) -> BlendInputs<'a> {
        let g = &model.gaussians;
        BlendInputs {
            m: ns.m,
            k: ns.cfg.knn,
            knn: ns.knn_rows(g.canonical_rows().len()),
            means: g.param(Section::Means),
            quats: g.param(Section::Quats),
            nodes: ns.param_block(),
            node_out: self.slot(k).node_out.as_ref().expect("nodes field").all(),
        }
    }

    /// D(·, t) of the control-node field into slot `k`: the MLP at the nodes, then the blend
    /// (over the dynamic rows when split). Unplaced nodes (before the deformation started)
    /// give D ≡ 0.
    fn nodes_forward(&self, rec: &mut Recorder<'_>, model: &Model, k: Slot, t: f32) {
        let (f, ns) = self.node_field(model).expect("nodes field");
        let (g, s, dynamic) = (&model.gaussians, self.slot(k), &model.dynamic);
        let n = g.canonical_rows().len();
        if !ns.placed() {
            rec.fill(s.out.slice(0, n.max(1) as u64 * row::DEFORM * 4), 0);
            return;
        }
        self.ensure_knn(rec, model);
        let params = model.deform.params.all();
        let x = self.blend_inputs(model, ns, k);
        let time = MlpTime::Batch(t);
        self.mlp
            .forward(rec, &s.mlp, ns.m, ns.positions(), time, params, x.node_out);
        let Some(count) = dynamic.split() else {
            (f.kernels).record_lbs(rec, n, &x, None, s.out.all());
            return;
        };
        if count > 0 {
            let (idx, out) = (Some(dynamic.idx()), s.compact_out.all());
            (f.kernels).record_lbs(rec, count, &x, idx, out);
        }
        let (row_of, out, fixed) = (dynamic.row_of(), s.compact_out.all(), dynamic.fixed());
        let width = row::DEFORM as u32;
        self.rows
            .expand(rec, n, width, row_of, out, fixed, s.out.all());
    }

    /// Backward of [`Self::nodes_forward`] from slot `k`'s output gradient: the blend's
    /// contributions (and its canonical mean/rotation terms, added), the per-node gather,
    /// then the MLP's weight gradients at the nodes.
    fn nodes_backward(&self, rec: &mut Recorder<'_>, model: &Model, k: Slot, accumulate: bool) {
        let (f, ns) = self.node_field(model).expect("nodes field");
        let (g, s, dynamic, d) = (
            &model.gaussians,
            self.slot(k),
            &model.dynamic,
            &model.deform,
        );
        let (params, grads) = (d.params.all(), d.grads.all());
        if !ns.placed() || dynamic.split() == Some(0) {
            // Nothing is blended: every gradient of the field is zero.
            if !accumulate {
                rec.fill(grads, 0);
                if ns.placed() {
                    rec.fill(ns.grad_block(), 0);
                }
            }
            return;
        }
        let (rows, d_out, idx) = match dynamic.split() {
            None => (g.canonical_rows().len(), self.output_grad(k), None),
            Some(count) => {
                let c = s.compact_d_out.as_ref().expect("a backward pass").all();
                let width = row::DEFORM as u32;
                let src = self.output_grad(k);
                self.rows.gather(rec, count, width, dynamic.idx(), src, c);
                (count, c, Some(dynamic.idx()))
            }
        };
        self.ensure_pairs(rec, model, f, ns);
        let x = self.blend_inputs(model, ns, k);
        let (gm, gq) = (g.grad(Section::Means), g.grad(Section::Quats));
        (f.kernels).record_lbs_bwd(rec, &f.bufs, rows, &x, idx, d_out, gm, gq);
        let node_d = s.node_d_out.as_ref().expect("a backward pass").all();
        (f.kernels).record_gather(rec, &f.bufs, ns.m, node_d, ns.grad_block(), accumulate);
        self.mlp
            .backward(rec, &s.mlp, ns.m, params, node_d, grads, accumulate);
    }

    fn slot(&self, k: Slot) -> &SlotBuffers {
        &self.slots[k as usize]
    }

    /// The drawn (deformed) means, scales and rotations of slot `k`.
    pub fn drawn(&self, k: Slot) -> [BufSlice<'_>; 3] {
        self.slot(k).drawn.each_ref().map(|b| b.all())
    }

    /// The MLP output [N,10] of slot `k`.
    pub fn output(&self, k: Slot) -> BufSlice<'_> {
        self.slot(k).out.all()
    }

    /// The gradient wrt the MLP output of slot `k`.
    pub fn output_grad(&self, k: Slot) -> BufSlice<'_> {
        self.slot(k).d_out.as_ref().expect("a backward pass").all()
    }

    /// D(·, t) by the MLP into slot `k` (the MLP sees the canonical means, detached): over
    /// the dynamic rows when the model is split (the static ones get their constant row),
    /// else over all.
    pub fn mlp_forward(&self, rec: &mut Recorder<'_>, model: &Model, k: Slot, t: f32) {
        if model.nodes.is_some() {
            return self.nodes_forward(rec, model, k, t);
        }
        let (g, s, dynamic) = (&model.gaussians, self.slot(k), &model.dynamic);
        let means = g.param(Section::Means);
        let params = model.deform.params.all();
        let Some(count) = dynamic.split() else {
            let time = MlpTime::Batch(t);
            let n = g.canonical_rows().len();
            self.mlp
                .forward(rec, &s.mlp, n, means, time, params, s.out.all());
            return;
        };
        if count > 0 {
            let xyz = self.compact_means.all();
            self.rows.gather(rec, count, 3, dynamic.idx(), means, xyz);
            let time = MlpTime::Batch(t);
            let out = s.compact_out.all();
            self.mlp.forward(rec, &s.mlp, count, xyz, time, params, out);
        }
        let (row_of, out, fixed) = (dynamic.row_of(), s.compact_out.all(), dynamic.fixed());
        let width = row::DEFORM as u32;
        self.rows.expand(
            rec,
            g.canonical_rows().len(),
            width,
            row_of,
            out,
            fixed,
            s.out.all(),
        );
    }

    /// The temporal stage's settings at time `t` (δ from `t` to `t2`).
    fn temporal_params(model: &Model, rows: Rows, t: f32, t2: f32) -> TemporalParams {
        let (g, tr) = (&model.gaussians, model.transient);
        TemporalParams {
            n: g.n,
            first: rows.start,
            t,
            log_floor: tr.log_floor,
            cutoff: tr.cutoff,
            t2,
            t_lo: tr.t_range[0],
            t_hi: tr.t_range[1],
        }
    }

    fn temporal_inputs(model: &Model) -> TemporalInputs<'_> {
        let g = &model.gaussians;
        TemporalInputs {
            means: g.param(Section::Means),
            log_scales: g.param(Section::LogScales),
            quats: g.param(Section::Quats),
            centre: g.param(Section::TimeCentre),
            log_width: g.param(Section::TimeLogWidth),
            velocity: g.param(Section::Velocity),
        }
    }

    /// Composes the canonical Gaussians with slot `k`'s MLP output (`deformed`) or with D ≡ 0,
    /// and draws the transients at time `t`.
    pub fn apply(&self, rec: &mut Recorder<'_>, model: &Model, k: Slot, t: f32, deformed: bool) {
        let (g, s) = (&model.gaussians, self.slot(k));
        let d = deformed.then(|| s.out.all());
        let drawn = drawn_of(&s.drawn);
        for pop in Population::of(g) {
            match pop {
                Population::Canonical(r) if !r.is_empty() => {
                    (self.apply).forward(rec, r.len(), &g.canonical(), d, &drawn);
                }
                Population::Canonical(_) => {}
                Population::Transient(r) => {
                    let p = Self::temporal_params(model, r, t, t);
                    let x = Self::temporal_inputs(model);
                    self.temporal.forward(rec, &p, &x, &drawn, s.op_scale.all());
                }
            }
        }
    }

    /// The model at time `t` into slot `k`: D(·, t) when `deformed` (else D ≡ 0, the
    /// warm-up) and the transients at `t`.
    pub fn forward(&self, rec: &mut Recorder<'_>, model: &Model, k: Slot, t: f32, deformed: bool) {
        if deformed && !model.gaussians.canonical_rows().is_empty() {
            self.mlp_forward(rec, model, k, t);
        }
        self.apply(rec, model, k, t, deformed);
    }

    /// What the rasteriser draws of slot `k`: its geometry, the model's opacity and SH, and the
    /// opacity factors when the model has transients.
    pub fn splats<'a>(&'a self, model: &'a Model, k: Slot, sh_degree: u32) -> SplatInputs<'a> {
        let g = &model.gaussians;
        SplatInputs {
            opacity_scale: Population::any_scales_opacity(g).then(|| self.slot(k).op_scale.all()),
            ..g.splats(self.drawn(k), sh_degree)
        }
    }

    /// The opacity factors of slot `k` over `rows` (meaningful only with transients).
    pub fn opacity_scale(&self, k: Slot, rows: Rows) -> BufSlice<'_> {
        (self.slot(k).op_scale).elems::<f32>(rows.start as u64, rows.len() as u64)
    }

    /// DispFlow's δ of the transient rows, v·(t2 − t1), over the deformation's rows of `delta`.
    pub fn transient_displacement(
        &self,
        rec: &mut Recorder<'_>,
        model: &Model,
        (t1, t2): (f32, f32),
        delta: BufSlice<'_>,
    ) {
        for r in Population::of(&model.gaussians)
            .iter()
            .filter_map(Population::velocity_rows)
        {
            let p = Self::temporal_params(model, r, t1, t2);
            let v = model.gaussians.param(Section::Velocity);
            self.temporal.displacement(rec, &p, v, delta);
        }
    }

    /// ∂L/∂δ of the transient rows into their velocity gradient (after [`Self::backward`]).
    pub fn transient_displacement_backward(
        &self,
        rec: &mut Recorder<'_>,
        model: &Model,
        (t1, t2): (f32, f32),
        d_delta: BufSlice<'_>,
    ) {
        for r in Population::of(&model.gaussians)
            .iter()
            .filter_map(Population::velocity_rows)
        {
            let p = Self::temporal_params(model, r, t1, t2);
            let gv = model.gaussians.grad(Section::Velocity);
            self.temporal.displacement_backward(rec, &p, d_delta, gv);
        }
    }

    /// Gradients wrt slot `k`'s drawn geometry → the canonical means/log-scales/quaternion
    /// gradients and, when `deformed`, ∂L/∂(dx, dr, ds) of the slot; the transient rows'
    /// gradients (with c, τ, v) from the drawn geometry's and the opacity factors'
    /// (`d_op_scale`) at time `t`.
    #[allow(clippy::too_many_arguments)] // the slot's time and the factor's gradient
    pub fn backward(
        &self,
        rec: &mut Recorder<'_>,
        model: &Model,
        k: Slot,
        d_drawn: &Drawn<'_>,
        deformed: bool,
        t: f32,
        d_op_scale: BufSlice<'_>,
    ) {
        let g = &model.gaussians;
        let d_out = deformed.then(|| self.output_grad(k));
        let grads = g.canonical_grads();
        for pop in Population::of(g) {
            match pop {
                Population::Canonical(r) if !r.is_empty() => {
                    let c = g.canonical();
                    (self.apply).backward(rec, r.len(), &c, d_drawn, &grads, d_out);
                }
                Population::Canonical(_) => {}
                Population::Transient(r) => {
                    let p = Self::temporal_params(model, r, t, t);
                    let x = Self::temporal_inputs(model);
                    let tg = TemporalGrads {
                        means: grads.means,
                        log_scales: grads.log_scales,
                        quats: grads.quats,
                        centre: g.grad(Section::TimeCentre),
                        log_width: g.grad(Section::TimeLogWidth),
                        velocity: g.grad(Section::Velocity),
                    };
                    self.temporal
                        .backward(rec, &p, &x, d_drawn, d_op_scale, &tg);
                }
            }
        }
    }

    /// [`DeformPass::backward`] of a second render of the step (deformed): its drawn-geometry
    /// gradients added to the canonical gradients and to slot `k`'s output gradient.
    pub fn backward_add(
        &self,
        rec: &mut Recorder<'_>,
        model: &Model,
        k: Slot,
        d_drawn: &Drawn<'_>,
    ) {
        let g = &model.gaussians;
        let grads = g.canonical_grads();
        let d_out = self.output_grad(k);
        // Transients learn from the photometric render only (their rows are left alone).
        let canonical = g.canonical_rows();
        if !canonical.is_empty() {
            let n = canonical.len();
            (self.apply).backward_add(rec, n, &g.canonical(), d_drawn, &grads, d_out);
        }
    }

    /// Zeroes slot `k`'s output gradient (before only [`DeformPass::backward_add`] writes it).
    pub fn clear_output_grad(&self, rec: &mut Recorder<'_>, k: Slot) {
        rec.fill(self.output_grad(k), 0);
    }

    /// The MLP's weight gradients from slot `k`'s output gradient, written into the model's
    /// MLP gradient buffer or added to it (`accumulate`); over the dynamic rows when split.
    pub fn mlp_backward(&self, rec: &mut Recorder<'_>, model: &Model, k: Slot, accumulate: bool) {
        if model.nodes.is_some() {
            return self.nodes_backward(rec, model, k, accumulate);
        }
        let (d, s, dynamic) = (&model.deform, self.slot(k), &model.dynamic);
        let (params, grads) = (d.params.all(), d.grads.all());
        let (rows, d_out) = match dynamic.split() {
            None if model.gaussians.canonical_rows().is_empty() => {
                // Transients only: the MLP had no input, its gradient is zero.
                if !accumulate {
                    rec.fill(grads, 0);
                }
                return;
            }
            None => (model.gaussians.canonical_rows().len(), self.output_grad(k)),
            Some(0) => {
                // Nothing is dynamic: the MLP had no input, its gradient is zero.
                if !accumulate {
                    rec.fill(grads, 0);
                }
                return;
            }
            Some(count) => {
                let c = s.compact_d_out.as_ref().expect("a backward pass").all();
                let src = self.output_grad(k);
                let width = row::DEFORM as u32;
                self.rows.gather(rec, count, width, dynamic.idx(), src, c);
                (count, c)
            }
        };
        self.mlp
            .backward(rec, &s.mlp, rows, params, d_out, grads, accumulate);
    }
}

fn drawn_of(b: &[Buffer; 3]) -> Drawn<'_> {
    Drawn {
        means: b[0].all(),
        scales: b[1].all(),
        quats: b[2].all(),
    }
}
