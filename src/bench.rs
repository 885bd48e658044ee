//! GPU-timed benchmark cases shared by `dispflow-vk bench` and the criterion benches.
//! Times are sums of GPU timestamp deltas over the timed dispatches, never host wall time.
//! Inputs are built once; every case verifies its first result against the CPU twin.
//!
//! Over 600 lines: the sort, scan and rasteriser cases with their input builders and
//! verification live here so `dispflow-vk bench` and `cargo bench` time exactly the same code
//! (the MLP, LPIPS, scene and step cases are in `src/bench/`).

use crate::error::{Error, Result};
use crate::kernels::radix_sort::{passes, KeyWidth, RadixSort, SortBuffers};
use crate::kernels::raster::{
    split_sh, Binning, BlendBwdVariant, BlendFwdVariant, Camera, DeviceShape, OutputGrads,
    RasterBuffers, RasterSize, Rasterizer, RenderOpts, SplatInputs,
};
use crate::kernels::scan::{Count, PrefixSum, ScanScratch};
use crate::reference;
use crate::testing::Noise;
use crate::vk::{Buffer, Gpu, Recorder, Timings};

pub mod field;
mod lpips_case;
mod mlp_case;
pub mod mlp_table;
pub mod motion;
pub mod raster_scenes;
pub mod sparsity;
pub mod step;

pub use lpips_case::*;
pub use mlp_case::*;

/// Key distributions for the sort benchmark.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum KeyShape {
    /// Uniform random u32 keys, all 32 bits significant (8 passes).
    Random32,
    /// Rasteriser-shaped u64 keys: `tile << 32 | depth`, 4096 tiles, 44 significant bits
    /// (11 passes), many keys per tile.
    TileDepth64,
}

impl KeyShape {
    pub fn bits(self) -> u32 {
        match self {
            KeyShape::Random32 => 32,
            KeyShape::TileDepth64 => 44,
        }
    }
    fn width(self) -> KeyWidth {
        match self {
            KeyShape::Random32 => KeyWidth::U32,
            KeyShape::TileDepth64 => KeyWidth::U64,
        }
    }
}

/// One sort benchmark: `n` pairs of a given key shape, input restored before every run.
pub struct SortCase {
    sort: RadixSort,
    bufs: SortBuffers,
    pristine_keys: Buffer,
    pristine_vals: Buffer,
    keys: Vec<u64>,
    pub n: u32,
    pub shape: KeyShape,
}

impl SortCase {
    pub fn new(gpu: &Gpu, n: u32, shape: KeyShape) -> Result<Self> {
        let sort = RadixSort::new(gpu)?;
        let bufs = sort.buffers(gpu, "bench sort", n, shape.width())?;
        let mut noise = Noise::new(n as u64 ^ 0xbe4c);
        let keys: Vec<u64> = match shape {
            KeyShape::Random32 => (0..n).map(|_| noise.next_u32() as u64).collect(),
            KeyShape::TileDepth64 => (0..n)
                .map(|_| ((noise.next_u64() % 4096) << 32) | noise.next_u32() as u64)
                .collect(),
        };
        let pristine_keys = match shape.width() {
            KeyWidth::U32 => gpu.buffer_from(
                "bench keys",
                &keys.iter().map(|&k| k as u32).collect::<Vec<u32>>(),
            )?,
            KeyWidth::U64 => gpu.buffer_from("bench keys", &keys)?,
        };
        let pristine_vals = gpu.buffer_from("bench values", &(0..n).collect::<Vec<u32>>())?;
        Ok(SortCase {
            sort,
            bufs,
            pristine_keys,
            pristine_vals,
            keys,
            n,
            shape,
        })
    }

    /// Restores the input (untimed copies), sorts (timed), returns the per-dispatch GPU times
    /// and the index of the output buffers.
    pub fn run(&self, gpu: &Gpu) -> Result<(Timings, usize)> {
        let kb = self.n as u64 * self.shape.width().bytes();
        let mut rec = Recorder::timed(gpu)?;
        if self.n > 0 {
            rec.copy(
                self.pristine_keys.slice(0, kb),
                self.bufs.keys[0].slice(0, kb),
            );
            rec.copy(
                self.pristine_vals.slice(0, self.n as u64 * 4),
                self.bufs.vals[0].slice(0, self.n as u64 * 4),
            );
        }
        let out = self
            .sort
            .record(&mut rec, &self.bufs, Count::Host(self.n), self.shape.bits());
        Ok((rec.finish()?, out))
    }

