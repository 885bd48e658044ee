//! Checkpoint integrity: every blob carries a checksum that is checked on load, the format
//! version is checked by name, and a restore refuses non-finite values and checkpoints of
//! another configuration (SH degree, MLP size, Gaussian budget) — before it changes anything.

use std::path::Path;

use dispflow_vk::model::gaussians::HostGaussians;
use dispflow_vk::testing;
use dispflow_vk::train::checkpoint::{Checkpoint, CHECKPOINT_VERSION};
use dispflow_vk::train::config::TrainConfig;
use dispflow_vk::train::Trainer;
use train_common::{tiny_config, tiny_dataset};

mod train_common;

/// A small checkpoint built on the host (no GPU): 3 Gaussians of SH degree 2.
fn host_checkpoint() -> Checkpoint {
    let mut c = Checkpoint {
        iteration: 7,
        ..Default::default()
    };
    c.model.gaussians = HostGaussians::from_points(
        &[[0.0, 0.0, 1.0], [1.0, 0.0, 1.0], [0.0, 1.0, 2.0]],
        None,
        2,
    )
    .unwrap();
    c.model.gauss_m = c.model.gaussians.clone();
    c.model.gauss_v = c.model.gaussians.clone();
    c.model.gauss_v.log_scales = vec![[0.5; 3]; 3]; // second moments are >= 0
    c.model.shape.mlp_depth = 2;
    c.model.shape.mlp_width = 16;
    c.model.shape.budget = 100;
    c.densify_stats = [vec![1.0; 3], vec![2.0; 3], vec![3.0; 3]];
    c.model.mlp_params = (0..10).map(|i| i as f32 * 0.5).collect();
    c.model.mlp_m = vec![0.25; 10];
    c.model.mlp_v = vec![0.125; 10];
    c
}

/// The JSON header of a checkpoint file and the byte offset where the blobs start.
#[test]
fn round_trip_temp_file_and_truncation() {
    let tmp = tempfile::tempdir().unwrap();
    let c = host_checkpoint();
    let p = tmp.path().join("last.ckpt");
    c.save(&p).unwrap();
    assert_eq!(Checkpoint::load(&p).unwrap(), c);
    assert!(
        !dispflow_vk::train::checkpoint::temp_path(&p).exists(),
        "the temp file was renamed away"
    );
    let bytes = std::fs::read(&p).unwrap();
    for cut in [0, 7, 20, bytes.len() / 2, bytes.len() - 1] {
        std::fs::write(&p, &bytes[..cut]).unwrap();
        let e = load_err(&p);
        assert!(e.contains("last.ckpt"), "error names the file: {e}");
    }
}

fn header(bytes: &[u8]) -> (serde_json::Value, usize) {
    let hl = u64::from_le_bytes(bytes[8..16].try_into().unwrap()) as usize;
    let h = serde_json::from_slice(&bytes[16..16 + hl]).unwrap();
    (h, 16 + hl + 8)
}

fn load_err(p: &Path) -> String {
    Checkpoint::load(p).unwrap_err().to_string()
}

