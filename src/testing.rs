//! Helpers for the conformance tests and benches: one shared validated device per process, and
//! deterministic noise.
//!
//! The validation layer (1.3.239) crashes now and then when several validated devices submit
//! from parallel threads, so every test in a binary shares one device behind a mutex: GPU tests
//! run one at a time while CPU-only tests stay parallel.

use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
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
    let rerun = |bits: u32| {
        std::process::Command::new(&exe)
            .args(["--skip", this_test, "--nocapture"])
            .env("LP_NATIVE_VECTOR_WIDTH", bits.to_string())
            .env("DISPFLOW_SUBGROUP_RERUN", "1")
            .output()
            .expect("re-run the test binary")
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

/// Points a child `dispflow-vk` at a fresh home and cache under `root` (a test never reads or
/// writes the user's built-in scene or LPIPS weights), while the driver's compiled-shader cache
/// stays the one this process uses: Mesa keeps it under `$XDG_CACHE_HOME` too, and a cold one
/// costs lavapipe ~24 s of LLVM compilation per run (the tiny scene's 4-iteration train: 27.3 s
/// cold, 2.9 s warm), paid again by every test with a fresh cache.
pub fn isolated_home<'a>(
    cmd: &'a mut std::process::Command,
    root: &Path,
) -> &'a mut std::process::Command {
    let shared = std::env::var_os("MESA_SHADER_CACHE_DIR")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("XDG_CACHE_HOME").map(PathBuf::from))
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")));
    cmd.env("HOME", root.join("home"))
        .env("XDG_CACHE_HOME", root.join("cache"));
    if let Some(dir) = shared {
        cmd.env("MESA_SHADER_CACHE_DIR", dir);
    }
    cmd
}
