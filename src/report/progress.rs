//! The terminal progress bar of the long loops: `eval`'s test frames, `render`'s views and a
//! sweep's cells.

/// A progress bar with ETA for `len` items of `what`.
pub fn progress(len: u64, what: &str) -> indicatif::ProgressBar {
    let pb = indicatif::ProgressBar::new(len);
    pb.set_style(
        indicatif::ProgressStyle::with_template(&format!(
            "{what} {{bar:30}} {{pos}}/{{len}} [{{elapsed_precise}}<{{eta_precise}}] {{msg}}"
        ))
        .expect("progress template"),
    );
    pb
}
