//! The built-in synthetic scene, generated once into the user's cache directory.
//!
//! Several processes may ask for it at once (a local sweep, parallel training runs): each
//! generates into its own scratch directory and renames it into place, so a reader never sees
//! another's half-written scene. A scene counts as complete only with its `.complete` marker,
//! written after every file; a directory without it (an interrupted or raced older cache) is
//! moved aside and regenerated.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use super::synthetic::{self, Preset};
use crate::data::DataError;
use crate::error::Result;

/// Written last into a generated scene: its presence means every frame is on disk.
pub const COMPLETE_MARKER: &str = ".complete";

/// Where the built-in scene is cached: `$XDG_CACHE_HOME` or `~/.cache`, else `./.cache`.
pub fn cache_dir() -> PathBuf {
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(|| PathBuf::from(".cache"));
    base.join("dispflow-vk")
}

/// The built-in scene in the user's cache (generated on first use).
pub fn builtin_scene(preset: Preset, seed: u64) -> Result<PathBuf> {
    builtin_scene_in(&cache_dir(), preset, seed)
}

/// The built-in scene under `cache` (generated on first use, safe against concurrent callers).
pub fn builtin_scene_in(cache: &Path, preset: Preset, seed: u64) -> Result<PathBuf> {
    let dir = cache.join(format!("synthetic-{}-seed{seed}", preset.name()));
    if is_complete(&dir) {
        return Ok(dir);
    }
    std::fs::create_dir_all(cache).map_err(|e| DataError::write(cache, e))?;
    let tmp = scratch(&dir, "partial");
    eprintln!(
        "generating the built-in synthetic scene ({}) into {}",
        preset.name(),
        dir.display()
    );
    let generated = synthetic::generate(preset, seed, &tmp).and_then(|_| {
        std::fs::write(tmp.join(COMPLETE_MARKER), b"").map_err(|e| DataError::write(&tmp, e))
    });
    if let Err(e) = generated {
        let _ = std::fs::remove_dir_all(&tmp);
        return Err(e.into());
    }
    if dir.exists() && !is_complete(&dir) {
        // An incomplete older cache: move it aside in one step (another process may be doing
        // the same; whoever loses finds it gone), then delete it.
        let stale = scratch(&dir, "stale");
        if std::fs::rename(&dir, &stale).is_ok() {
            let _ = std::fs::remove_dir_all(&stale);
        }
    }
    match std::fs::rename(&tmp, &dir) {
        Ok(()) => Ok(dir),
        // Another process finished first: its scene is the same, use it.
        Err(_) if is_complete(&dir) => {
            let _ = std::fs::remove_dir_all(&tmp);
            Ok(dir)
        }
        Err(source) => {
            let _ = std::fs::remove_dir_all(&tmp);
            Err(DataError::write(&dir, source).into())
        }
    }
}

fn is_complete(dir: &Path) -> bool {
    dir.join(COMPLETE_MARKER).is_file()
}

/// A sibling of `dir` no other caller (process or thread) uses.
fn scratch(dir: &Path, what: &str) -> PathBuf {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    dir.with_extension(format!("{what}-{}-{n}", std::process::id()))
}
