//! `dispflow-vk bench step`: the end-to-end training step (built-in scene and a mujoco scene,
//! fast preset; baseline and DispFlow), today's kernels against the kernels of an older
//! choice in the same run, per zone, with the MLP's share of the FMA ceiling measured in the
//! same run. Steps of the variants are interleaved so load on a shared machine hits them alike.

use std::path::PathBuf;

use super::{median, BenchRow};
use crate::data::builtin::builtin_scene;
use crate::data::{self, synthetic::Preset as ScenePreset};
use crate::error::Result;
use crate::kernels::mlp_fused::FmaPeak;
use crate::train::checkpoint::Checkpoint;
use crate::train::config::{MotionWeights, Preset, TrainConfig};
use crate::train::Trainer;
use crate::vk::{Gpu, Recorder, Timings};

/// A kernel choice a step runs with (set through the override variables, which the passes
/// read when they are built at the first step).
#[derive(Clone, Copy, Debug)]
pub struct KernelSet {
    pub name: &'static str,
    pub mlp: &'static str,
    pub blend_fwd: &'static str,
    pub blend_bwd: &'static str,
    /// The control-node field's gradient gather (`DISPFLOW_NODES_GATHER`).
    pub nodes_gather: &'static str,
    /// The SSIM loss's separable blur (`DISPFLOW_LOSS_BLUR`).
    pub loss_blur: &'static str,
    /// The radix sort's digit passes (`DISPFLOW_SORT`).
    pub sort: &'static str,
    /// The tiles a splat is binned to (`DISPFLOW_SPLAT_EXTENT`).
    pub splat_extent: &'static str,
    /// How splats are binned to tiles (`DISPFLOW_BINNING`).
    pub binning: &'static str,
    /// The motion normalisation's magnitude pass (`DISPFLOW_MOTION_NORM`).
    pub motion_norm: &'static str,
    /// The slots the control-node blend loops over (`DISPFLOW_NODES_SLOTS`).
    pub nodes_slots: &'static str,
    /// How the kernels with a texel twin reach their arrays (`DISPFLOW_ACCESS`).
    pub access: &'static str,
}

impl KernelSet {
    /// Each choice with the variable that carries it.
    fn vars(&self) -> [(&'static str, &'static str); 11] {
        use crate::kernels::{
            binning, loss, mlp_rows, motion, nodes, radix_sort, raster, shape::Access,
            shape::DeviceShape,
        };
        [
            (mlp_rows::MlpKernels::ENV, self.mlp),
            (raster::BlendFwdVariant::ENV, self.blend_fwd),
            (raster::BlendBwdVariant::ENV, self.blend_bwd),
            (nodes::GatherShape::ENV, self.nodes_gather),
            (loss::BlurShape::ENV, self.loss_blur),
            (radix_sort::SortShape::ENV, self.sort),
            (raster::SplatExtent::ENV, self.splat_extent),
            (binning::Binning::ENV, self.binning),
            (motion::NormMagShape::ENV, self.motion_norm),
            (nodes::SlotLoop::ENV, self.nodes_slots),
            (Access::ENV, self.access),
        ]
    }

    /// Sets the override variables, so passes built next run this set.
    fn apply(&self) {
        for (var, v) in self.vars() {
            std::env::set_var(var, v);
        }
    }

    /// Removes the override variables (the device's choices apply again).
    fn clear_all() {
        for (var, _) in KERNEL_SETS[0].vars() {
            std::env::remove_var(var);
        }
    }
}

/// Issue 60's CPU set: the CPU kernels after issue 14, splats binned to their 3σ squares.
/// Since stop 74 its whole-tile blends are today's, which load their splats in batches: the
/// issue's own blends ran 2–3.6× slower (the stop-73 binary's rows, docs/measurements.md).
const ISSUE_60: KernelSet = KernelSet {
    name: "rows MLP + tile-regs blend fwd + tile-accum blend bwd + serial node gather + rows \
           blur + serial sort, 3σ tile squares (today's batched whole-tile blends)",
    mlp: "rows",
    blend_fwd: "tile-regs",
    blend_bwd: "tile-accum",
    nodes_gather: "serial",
    loss_blur: "rows",
    sort: "serial",
    splat_extent: "radius",
    binning: "radix",
    motion_norm: "tree",
    nodes_slots: "max",
    access: "buffer",
};

