//! The control-node deformation field (`glsl/nodes/*.comp`, docs/nodes.md); CPU twin:
//! `reference::nodes`. KNN of every Gaussian among the nodes, the blend of the nodes'
//! transforms into per-Gaussian deformation rows, its backward into per-(Gaussian, slot)
//! contributions, and the per-node gather of those (pairs sorted by node with the radix sort:
//! deterministic, no float atomics).

use bytemuck::{Pod, Zeroable};

use super::radix_sort::{passes, KeyWidth, RadixSort, SortBuffers};
use super::scan::Count;
pub use super::shape::{Access, DeviceShape};
use crate::error::{Error, Result};
use crate::shaders;
use crate::vk::{BufSlice, Buffer, ComputePipeline, Gpu, Recorder};

/// Nearest nodes per Gaussian at most (mirrors `NODES_KMAX` in glsl/nodes/nodes.glsl).
pub const KMAX: u32 = 8;
/// An empty KNN slot (mirrors `NO_NODE`).
pub const NO_NODE: u32 = u32::MAX;
/// Floats per contribution row (mirrors `CONTRIB`); stored padded to 16 (`CONTRIB_VEC4` vec4).
pub const CONTRIB: u64 = 14;
/// Floats each contribution row takes in the buffer (4 vec4, mirrors `CONTRIB_VEC4`).
pub const CONTRIB_STORED: u64 = 16;
/// Clamp of the node log-radius (mirrors `RHO_MIN`/`RHO_MAX`).
pub const RHO_MIN: f32 = -16.0;
pub const RHO_MAX: f32 = 8.0;
/// Nodes at most: one gather workgroup each within every device's 65 535 limit, and far more
/// than a scene's motion needs (SC-GS uses 512–1024).
pub const MAX_NODES: u32 = 16_384;

/// Mirrors `NodesParams` in glsl/include/params.glsl (checked by tests/layout.rs).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct NodesParams {
    pub n: u32,
    pub m: u32,
    pub k: u32,
    pub flags: u32,
}

/// Significant key bits of the node sort: enough that `NO_NODE`'s low bits sort after every
/// node index.
pub fn key_bits(m: u32) -> u32 {
    (32 - m.leading_zeros()).max(1)
}

/// Checks a node count and K; errors name the setting.
pub fn check_shape(m: u32, k: u32) -> Result<()> {
    if !(1..=MAX_NODES).contains(&m) {
        return Err(Error::Invalid(format!(
            "deform_field.nodes = {m}: expected 1..={MAX_NODES}"
        )));
    }
    if !(1..=KMAX).contains(&k) {
        return Err(Error::Invalid(format!(
            "deform_field.knn = {k}: expected 1..={KMAX}"
        )));
    }
    Ok(())
}

pub struct NodeKernels {
    knn: ComputePipeline,
    pairs: ComputePipeline,
    ranges: ComputePipeline,
    lbs: ComputePipeline,
    lbs_bwd: ComputePipeline,
    /// The blend and its backward over 4 slots (`SlotLoop::Fit`, for K <= 4).
    lbs4: Option<(ComputePipeline, ComputePipeline)>,
    gather: ComputePipeline,
    /// Which gather shape `gather` is.
    pub gather_shape: GatherShape,
    sort: RadixSort,
}

/// The per-node gather's shape: both sum each node's sorted pairs in a fixed order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GatherShape {
    /// One workgroup per node, strided partial sums and a tree in shared memory (GPUs: a node
    /// with thousands of pairs spreads over 64 invocations).
    Tree,
    /// One invocation per node, a plain loop (CPU devices: lavapipe's barriers and shared
    /// arrays made the tree 15x slower on the tiny scene, 100 against 6 ms a step).
    Serial,
}

/// The shape a device runs: serial on CPU devices, the tree elsewhere
/// (override: `DISPFLOW_NODES_GATHER=tree|serial`).
impl DeviceShape for GatherShape {
    const ENV: &'static str = "DISPFLOW_NODES_GATHER";
    const ALL: &'static [Self] = &[GatherShape::Tree, GatherShape::Serial];
    const CPU: Self = GatherShape::Serial;
    const GPU: Self = GatherShape::Tree;

