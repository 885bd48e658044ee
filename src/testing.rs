//! Helpers for the conformance tests and benches: one shared validated device per process,
//! deterministic noise and uniform draws ([`Noise`]), and the comparisons of results with their
//! references ([`assert_close`] with a [`Tol`], [`max_abs`]).
//!
//! The validation layer (1.3.239) crashes now and then when several validated devices submit
//! from parallel threads, so every test in a binary shares one device behind a mutex: GPU tests
//! run one at a time while CPU-only tests stay parallel.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Mutex, MutexGuard};

use crate::vk::{Gpu, GpuOptions, Validation, VALIDATION_ERRORS};

/// `None` before the first use and after the process-exit hook destroyed the device.
static GPU: Mutex<Option<Gpu>> = Mutex::new(None);

extern "C" {
    // libc's: the hook runs at process exit, before the dynamic loader unloads the Vulkan
    // driver and the validation layer.
    fn atexit(f: extern "C" fn()) -> std::os::raw::c_int;
}

/// Destroys the shared device at exit so the validation layer reports leaked objects; a
/// report fails the test binary (abort: nothing else can change the exit code by then).
extern "C" fn destroy_test_device() {
    let gpu = GPU.lock().unwrap_or_else(|e| e.into_inner()).take();
    let Some(gpu) = gpu else { return };
    let validated = gpu.info.validation;
    let before = VALIDATION_ERRORS.load(Ordering::SeqCst);
    drop(gpu);
    let after = VALIDATION_ERRORS.load(Ordering::SeqCst);
    if validated && after > before {
        eprintln!(
            "{} Vulkan validation error(s) when the test device was destroyed (leaked objects; see above)",
            after - before
        );
        std::process::abort();
    }
}

/// `LP_NUM_THREADS` for a bit-reproducible lavapipe run: no worker threads, so every
/// workgroup runs in order on the queue's own thread and float-atomic sums add in one order.
/// `0` rather than `1`: the same order and results, without handing each dispatch to a worker
/// (the built-in scene's 150-iteration fast train: 33.0 s at `1`, 30.0 s at `0`, same PSNR).
pub const LP_SERIAL: &str = "0";

/// Makes devices this process creates next bit-reproducible (see [`LP_SERIAL`]). A test that
/// needs it takes its device from [`serial_gpu`], which also checks the shared device obeyed.
pub fn serial_lavapipe() {
    std::env::set_var("LP_NUM_THREADS", LP_SERIAL);
}

/// Whether the shared device was created with serial lavapipe (or is not lavapipe).
static CREATED_SERIAL: AtomicBool = AtomicBool::new(false);

/// The shared device, bit-reproducible: lavapipe created serially ([`serial_lavapipe`]). The
/// device is created once per process, by whichever test asks first, so every test of a binary
/// that has a bit-reproducibility test must ask through here; one that called [`gpu`] first
/// makes this panic instead of letting the comparison fail by the thread scheduler's order.
pub fn serial_gpu() -> TestGpu {
    serial_lavapipe();
    let g = gpu();
    assert!(
        CREATED_SERIAL.load(Ordering::SeqCst),
        "this binary's test device was created with threaded lavapipe, by a test that asked \
         testing::gpu() for it before this one asked testing::serial_gpu(): every test of a \
         binary with a bit-reproducibility test must take its device from serial_gpu()"
    );
    g
}

/// Whether this process's lavapipe runs workgroups in a fixed order (`LP_NUM_THREADS` 0 or 1).
pub fn lavapipe_is_serial() -> bool {
    matches!(
        std::env::var("LP_NUM_THREADS").as_deref(),
        Ok("0") | Ok("1")
    )
}

/// The child process that runs a binary's half-1 tests ([`in_other_half`]) and the file its
/// output goes to; checked at exit.
static HALF_CHILD: Mutex<Option<(std::process::Child, PathBuf)>> = Mutex::new(None);