    /// Runs once and compares keys and values with the CPU twin.
    pub fn verify(&self, gpu: &Gpu) -> Result<()> {
        let (_, out) = self.run(gpu)?;
        let vals: Vec<u32> = (0..self.n).collect();
        let (want_k, want_v) =
            reference::radix_sort::sort_pairs_u64(&self.keys, &vals, self.shape.bits());
        let got_k: Vec<u64> = match self.shape.width() {
            KeyWidth::U32 => gpu
                .read::<u32>(self.bufs.keys[out].elems::<u32>(0, self.n as u64))?
                .into_iter()
                .map(u64::from)
                .collect(),
            KeyWidth::U64 => gpu.read(self.bufs.keys[out].elems::<u64>(0, self.n as u64))?,
        };
        let got_v: Vec<u32> = gpu.read(self.bufs.vals[out].elems::<u32>(0, self.n as u64))?;
        if got_k != want_k || got_v != want_v {
            return Err(Error::Invalid(format!(
                "sort of {} {:?} keys disagrees with the CPU twin",
                self.n, self.shape
            )));
        }
        Ok(())
    }
}

/// One scan benchmark over `n` u32.
pub struct ScanCase {
    scan: PrefixSum,
    scratch: ScanScratch,
    input: Buffer,
    output: Buffer,
    data: Vec<u32>,
    pub n: u32,
}

impl ScanCase {
    pub fn new(gpu: &Gpu, n: u32) -> Result<Self> {
        let scan = PrefixSum::new(gpu)?;
        let scratch = scan.scratch(gpu, n)?;
        let data: Vec<u32> = Noise::new(n as u64)
            .u32s(n as usize)
            .iter()
            .map(|x| x % 64)
            .collect();
        let input = gpu.buffer_from("bench scan input", &data)?;
        let output = gpu.buffer("bench scan output", n as u64 * 4)?;
        Ok(ScanCase {
            scan,
            scratch,
            input,
            output,
            data,
            n,
        })
    }

    pub fn run(&self, gpu: &Gpu) -> Result<Timings> {
        let mut rec = Recorder::timed(gpu)?;
        self.scan.record(
            &mut rec,
            &self.scratch,
            self.input.all(),
            self.output.all(),
            Count::Host(self.n),
        );
        rec.finish()
    }

    pub fn verify(&self, gpu: &Gpu) -> Result<()> {
        self.run(gpu)?;
        let got: Vec<u32> = gpu.read(self.output.elems::<u32>(0, self.n as u64))?;
        if got != reference::scan::exclusive_scan(&self.data) {
            return Err(Error::Invalid(format!(
                "scan of {} elements disagrees with the CPU twin",
                self.n
            )));
        }
        Ok(())
    }
}

/// One rasteriser benchmark: `n` random Gaussians (SH degree 3) seen by a `res`×`res` camera,
/// sized so the covered area per Gaussian shrinks as `n` grows (like a real capture).
pub struct RasterCase {
    rast: Rasterizer,
    bufs: RasterBuffers,
    cam: Camera,
    inputs: [Buffer; 6],
    d_rgba: Buffer,
    d_depth: Buffer,
    pub n: u32,
    pub res: u32,
}

impl RasterCase {
    pub fn new(gpu: &Gpu, n: u32, res: u32) -> Result<Self> {
        let mut r = Noise::new(n as u64 ^ res as u64);
        let mut u = move || (r.next_u32() as f32 + 0.5) / 4_294_967_296.0;
        let s = 0.6 / (n as f32).cbrt();
        let mut h = raster_scenes::HostSplats::default();
        for _ in 0..n {
            let z = 2.0 + 4.0 * u();
            h.means.extend([(u() - 0.5) * z, (u() - 0.5) * z, z]);
            h.scales
                .extend([s * (0.3 + u()), s * (0.3 + u()), s * (0.3 + u())]);
            h.quats.extend([u() - 0.5, u() - 0.5, u() - 0.5, u() - 0.5]);
            h.logits.push(2.0 * u() - 1.0);
            h.sh.extend((0..48).map(|_| 0.3 * (u() - 0.5)));
        }
        let cam = Camera {
            rot: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            trans: [0.0; 3],
            fx: res as f32,
            fy: res as f32,
            cx: 0.5 * res as f32,
            cy: 0.5 * res as f32,
            width: res,
            height: res,
            near: 0.01,
        };
        Self::from_host(gpu, &h, cam)
    }

