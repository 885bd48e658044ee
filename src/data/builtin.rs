//! The built-in synthetic scene, generated once into the user's cache directory.

use std::path::PathBuf;

use super::synthetic::{self, Preset};
use crate::error::{Error, Result};

/// Where the built-in scene is cached: `$XDG_CACHE_HOME` or `~/.cache`, else `./.cache`.
pub fn cache_dir() -> PathBuf {
    let base = std::env::var_os("XDG_CACHE_HOME")
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or_else(|| PathBuf::from(".cache"));
    base.join("dispflow-vk")
}

/// The built-in scene (generated on first use; a complete generation is marked by
/// `synthetic.json`, so an interrupted one is redone).
pub fn builtin_scene(preset: Preset, seed: u64) -> Result<PathBuf> {
    let dir = cache_dir().join(format!("synthetic-{}-seed{seed}", preset.name()));
    if !dir.join("synthetic.json").is_file() {
        let tmp = dir.with_extension("partial");
        let _ = std::fs::remove_dir_all(&tmp);
        eprintln!(
            "generating the built-in synthetic scene ({}) into {}",
            preset.name(),
            dir.display()
        );
        synthetic::generate(preset, seed, &tmp)?;
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::rename(&tmp, &dir).map_err(|source| Error::Io {
            path: dir.display().to_string(),
            source,
        })?;
    }
    Ok(dir)
}