/// Waits for the half-1 child at exit; if it failed, prints its output and fails this binary
/// (abort: by then nothing else can change the exit code).
extern "C" fn check_half_child() {
    let child = HALF_CHILD.lock().unwrap_or_else(|e| e.into_inner()).take();
    let Some((mut child, log)) = child else {
        return;
    };
    let status = child.wait();
    let text = std::fs::read_to_string(&log).unwrap_or_default();
    let _ = std::fs::remove_file(&log);
    if !status.as_ref().is_ok_and(|s| s.success()) {
        eprintln!(
            "the tests of half 1, which ran in a child process of this binary, failed \
             ({status:?}); its output:\n{text}"
        );
        std::process::abort();
    }
}

/// Splits a binary whose tests run one at a time on one core (serial lavapipe behind the one
/// test device) over two processes: the first call starts a child process of this binary, with
/// the same arguments, that runs the tests marked half 1 while this process runs those marked
/// half 0. True when `this_test` belongs to the other process (the caller returns at once). A
/// failure in the child fails this binary at exit with the child's output (libtest has already
/// listed the half-1 tests as passed here; their results are the child's).
#[track_caller]
pub fn in_other_half(half: u8) -> bool {
    assert!(half < 2, "half must be 0 or 1, not {half}");
    if std::env::var_os("DISPFLOW_HALF").is_some() {
        return half != 1;
    }
    let mut guard = HALF_CHILD.lock().unwrap_or_else(|e| e.into_inner());
    if guard.is_none() {
        let exe = std::env::current_exe().expect("the test binary's path");
        let log = std::env::temp_dir().join(format!("dispflow-half1-{}.log", std::process::id()));
        let out = std::fs::File::create(&log).expect("the half-1 child's log file");
        let err = out.try_clone().expect("the half-1 child's log file");
        let child = std::process::Command::new(&exe)
            .args(std::env::args_os().skip(1))
            .env("DISPFLOW_HALF", "1")
            .stdout(out)
            .stderr(err)
            .spawn()
            .expect("start the half-1 child process");
        // SAFETY: registering a plain function with libc's atexit.
        unsafe { atexit(check_half_child) };
        *guard = Some((child, log));
    }
    half == 1
}

/// Whether this run is CI's (`CI=true`), where a skipped check is a failure.
pub fn in_ci() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true" || v == "1")
}

/// Marks a check that cannot run here: a failure under CI, a loud line otherwise.
pub fn skip(what: &str, why: &str) {
    if in_ci() {
        panic!("CI=true: {what} cannot run ({why}); a skipped check is a failure in CI");
    }
    eprintln!("SKIPPED {what}: {why}");
}

/// Devices that the library makes itself (inside `train`/`eval`/`render`) load the validation
/// layer too, unless `DISPFLOW_VALIDATION` says otherwise; those commands fail on a
/// validation error.
pub fn validate_command_devices() {
    if std::env::var_os("DISPFLOW_VALIDATION").is_none() {
        std::env::set_var("DISPFLOW_VALIDATION", "1");
    }
}

/// The process-wide test device, locked for the caller. Validation is on when the layer is
/// installed (`DISPFLOW_VALIDATION=required` makes a missing layer an error, as CI does; under
/// `CI=true` a missing layer fails too). Messages from creating the device fail the first
/// test; when the guard drops, any validation error reported meanwhile fails the test.
pub fn gpu() -> TestGpu {
    let mut guard = GPU.lock().unwrap_or_else(|e| e.into_inner());
    if guard.is_none() {
        let mut opts = GpuOptions::from_env();
        if opts.validation == Validation::Off
            && std::env::var("DISPFLOW_VALIDATION").as_deref() != Ok("0")
        {
            opts.validation = if in_ci() {
                Validation::Required
            } else {
                Validation::IfAvailable
            };
        }
        let gpu = Gpu::new(&opts).unwrap_or_else(|e| panic!("test device: {e}"));
        let serial = lavapipe_is_serial() || !gpu.info.name.contains("llvmpipe");
        CREATED_SERIAL.store(serial, Ordering::SeqCst);
        eprintln!(
            "test device: {} (subgroup {}, validation {})",
            gpu.info,
            gpu.info.subgroup_size,
            if gpu.info.validation { "on" } else { "off" }
        );
        if let Err(e) = gpu.check_validation("test device creation") {
            panic!("{e}");
        }
        // SAFETY: registering a plain function with libc's atexit.
        unsafe { atexit(destroy_test_device) };
        *guard = Some(gpu);
    } else if let Some(g) = guard.as_ref() {
        g.take_validation_errors(); // errors of an earlier, failed test are not ours
    }
    TestGpu { guard }
}