#[test]
fn a_flipped_byte_in_any_blob_is_refused_with_the_blobs_name() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("last.ckpt");
    let c = host_checkpoint();
    c.save(&p).unwrap();
    assert_eq!(Checkpoint::load(&p).unwrap(), c);
    let bytes = std::fs::read(&p).unwrap();
    let (h, mut at) = header(&bytes);
    assert_eq!(h["version"], CHECKPOINT_VERSION);
    let blobs = h["blobs"].as_array().unwrap();
    assert_eq!(blobs.len(), 24, "18 Gaussian, 3 MLP and 3 statistics blobs");
    let mut checked = 0;
    for b in blobs {
        let name = b["name"].as_str().unwrap();
        let len = b["floats"].as_u64().unwrap() as usize * 4;
        assert!(b["fnv1a64"].as_str().is_some_and(|s| s.len() == 16), "{b}");
        if len > 0 {
            // One bit of the middle byte: a change no length check can see.
            let mut bad = bytes.clone();
            bad[at + len / 2] ^= 0x01;
            std::fs::write(&p, &bad).unwrap();
            let e = load_err(&p);
            assert!(
                e.contains("last.ckpt")
                    && e.contains(&format!("blob {name}:"))
                    && e.contains("checksum"),
                "flipped byte in {name}: {e}"
            );
            checked += 1;
        }
        at += len;
    }
    assert_eq!(at, bytes.len(), "the header lists every blob");
    assert_eq!(checked, 24, "every blob is non-empty here");
    // A changed byte in the header is refused as well (its own checksum).
    let mut bad = bytes.clone();
    let digit = bytes
        .windows(12)
        .position(|w| w == b"\"iteration\":")
        .unwrap()
        + 12;
    bad[digit] = b'9';
    std::fs::write(&p, &bad).unwrap();
    let e = load_err(&p);
    assert!(e.contains("last.ckpt") && e.contains("header"), "{e}");
}

#[test]
fn another_format_version_is_named() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("last.ckpt");
    host_checkpoint().save(&p).unwrap();
    let bytes = std::fs::read(&p).unwrap();
    let (mut h, blobs_at) = header(&bytes);
    for v in [1u32, CHECKPOINT_VERSION + 1] {
        h["version"] = v.into();
        let hb = serde_json::to_vec(&h).unwrap();
        let mut out = b"DFVKCKPT".to_vec();
        out.extend_from_slice(&(hb.len() as u64).to_le_bytes());
        out.extend_from_slice(&hb);
        out.extend_from_slice(&bytes[blobs_at - 8..]);
        std::fs::write(&p, &out).unwrap();
        let e = load_err(&p);
        assert!(
            e.contains("last.ckpt")
                && e.contains(&format!("version {v}"))
                && e.contains(&format!("reads version {CHECKPOINT_VERSION}")),
            "{e}"
        );
    }
}

/// A tiny trainer after a few steps (the deformation network trains from step 2 on).
fn trained<'g>(
    gpu: &'g dispflow_vk::vk::Gpu,
    cfg: &TrainConfig,
    ds: &dispflow_vk::data::Dataset,
) -> Trainer<'g> {
    let mut tr = Trainer::new(gpu, cfg, ds).unwrap();
    while tr.iteration < cfg.iterations {
        tr.step(false, false).unwrap();
    }
    tr
}

/// Changes one value of a checkpoint.
type Poison<'a> = Box<dyn Fn(&mut Checkpoint) + 'a>;

fn restore_err(tr: &mut Trainer, c: &Checkpoint) -> String {
    let before = tr.checkpoint().unwrap();
    let e = tr.restore(c).unwrap_err().to_string();
    assert!(
        tr.checkpoint().unwrap() == before,
        "a refused restore left the model changed ({e})"
    );
    e
}