    fn name(self) -> &'static str {
        match self {
            GatherShape::Tree => "tree",
            GatherShape::Serial => "serial",
        }
    }
}

/// How many slots the blend kernels loop over. Both give the same bits: the slots past K are
/// masked off either way.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SlotLoop {
    /// Always `KMAX` (GPUs: a masked slot costs little where lanes diverge anyway).
    Max,
    /// 4 when K <= 4, else `KMAX` (CPU devices: llvmpipe runs a masked slot's loads and maths
    /// as if it were used, so at the default K = 4 the 8-slot loop spends half its time on
    /// nothing; docs/measurements.md, stop 71).
    Fit,
}

/// `fit` on CPU devices, `max` elsewhere (override: `DISPFLOW_NODES_SLOTS=max|fit`).
impl DeviceShape for SlotLoop {
    const ENV: &'static str = "DISPFLOW_NODES_SLOTS";
    const ALL: &'static [Self] = &[SlotLoop::Max, SlotLoop::Fit];
    const CPU: Self = SlotLoop::Fit;
    const GPU: Self = SlotLoop::Max;

    fn name(self) -> &'static str {
        match self {
            SlotLoop::Max => "max",
            SlotLoop::Fit => "fit",
        }
    }
}

/// The backward's scratch for `capacity` Gaussians, `max_nodes` nodes and K slots, allocated
/// once (the KNN itself is model state: `model::nodes::NodeState::knn`).
pub struct NodeBuffers {
    pub k: u32,
    pub max_nodes: u32,
    /// Pairs (node key, pair id), sorted by node by [`NodeKernels::record_pairs`].
    pub sort: SortBuffers,
    /// [max_nodes, 2] u32: each node's range in the sorted pairs.
    pub ranges: Buffer,
    /// [capacity, K, 16] f32 contribution rows of the backward (14 floats padded to 4 vec4).
    pub contrib: Buffer,
}

/// One blend's inputs.
#[derive(Clone, Copy)]
pub struct BlendInputs<'a> {
    pub m: u32,
    pub k: u32,
    /// [N,K] u32 nearest nodes.
    pub knn: BufSlice<'a>,
    /// Canonical means [N,3] and quaternions [N,4].
    pub means: BufSlice<'a>,
    pub quats: BufSlice<'a>,
    /// Node parameters [4M] (positions, log-radii) and the MLP's output at the nodes [M,10].
    pub nodes: BufSlice<'a>,
    pub node_out: BufSlice<'a>,
}

impl<'a> BlendInputs<'a> {
    /// The blend's push constants over `rows` rows (through `idx` when given) and the index
    /// binding (the KNN stands in, unread, for a dense blend).
    fn params(&self, rows: u32, idx: Option<BufSlice<'a>>) -> (NodesParams, BufSlice<'a>) {
        let pc = NodesParams {
            n: rows,
            m: self.m,
            k: self.k,
            flags: idx.is_some() as u32,
        };
        (pc, idx.unwrap_or(self.knn))
    }
}

/// The most Gaussians the `serial` gather sums exactly: a node holds at most one pair per
/// Gaussian, and lavapipe ends an invocation's loops after 65 535 iterations in all
/// (docs/development.md, "lavapipe limits"; `tests/nodes.rs`: a node of 70 000 pairs is cut).
pub const SERIAL_GATHER_MAX: u32 = 65_535;

impl NodeKernels {
    pub fn new(gpu: &Gpu) -> Result<Self> {
        Self::with_gather(gpu, GatherShape::for_device(&gpu.info))
    }

    /// The device's kernels for a model of at most `capacity` Gaussians: the `serial` gather
    /// gives way to the tree above [`SERIAL_GATHER_MAX`], where it could be cut.
    pub fn for_capacity(gpu: &Gpu, capacity: u32) -> Result<Self> {
        let shape = match GatherShape::for_device(&gpu.info) {
            GatherShape::Serial if capacity > SERIAL_GATHER_MAX => GatherShape::Tree,
            s => s,
        };
        Self::with_gather(gpu, shape)
    }

    /// The gather's shape these kernels run.
    pub fn gather_shape(&self) -> GatherShape {
        self.gather_shape
    }

