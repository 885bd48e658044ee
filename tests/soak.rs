//! Long training without growth: device allocations stop growing once densification has
//! ended (every buffer is allocated once per capacity; only the tile-intersection buffers grow,
//! on their first overflow at a view), and host memory stays flat.
//!
//! CI runs a short version. `tools/soak.sh` runs the long one (`DISPFLOW_SOAK_STEPS=10000`,
//! ignored test) and writes the curve as CSV: iteration, RSS, device bytes allocated and
//! reserved, live allocations, Gaussians.

use dispflow_vk::testing;
use dispflow_vk::train::Trainer;
use train_common::{tiny_config, tiny_dataset};

mod train_common;

/// Resident set size of this process, from /proc (0 where unavailable).
fn rss_bytes() -> u64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        .map_or(0, |kb| kb * 1024)
}

struct Sample {
    iteration: u32,
    rss: u64,
    allocated: u64,
    reserved: u64,
    allocations: usize,
    gaussians: u32,
}

/// Trains `steps` iterations (densification until `densify_until`, motion loss from a third
/// of the run) and samples memory every `every` iterations.
fn soak(steps: u32, densify_until: u32, every: u32) -> Vec<Sample> {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::gpu();
    let mut cfg = tiny_config(steps);
    cfg.warm_up = steps / 6;
    cfg.motion_weight = 0.1;
    cfg.motion_start = steps / 3;
    cfg.flow_preset = "fast".into();
    cfg.densify.from = densify_until / 5;
    cfg.densify.interval = (densify_until / 5).max(1);
    cfg.densify.until = densify_until;
    let mut tr = Trainer::new(&gpu, &cfg, &ds).unwrap();
    let mut samples = Vec::new();
    while tr.iteration < steps {
        tr.step(false, false).unwrap();
        if tr.iteration % every == 0 {
            let m = gpu.memory_use();
            samples.push(Sample {
                iteration: tr.iteration,
                rss: rss_bytes(),
                allocated: m.allocated_bytes,
                reserved: m.reserved_bytes,
                allocations: m.allocations,
                gaussians: tr.n(),
            });
        }
    }
    samples
}

fn print(samples: &[Sample]) -> String {
    let mut csv = String::from(
        "iteration,rss_bytes,device_allocated_bytes,device_reserved_bytes,allocations,gaussians\n",
    );
    for s in samples {
        csv += &format!(
            "{},{},{},{},{},{}\n",
            s.iteration, s.rss, s.allocated, s.reserved, s.allocations, s.gaussians
        );
    }
    eprint!("{csv}");
    csv
}

/// After two epochs past the densification window every view has been rendered at its final
/// Gaussian count, so nothing may allocate any more.
fn assert_flat_after(samples: &[Sample], from: u32) {
    let tail: Vec<&Sample> = samples.iter().filter(|s| s.iteration >= from).collect();
    assert!(tail.len() >= 2, "too few samples after iteration {from}");
    for s in &tail[1..] {
        assert_eq!(
            (s.allocations, s.allocated, s.reserved),
            (tail[0].allocations, tail[0].allocated, tail[0].reserved),
            "device memory grew between iterations {} and {}",
            tail[0].iteration,
            s.iteration
        );
    }
}

#[test]
fn device_allocations_stop_growing_after_densification() {
    let samples = soak(150, 45, 15);
    print(&samples);
    // 21 training frames: iteration 90 is two epochs after densification ended.
    assert_flat_after(&samples, 90);
}

#[test]
#[ignore = "long: run through tools/soak.sh"]
fn soak_long() {
    let steps: u32 = std::env::var("DISPFLOW_SOAK_STEPS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(10_000);
    let until = steps / 2;
    let samples = soak(steps, until, 500.min(steps / 4).max(1));
    let csv = print(&samples);
    if let Ok(p) = std::env::var("DISPFLOW_SOAK_CSV") {
        std::fs::write(&p, csv).unwrap();
    }
    assert_flat_after(&samples, until + until / 5);
}
