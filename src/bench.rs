//! GPU-timed benchmark cases shared by `dispflow-vk bench` and the criterion benches.
//! Times are sums of GPU timestamp deltas over the timed dispatches, never host wall time.
//! Inputs are built once; every case verifies its first result against the CPU twin.
//!
//! Over 600 lines: every case (sort, scan, rasteriser) with its input builder and verification
//! lives here so `dispflow-vk bench` and `cargo bench` time exactly the same code.

use crate::error::{Error, Result};
use crate::kernels::radix_sort::{passes, KeyWidth, RadixSort, SortBuffers};
use crate::kernels::raster::{
    split_sh, BlendBwdVariant, BlendFwdVariant, Camera, OutputGrads, RasterBuffers, RasterSize,
    Rasterizer, RenderOpts, SplatInputs,
};
use crate::kernels::scan::{Count, PrefixSum, ScanScratch};
use crate::reference;
use crate::testing::Noise;
use crate::vk::{Buffer, Gpu, Recorder, Timings};

pub mod mlp_table;
pub mod raster_scenes;
pub mod step;

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
    }
}

/// Median of a sample (NaN-free).
pub fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    let m = v.len() / 2;
    if v.len() % 2 == 1 {
        v[m]
    } else {
        0.5 * (v[m - 1] + v[m])
    }
}

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
                let runs = std::iter::once(None).chain(BlendBwdVariant::ALL.map(Some));
                for bwd in runs {
                    if let Some(v) = bwd {
                        case.set_blend_bwd_variant(v);
                    }
                    let (med, stages) = measure(args.reps, || case.run(&gpu, bwd.is_some()))?;
                    rows.push(BenchRow {
                        kernel: format!(
                            "raster {} {res}² ({isect} tile hits)",
                            bwd.map_or("fwd".into(), |v| format!("fwd+bwd {}", v.name()))
                        ),
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
        let st = step::run_step_bench(&gpu, args.warm_steps, args.steps)?;
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
        std::fs::write(p, text).map_err(|source| Error::Io {
            path: p.display().to_string(),
            source,
        })?;
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

// ---------------------------------------------------------------------------------------------
// Deformation MLP: layer-wise vs fused vs fp16, and the GEMM microbenchmark.

use crate::kernels::mlp::{Mlp, MlpBuffers, MlpTime};
use crate::kernels::mlp_fused::{FmaPeak, MlpFused, Precision};
use crate::kernels::mlp_rows::MlpKernels;
use crate::model::deform::{LinearRole, LinearSpec, MlpConfig, MlpLayout};

/// Which MLP implementation a case runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MlpImpl {
    /// Layer-wise tiled GEMMs, activations stored (forward and backward).
    Layerwise(MlpKernels),
    /// Fused whole-network forward, f32, no stored activations (forward only).
    Fused,
    /// Fused forward with fp16 weights/activations, f32 arithmetic (forward only).
    FusedF16,
}

/// FLOP of one forward over `n` Gaussians (2 per multiply-add).
pub fn mlp_fwd_flops(cfg: &MlpConfig, n: u32) -> f64 {
    2.0 * cfg.macs_per_gaussian() as f64 * n as f64
}

/// FLOP of the layer-wise backward as dispatched: weight gradients (fan_out·(fan_in + 1) per
/// Linear, the +1 is the bias) and input gradients for every input that needs one (none for
/// γ(x); the time features only with a time net).
pub fn mlp_bwd_flops(cfg: &MlpConfig, n: u32) -> f64 {
    let lay = MlpLayout::new(cfg).expect("valid config");
    let (w, tf) = (cfg.width as f64, cfg.t_feat_dims() as f64);
    let tn = cfg.time_net();
    let mut macs = 0.0;
    for l in &lay.linears {
        let (fi, fo) = (l.fan_in as f64, l.fan_out as f64);
        macs += fo * (fi + 1.0);
        macs += fo
            * match l.role {
                LinearRole::Head => w,
                LinearRole::Trunk(0) => {
                    if tn {
                        tf
                    } else {
                        0.0
                    }
                }
                LinearRole::Trunk(i) if cfg.skip.map(|s| s + 1) == Some(i) => {
                    w + if tn { tf } else { 0.0 }
                }
                LinearRole::Trunk(_) => w,
                LinearRole::TimeNet(1) => fi,
                LinearRole::TimeNet(_) => 0.0,
            };
    }
    2.0 * macs * n as f64
}

/// One MLP benchmark case: inputs built once, `n` Gaussians, one configuration.
pub struct MlpCase {
    pub imp: MlpImpl,
    pub cfg: MlpConfig,
    pub n: u32,
    layerwise: Option<(Mlp, MlpBuffers)>,
    fused: Option<MlpFused>,
    xyz_host: Vec<f32>,
    params_host: Vec<f32>,
    xyz: Buffer,
    params: Buffer,
    params16: Option<Buffer>,
    out: Buffer,
    d_out: Buffer,
    grads: Buffer,
    pub time: f32,
}

impl MlpCase {
    pub fn new(gpu: &Gpu, cfg: &MlpConfig, n: u32, imp: MlpImpl) -> Result<Self> {
        let lay = MlpLayout::new(cfg)?;
        let mut noise = Noise::new(n as u64 ^ 0x3170);
        let mut unif =
            |lo: f32, hi: f32| lo + (hi - lo) * (noise.next_u32() as f32 / u32::MAX as f32);
        let xyz_host: Vec<f32> = (0..3 * n).map(|_| unif(-1.5, 1.5)).collect();
        let d_out: Vec<f32> = (0..10 * n).map(|_| unif(-1.0, 1.0)).collect();
        let params_host = lay.init_params(1);
        let (layerwise, fused) = match imp {
            MlpImpl::Layerwise(k) => {
                let m = Mlp::with_kernels(gpu, cfg, k)?;
                let b = m.buffers(gpu, n)?;
                (Some((m, b)), None)
            }
            MlpImpl::Fused => (None, Some(MlpFused::new(gpu, cfg, Precision::F32)?)),
            MlpImpl::FusedF16 => (None, Some(MlpFused::new(gpu, cfg, Precision::F16)?)),
        };
        let params = gpu.buffer_from("bench mlp params", &params_host)?;
        let params16 = match &fused {
            Some(f) if f.precision == Precision::F16 => {
                let p16 = gpu.buffer("bench mlp params f16", f.f16_params_bytes())?;
                let mut rec = Recorder::new(gpu)?;
                f.convert_params(&mut rec, params.all(), p16.all());
                rec.finish()?;
                Some(p16)
            }
            _ => None,
        };
        Ok(MlpCase {
            imp,
            cfg: *cfg,
            n,
            layerwise,
            fused,
            xyz: gpu.buffer_from("bench mlp xyz", &xyz_host)?,
            xyz_host,
            params16,
            out: gpu.buffer("bench mlp out", n as u64 * 40)?,
            d_out: gpu.buffer_from("bench mlp d_out", &d_out)?,
            grads: gpu.buffer("bench mlp grads", lay.total as u64 * 4)?,
            params,
            params_host,
            time: 0.37,
        })
    }

    /// Forward only (timed).
    pub fn run_forward(&self, gpu: &Gpu) -> Result<Timings> {
        let mut rec = Recorder::timed(gpu)?;
        let t = MlpTime::Batch(self.time);
        if let Some((m, b)) = &self.layerwise {
            m.forward(
                &mut rec,
                b,
                self.n,
                self.xyz.all(),
                t,
                self.params.all(),
                self.out.all(),
            );
        } else if let Some(f) = &self.fused {
            let p = self.params16.as_ref().unwrap_or(&self.params);
            f.forward(&mut rec, self.n, self.xyz.all(), t, p.all(), self.out.all());
        }
        rec.finish()
    }

    /// Forward + backward (timed); `None` for forward-only implementations.
    pub fn run_train(&self, gpu: &Gpu) -> Result<Option<Timings>> {
        let Some((m, b)) = &self.layerwise else {
            return Ok(None);
        };
        let mut rec = Recorder::timed(gpu)?;
        let p = self.params.all();
        m.forward(
            &mut rec,
            b,
            self.n,
            self.xyz.all(),
            MlpTime::Batch(self.time),
            p,
            self.out.all(),
        );
        m.backward(
            &mut rec,
            b,
            self.n,
            p,
            self.d_out.all(),
            self.grads.all(),
            false,
        );
        Ok(Some(rec.finish()?))
    }

    /// Runs the forward once and compares the first ≤ 256 Gaussians with the CPU twin
    /// (normwise: 1e-5 for f32, 2e-3 for fp16 storage). Returns the normwise error.
    pub fn verify(&self, gpu: &Gpu) -> Result<f64> {
        self.run_forward(gpu)?;
        let k = self.n.min(256);
        let lay = MlpLayout::new(&self.cfg)?;
        let want = reference::mlp::forward(
            &lay,
            &self.params_host,
            &self.xyz_host[..3 * k as usize],
            reference::mlp::Times::Batch(self.time),
        );
        let got: Vec<f32> = gpu.read(self.out.elems::<f32>(0, k as u64 * 10))?;
        let scale = want.iter().fold(0.0f32, |m, v| m.max(v.abs())) as f64;
        let err = got
            .iter()
            .zip(&want)
            .map(|(a, b)| (*a as f64 - *b as f64).abs())
            .fold(0.0, f64::max)
            / scale.max(1e-30);
        let tol = if self.imp == MlpImpl::FusedF16 {
            2e-3
        } else {
            1e-5
        };
        if err.is_nan() || err > tol {
            return Err(Error::Invalid(format!(
                "MLP {:?} n={}: normwise error {err:.2e} against the CPU twin exceeds {tol:.0e}",
                self.imp, self.n
            )));
        }
        Ok(err)
    }

    /// Bytes stored per Gaussian by this implementation (activations + backward scratch for
    /// the layer-wise path; nothing for the fused forward).
    pub fn bytes_per_gaussian(&self) -> u64 {
        match self.imp {
            MlpImpl::Layerwise(_) => MlpBuffers::bytes_per_gaussian(&self.cfg),
            _ => 0,
        }
    }
}

/// Measured device ceilings: register-only FMA throughput and the tiled GEMM kernel on a
/// large square-ish problem (`rows` × 512 × 512), both in GFLOP/s (median of `reps`).
pub struct GemmPeak {
    pub fma_gflops: f64,
    pub gemm_gflops: f64,
    pub gemm_shape: (u32, u32, u32),
}

pub fn gemm_peak(gpu: &Gpu, rows: u32, reps: usize) -> Result<GemmPeak> {
    let fma = FmaPeak::new(gpu)?;
    let groups = 512;
    let out = gpu.buffer("fma peak out", groups as u64 * 256 * 4)?;
    let mut flop = 0.0;
    let (fma_ms, _) = measure(reps, || {
        let mut rec = Recorder::timed(gpu)?;
        flop = fma.record(&mut rec, out.all(), groups, 2048);
        rec.finish()
    })?;
    // The GEMM: one square Linear (256 and 512 wide) over `rows` rows through the MLP's own
    // tiled kernel; the faster shape is the peak.
    let mlp = Mlp::new(gpu, &MlpConfig::real())?;
    let mut best = (0.0f64, (0, 0, 0));
    for km in [256usize, 512] {
        let g = gemm_gflops(gpu, &mlp, rows, km, reps)?;
        if g > best.0 {
            best = (g, (rows, km as u32, km as u32));
        }
    }
    Ok(GemmPeak {
        fma_gflops: flop / (fma_ms * 1e6),
        gemm_gflops: best.0,
        gemm_shape: best.1,
    })
}

/// GFLOP/s of one `km` → `km` Linear over `rows` rows (median of `reps`), spot-checked.
fn gemm_gflops(gpu: &Gpu, mlp: &Mlp, rows: u32, km: usize, reps: usize) -> Result<f64> {
    let (k, m) = (km, km);
    let l = LinearSpec {
        role: LinearRole::Trunk(1),
        fan_in: k,
        fan_out: m,
        w_off: 0,
        b_off: k * m,
    };
    let mut noise = Noise::new(7);
    let mut u = || (noise.next_u32() as f32 / u32::MAX as f32) - 0.5;
    let w: Vec<f32> = (0..k * m + m).map(|_| u()).collect();
    let a: Vec<f32> = (0..rows as usize * k).map(|_| u()).collect();
    let wb = gpu.buffer_from("gemm weights", &w)?;
    let ab = gpu.buffer_from("gemm a", &a)?;
    let ob = gpu.buffer("gemm out", rows as u64 * m as u64 * 4)?;
    let (gemm_ms, _) = measure(reps, || {
        let mut rec = Recorder::timed(gpu)?;
        let (ku, mu) = (k as u32, m as u32);
        mlp.linear(
            &mut rec,
            rows,
            &l,
            wb.all(),
            (ab.all(), ku, ku),
            None,
            (ob.all(), mu, 0),
            false,
        );
        rec.finish()
    })?;
    // Spot-check one output row against a plain dot product.
    let got: Vec<f32> = gpu.read(ob.elems::<f32>(0, m as u64))?;
    for (o, g) in got.iter().enumerate() {
        let want: f64 = w[k * m + o] as f64
            + (0..k)
                .map(|i| w[o * k + i] as f64 * a[i] as f64)
                .sum::<f64>();
        if (*g as f64 - want).abs() > 1e-4 {
            return Err(Error::Invalid(format!(
                "GEMM microbenchmark: out[0][{o}] = {g}, expected {want}"
            )));
        }
    }
    Ok(2.0 * rows as f64 * (k * m) as f64 / (gemm_ms * 1e6))
}
/// One row of the MLP table: median GPU milliseconds of forward and forward + backward.
#[derive(Debug, Clone, serde::Serialize)]
pub struct MlpRow {
    pub imp: String,
    pub config: String,
    pub n: u32,
    pub fwd_ms: f64,
    pub train_ms: Option<f64>,
    pub fwd_gflops: f64,
    pub train_gflops: Option<f64>,
    pub bytes_per_gaussian: u64,
    pub verify_err: f64,
    /// Share of GPU time per kernel (percent) in the last timed run (fwd+bwd when there is one).
    pub stages: Vec<(String, f64)>,
}

/// Times one case: verify, then `reps` forward (and forward + backward) runs.
pub fn mlp_row(
    gpu: &Gpu,
    cfg: &MlpConfig,
    name: &str,
    n: u32,
    imp: MlpImpl,
    reps: usize,
) -> Result<MlpRow> {
    let case = MlpCase::new(gpu, cfg, n, imp)?;
    // The verified forward doubles as the warm-up (pipelines are compiled at creation); at
    // 10^5 Gaussians one lavapipe run takes a minute, so no further warm-up runs.
    let verify_err = case.verify(gpu)?;
    let mut stages = Vec::new();
    let mut timed = |f: &dyn Fn() -> Result<Timings>| -> Result<f64> {
        let mut v = Vec::new();
        for _ in 0..reps.max(1) {
            let t = f()?;
            v.push(t.total_ms());
            let total = t.total_ms().max(1e-12);
            stages = t
                .by_label()
                .into_iter()
                .map(|(l, ms)| (l, 100.0 * ms / total))
                .collect();
        }
        Ok(median(v))
    };
    let fwd_ms = timed(&|| case.run_forward(gpu))?;
    let train_ms = if matches!(imp, MlpImpl::Layerwise(_)) {
        Some(timed(&|| Ok(case.run_train(gpu)?.unwrap_or_default()))?)
    } else {
        None
    };
    let ff = mlp_fwd_flops(cfg, n);
    let fb = ff + mlp_bwd_flops(cfg, n);
    Ok(MlpRow {
        imp: format!("{imp:?}"),
        config: name.to_string(),
        n,
        fwd_ms,
        train_ms,
        fwd_gflops: ff / (fwd_ms * 1e6),
        train_gflops: train_ms.map(|t| fb / (t * 1e6)),
        bytes_per_gaussian: case.bytes_per_gaussian(),
        verify_err,
        stages,
    })
}

// ---------------------------------------------------------------------------------------------
// LPIPS: one image pair per run, the whole network (input, 5 convs, 2 pools, 5 stage diffs).

use crate::eval::lpips::{random_weights, LpipsScorer};

/// `WIDTHxHEIGHT` → (width, height).
pub fn parse_size(s: &str) -> Result<(u32, u32)> {
    let bad = || {
        Error::Invalid(format!(
            "--lpips-sizes {s:?}: expected WIDTHxHEIGHT, e.g. 480x270"
        ))
    };
    let (w, h) = s.split_once(['x', '×']).ok_or_else(bad)?;
    Ok((
        w.trim().parse().map_err(|_| bad())?,
        h.trim().parse().map_err(|_| bad())?,
    ))
}

/// LPIPS of two random `width`×`height` images with random AlexNet weights.
pub struct LpipsCase {
    scorer: std::cell::RefCell<LpipsScorer>,
    imgs: [Buffer; 2],
    pub size: (u32, u32),
}

impl LpipsCase {
    pub fn new(gpu: &Gpu, width: u32, height: u32) -> Result<Self> {
        let mut noise = Noise::new(0x1b1b5);
        let mut img = |name: &str| {
            let px: Vec<f32> = (0..4 * width as usize * height as usize)
                .map(|_| (noise.next_u32() >> 8) as f32 / 16_777_216.0)
                .collect();
            gpu.buffer_from(name, &px)
        };
        let imgs = [img("bench lpips img0")?, img("bench lpips img1")?];
        let mut scorer = LpipsScorer::new(gpu, random_weights(3))?;
        // Allocates the scratch outside the timed runs.
        scorer.score(gpu, (width, height), imgs[0].all(), imgs[1].all())?;
        Ok(LpipsCase {
            scorer: std::cell::RefCell::new(scorer),
            imgs,
            size: (width, height),
        })
    }

    pub fn run(&self, gpu: &Gpu) -> Result<Timings> {
        let mut rec = Recorder::timed(gpu)?;
        let (a, b) = (self.imgs[0].all(), self.imgs[1].all());
        self.scorer.borrow_mut().record(&mut rec, self.size, a, b)?;
        rec.finish()
    }

    /// Runs once and checks the value: against the CPU twin up to 96×96 (the f64 twin of a
    /// large image takes minutes), finite and positive above.
    pub fn verify(&self, gpu: &Gpu) -> Result<f64> {
        self.run(gpu)?;
        let got = self.scorer.borrow().value(gpu)?;
        let (w, h) = self.size;
        let ok = if w * h <= 96 * 96 {
            let px = |i: usize| -> Result<Vec<[f32; 4]>> { gpu.read(self.imgs[i].all()) };
            let s = self.scorer.borrow();
            let want: f64 =
                reference::lpips::lpips(s.weights(), &px(0)?, &px(1)?, w as usize, h as usize)?
                    .iter()
                    .sum();
            (got - want).abs() <= 1e-6 + 1e-4 * want
        } else {
            got.is_finite() && got > 0.0
        };
        if !ok {
            return Err(Error::Invalid(format!("bench: LPIPS {w}×{h} gave {got}")));
        }
        Ok(got)
    }
}
