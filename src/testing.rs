//! Helpers for the conformance tests and benches: one shared validated device per process, and
//! deterministic noise.
//!
//! The validation layer (1.3.239) crashes now and then when several validated devices submit
//! from parallel threads, so every test in a binary shares one device behind a mutex: GPU tests
//! run one at a time while CPU-only tests stay parallel.

use std::sync::{Mutex, MutexGuard, OnceLock};

use crate::vk::{Gpu, GpuOptions, Validation};

static GPU: OnceLock<Mutex<Gpu>> = OnceLock::new();

/// The process-wide test device, locked for the caller. Validation is on when the layer is
/// installed (`DISPFLOW_VALIDATION=required` makes a missing layer an error, as CI does). When
/// the guard drops, any validation error reported meanwhile fails the test.
pub fn gpu() -> TestGpu {
    let m = GPU.get_or_init(|| {
        let mut opts = GpuOptions::from_env();
        if opts.validation == Validation::Off
            && std::env::var("DISPFLOW_VALIDATION").as_deref() != Ok("0")
        {
            opts.validation = Validation::IfAvailable;
        }
        let gpu = Gpu::new(&opts).unwrap_or_else(|e| panic!("test device: {e}"));
        eprintln!(
            "test device: {} (subgroup {}, validation {})",
            gpu.info,
            gpu.info.subgroup_size,
            if gpu.info.validation { "on" } else { "off" }
        );
        Mutex::new(gpu)
    });
    let guard = m.lock().unwrap_or_else(|e| e.into_inner());
    guard.take_validation_errors(); // errors of an earlier, failed test are not ours
    TestGpu { guard }
}

pub struct TestGpu {
    guard: MutexGuard<'static, Gpu>,
}

impl std::ops::Deref for TestGpu {
    type Target = Gpu;
    fn deref(&self) -> &Gpu {
        &self.guard
    }
}

impl Drop for TestGpu {
    fn drop(&mut self) {
        let errors = self.guard.take_validation_errors();
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