pub struct TestGpu {
    guard: MutexGuard<'static, Option<Gpu>>,
}

impl std::ops::Deref for TestGpu {
    type Target = Gpu;
    fn deref(&self) -> &Gpu {
        self.guard
            .as_ref()
            .expect("the test device exists until exit")
    }
}

impl Drop for TestGpu {
    fn drop(&mut self) {
        let Some(gpu) = self.guard.as_ref() else {
            return;
        };
        let errors = gpu.take_validation_errors();
        if !errors.is_empty() && !std::thread::panicking() {
            panic!(
                "{} Vulkan validation error(s):\n{}",
                errors.len(),
                errors.join("\n")
            );
        }
    }
}

/// SplitMix64: a tiny, fast, deterministic generator for test data.
pub struct Noise(u64);

impl Noise {
    pub fn new(seed: u64) -> Self {
        Noise(seed ^ 0x9E37_79B9_7F4A_7C15)
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    pub fn next_u32(&mut self) -> u32 {
        (self.next_u64() >> 32) as u32
    }
    pub fn u32s(&mut self, n: usize) -> Vec<u32> {
        (0..n).map(|_| self.next_u32()).collect()
    }
    pub fn u64s(&mut self, n: usize) -> Vec<u64> {
        (0..n).map(|_| self.next_u64()).collect()
    }

    /// `lo + (hi − lo)·u`, computed in `F`, with `u = next_u32() / 2³²` rounded once to `F`.
    ///
    /// In `f64`, `u` is exact: one of the 2³² values `k / 2³²` in `[0, 1 − 2⁻³²]`. In `f32`,
    /// `u` keeps 24 bits and the top 128 draws (probability 2⁻²⁵) round to exactly 1. So the
    /// result lies in `[lo, hi]`, `hi` included (in f32 through `u = 1`, in either type when
    /// `lo + (hi − lo)·u` rounds up), and `lo` itself comes with probability 2⁻³². A caller
    /// that needs draws above 0 adds half a step, `0.5 / 2³²`, itself.
    pub fn uniform<F: Real>(&mut self, lo: F, hi: F) -> F {
        lo + (hi - lo) * F::unit(self.next_u32())
    }

    /// `n` draws of [`Noise::uniform`] in order.
    pub fn uniforms<F: Real>(&mut self, n: usize, lo: F, hi: F) -> Vec<F> {
        (0..n).map(|_| self.uniform(lo, hi)).collect()
    }
}

/// The float types [`Noise::uniform`] draws: `f32` and `f64`.
pub trait Real:
    Copy + std::ops::Add<Output = Self> + std::ops::Sub<Output = Self> + std::ops::Mul<Output = Self>
{
    /// `bits / 2³²`, rounded once to this type.
    fn unit(bits: u32) -> Self;
}

impl Real for f32 {
    fn unit(bits: u32) -> f32 {
        bits as f32 / 4_294_967_296.0
    }
}

impl Real for f64 {
    fn unit(bits: u32) -> f64 {
        bits as f64 / 4_294_967_296.0
    }
}

/// How far a result may stray from its reference. The bounds are named at every use, so they
/// cannot trade places, and so is what `rel` scales.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Tol {
    /// `|got[i] − want[i]| ≤ abs + rel·|want[i]|` for every `i`.
    Elementwise { abs: f64, rel: f64 },
    /// `|got[i] − want[i]| ≤ abs + rel·max_j |want[j]|` for every `i`: one scale per tensor,
    /// for values whose f32 error follows the tensor's magnitude rather than each value's
    /// (sums of many products, gradients).
    Normwise { abs: f64, rel: f64 },
}

