//! The Vulkan layer: device facts, the hazard tracker, timestamps, validation wiring, errors.

use dispflow_vk::kernels::scan::{Count, PrefixSum};
use dispflow_vk::shaders;
use dispflow_vk::testing;
use dispflow_vk::vk::{Gpu, GpuOptions, Recorder, Validation};

#[test]
fn device_reports_queried_limits() {
    let gpu = testing::gpu();
    let i = &gpu.info;
    assert!(
        i.subgroup_size >= 1 && i.subgroup_size.is_power_of_two(),
        "subgroup size {}",
        i.subgroup_size
    );
    assert!(
        i.max_shared_memory >= 16 * 1024,
        "shared memory {}",
        i.max_shared_memory
    );
    assert!(i.max_workgroup_invocations >= 256);
    assert!(i.float_atomic_add);
    eprintln!("{i:#?}");
}

#[test]
fn barriers_only_where_data_flows() {
    let gpu = testing::gpu();
    let a = gpu.buffer("a", 1024).unwrap();
    let b = gpu.buffer("b", 1024).unwrap();
    let mut rec = Recorder::new(&gpu).unwrap();
    rec.fill(a.slice(0, 512), 1);
    rec.fill(a.slice(512, 512), 2); // disjoint range: no barrier
    rec.fill(b.all(), 3); // other buffer: no barrier
    assert_eq!(rec.barrier_count(), 0);
    rec.copy(a.slice(0, 256), b.slice(0, 256)); // reads a (written): RAW → barrier
    assert_eq!(rec.barrier_count(), 1);
    rec.copy(a.slice(512, 256), b.slice(256, 256)); // nothing written since the barrier
    assert_eq!(rec.barrier_count(), 1);
    rec.fill(a.slice(0, 4), 9); // overwrites what the first copy read: WAR → barrier
    assert_eq!(rec.barrier_count(), 2);
    rec.finish().unwrap();
    let got: Vec<u32> = gpu.read(b.elems::<u32>(0, 128)).unwrap();
    assert!(got[..64].iter().all(|&x| x == 1) && got[64..].iter().all(|&x| x == 2));
}

#[test]
fn validation_catches_a_missing_barrier() {
    let gpu = testing::gpu();
    if !gpu.info.validation {
        testing::skip(
            "the missing-barrier check",
            "the validation layer is not installed (apt-get install vulkan-validationlayers)",
        );
        return;
    }
    let a = gpu.buffer("a", 1024).unwrap();
    let b = gpu.buffer("b", 1024).unwrap();
    let mut rec = Recorder::new(&gpu).unwrap();
    rec.disable_hazard_tracking_for_tests();
    rec.fill(a.all(), 1);
    rec.copy(a.all(), b.all()); // read-after-write with no barrier
    rec.finish().unwrap();
    // What `train`, `eval` and `render` do at their end: the command fails with the messages.
    let e = gpu
        .check_validation("the test command")
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("SYNC-HAZARD") && e.contains("during the test command"),
        "synchronisation validation should report the hazard, got: {e}"
    );
    gpu.check_validation("nothing since").unwrap();
}

#[test]
fn timestamps_time_every_dispatch() {
    let gpu = testing::gpu();
    if gpu.info.timestamp_period_ns.is_none() {
        eprintln!("skipped: the compute queue has no timestamps");
        return;
    }
    let scan = PrefixSum::new(&gpu).unwrap();
    let n = 100_000u32;
    let s = scan.scratch(&gpu, n).unwrap();
    let buf = gpu.buffer_from("data", &vec![1u32; n as usize]).unwrap();
    let mut rec = Recorder::timed(&gpu).unwrap();
    rec.set_zone("scan");
    scan.record(&mut rec, &s, buf.all(), buf.all(), Count::Host(n));
    let dispatches = rec.dispatch_count();
    let t = rec.finish().unwrap();
    assert_eq!(t.entries.len() as u32, dispatches);
    assert!(
        t.entries
            .iter()
            .all(|(l, ms)| l.starts_with("scan/") && ms.is_finite() && *ms >= 0.0),
        "{t:?}"
    );
    assert!(t.total_ms() > 0.0);
    let got: Vec<u32> = gpu.read(buf.elems::<u32>(n as u64 - 1, 1)).unwrap();
    assert_eq!(got[0], n - 1);
}

#[test]
fn a_device_builds_each_pipeline_once_and_keeps_it_while_used() {
    let gpu = testing::gpu();
    let a = gpu.pipeline(&shaders::scan::SCAN_SETUP).unwrap();
    let b = gpu.pipeline(&shaders::scan::SCAN_SETUP).unwrap();
    let other = gpu.pipeline(&shaders::scan::SCAN_REDUCE).unwrap();
    assert_eq!(a.raw(), b.raw(), "the same shader, the same pipeline");
    assert_ne!(a.raw(), other.raw());
    drop((a, b, other));
    // A wrapper dropped and another built: the second one's pipelines work (the device keeps
    // them; the validation layer reports any use of a destroyed one, and leaks at exit).
    drop(PrefixSum::new(&gpu).unwrap());
    let scan = PrefixSum::new(&gpu).unwrap();
    let n = 5_000u32;
    let s = scan.scratch(&gpu, n).unwrap();
    let buf = gpu.buffer_from("data", &vec![1u32; n as usize]).unwrap();
    let mut rec = Recorder::new(&gpu).unwrap();
    scan.record(&mut rec, &s, buf.all(), buf.all(), Count::Host(n));
    rec.finish().unwrap();
    let got: Vec<u32> = gpu.read(buf.elems::<u32>(n as u64 - 1, 1)).unwrap();
    assert_eq!(got[0], n - 1);
}

#[test]
fn unknown_device_override_is_a_clear_error() {
    let opts = GpuOptions {
        validation: Validation::Off,
        device: Some("no-such-gpu-xyz".into()),
        poison: None,
    };
    match Gpu::new(&opts) {
        Err(e) => {
            let msg = e.to_string();
            assert!(
                msg.contains("no-such-gpu-xyz") && msg.contains("have:"),
                "{msg}"
            );
        }
        Ok(_) => panic!("a device named no-such-gpu-xyz should not exist"),
    }
}

#[test]
fn poisoned_buffers_start_filled_with_the_word() {
    let gpu = testing::gpu();
    gpu.set_poison(Some(0x7fc0_0001));
    let b = gpu.buffer("poisoned", 40);
    gpu.set_poison(None);
    let got: Vec<u32> = gpu.read(b.unwrap().all()).unwrap();
    assert_eq!(got, vec![0x7fc0_0001; 10]);
    assert_eq!(gpu.poison(), None);
}
