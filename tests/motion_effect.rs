//! The DispFlow-GS claim in miniature: on the tiny synthetic scene (exact motion masks), the
//! motion-supervised run concentrates its displacement flow on the moving pixels better than
//! the Deformable-3DGS baseline trained with the same seed and iterations (higher MMAP).
//! The full comparison (built-in scene, mujoco) lives in `tools/compare_motion.sh`.

mod train_common;

use dispflow_vk::data::{self, LoadOptions};
use dispflow_vk::testing;
use dispflow_vk::train::cli::motion_means;
use dispflow_vk::train::config::{MotionOrder, TrainConfig};
use dispflow_vk::train::Trainer;
use train_common::{tiny_config, tiny_scene};

struct Outcome {
    psnr: f64,
    mmap: f64,
    drc: f64,
}

fn train(ds: &data::Dataset, cfg: &TrainConfig) -> Outcome {
    let gpu = testing::gpu();
    let mut tr = Trainer::new(&gpu, cfg, ds).unwrap();
    while tr.iteration < cfg.iterations {
        tr.step(false, false).unwrap();
    }
    let per = tr.evaluate(false).unwrap();
    let (mmap, drc) = motion_means(&per);
    let psnr = per.iter().map(|e| e.values.psnr).sum::<f64>() / per.len() as f64;
    for e in &per {
        assert!(e.values.psnr.is_finite() && e.drc.is_some_and(|d| (0.0..=1.0).contains(&d)));
        assert!(e.ap.is_none_or(|a| (0.0..=1.0).contains(&a)));
    }
    Outcome {
        psnr,
        mmap: mmap.expect("the tiny scene has motion masks"),
        drc: drc.expect("every test frame but the first has a predecessor"),
    }
}

fn config(weight: f32) -> TrainConfig {
    let mut c = tiny_config(300);
    c.warm_up = 100;
    c.motion_start = 150;
    c.flow_preset = "fast".into();
    c.motion_weight = weight;
    c
}

#[test]
fn motion_loss_raises_mmap_over_the_baseline() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tiny_scene(tmp.path());
    let opts = LoadOptions {
        progress: false,
        ..LoadOptions::default()
    };
    let ds = data::load(&dir, &opts).unwrap();
    let weights: Vec<f32> = std::env::var("DISPFLOW_MOTION_WEIGHTS")
        .map(|s| s.split(',').map(|w| w.parse().unwrap()).collect())
        .unwrap_or_else(|_| vec![0.1]);
    let base = train(&ds, &config(0.0));
    eprintln!(
        "baseline: PSNR {:.3} MMAP {:.4} DRC {:.4}",
        base.psnr, base.mmap, base.drc
    );
    for &w in &weights {
        for order in [MotionOrder::Direct] {
            let mut c = config(w);
            c.motion_order = order;
            let m = train(&ds, &c);
            eprintln!(
                "alpha {w} {order:?}: PSNR {:.3} MMAP {:.4} DRC {:.4}",
                m.psnr, m.mmap, m.drc
            );
            assert!(
                m.mmap > base.mmap,
                "alpha {w}: MMAP {:.4} not above the baseline's {:.4}",
                m.mmap,
                base.mmap
            );
        }
    }
}