    /// A case from host-side Gaussians (SH degree 3) and a camera; renders once.
    pub fn from_host(gpu: &Gpu, h: &raster_scenes::HostSplats, cam: Camera) -> Result<Self> {
        let rast = Rasterizer::new(gpu)?;
        let n = h.logits.len() as u32;
        let (dc, rest) = split_sh(&h.sh, 16);
        let inputs = [
            gpu.buffer_from("bench means", &h.means)?,
            gpu.buffer_from("bench scales", &h.scales)?,
            gpu.buffer_from("bench quats", &h.quats)?,
            gpu.buffer_from("bench logits", &h.logits)?,
            gpu.buffer_from("bench sh dc", &dc)?,
            gpu.buffer_from("bench sh rest", &rest)?,
        ];
        let px = (cam.width * cam.height) as usize;
        let d_rgba = gpu.buffer_from(
            "bench d rgba",
            &(0..4 * px)
                .map(|i| ((i % 7) as f32 - 3.0) * 1e-3)
                .collect::<Vec<_>>(),
        )?;
        let d_depth = gpu.buffer_from("bench d depth", &vec![0f32; px])?;
        let size = RasterSize {
            max_gaussians: n,
            width: cam.width,
            height: cam.height,
            sh_coeffs: 16,
            feature_dims: 0,
            isect_capacity: 4 * n,
        };
        let mut bufs = rast.buffers(gpu, &size)?;
        rast.render_checked(
            gpu,
            &mut bufs,
            &cam,
            &splat_inputs(&inputs, n),
            &RenderOpts::default(),
        )?;
        Ok(RasterCase {
            rast,
            bufs,
            cam,
            inputs,
            d_rgba,
            d_depth,
            n,
            res: cam.width,
        })
    }

    /// Forward, and backward when `with_backward`; timings labelled `fwd/…` and `bwd/…`.
    pub fn run(&self, gpu: &Gpu, with_backward: bool) -> Result<Timings> {
        let g = splat_inputs(&self.inputs, self.n);
        let o = RenderOpts::default();
        let mut rec = Recorder::timed(gpu)?;
        rec.set_zone("fwd");
        self.rast.forward(&mut rec, &self.bufs, &self.cam, &g, &o);
        if with_backward {
            rec.set_zone("bwd");
            let d = OutputGrads {
                rgba: self.d_rgba.all(),
                depth: Some(self.d_depth.all()),
                features: None,
            };
            self.rast
                .backward(&mut rec, &self.bufs, &self.cam, &g, &o, &d);
        }
        rec.finish()
    }

    /// Backward only, of the forward pass `new` rendered (its outputs stay in the buffers).
    pub fn run_backward(&self, gpu: &Gpu) -> Result<Timings> {
        let g = splat_inputs(&self.inputs, self.n);
        let mut rec = Recorder::timed(gpu)?;
        let d = OutputGrads {
            rgba: self.d_rgba.all(),
            depth: Some(self.d_depth.all()),
            features: None,
        };
        self.rast.backward(
            &mut rec,
            &self.bufs,
            &self.cam,
            &g,
            &RenderOpts::default(),
            &d,
        );
        rec.finish()
    }

    pub fn intersections(&self, gpu: &Gpu) -> Result<u32> {
        self.bufs.intersections(gpu)
    }

    /// The 2D gradients of the last backward, [n, G2D_STRIDE].
    pub fn grad2d(&self, gpu: &Gpu) -> Result<Vec<f32>> {
        gpu.read(
            self.bufs
                .grad2d
                .elems::<f32>(0, self.n as u64 * crate::kernels::raster::G2D_STRIDE),
        )
    }

    /// The binning the next `run` records (the buffers serve both).
    pub fn set_binning(&mut self, b: Binning) {
        self.rast.set_binning(b);
    }

    /// The blend-backward variant the next `run` records.
    pub fn set_blend_bwd_variant(&mut self, v: BlendBwdVariant) {
        self.rast.set_blend_bwd_variant(v);
    }

    /// The blend-forward variant the next `run` records.
    pub fn set_blend_fwd_variant(&mut self, v: BlendFwdVariant) {
        self.rast.set_blend_fwd_variant(v);
    }