#[test]
fn restore_refuses_non_finite_values_and_other_configurations() {
    let tmp = tempfile::tempdir().unwrap();
    let ds = tiny_dataset(tmp.path());
    let gpu = testing::gpu();
    let mut cfg = tiny_config(4);
    cfg.warm_up = 1;
    let mut tr = trained(&gpu, &cfg, &ds);
    let good = tr.checkpoint().unwrap();
    assert_eq!(good.model.shape.mlp_width, 16);
    let p = tmp.path().join("last.ckpt");

    // Saved with a NaN / an infinity / a negative second moment: the checksums are right, so
    // the file loads; the restore refuses it by blob name (and Gaussian).
    let n = good.model.gaussians.len();
    let cases: Vec<(&str, Poison)> = vec![
        (
            "blob means: element 7 (Gaussian 2) is NaN",
            Box::new(|c| c.model.gaussians.means[2][1] = f32::NAN),
        ),
        (
            "blob sh_dc:",
            Box::new(|c| c.model.gaussians.sh_dc[n - 1][0] = f32::INFINITY),
        ),
        (
            "blob m.quats:",
            Box::new(|c| c.model.gauss_m.quats[0][3] = f32::NEG_INFINITY),
        ),
        (
            "blob v.opacity: element 5 (Gaussian 5) is -0.5",
            Box::new(|c| c.model.gauss_v.opacity[5] = -0.5),
        ),
        (
            "blob mlp_params: element 11 is NaN",
            Box::new(|c| c.model.mlp_params[11] = f32::NAN),
        ),
        ("blob mlp_v:", Box::new(|c| c.model.mlp_v[0] = f32::NAN)),
        (
            "blob grad_accum:",
            Box::new(|c| c.densify_stats[0][3] = f32::NAN),
        ),
    ];
    for (want, poison) in &cases {
        let mut c = good.clone();
        poison(&mut c);
        c.save(&p).unwrap();
        let c = Checkpoint::load(&p).unwrap();
        let e = restore_err(&mut tr, &c);
        assert!(e.contains(want), "want {want:?} in: {e}");
    }

    // Another configuration: each gets an error naming the setting.
    let other = |f: &dyn Fn(&mut TrainConfig), want: &[&str]| {
        let mut c2 = cfg.clone();
        f(&mut c2);
        let mut tr2 = Trainer::new(&gpu, &c2, &ds).unwrap();
        let e = restore_err(&mut tr2, &good);
        assert!(want.iter().all(|w| e.contains(w)), "want {want:?} in: {e}");
    };
    other(
        &|c| c.sh_degree = 2,
        &["SH degree", "degree 1", "sh_degree = 2"],
    );
    other(&|c| c.mlp_width = 32, &["MLP", "2×16", "mlp_width = 32"]);
    other(&|c| c.mlp_depth = 3, &["MLP", "2×16", "mlp_depth = 3"]);
    other(&|c| c.densify.budget = 9000, &["budget", "8000", "9000"]);

    // The untouched checkpoint restores, through the file, into a fresh trainer.
    good.save(&p).unwrap();
    let mut fresh = Trainer::new(&gpu, &cfg, &ds).unwrap();
    fresh.restore(&Checkpoint::load(&p).unwrap()).unwrap();
    assert_eq!(fresh.iteration, 4);
    assert!(fresh.checkpoint().unwrap() == good);
}

/// Transient Gaussians (format version 4): the header's count and the `time` / `velocity` blobs
/// (with their moments) round-trip; a version-3 checkpoint, written before transients, still
/// loads as a model without them.
/// [`host_checkpoint`] with its last `k` rows transient (centre 0.4, log-width −3, a velocity).
fn with_transients(k: usize) -> Checkpoint {
    let mut c = host_checkpoint();
    for g in [
        &mut c.model.gaussians,
        &mut c.model.gauss_m,
        &mut c.model.gauss_v,
    ] {
        g.transients = k;
        g.time = (0..3)
            .map(|i| if i + k >= 3 { [0.4, -3.0] } else { [0.0; 2] })
            .collect();
        g.velocity = (0..3)
            .map(|i| {
                if i + k >= 3 {
                    [0.5, -0.25, 1.0]
                } else {
                    [0.0; 3]
                }
            })
            .collect();
    }
    c
}

