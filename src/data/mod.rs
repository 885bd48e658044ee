//! Dataset loaders and the built-in synthetic scene (filled in by the datasets issue).

/// Errors from loading or generating datasets: each names the file, the field and what was expected.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    #[error("{path}: {msg}")]
    File { path: String, msg: String },
}
