//! Checkpoint → resume reproduces an uninterrupted run bit for bit.
//!
//! Why bit-exact is possible: every choice of the run (frame order, time noise, background,
//! split samples) is hashed from (seed, iteration), Adam's step count is the iteration, and
//! the checkpoint holds parameters, moments and densification statistics. The one source of
//! run-to-run variation on lavapipe is the order of float atomic additions in blend_bwd across
//! its worker threads, so this binary runs lavapipe serially (`testing::serial_gpu`). The
//! same bit-exactness shows that evaluating in the middle of a run changes nothing of training.
//! Serial lavapipe uses one core, so the tests split over two processes
//! (`testing::in_other_half`).

use dispflow_vk::testing;
use dispflow_vk::train::checkpoint::Checkpoint;
use dispflow_vk::train::Trainer;
use train_common::{run_to, spawn_transients, tiny_config, tiny_dataset, tiny_motion_config};

mod train_common;

#[test]
fn resume_reproduces_an_uninterrupted_run() {
    if testing::in_other_half(1) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    let mut cfg = tiny_config(60);
    cfg.warm_up = 25; // the MLP trains in both halves
    cfg.densify.from = 10;
    cfg.densify.interval = 20; // densify at 20 and 40: before and after the interruption

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

#[test]
fn evaluating_mid_run_does_not_change_training() {
    if testing::in_other_half(0) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    let cfg = tiny_motion_config();
    let run = |eval_at: Option<u32>| {
        let mut tr = Trainer::new(&gpu, &cfg, &ds).unwrap();
        while tr.iteration < 60 {
            if Some(tr.iteration) == eval_at {
                // Every path of the evaluator: scores, pictures, a free view, a PLY export.
                let per = tr.evaluate(true).unwrap();
                assert!(per.iter().all(|e| e.psnr.is_finite()));
                let cam = tr.val[0].camera;
                tr.render_view(&cam, 0.5, Some(0.25)).unwrap();
                tr.deformed_gaussians(0.7).unwrap();
            }
            tr.step(false, false).unwrap();
        }
        tr.checkpoint().unwrap()
    };
    let straight = run(None);
    // After the warm-up, between densifications, with the motion term on.
    assert!(
        run(Some(30)) == straight,
        "evaluating at iteration 30 changed the trained parameters, moments or statistics"
    );
}

/// A checkpoint taken while the model is split (flags and static deformations in it)
/// resumes bit-identically.
#[test]
fn split_checkpoint_resumes_bit_identically() {
    if testing::in_other_half(1) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    let mut cfg = tiny_config(120);
    cfg.warm_up = 40;
    cfg.sparsity.start = 0.1; // first split after 48, re-splits every 20
    cfg.sparsity.threshold_px = 0.0; // above the median: about half of them dynamic
    cfg.sparsity.noise_k = 1.0;
    cfg.densify.until = 0;
    cfg.sparsity.mode = dispflow_vk::train::config::SparsityMode::Auto;
    let run_to = |tr: &mut Trainer, end: u32| {
        while tr.iteration < end {
            tr.step(false, false).unwrap();
        }
    };
    let mut a = Trainer::new(&gpu, &cfg, &ds).unwrap();
    run_to(&mut a, 120);
    let straight = a.checkpoint().unwrap();
    let mut b = Trainer::new(&gpu, &cfg, &ds).unwrap();
    run_to(&mut b, 60);
    let c60 = b.checkpoint().unwrap();
    let split = c60
        .model
        .dynamic
        .as_ref()
        .expect("iteration 60 is inside a split stretch");
    let dynamic = split.flags.iter().filter(|&&f| f == 1).count();
    assert!(
        dynamic > 0 && dynamic < split.flags.len(),
        "{dynamic} dynamic"
    );
    let path = tmp.path().join("split.ckpt");
    c60.save(&path).unwrap();
    let mut c = Trainer::new(&gpu, &cfg, &ds).unwrap();
    c.restore(&Checkpoint::load(&path).unwrap()).unwrap();
    assert_eq!(c.dynamic_fraction(), b.dynamic_fraction());
    run_to(&mut c, 120);
    assert!(c.checkpoint().unwrap() == straight, "resumed run differs");
}

/// No kernel of a training step, a densification, a transient spawn or an evaluation reads
/// device memory that nothing wrote: two runs whose fresh buffers start as different words
/// (0 and a quiet NaN) end bit-identical. A read of such memory (a missing clear, a tail past
/// the written rows) differs between them, or turns the NaN run's numbers into NaN.
#[test]
fn memory_nothing_wrote_changes_nothing() {
    if testing::in_other_half(0) {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    let mut cfg = tiny_motion_config();
    spawn_transients(&mut cfg, 15, 0.3);
    /// Clears the poison however the run ends (the device is shared by this binary's tests).
    struct Clear<'a>(&'a dispflow_vk::vk::Gpu);
    impl Drop for Clear<'_> {
        fn drop(&mut self) {
            self.0.set_poison(None);
        }
    }
    let run = |word: u32| {
        gpu.set_poison(Some(word));
        let _clear = Clear(&gpu);
        let mut tr = Trainer::new(&gpu, &cfg, &ds).unwrap();
        let mut psnr = Vec::new();
        while tr.iteration < 60 {
            if tr.iteration == 35 {
                psnr = tr.evaluate(true).unwrap().iter().map(|e| e.psnr).collect();
            }
            tr.step(false, false).unwrap();
        }
        let transients = tr.model.gaussians.transient_rows().len();
        (tr.checkpoint().unwrap(), psnr, transients)
    };
    let (zero, zero_psnr, transients) = run(0);
    assert!(
        transients > 0,
        "no transient spawned: the test misses that path"
    );
    assert!(zero_psnr.iter().all(|p| p.is_finite()), "{zero_psnr:?}");
    let (nan, nan_psnr, _) = run(0x7fc0_0000);
    assert_eq!(
        zero_psnr.iter().map(|p| p.to_bits()).collect::<Vec<_>>(),
        nan_psnr.iter().map(|p| p.to_bits()).collect::<Vec<_>>(),
        "evaluation at 35: {zero_psnr:?} vs {nan_psnr:?}"
    );
    assert!(
        zero == nan,
        "fresh buffers of 0 and of NaN trained different parameters, moments or statistics"
    );
}