impl Tol {
    /// The largest `|got − want|` allowed where `|want| = want_abs`, in a slice whose largest
    /// `|want|` is `scale`.
    fn allowed(self, want_abs: f64, scale: f64) -> f64 {
        match self {
            Tol::Elementwise { abs, rel } => abs + rel * want_abs,
            Tol::Normwise { abs, rel } => abs + rel * scale,
        }
    }
}

/// What a passing [`assert_close`] measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Closeness {
    /// The largest `|got − want|`.
    pub max_diff: f64,
    /// The largest `|want|`.
    pub scale: f64,
    /// The largest `|got − want|` over what the tolerance allowed there (at most 1).
    pub worst_ratio: f64,
}

impl Closeness {
    /// The normwise relative error `max |got − want| / max |want|` (0 for an all-zero
    /// reference).
    pub fn normwise(&self) -> f64 {
        if self.scale > 0.0 {
            self.max_diff / self.scale
        } else {
            0.0
        }
    }
}

/// Asserts that `got` and `want` have the same length, hold only finite values, and are within
/// `tol` of each other everywhere; the failure names `what`, the worst element (the largest
/// `|got − want|` over what `tol` allows there) and the bound.
#[track_caller]
pub fn assert_close<G, W>(what: &str, got: &[G], want: &[W], tol: Tol) -> Closeness
where
    G: Copy + Into<f64>,
    W: Copy + Into<f64>,
{
    assert_eq!(got.len(), want.len(), "{what}: length");
    let scale = max_abs(want.iter().map(|&w| w.into()));
    let mut c = Closeness {
        max_diff: 0.0,
        scale,
        worst_ratio: 0.0,
    };
    // The worst element: a failing one before any passing one, then by `diff / allowed`.
    let mut worst: Option<(bool, f64, usize)> = None;
    for (i, (&g, &w)) in got.iter().zip(want).enumerate() {
        let (g, w): (f64, f64) = (g.into(), w.into());
        assert!(
            g.is_finite() && w.is_finite(),
            "{what}[{i}]: got {g}, want {w} (not finite)"
        );
        let (diff, allowed) = ((g - w).abs(), tol.allowed(w.abs(), scale));
        c.max_diff = c.max_diff.max(diff);
        let ratio = if diff == 0.0 { 0.0 } else { diff / allowed };
        let key = (diff > allowed, ratio);
        if worst.map_or(ratio > 0.0, |(f, r, _)| key > (f, r)) {
            worst = Some((key.0, ratio, i));
        }
    }
    if let Some((failed, ratio, i)) = worst {
        let (g, w): (f64, f64) = (got[i].into(), want[i].into());
        let (diff, allowed) = ((g - w).abs(), tol.allowed(w.abs(), scale));
        assert!(
            !failed,
            "{what}[{i}]: got {g}, want {w}: |diff| {diff:.3e} > {allowed:.3e} allowed by {tol:?} \
             (max |want| {scale:.3e})"
        );
        c.worst_ratio = ratio;
    }
    c
}

/// The largest `|x|` of `v`; 0 for none, and NaN entries are passed over (as `f64::max` does).
pub fn max_abs(v: impl IntoIterator<Item = impl std::borrow::Borrow<f64>>) -> f64 {
    v.into_iter().fold(0.0, |m, x| m.max(x.borrow().abs()))
}

/// Fills a device buffer with noise so no kernel can rely on zero-initialised memory.
pub fn fill_noise(gpu: &Gpu, buf: &crate::vk::Buffer, seed: u64) {
    let words = Noise::new(seed).u32s((buf.size() / 4) as usize);
    gpu.upload(buf.all(), &words).expect("noise upload");
}

/// The rotation `rz · ry · rx` of Euler angles `a` (radians), for test cameras.
pub fn rot_from_angles(a: [f64; 3]) -> [[f64; 3]; 3] {
    let (sx, cx) = a[0].sin_cos();
    let (sy, cy) = a[1].sin_cos();
    let (sz, cz) = a[2].sin_cos();
    let rx = [[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]];
    let ry = [[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]];
    let rz = [[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]];
    let mul = |a: [[f64; 3]; 3], b: [[f64; 3]; 3]| {
        let mut c = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                for k in 0..3 {
                    c[i][j] += a[i][k] * b[k][j];
                }
            }
        }
        c
    };
    mul(mul(rz, ry), rx)
}