/// The same kernels binning each splat to its opacity-aware box.
const BOXES: KernelSet = KernelSet {
    name: "the same CPU kernels, opacity-aware tile boxes",
    splat_extent: "opacity-box",
    ..ISSUE_60
};

/// The whole-tile CPU kernels binned depth first (stops 63–66's default).
const DEPTH_FIRST: KernelSet = KernelSet {
    name: "the same CPU kernels, opacity-aware tile boxes, depth-first binning, motion \
           magnitude in runs",
    binning: "depth-first",
    motion_norm: "runs",
    ..BOXES
};

/// Stop 67–71's CPU default: [`DEPTH_FIRST`] with the blends in bands of rows and the
/// control-node blend over 4 slots.
const BANDS: KernelSet = KernelSet {
    name: "the same, blends in bands of rows stepping over the splats that miss them",
    blend_fwd: "tile-bands",
    blend_bwd: "tile-bands",
    nodes_slots: "fit",
    ..DEPTH_FIRST
};

/// The choice before issue 14, the CPU set after it (3σ tile squares), the same kernels
/// binning each splat to its opacity-aware box (issue 60), the same boxes binned depth first
/// with the motion magnitude in runs (issue 60), that set with the blends in bands (issue 60)
/// and the control-node blend over 4 slots at K <= 4 (stop 71; the older sets loop over all 8),
/// the same with the blend backward giving each tile to the bands or the whole-tile kernel by
/// the forward's stopping points (stop 72), and today's CPU default: the same choices with the
/// whole-tile blends, whose walks load their splats in batches (stop 74), and today's CPU
/// default: that set with the flow, the whole-tile blends, the rows MLP, the loss, the
/// control-node blend and Adam reading and writing their arrays through texel buffers (stop 76).
pub const KERNEL_SETS: [KernelSet; 8] = [
    KernelSet {
        name: "tiled MLP + shared blend fwd + subgroup-atomic blend bwd (before)",
        mlp: "tiled",
        blend_fwd: "shared",
        blend_bwd: "subgroup-atomic",
        nodes_gather: "tree",
        loss_blur: "pixel",
        sort: "block",
        splat_extent: "radius",
        binning: "radix",
        motion_norm: "tree",
        nodes_slots: "max",
        access: "buffer",
    },
    ISSUE_60,
    BOXES,
    DEPTH_FIRST,
    BANDS,
    PICKED,
    BATCHED,
    KernelSet {
        name: "the same with the flow, whole-tile blends, rows MLP, loss, node blend and Adam \
               reading and writing through texel buffers (today's CPU default)",
        access: "texel",
        ..BATCHED
    },
];

/// Stop 74–75's CPU default: [`PICKED`] with whole-tile blends that load their splats in
/// batches, every array a storage buffer.
const BATCHED: KernelSet = KernelSet {
    name: "the same with whole-tile blends, which load their splats in batches (stop 74–75's \
           CPU default)",
    blend_fwd: "tile-regs",
    blend_bwd: "tile-accum",
    ..PICKED
};

/// Stop 72–73's CPU default: [`BANDS`] with the blend backward picked per tile.
const PICKED: KernelSet = KernelSet {
    name: "the same, the blend backward in bands or whole tiles picked per tile from the \
           forward's stopping points",
    blend_bwd: "tile-picked",
    ..BANDS
};

/// One timed configuration's result.
pub struct StepRow {
    pub scene: String,
    pub method: &'static str,
    pub kernels: &'static str,
    pub gaussians: u32,
    pub median_ms: f64,
    /// (zone, median ms) over the timed steps.
    pub zones: Vec<(String, f64)>,
}

