//! GPU-timed benchmark cases shared by `dispflow-vk bench` and the criterion benches.
//! Times are sums of GPU timestamp deltas over the timed dispatches, never host wall time.
//! Inputs are built once; every case verifies its first result against the CPU twin.

use crate::error::{Error, Result};
use crate::kernels::radix_sort::{passes, KeyWidth, RadixSort, SortBuffers};
use crate::kernels::scan::{Count, PrefixSum, ScanScratch};
use crate::reference;
use crate::testing::Noise;
use crate::vk::{Buffer, Gpu, Recorder, Timings};

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

#[derive(clap::Args, Debug)]
pub struct BenchArgs {
    /// Problem sizes as powers of two (comma-separated).
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
    for &lg in &args.log2_sizes {
        let n = 1u32 << lg.min(26);
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
    println!("\n| kernel | n | median GPU ms | M elements/s | time share by stage |");
    println!("|---|---:|---:|---:|---|");
    for r in &rows {
        let st: Vec<String> = r
            .stages
            .iter()
            .map(|(l, p)| format!("{l} {p:.0}%"))
            .collect();
        println!(
            "| {} | 2^{} | {:.3} | {:.1} | {} |",
            r.kernel,
            r.n.trailing_zeros(),
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

/// Folds the many per-pass sort dispatches into their stage names (hist, scan, scatter).
fn merge_stages(stages: Vec<(String, f64)>) -> Vec<(String, f64)> {
    let mut out: Vec<(String, f64)> = Vec::new();
    for (l, p) in stages {
        let key = if l.starts_with("scan_") {
            "scan".to_string()
        } else {
            l.replace("_u32", "").replace("_u64", "")
        };
        match out.iter_mut().find(|e| e.0 == key) {
            Some(e) => e.1 += p,
            None => out.push((key, p)),
        }
    }
    out
}