    /// The last forward's outputs: rgba [px,4], depth [px] and final T [px] in one float
    /// vector, and n_contrib [px].
    pub fn forward_outputs(&self, gpu: &Gpu) -> Result<(Vec<f32>, Vec<u32>)> {
        let px = (self.cam.width * self.cam.height) as u64;
        let mut f = gpu.read(self.bufs.out_rgba.elems::<f32>(0, 4 * px))?;
        f.extend(gpu.read::<f32>(self.bufs.out_depth.elems::<f32>(0, px))?);
        f.extend(gpu.read::<f32>(self.bufs.final_t.elems::<f32>(0, px))?);
        Ok((f, gpu.read(self.bufs.n_contrib.elems::<u32>(0, px))?))
    }
}

fn splat_inputs(inputs: &[Buffer; 6], n: u32) -> SplatInputs<'_> {
    SplatInputs {
        n,
        means: inputs[0].all(),
        scales: inputs[1].all(),
        quats: inputs[2].all(),
        opacity_logits: inputs[3].all(),
        sh_dc: inputs[4].all(),
        sh_rest: inputs[5].all(),
        sh_coeffs: 16,
        sh_degree: 3,
        features: None,
        opacity_scale: None,
    }
}

pub use crate::stats::median;

/// Kernel families `dispflow-vk bench` can time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Suite {
    Sort,
    Scan,
    Raster,
    /// The deformation MLP: tiled vs register kernels, fused forwards, % of the FMA ceiling.
    Mlp,
    /// The whole training step (built-in and mujoco scenes, baseline and DispFlow), old vs new
    /// kernels, per zone.
    Step,
    /// LPIPS (AlexNet) of one image pair, random weights (the cost does not depend on them).
    Lpips,
    /// The training step with the MLP over every Gaussian against split models (50, 20, 5,
    /// 0 % dynamic), per zone.
    Sparsity,
    /// The training step with the per-Gaussian MLP against the control-node field (256, 512,
    /// 1024 nodes), at --field-gaussians Gaussians, per zone.
    Field,
    /// The DispFlow step with each scene-motion option (flow preset, level, blur, texture,
    /// residual, confidence) next to the baseline step, per zone.
    Motion,
    /// The step of every compared method (3DGS, Deformable 3DGS, MotionGS, DispFlow-GS) and
    /// representation × scene-motion cell of the paper's Tab. 5, per zone.
    Methods,
}

#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// What to time, e.g. `dispflow-vk bench step` (same as --suite).
    #[arg(value_enum)]
    pub what: Vec<Suite>,
    /// Kernel families to time (comma-separated); positional names take precedence.
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "sort,scan,raster,mlp,step"
    )]
    pub suite: Vec<Suite>,
    /// MLP and step: Gaussians per MLP case (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "10000")]
    pub mlp_sizes: Vec<u32>,
    /// Step: untimed steps before the timed ones (per kernel set).
    #[arg(long, default_value_t = 2)]
    pub warm_steps: u32,
    /// Step: timed steps per kernel set (the table reports the median).
    #[arg(long, default_value_t = 5)]
    pub steps: u32,
    /// Step: also time every kernel set on trained models, the last checkpoints of these
    /// finished fast-preset run directories (comma-separated; `dispflow-vk train`'s output,
    /// e.g. the quickstart's `runs/builtin`; the scene is the run's `metrics.json` dataset).
    /// Their splats are the small, dense ones a run spends most of its steps on; the default
    /// rows time the initial points.
    #[arg(long, value_name = "RUN_DIR", value_delimiter = ',')]
    pub trained: Vec<std::path::PathBuf>,
    /// Field: Gaussians of each scene's model (its points grown by jittered copies; 0 = the
    /// initial points) — a trained fast-preset run of mujoco-scene7 holds about 20 000.
    #[arg(long, default_value_t = 20_000)]
    pub field_gaussians: u32,
    /// Sort/scan sizes as powers of two (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "16,18,20,22")]
    pub log2_sizes: Vec<u32>,
    /// Timed repetitions per case; the table reports the median.
    #[arg(long, default_value_t = 7)]
    pub reps: usize,
    /// Sort key shapes to time (comma-separated).
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "random32,tile-depth64"
    )]
    pub shapes: Vec<KeyShape>,
    /// Rasteriser: Gaussian counts (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "1000,10000,100000")]
    pub gaussians: Vec<u32>,
    /// Rasteriser: square image sizes in pixels (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "128,256")]
    pub resolutions: Vec<u32>,
    /// Rasteriser: issue-14 scenes timed for blend forward and backward, every variant
    /// (comma-separated).
    #[arg(
        long,
        value_enum,
        value_delimiter = ',',
        default_value = "dnerf,builtin"
    )]
    pub raster_scenes: Vec<raster_scenes::RasterScene>,
    /// LPIPS: image sizes WIDTHxHEIGHT (comma-separated).
    #[arg(long, value_delimiter = ',', default_value = "480x270,800x800")]
    pub lpips_sizes: Vec<String>,
    /// Also write the rows as JSON to this file.
    #[arg(long)]
    pub json: Option<std::path::PathBuf>,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct BenchRow {
    pub kernel: String,
    pub n: u32,
    pub median_ms: f64,
    pub m_per_s: f64,
    /// Share of GPU time per stage label, in percent.
    pub stages: Vec<(String, f64)>,
}