#[test]
fn transients_round_trip_and_a_version_3_checkpoint_still_loads() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("last.ckpt");
    let mut c = with_transients(1);
    c.model.gauss_v.time[2] = [0.01, 0.02]; // second moments are >= 0
    c.model.gauss_v.velocity[2] = [0.1, 0.2, 0.3];
    c.save(&p).unwrap();
    assert_eq!(Checkpoint::load(&p).unwrap(), c);
    let bytes = std::fs::read(&p).unwrap();
    let (h, _) = header(&bytes);
    assert_eq!(h["transients"], 1);
    let names: Vec<&str> = h["blobs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["name"].as_str().unwrap())
        .collect();
    for n in ["time", "velocity", "m.time", "v.velocity"] {
        assert!(names.contains(&n), "{n} in {names:?}");
    }
    // Without transients nothing new is written; relabelled version 3, it loads.
    let plain = tmp.path().join("plain.ckpt");
    let c3 = host_checkpoint();
    c3.save(&plain).unwrap();
    let bytes = std::fs::read(&plain).unwrap();
    let (mut h, blobs_at) = header(&bytes);
    assert!(h.get("transients").is_none());
    h["version"] = 3.into();
    let hb = serde_json::to_vec(&h).unwrap();
    let mut out = b"DFVKCKPT".to_vec();
    out.extend_from_slice(&(hb.len() as u64).to_le_bytes());
    out.extend_from_slice(&hb);
    out.extend_from_slice(&dispflow_vk::train::checkpoint::fnv1a64(&hb).to_le_bytes());
    out.extend_from_slice(&bytes[blobs_at..]);
    std::fs::write(&plain, &out).unwrap();
    assert_eq!(Checkpoint::load(&plain).unwrap(), c3);
    // A header that claims more transients than Gaussians is refused by name.
    let mut h2 = h.clone();
    h2["version"] = CHECKPOINT_VERSION.into();
    h2["transients"] = 9.into();
    let hb = serde_json::to_vec(&h2).unwrap();
    let mut out = b"DFVKCKPT".to_vec();
    out.extend_from_slice(&(hb.len() as u64).to_le_bytes());
    out.extend_from_slice(&hb);
    out.extend_from_slice(&dispflow_vk::train::checkpoint::fnv1a64(&hb).to_le_bytes());
    out.extend_from_slice(&bytes[blobs_at..]);
    std::fs::write(&plain, &out).unwrap();
    let e = load_err(&plain);
    assert!(e.contains("9 transients among 3 Gaussians"), "{e}");
}

/// The spawns' state (their looks and the depth hypotheses waiting to be resolved) round-trips;
/// one that names rows outside the transients, or frames the data does not have, is refused by
/// name.
#[test]
fn the_spawn_state_round_trips_and_a_bad_one_is_refused_by_name() {
    use dispflow_vk::train::transients::resolve::Hypotheses;
    use dispflow_vk::train::transients::spawn::Looks;
    use dispflow_vk::train::transients::SpawnState;
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("last.ckpt");
    let mut c = with_transients(2);
    c.model.gauss_v.time = vec![[0.0, 0.0]; 3]; // second moments are >= 0
    c.model.gauss_v.velocity = vec![[0.0; 3]; 3];
    let mut looks = Looks::default();
    let by_time = [3, 0, 2, 1];
    assert_eq!(looks.candidates(&by_time, 2, 0.8, 1), vec![3, 2]);
    looks.judge(3, 12.5, 0.8, 1);
    looks.opened = Some(5);
    c.spawns = Some(SpawnState {
        looks,
        hypotheses: Some(Hypotheses {
            iteration: 5,
            groups: vec![1..2, 2..3],
        }),
    });
    c.save(&p).unwrap();
    let back = Checkpoint::load(&p).unwrap();
    assert_eq!(back, c);
    let s = back.spawns.unwrap();
    let rows = c.model.gaussians.populations();
    assert_eq!(s.problem(rows, Some(4)), None);
    let e = s.problem(rows, Some(3)).expect("frame 3 of 3");
    assert!(e.contains("frame 3; the data has 3 training frames"), "{e}");
    // Hypotheses on a canonical row.
    let mut bad = c.clone();
    bad.spawns.as_mut().unwrap().hypotheses = Some(Hypotheses {
        iteration: 5,
        groups: vec![0..2, 2..3],
    });
    bad.save(&p).unwrap();
    let e = load_err(&p);
    assert!(
        e.contains("last.ckpt")
            && e.contains("depth hypotheses at rows 0..2")
            && e.contains("1..3"),
        "{e}"
    );
}
