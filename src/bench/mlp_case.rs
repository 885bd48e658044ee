//! Deformation MLP cases: layer-wise (tiled or register path) vs fused vs fp16, and the GEMM
//! microbenchmark.

use super::*;

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