/// Median GPU time of `reps` runs plus the per-stage share of the median-closest run.
fn measure(
    reps: usize,
    mut run: impl FnMut() -> Result<Timings>,
) -> Result<(f64, Vec<(String, f64)>)> {
    run()?; // warm-up (pipeline caches, first-touch of memory)
    let mut all = Vec::with_capacity(reps);
    for _ in 0..reps.max(1) {
        all.push(run()?);
    }
    let med = median(all.iter().map(Timings::total_ms).collect());
    let best = all
        .iter()
        .min_by(|a, b| {
            (a.total_ms() - med)
                .abs()
                .total_cmp(&(b.total_ms() - med).abs())
        })
        .unwrap();
    let total = best.total_ms().max(1e-12);
    let stages = best
        .by_label()
        .into_iter()
        .map(|(l, ms)| (l, 100.0 * ms / total))
        .collect();
    Ok((med, stages))
}

/// `dispflow-vk bench`: sort and scan throughput on the selected device.
pub fn run(args: &BenchArgs) -> Result<Vec<BenchRow>> {
    let gpu = Gpu::new_default()?;
    if gpu.info.timestamp_period_ns.is_none() {
        return Err(Error::MissingFeature {
            device: gpu.info.name.clone(),
            feature: "timestampValidBits > 0 on the compute queue",
            why: "the benchmark reports GPU time from timestamp queries",
        });
    }
    println!(
        "device: {} (subgroup size {})",
        gpu.info, gpu.info.subgroup_size
    );
    let mut rows = Vec::new();
    let chosen = if args.what.is_empty() {
        &args.suite
    } else {
        &args.what
    };
    let has = |x: Suite| chosen.contains(&x);
    for &lg in &args.log2_sizes {
        let n = 1u32 << lg.min(26);
        if has(Suite::Sort) {
            for &shape in &args.shapes {
                let case = SortCase::new(&gpu, n, shape)?;
                case.verify(&gpu)?;
                let (med, stages) = measure(args.reps, || case.run(&gpu).map(|r| r.0))?;
                rows.push(BenchRow {
                    kernel: format!("sort {shape:?} ({} passes)", passes(shape.bits())),
                    n,
                    median_ms: med,
                    m_per_s: n as f64 / med / 1e3,
                    stages: merge_stages(stages),
                });
            }
        }
        if has(Suite::Scan) {
            let case = ScanCase::new(&gpu, n)?;
            case.verify(&gpu)?;
            let (med, stages) = measure(args.reps, || case.run(&gpu))?;
            rows.push(BenchRow {
                kernel: "exclusive scan u32".into(),
                n,
                median_ms: med,
                m_per_s: n as f64 / med / 1e3,
                stages,
            });
        }
    }
    if has(Suite::Raster) {
        for &res in &args.resolutions {
            for &n in &args.gaussians {
                let mut case = RasterCase::new(&gpu, n, res)?;
                let isect = case.intersections(&gpu)?;
                // The forward once per binning (zone `fwd binning`: the sort's share), then
                // the device's binning with each backward.
                for b in Binning::ALL {
                    case.set_binning(b);
                    let (med, stages) = measure(args.reps, || case.run(&gpu, false))?;
                    rows.push(BenchRow {
                        kernel: format!(
                            "raster fwd {res}² ({isect} tile hits), {} binning",
                            b.name()
                        ),
                        n,
                        median_ms: med,
                        m_per_s: n as f64 / med / 1e3,
                        stages: merge_stages(stages),
                    });
                }
                case.set_binning(Binning::for_device(&gpu.info));
                for v in BlendBwdVariant::ALL {
                    case.set_blend_bwd_variant(v);
                    let (med, stages) = measure(args.reps, || case.run(&gpu, true))?;
                    rows.push(BenchRow {
                        kernel: format!("raster fwd+bwd {} {res}² ({isect} tile hits)", v.name()),
                        n,
                        median_ms: med,
                        m_per_s: n as f64 / med / 1e3,
                        stages: merge_stages(stages),
                    });
                }
            }
        }
    }
    if has(Suite::Raster) {
        rows.extend(raster_scenes::blend_rows(
            &gpu,
            &args.raster_scenes,
            args.reps,
        )?);
    }
    if has(Suite::Mlp) {
        rows.extend(mlp_table::mlp_rows(&gpu, &args.mlp_sizes, args.reps)?);
    }
    if has(Suite::Step) {
        let st = step::run_step_bench(&gpu, args.warm_steps, args.steps, &args.trained)?;
        rows.extend(step::report(&gpu, &st, args.reps)?);
    }
    if has(Suite::Sparsity) {
        let st = sparsity::run_sparsity_bench(&gpu, args.warm_steps, args.steps)?;
        rows.extend(step::report(&gpu, &st, args.reps)?);
    }
    if has(Suite::Field) {
        let st = field::run_field_bench(&gpu, args.warm_steps, args.steps, args.field_gaussians)?;
        rows.extend(step::report(&gpu, &st, args.reps)?);
    }
    if has(Suite::Motion) {
        let st = motion::run_motion_bench(&gpu, args.warm_steps, args.steps)?;
        rows.extend(step::report(&gpu, &st, args.reps)?);
    }
    if has(Suite::Methods) {
        let st = motion::run_method_bench(&gpu, args.warm_steps, args.steps)?;
        rows.extend(step::report(&gpu, &st, args.reps)?);
    }
    if has(Suite::Lpips) {
        for size in &args.lpips_sizes {
            let (w, h) = parse_size(size)?;
            let case = LpipsCase::new(&gpu, w, h)?;
            case.verify(&gpu)?;
            let (med, stages) = measure(args.reps, || case.run(&gpu))?;
            rows.push(BenchRow {
                kernel: format!("lpips alex {w}×{h} (one pair)"),
                n: w * h,
                median_ms: med,
                m_per_s: (w * h) as f64 / med / 1e3,
                stages: merge_stages(stages),
            });
        }
    }
    println!("\n| kernel | n | median GPU ms | M elements/s | time share by stage |");
    println!("|---|---:|---:|---:|---|");
    for r in &rows {
        let st: Vec<String> = r
            .stages
            .iter()
            .map(|(l, p)| format!("{l} {p:.0}%"))
            .collect();
        println!(
            "| {} | {} | {:.3} | {:.2} | {} |",
            r.kernel,
            r.n,
            r.median_ms,
            r.m_per_s,
            st.join(", ")
        );
    }
    if let Some(p) = &args.json {
        let text = serde_json::to_string_pretty(&rows).expect("rows serialise");
        std::fs::write(p, text).map_err(Error::io(p))?;
    }
    Ok(rows)
}

/// Folds the many per-pass dispatches into stage names (scan levels into `scan`, sort passes
/// into `radix_hist`/`radix_scatter`, feature variants into their stage), keeping the zone.
fn merge_stages(stages: Vec<(String, f64)>) -> Vec<(String, f64)> {
    let mut out: Vec<(String, f64)> = Vec::new();
    for (l, p) in stages {
        let (zone, name) = l.rsplit_once('/').unwrap_or(("", l.as_str()));
        let name = if name.starts_with("scan_") {
            "scan"
        } else {
            name
        };
        let name = ["_u32", "_u64", "_f0", "_f2", "_f3"]
            .iter()
            .fold(name.to_string(), |n, s| n.replace(s, ""));
        let key = if zone.is_empty() {
            name
        } else {
            format!("{zone}/{name}")
        };
        match out.iter_mut().find(|e| e.0 == key) {
            Some(e) => e.1 += p,
            None => out.push((key, p)),
        }
    }
    out
}