fn zones(t: &Timings) -> Vec<(String, f64)> {
    let mut out: Vec<(String, f64)> = Vec::new();
    for (label, ms) in t.by_label() {
        let zone = label.rsplit_once('/').map_or("other", |z| z.0).to_string();
        match out.iter_mut().find(|e| e.0 == zone) {
            Some(e) => e.1 += ms,
            None => out.push((zone, ms)),
        }
    }
    out
}

/// `steps` timed steps (after `warm` untimed ones) of every trainer, interleaved so load on a
/// shared machine hits them alike.
pub(crate) fn time_interleaved(
    trainers: &mut [Trainer],
    warm: u32,
    steps: u32,
) -> Result<Vec<Vec<Timings>>> {
    let mut times: Vec<Vec<Timings>> = vec![Vec::new(); trainers.len()];
    for _ in 0..warm {
        for tr in trainers.iter_mut() {
            tr.step(false, false)?;
        }
    }
    for _ in 0..steps {
        for (tr, t) in trainers.iter_mut().zip(&mut times) {
            let log = tr.step(true, true)?.expect("values asked");
            t.push(log.timings);
        }
    }
    Ok(times)
}

/// One row per trainer (labelled in order by `labels`) of `scene` × `method` from its timed
/// steps.
pub(crate) fn rows_of(
    scene: &str,
    method: &'static str,
    trainers: &[Trainer],
    times: Vec<Vec<Timings>>,
    labels: impl IntoIterator<Item = &'static str>,
) -> Vec<StepRow> {
    trainers
        .iter()
        .zip(times)
        .zip(labels)
        .map(|((tr, t), label)| StepRow {
            scene: scene.to_string(),
            method,
            kernels: label,
            gaussians: tr.n(),
            median_ms: median(t.iter().map(Timings::total_ms).collect()),
            zones: median_zones(&t),
        })
        .collect()
}

/// Median ms per zone over steps.
pub(crate) fn median_zones(t: &[Timings]) -> Vec<(String, f64)> {
    let mut zs: Vec<(String, Vec<f64>)> = Vec::new();
    for z in t.iter().map(zones) {
        for (name, ms) in z {
            match zs.iter_mut().find(|e| e.0 == name) {
                Some(e) => e.1.push(ms),
                None => zs.push((name, vec![ms])),
            }
        }
    }
    zs.into_iter().map(|(n, v)| (n, median(v))).collect()
}

/// The scenes: the built-in one, and mujoco-scene7 when the shared data is present.
pub(crate) fn scenes() -> Result<Vec<(String, PathBuf)>> {
    let mut v = vec![(
        "built-in".to_string(),
        builtin_scene(ScenePreset::Small, 0)?,
    )];
    let mujoco = PathBuf::from("../shared/data/mujoco-scene7_deformation");
    if mujoco.is_dir() {
        v.push(("mujoco-scene7".to_string(), mujoco));
    }
    Ok(v)
}

/// The fast preset with the deformation and the motion term (weight `weight`) on from the
/// first step and densification off, so every timed step does the same work.
pub(crate) fn timed_config(weight: f32) -> TrainConfig {
    let mut cfg = TrainConfig::preset(Preset::Fast);
    cfg.warm_up = 0;
    cfg.motion_start = 0;
    cfg.motion_weight = weight;
    cfg.densify.from = u32::MAX;
    cfg
}

/// The label of the transient row: today's kernels with a quarter of the same Gaussians
/// turned into transients (issue 37: what a step costs at the same total count).
pub const TRANSIENT_ROW: &str = "the device's kernel set, 25 % of the Gaussians transient";

/// [`TRANSIENT_ROW`] with the transients' temporal weights detached in the motion pass (the
/// blend backward's extra per-splat sum, `[transient] motion_weights = "detached"`): DispFlow
/// only, the baseline has no motion channels.
pub const DETACHED_ROW: &str = "the device's kernel set, 25 % transient, motion weights detached";