/// The test every kernel test binary carries: the whole binary again at the subgroup sizes of
/// other devices (lavapipe: `LP_NATIVE_VECTOR_WIDTH` 1024 → 32 lanes as on NVIDIA, 128 → 4),
/// so no kernel can assume lavapipe's 8.
#[macro_export]
macro_rules! subgroup_reruns {
    () => {
        #[test]
        fn kernels_pass_at_other_subgroup_sizes() {
            $crate::testing::rerun_at_subgroup_sizes("kernels_pass_at_other_subgroup_sizes");
        }
    };
}

/// Whether this process is one of [`rerun_at_subgroup_sizes`]'s re-runs. A test whose size
/// exercises host-side chunking or serial depth, not lane counts, may shrink there: what the
/// re-runs check (no kernel assumes 8 lanes) shows within a few workgroups.
pub fn subgroup_rerun() -> bool {
    std::env::var_os("DISPFLOW_SUBGROUP_RERUN").is_some()
}

/// Re-runs the calling test binary (all its tests but `this_test`) with lavapipe vectors of
/// 1024 and 128 bits and checks that the device reported 32- and 4-lane subgroups.
pub fn rerun_at_subgroup_sizes(this_test: &str) {
    if subgroup_rerun() {
        return;
    }
    let lavapipe = gpu().info.name.contains("llvmpipe");
    if !lavapipe {
        skip(
            "subgroup-size re-runs",
            "they steer lavapipe, and this device is not lavapipe",
        );
        return;
    }
    let exe = std::env::current_exe().expect("the test binary's path");
    // Both re-runs at once: a kernel test's CPU twins and serial stretches leave a core idle.
    // Each width keeps its own compiled-shader cache: Mesa 22.3's key leaves the vector width
    // out, so a shader compiled at one width was run at another (the re-runs then tested the
    // default width's code, and the default run could pick up a re-run's).
    let cache = mesa_cache_dir();
    let rerun = |bits: u32| {
        let mut cmd = std::process::Command::new(&exe);
        cmd.args(["--skip", this_test, "--nocapture"])
            .env("LP_NATIVE_VECTOR_WIDTH", bits.to_string())
            .env("DISPFLOW_SUBGROUP_RERUN", "1");
        if let Some(dir) = &cache {
            cmd.env(
                "MESA_SHADER_CACHE_DIR",
                dir.join(format!("dispflow-lanes-{bits}")),
            );
        }
        cmd.output().expect("re-run the test binary")
    };
    let outs = std::thread::scope(|sc| {
        let wide = sc.spawn(|| rerun(1024));
        let narrow = rerun(128);
        [(1024, 32, wide.join().unwrap()), (128, 4, narrow)]
    });
    for (bits, lanes, out) in outs {
        let text = format!(
            "{}{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
        let tail: String = text
            .lines()
            .rev()
            .take(60)
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .collect::<Vec<_>>()
            .join("\n");
        assert!(
            out.status.success(),
            "{} at {lanes}-lane subgroups failed:\n{tail}",
            exe.display()
        );
        assert!(
            text.contains(&format!("(subgroup {lanes},")) || !text.contains("test device:"),
            "LP_NATIVE_VECTOR_WIDTH={bits} did not give {lanes}-lane subgroups:\n{tail}"
        );
    }
}

/// The directory Mesa keeps its compiled-shader cache under (`MESA_SHADER_CACHE_DIR`, else
/// `$XDG_CACHE_HOME`, else `~/.cache`; Mesa adds `mesa_shader_cache`).
fn mesa_cache_dir() -> Option<PathBuf> {
    std::env::var_os("MESA_SHADER_CACHE_DIR")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("XDG_CACHE_HOME").map(PathBuf::from))
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
}