    /// The kernels with the gather of shape `gather` (tests and benches run both).
    pub fn with_gather(gpu: &Gpu, gather: GatherShape) -> Result<Self> {
        Self::with_shapes(gpu, gather, SlotLoop::for_device(&gpu.info))
    }

    /// The kernels with both shapes given (tests run every pair).
    pub fn with_shapes(gpu: &Gpu, gather: GatherShape, slots: SlotLoop) -> Result<Self> {
        Self::with_access(gpu, gather, slots, Access::for_device(&gpu.info))
    }

    /// [`NodeKernels::with_shapes`] with the blend and its backward reaching their arrays
    /// through `access`.
    pub fn with_access(
        gpu: &Gpu,
        gather: GatherShape,
        slots: SlotLoop,
        access: Access,
    ) -> Result<Self> {
        use shaders::nodes as s;
        let pick = |b, t| gpu.pipeline(access.pick(b, t));
        Ok(NodeKernels {
            knn: gpu.pipeline(&s::NODES_KNN)?,
            pairs: gpu.pipeline(&s::NODES_PAIRS)?,
            ranges: gpu.pipeline(&s::NODES_RANGES)?,
            lbs: pick(&s::NODES_LBS, &s::NODES_LBS_TEXEL)?,
            lbs_bwd: pick(&s::NODES_LBS_BWD, &s::NODES_LBS_BWD_TEXEL)?,
            lbs4: match slots {
                SlotLoop::Fit => Some((
                    pick(&s::NODES_LBS_K4, &s::NODES_LBS_K4_TEXEL)?,
                    pick(&s::NODES_LBS_BWD_K4, &s::NODES_LBS_BWD_K4_TEXEL)?,
                )),
                SlotLoop::Max => None,
            },
            gather: gpu.pipeline(match gather {
                GatherShape::Tree => &s::NODES_GATHER,
                GatherShape::Serial => &s::NODES_GATHER_SERIAL,
            })?,
            gather_shape: gather,
            sort: RadixSort::new(gpu)?,
        })
    }

    pub fn buffers(&self, gpu: &Gpu, capacity: u32, max_nodes: u32, k: u32) -> Result<NodeBuffers> {
        check_shape(max_nodes, k)?;
        let pairs = capacity.max(1) as u64 * k as u64;
        let pairs32 = u32::try_from(pairs).map_err(|_| Error::Capacity {
            what: "node pairs (Gaussian budget × deform.knn)",
            capacity: u32::MAX as u64,
            asked: pairs,
        })?;
        Ok(NodeBuffers {
            k,
            max_nodes,
            sort: self
                .sort
                .buffers(gpu, "node pairs", pairs32, KeyWidth::U32)?,
            ranges: gpu.buffer("node ranges", max_nodes as u64 * 8)?,
            contrib: gpu.buffer("node contributions", pairs * CONTRIB_STORED * 4)?,
        })
    }

    /// KNN of the `n` Gaussians among the first `m` nodes into `knn` [n,k] (`row_of`: the
    /// split model's rows; a static Gaussian gets no node).
    #[allow(clippy::too_many_arguments)]
    pub fn record_knn(
        &self,
        rec: &mut Recorder<'_>,
        knn: BufSlice<'_>,
        n: u32,
        m: u32,
        k: u32,
        means: BufSlice<'_>,
        nodes: BufSlice<'_>,
        row_of: Option<BufSlice<'_>>,
    ) {
        let pc = NodesParams {
            n,
            m,
            k,
            flags: row_of.is_some() as u32,
        };
        let row_of = row_of.unwrap_or(means); // unread (flags 0)
        let outer = rec.set_zone("nodes knn");
        rec.dispatch_rows(&self.knn, &pc, &[means, nodes, row_of, knn], n);
        rec.set_zone(&outer);
    }