/// Turns the last quarter of `tr`'s Gaussians into transients: centres spread over the time
/// range, widths at twice the floor, small velocities; so at any time a few of them are alive,
/// the rest culled before projection, as in a trained model.
pub fn make_quarter_transient(tr: &mut Trainer) -> Result<()> {
    let gpu = tr.gpu;
    let mut g = tr.gaussians()?;
    let n = g.len();
    let k = n / 4;
    let floor = tr.model.transient.log_floor;
    g.time = (0..n)
        .map(|i| {
            let j = i.saturating_sub(n - k);
            [
                (j as f32 + 0.5) / k.max(1) as f32,
                floor + std::f32::consts::LN_2,
            ]
        })
        .collect();
    g.velocity = (0..n)
        .map(|i| [0.1 * ((i % 7) as f32 - 3.0), 0.0, 0.05])
        .collect();
    g.transients = k;
    let mlp = tr.model.deform.download(gpu)?;
    let it = tr.iteration;
    tr.load_model(&g, &mlp, it)
}

/// The index in [`KERNEL_SETS`] of the set a device runs without overrides (on a GPU up to
/// the splat extent: GPUs bin to the opacity-aware box too).
pub fn default_set(gpu: &Gpu) -> usize {
    if gpu.info.kind == "CPU" {
        7
    } else {
        0
    }
}

/// A finished run's scene name and dataset directory, from its `metrics.json`.
fn trained_scene(run: &std::path::Path) -> Result<(String, PathBuf)> {
    let path = run.join("metrics.json");
    let bad = |why: String| {
        crate::error::Error::Invalid(format!("bench --trained: {}: {why}", path.display()))
    };
    let text = std::fs::read_to_string(&path)
        .map_err(|e| bad(format!("{e} (a finished run writes it)")))?;
    let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
    let field = |k: &str| {
        v.get(k)
            .and_then(|x| x.as_str())
            .map(str::to_string)
            .ok_or_else(|| bad(format!("no string field `{k}`")))
    };
    Ok((field("scene")?, PathBuf::from(field("dataset")?)))
}

/// Times `steps` steps (after `warm`) of each scene × method × kernel set, and of each
/// `trained` run (fast preset) on its last checkpoint.
pub fn run_step_bench(
    gpu: &Gpu,
    warm: u32,
    steps: u32,
    trained: &[PathBuf],
) -> Result<Vec<StepRow>> {
    let mut cases: Vec<(String, PathBuf, Option<Checkpoint>)> =
        scenes()?.into_iter().map(|(s, d)| (s, d, None)).collect();
    for run in trained {
        let (scene, dir) = trained_scene(run)?;
        let c = Checkpoint::load(&crate::train::checkpoint::last_checkpoint(run))?;
        cases.push((
            format!("{scene}, trained ({} it.)", c.iteration),
            dir,
            Some(c),
        ));
    }
    let mut rows = Vec::new();
    for (scene, dir, ckpt) in &cases {
        for (method, weight) in [("baseline", 0.0f32), ("DispFlow", 0.1)] {
            let cfg = timed_config(weight);
            let data = data::load(dir, &cfg.load_options())?;
            let new_trainer = |c: &TrainConfig| -> Result<Trainer> {
                let mut tr = Trainer::new(gpu, c, &data)?;
                if let Some(ck) = ckpt {
                    tr.restore(ck).map_err(|e| {
                        crate::error::Error::Invalid(format!(
                            "bench --trained: cannot time {scene}'s checkpoint with the fast \
                             preset: {e}"
                        ))
                    })?;
                }
                tr.step(false, false)?; // builds the passes with this kernel set
                Ok(tr)
            };
            let mut trainers = Vec::new();
            for k in KERNEL_SETS {
                k.apply();
                trainers.push(new_trainer(&cfg)?);
            }
            KernelSet::clear_all();
            // The device's own kernel set (as `for_device` picks: CPU-shaped on lavapipe) with a
            // quarter of the Gaussians transient.
            let own = KERNEL_SETS[default_set(gpu)];
            own.apply();
            let mut detached = cfg.clone();
            detached.transient.motion_weights = MotionWeights::Detached;
            let mut transient_rows = vec![(TRANSIENT_ROW, &cfg)];
            if weight > 0.0 {
                transient_rows.push((DETACHED_ROW, &detached));
            }
            for (_, c) in &transient_rows {
                let mut tr = new_trainer(c)?;
                make_quarter_transient(&mut tr)?;
                trainers.push(tr);
            }
            KernelSet::clear_all();
            let labels =
                (KERNEL_SETS.iter().map(|k| k.name)).chain(transient_rows.iter().map(|(l, _)| *l));
            let times = time_interleaved(&mut trainers, warm, steps)?;
            for ((tr, t), k) in trainers.iter().zip(times).zip(labels) {
                rows.push(StepRow {
                    scene: scene.clone(),
                    method,
                    kernels: k,
                    gaussians: tr.n(),
                    median_ms: median(t.iter().map(Timings::total_ms).collect()),
                    zones: median_zones(&t),
                });
            }
        }
    }
    Ok(rows)
}