/// Points a child `dispflow-vk` at a fresh home and cache under `root` (a test never reads or
/// writes the user's built-in scene or LPIPS weights), while the driver's compiled-shader cache
/// stays the one this process uses: Mesa keeps it under `$XDG_CACHE_HOME` too, and a cold one
/// costs lavapipe ~24 s of LLVM compilation per run (the tiny scene's 4-iteration train: 27.3 s
/// cold, 2.9 s warm), paid again by every test with a fresh cache.
pub fn isolated_home<'a>(
    cmd: &'a mut std::process::Command,
    root: &Path,
) -> &'a mut std::process::Command {
    let shared = mesa_cache_dir();
    cmd.env("HOME", root.join("home"))
        .env("XDG_CACHE_HOME", root.join("cache"));
    if let Some(dir) = shared {
        cmd.env("MESA_SHADER_CACHE_DIR", dir);
    }
    cmd
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_draws_are_the_documented_ones() {
        // f64 keeps all 32 bits: never 1. f32 rounds the top draws up to exactly 1.
        assert_eq!(f64::unit(u32::MAX), 1.0 - 2f64.powi(-32));
        assert_eq!(f32::unit(u32::MAX), 1.0);
        assert_eq!(f32::unit(u32::MAX - 127), 1.0); // the top 128 draws
        assert!(f32::unit(u32::MAX - 128) < 1.0);
        let (mut a, mut b) = (Noise::new(7), Noise::new(7));
        for _ in 0..1000 {
            let x = b.next_u32();
            let v: f32 = a.uniform(-2.0, 3.0);
            assert_eq!(v, -2.0 + 5.0 * (x as f32 / 4_294_967_296.0));
            assert!((-2.0..=3.0).contains(&v));
        }
        let v: Vec<f64> = Noise::new(3).uniforms(5, 0.0, 1.0);
        let want: Vec<f64> = Noise::new(3)
            .u32s(5)
            .iter()
            .map(|&x| x as f64 / 4_294_967_296.0)
            .collect();
        assert_eq!(v, want);
    }

    #[test]
    fn assert_close_scales_rel_by_each_value_or_the_largest() {
        let (got, want) = ([100.05f32, 1.002], [100.0f64, 1.0]);
        let passes = |tol| std::panic::catch_unwind(|| assert_close("t", &got, &want, tol)).is_ok();
        // 2e-3 relative at the small value, 5e-4 at the large one…
        assert!(!passes(Tol::Elementwise {
            abs: 0.0,
            rel: 1e-3
        }));
        assert!(passes(Tol::Elementwise {
            abs: 0.0,
            rel: 2.5e-3
        }));
        assert!(!passes(Tol::Elementwise {
            abs: 1e-3,
            rel: 0.0
        }));
        // …but both within 1e-3 of the largest |want|.
        assert!(passes(Tol::Normwise {
            abs: 0.0,
            rel: 1e-3
        }));
        let c = assert_close(
            "t",
            &got,
            &want,
            Tol::Normwise {
                abs: 0.0,
                rel: 1e-3,
            },
        );
        assert!((c.max_diff - 0.05).abs() < 1e-5 && c.scale == 100.0);
        assert!((c.normwise() - 5e-4).abs() < 1e-7 && c.worst_ratio <= 1.0);
        // Exact equality passes a zero tolerance; non-finite values never pass.
        assert_close(
            "t",
            &[0.0f32, 2.0],
            &[0.0f64, 2.0],
            Tol::Normwise { abs: 0.0, rel: 0.0 },
        );
        let nan = std::panic::catch_unwind(|| {
            assert_close(
                "t",
                &[f32::NAN],
                &[1.0f64],
                Tol::Normwise { abs: 1.0, rel: 1.0 },
            )
        });
        assert!(nan.is_err());
    }

    #[test]
    fn max_abs_takes_values_or_references() {
        assert_eq!(max_abs([1.0, -3.0, f64::NAN, 2.0]), 3.0);
        let v: &[f64] = &[-0.5, 0.25];
        assert_eq!(max_abs(v), 0.5);
        assert_eq!(max_abs(std::iter::empty::<f64>()), 0.0);
    }
}