    /// The pairs of `knn` [n,K] sorted by node and each node's range (for the gather).
    pub fn record_pairs(
        &self,
        rec: &mut Recorder<'_>,
        b: &NodeBuffers,
        knn: BufSlice<'_>,
        n: u32,
        m: u32,
    ) {
        assert!(m <= b.max_nodes, "{m} nodes in buffers for {}", b.max_nodes);
        let pairs = n * b.k;
        let pc = NodesParams {
            n: pairs,
            m,
            k: b.k,
            flags: 0,
        };
        let binds = [knn, b.sort.keys[0].all(), b.sort.vals[0].all()];
        let outer = rec.set_zone("nodes knn");
        rec.dispatch_rows(&self.pairs, &pc, &binds, pairs);
        let out = self
            .sort
            .record(rec, &b.sort, Count::Host(pairs), key_bits(m));
        rec.fill(b.ranges.all(), 0);
        let binds = [b.sort.keys[out].all(), b.ranges.all()];
        rec.dispatch_rows(&self.ranges, &pc, &binds, pairs);
        rec.set_zone(&outer);
    }

    /// Deformation rows [rows,10] of the Gaussians (all `rows` = N, or the dynamic rows
    /// `idx[0..rows]` of a split model, written compactly).
    pub fn record_lbs(
        &self,
        rec: &mut Recorder<'_>,
        rows: u32,
        x: &BlendInputs<'_>,
        idx: Option<BufSlice<'_>>,
        out: BufSlice<'_>,
    ) {
        let (pc, idx) = x.params(rows, idx);
        let binds = [x.means, x.quats, x.nodes, x.node_out, x.knn, idx, out];
        let outer = rec.set_zone("nodes blend");
        rec.dispatch_rows(self.blend_pipelines(x.k).0, &pc, &binds, rows);
        rec.set_zone(&outer);
    }

    /// The blend and its backward for `k` slots: the 4-slot pair when it serves `k`
    /// (`SlotLoop::Fit`), else the 8-slot one.
    fn blend_pipelines(&self, k: u32) -> (&ComputePipeline, &ComputePipeline) {
        match &self.lbs4 {
            Some((f, b)) if k <= 4 => (f, b),
            _ => (&self.lbs, &self.lbs_bwd),
        }
    }

    /// Backward of [`Self::record_lbs`] from `d_out` [rows,10]: contribution rows, and the
    /// canonical mean/quaternion gradients added into `g_means` [N,3], `g_quats` [N,4].
    #[allow(clippy::too_many_arguments)]
    pub fn record_lbs_bwd(
        &self,
        rec: &mut Recorder<'_>,
        b: &NodeBuffers,
        rows: u32,
        x: &BlendInputs<'_>,
        idx: Option<BufSlice<'_>>,
        d_out: BufSlice<'_>,
        g_means: BufSlice<'_>,
        g_quats: BufSlice<'_>,
    ) {
        assert_eq!(x.k, b.k, "blend and scratch for another K");
        let (pc, idx) = x.params(rows, idx);
        let binds = [
            x.means,
            x.quats,
            x.nodes,
            x.node_out,
            x.knn,
            idx,
            d_out,
            b.contrib.all(),
            g_means,
            g_quats,
        ];
        let outer = rec.set_zone("nodes blend bwd");
        rec.dispatch_rows(self.blend_pipelines(x.k).1, &pc, &binds, rows);
        rec.set_zone(&outer);
    }

    /// Per-node sums of the contributions: `d_node_out` [M,10] written, node-parameter
    /// gradients `g_nodes` [4M] written or added (`accumulate`).
    pub fn record_gather(
        &self,
        rec: &mut Recorder<'_>,
        b: &NodeBuffers,
        m: u32,
        d_node_out: BufSlice<'_>,
        g_nodes: BufSlice<'_>,
        accumulate: bool,
    ) {
        let pc = NodesParams {
            n: 0,
            m,
            k: b.k,
            flags: accumulate as u32,
        };
        let sorted = (passes(key_bits(m)) % 2) as usize;
        let binds = [
            b.ranges.all(),
            b.sort.vals[sorted].all(),
            b.contrib.all(),
            d_node_out,
            g_nodes,
        ];
        let outer = rec.set_zone("nodes blend bwd");
        match self.gather_shape {
            GatherShape::Tree => rec.dispatch(&self.gather, &pc, &binds, [m, 1, 1]),
            GatherShape::Serial => rec.dispatch_rows(&self.gather, &pc, &binds, m),
        }
        rec.set_zone(&outer);
    }
}