/// Prints the step table (speed-up of each kernel set against the first, same scene and
/// method) and the per-zone table; returns rows for the JSON output.
pub fn report(gpu: &Gpu, rows: &[StepRow], reps: usize) -> Result<Vec<BenchRow>> {
    let peak = fma_peak(gpu, reps)?;
    println!("\nFMA ceiling (register-only `fma_peak`, same run): {peak:.2} GFLOP/s");
    println!("\n| scene | method | kernels | Gaussians | median ms/step | speed-up | zones (median ms, share) |");
    println!("|---|---|---|---:|---:|---:|---|");
    let mut out = Vec::new();
    for r in rows {
        let base = rows
            .iter()
            .find(|b| b.scene == r.scene && b.method == r.method)
            .map_or(r.median_ms, |b| b.median_ms);
        let z: Vec<String> = r
            .zones
            .iter()
            .map(|(n, ms)| format!("{n} {ms:.1} ({:.0}%)", 100.0 * ms / r.median_ms))
            .collect();
        println!(
            "| {} | {} | {} | {} | {:.1} | {:.2}× | {} |",
            r.scene,
            r.method,
            r.kernels,
            r.gaussians,
            r.median_ms,
            base / r.median_ms,
            z.join(", ")
        );
        out.push(BenchRow {
            kernel: format!("step {} {} [{}]", r.scene, r.method, r.kernels),
            n: r.gaussians,
            median_ms: r.median_ms,
            m_per_s: r.gaussians as f64 / r.median_ms / 1e3,
            stages: r
                .zones
                .iter()
                .map(|(n, ms)| (n.clone(), 100.0 * ms / r.median_ms))
                .collect(),
        });
    }
    let own = KERNEL_SETS[default_set(gpu)].name;
    let find = |r: &StepRow, kernels: &str| {
        (rows.iter()).find(|b| b.scene == r.scene && b.method == r.method && b.kernels == kernels)
    };
    let (squares, boxes) = (KERNEL_SETS[1].name, KERNEL_SETS[2].name);
    for r in rows.iter().filter(|r| r.kernels == boxes) {
        if let Some(b) = find(r, squares) {
            println!(
                "{} {}: binned to opacity-aware boxes the CPU step costs {:.2}× the one with 3σ \
                 squares ({:.2} vs {:.2} ms)",
                r.scene,
                r.method,
                r.median_ms / b.median_ms,
                r.median_ms,
                b.median_ms
            );
        }
    }
    let (radix, depth_first) = (KERNEL_SETS[2].name, KERNEL_SETS[3].name);
    for r in rows.iter().filter(|r| r.kernels == depth_first) {
        if let Some(b) = find(r, radix) {
            println!(
                "{} {}: binned depth first the CPU step costs {:.2}× the radix binning ({:.2} \
                 vs {:.2} ms); per zone, radix → depth first: {}",
                r.scene,
                r.method,
                r.median_ms / b.median_ms,
                r.median_ms,
                b.median_ms,
                zone_pairs(b, r)
            );
        }
    }
    // Each later CPU set against the issue's and against the set it changes.
    let issue_set = KERNEL_SETS[1].name;
    let (bands, picked, whole, texel) = (
        KERNEL_SETS[4].name,
        KERNEL_SETS[5].name,
        KERNEL_SETS[6].name,
        KERNEL_SETS[7].name,
    );
    for (set, prev, what, prev_what, change) in [
        (
            bands,
            depth_first,
            "with the blends in bands",
            "the same set with whole-tile blends",
            "whole tiles → bands",
        ),
        (
            picked,
            bands,
            "with the blend backward picked per tile",
            "the bands alone",
            "bands → picked",
        ),
        (
            whole,
            picked,
            "with whole-tile blends loading their splats in batches",
            "stop 72–73's picked bands",
            "picked bands → batched whole tiles",
        ),
        (
            texel,
            whole,
            "with texel-buffer arrays",
            "stop 74–75's storage buffers",
            "storage → texel buffers",
        ),
    ] {
        for r in rows.iter().filter(|r| r.kernels == set) {
            if let (Some(a), Some(b)) = (find(r, issue_set), find(r, prev)) {
                println!(
                    "{} {}: {what} the CPU step is {:.2}× faster than the issue-60 row ({:.2} \
                     vs {:.2} ms) and {:.2}× than {prev_what} ({:.2} ms); per zone, {change}: {}",
                    r.scene,
                    r.method,
                    a.median_ms / r.median_ms,
                    r.median_ms,
                    a.median_ms,
                    b.median_ms / r.median_ms,
                    b.median_ms,
                    zone_pairs(b, r)
                );
            }
        }
    }
    for r in rows.iter().filter(|r| r.kernels == TRANSIENT_ROW) {
        // The same kernels without transients.
        if let Some(b) = find(r, own) {
            println!(
                "{} {}: a step with a quarter of its {} Gaussians transient costs {:.2}× one \
                 without ({:.2} vs {:.2} ms)",
                r.scene,
                r.method,
                r.gaussians,
                r.median_ms / b.median_ms,
                r.median_ms,
                b.median_ms
            );
        }
    }
    for r in rows.iter().filter(|r| r.kernels == DETACHED_ROW) {
        if let Some(b) = find(r, TRANSIENT_ROW) {
            println!(
                "{} {}: with the motion weights detached the step costs {:.2}× the attached \
                 one ({:.2} vs {:.2} ms)",
                r.scene,
                r.method,
                r.median_ms / b.median_ms,
                r.median_ms,
                b.median_ms
            );
        }
    }
    Ok(out)
}

/// The rasteriser's zones of `a` and `b` side by side: "zone a → b ms".
fn zone_pairs(a: &StepRow, b: &StepRow) -> String {
    let ms = |r: &StepRow, z: &str| r.zones.iter().find(|e| e.0 == z).map_or(0.0, |e| e.1);
    (a.zones.iter())
        .filter(|(z, _)| z.contains("raster") || z.contains("intermediate"))
        .map(|(z, _)| format!("{z} {:.2} → {:.2}", ms(a, z), ms(b, z)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// GFLOP/s of the register-only FMA probe (median of `reps`).
pub fn fma_peak(gpu: &Gpu, reps: usize) -> Result<f64> {
    let fma = FmaPeak::new(gpu)?;
    let out = gpu.buffer("fma peak out", 512 * 256 * 4)?;
    let mut flop = 0.0;
    let mut v = Vec::new();
    for _ in 0..reps.max(3) {
        let mut rec = Recorder::timed(gpu)?;
        flop = fma.record(&mut rec, out.all(), 512, 2048);
        v.push(rec.finish()?.total_ms());
    }
    Ok(flop / (median(v) * 1e6))
}
