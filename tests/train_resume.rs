//! Checkpoint → resume reproduces an uninterrupted run bit for bit.
//!
//! Why bit-exact is possible: every choice of the run (frame order, time noise, background,
//! split samples) is hashed from (seed, iteration), Adam's step count is the iteration, and
//! the checkpoint holds parameters, moments and densification statistics. The one source of
//! run-to-run variation on lavapipe is the order of float atomic additions in blend_bwd across
//! its worker threads, so this binary (one test) runs lavapipe with LP_NUM_THREADS=1.

use dispflow_vk::testing;
use dispflow_vk::train::checkpoint::Checkpoint;
use dispflow_vk::train::Trainer;
use train_common::{tiny_config, tiny_dataset};

mod train_common;

#[test]
fn resume_reproduces_an_uninterrupted_run() {
    // Must happen before the device exists (the first testing::gpu() call).
    std::env::set_var("LP_NUM_THREADS", "1");
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::gpu();
    let mut cfg = tiny_config(60);
    cfg.warm_up = 25; // the MLP trains in both halves
    cfg.densify.from = 10;
    cfg.densify.interval = 20; // densify at 20 and 40: before and after the interruption

    let run_to = |tr: &mut Trainer, end: u32| {
        while tr.iteration < end {
            tr.step(false, false).unwrap();
        }
    };
    let mut a = Trainer::new(&gpu, &cfg, &ds).unwrap();
    run_to(&mut a, 60);
    let straight = a.checkpoint().unwrap();
    drop(a);

    let mut b = Trainer::new(&gpu, &cfg, &ds).unwrap();
    run_to(&mut b, 30);
    let path = tmp.path().join("last.ckpt");
    b.checkpoint().unwrap().save(&path).unwrap();
    drop(b);
    let mut c = Trainer::new(&gpu, &cfg, &ds).unwrap();
    c.restore(&Checkpoint::load(&path).unwrap()).unwrap();
    assert_eq!(c.iteration, 30);
    run_to(&mut c, 60);
    let resumed = c.checkpoint().unwrap();

    assert_eq!(resumed.iteration, straight.iteration);
    assert_eq!(
        resumed.model.gaussians.len(),
        straight.model.gaussians.len(),
        "same densification"
    );
    assert!(
        resumed == straight,
        "resumed parameters, moments or statistics differ from the uninterrupted run"
    );
}
