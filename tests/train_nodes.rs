//! Training through the control-node field (docs/nodes.md) on the tiny scene: with DispFlow
//! and densification the nodes are placed when the deformation starts, every parameter stays
//! finite, the nodes and the MLP move, a checkpoint round-trips (nodes, moments and KNN), a
//! resumed run reproduces the uninterrupted one bit for bit (single-threaded lavapipe, as
//! `train_resume`), and a checkpoint of the other field is refused by name.

use dispflow_vk::model::nodes::FieldKind;
use dispflow_vk::testing;
use dispflow_vk::train::checkpoint::Checkpoint;
use dispflow_vk::train::config::TrainConfig;
use dispflow_vk::train::Trainer;
use train_common::{run_to, tiny_dataset, tiny_motion_config};

mod train_common;

fn nodes_config() -> TrainConfig {
    // Densification at 20 and 40 (before and after the interruption) ...
    let mut cfg = tiny_motion_config();
    cfg.densify.until = 61; // ... and at the last step, 60 (`until` is exclusive, as the official)
    cfg.deform_field.kind = FieldKind::Nodes;
    cfg.deform_field.nodes = 24;
    cfg.deform_field.knn = 4;
    cfg.deform_field.knn_every = 15; // a KNN update at 45, after the interruption
    cfg
}

#[test]
fn nodes_field_trains_resumes_bit_exactly_and_is_refused_by_the_mlp_field() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::serial_gpu();
    let cfg = nodes_config();

    let mut a = Trainer::new(&gpu, &cfg, &ds).unwrap();
    run_to(&mut a, 20);
    assert!(
        !a.model.nodes.as_ref().unwrap().placed(),
        "warm-up: no node yet"
    );
    run_to(&mut a, 21);
    let placed = a.checkpoint().unwrap().model.nodes.expect("placed at 21");
    assert_eq!(placed.params.len(), 4 * 24);
    run_to(&mut a, 60);
    let straight = a.checkpoint().unwrap();
    let nodes = straight.model.nodes.as_ref().unwrap();
    assert!(nodes.params.iter().all(|v| v.is_finite()));
    assert!(
        nodes.params != placed.params,
        "node positions or radii never moved"
    );
    // Densified at 60: the KNN is stale (recomputed by the next step), so not saved.
    assert!(nodes.knn.is_empty());
    let moved = (straight.model.mlp_params.iter())
        .zip(&placed.params)
        .any(|(a, b)| a != b);
    assert!(moved);
    let e = a.evaluate(false).unwrap();
    assert!(e.iter().all(|f| f.psnr.is_finite()));
    drop(a);

    let mut b = Trainer::new(&gpu, &cfg, &ds).unwrap();
    run_to(&mut b, 30);
    let path = tmp.path().join("last.ckpt");
    b.checkpoint().unwrap().save(&path).unwrap();
    drop(b);
    let loaded = Checkpoint::load(&path).unwrap();
    let (knn, n) = (
        &loaded.model.nodes.as_ref().unwrap().knn,
        loaded.model.gaussians.len(),
    );
    assert_eq!(knn.len(), 4 * n, "the KNN of iteration 30 is saved");
    assert!(knn.iter().all(|&j| j < 24 || j == u32::MAX));
    assert!(knn.iter().any(|&j| j != u32::MAX));
    let mut c = Trainer::new(&gpu, &cfg, &ds).unwrap();
    c.restore(&loaded).unwrap();
    assert_eq!(c.iteration, 30);
    run_to(&mut c, 60);
    let resumed = c.checkpoint().unwrap();
    assert_eq!(
        resumed.model.nodes, straight.model.nodes,
        "nodes, moments or KNN differ after a resume"
    );
    assert!(
        resumed == straight,
        "resumed parameters, moments or statistics differ from the uninterrupted run"
    );
    drop(c);

    // The MLP field refuses the nodes run's checkpoint, naming the setting.
    let mut mlp_cfg = cfg.clone();
    mlp_cfg.deform_field.kind = FieldKind::Mlp;
    let mut d = Trainer::new(&gpu, &mlp_cfg, &ds).unwrap();
    let err = d.restore(&loaded).unwrap_err().to_string();
    assert!(err.contains("deform_field.kind"), "{err}");
}
