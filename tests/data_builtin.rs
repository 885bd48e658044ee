//! The built-in scene's cache: concurrent callers (parallel runs of a local sweep) each get one
//! complete scene, and an incomplete cache left by an older version or an interrupted run is
//! regenerated instead of trained on.

use std::path::Path;
use std::sync::{Arc, Barrier};

use dispflow_vk::data::builtin::{builtin_scene_in, COMPLETE_MARKER};
use dispflow_vk::data::synthetic::{self, Preset};

fn count(dir: &Path) -> usize {
    std::fs::read_dir(dir).map(|d| d.count()).unwrap_or(0)
}

/// Every frame's image, mask and flow are on disk.
fn assert_complete(dir: &Path) {
    let frames = Preset::Tiny.dims().2;
    for sub in ["rgb/1x", "mask/1x", "flow", "camera"] {
        assert_eq!(count(&dir.join(sub)), frames, "{}/{sub}", dir.display());
    }
    assert!(dir.join(COMPLETE_MARKER).is_file());
}

#[test]
fn concurrent_callers_get_one_complete_scene() {
    let cache = tempfile::tempdir().unwrap();
    let n = 4;
    let start = Arc::new(Barrier::new(n));
    let dirs: Vec<_> = (0..n)
        .map(|_| {
            let (start, cache) = (start.clone(), cache.path().to_path_buf());
            std::thread::spawn(move || {
                start.wait();
                builtin_scene_in(&cache, Preset::Tiny, 3)
            })
        })
        .collect::<Vec<_>>()
        .into_iter()
        .map(|h| h.join().unwrap().expect("every caller gets the scene"))
        .collect();
    assert!(dirs.iter().all(|d| d == &dirs[0]));
    assert_complete(&dirs[0]);
    // No scratch directory is left behind.
    assert_eq!(count(cache.path()), 1);
}

#[test]
fn an_incomplete_cache_is_regenerated() {
    let cache = tempfile::tempdir().unwrap();
    let dir = cache.path().join("synthetic-tiny-seed3");
    // What a raced older version left: the scene's description but half its flow files.
    synthetic::generate(Preset::Tiny, 3, &dir).unwrap();
    let mut flows: Vec<_> = std::fs::read_dir(dir.join("flow"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    flows.sort();
    for f in &flows[flows.len() / 2..] {
        std::fs::remove_file(f).unwrap();
    }
    assert!(dir.join("synthetic.json").is_file());
    let got = builtin_scene_in(cache.path(), Preset::Tiny, 3).unwrap();
    assert_eq!(got, dir);
    assert_complete(&got);
    assert_eq!(count(cache.path()), 1);
    // A complete cache is used as it is (not regenerated: its files keep their times).
    let before = std::fs::metadata(got.join("flow").join(flows[0].file_name().unwrap()))
        .and_then(|m| m.modified())
        .unwrap();
    builtin_scene_in(cache.path(), Preset::Tiny, 3).unwrap();
    let after = std::fs::metadata(got.join("flow").join(flows[0].file_name().unwrap()))
        .and_then(|m| m.modified())
        .unwrap();
    assert_eq!(before, after);
}
