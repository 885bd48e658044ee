//! Pictures and tables for `dispflow-vk eval` and `render`, drawn on the CPU.
//!
//! Evaluation turns renders, ground truth and motion maps into PNGs a person can check at a
//! glance, and metrics into Markdown tables that read well in a terminal and parse back:
//! - [`colormap`]: heat maps (INFERNO), masks, render-vs-ground-truth error, plain renders;
//! - [`strip`]: labelled panels side by side, and atomic PNG writing;
//! - [`plot`]: line plots of training/eval curves;
//! - [`progress()`]: the terminal progress bar of long loops (eval, render, sweep cells);
//! - [`table`]: Markdown metric tables;
//! - [`text`]: the 8x8 bitmap text all of the above use.
//!
//! Everything is self-contained (no system fonts or plotting libraries), so it works on CI
//! machines and never needs the GPU.

pub mod colormap;
mod draw;
pub mod plot;
mod progress;
pub mod strip;
pub mod table;
pub mod text;

pub use colormap::{error_map, heatmap, mask_image, rgb_image, ERROR_FULL_SCALE};
pub use plot::{stacked, Plot, Series, PALETTE};
pub use progress::progress;
pub use strip::{labelled_strip, save_png};
pub use table::{fmt_metric, Table};
pub use text::{draw_text, text_width};
