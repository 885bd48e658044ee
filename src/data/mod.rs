//! Dataset loaders and the built-in synthetic scene (DESIGN §4, §7).
//!
//! - [`nerfies`]: NeRF-DS / HyperNeRF / Nerfies captures (`dataset.json`, `camera/*.json`, ...).
//! - [`blender`]: D-NeRF / blender scenes (`transforms_{train,val,test}.json`).
//! - [`points`]: initial points (`points.npy`, COLMAP `points3D.bin` aligned to the JSON cameras,
//!   PLY, or random in the scene bounds).
//! - [`synthetic`]: an analytic scene generator that writes the nerfies format plus exact motion
//!   masks and ground-truth 2D scene flow.
//! - [`check`]: the `data check` report; [`cli`]: the `data` subcommand.
//!
//! Loading is all-or-nothing: [`load`] returns a complete [`Dataset`] or a [`DataError`] that names
//! the file, the field and what was expected. Nothing in here panics on malformed input.
//!
//! Conventions of a loaded [`Dataset`]:
//! - cameras are OpenCV pinhole cameras with a principal point (x right, y down, z forward), world
//!   to camera `p_cam = R·p + t`; distortion (if the source had any) has been removed by resampling
//!   the images at load ([`image::undistort`]);
//! - continuous pixel coordinates have their origin at the top-left corner of the image, so the
//!   centre of pixel `(i, j)` is `(i + 0.5, j + 0.5)`; scaling an image by `1/s` scales
//!   `fx, fy, cx, cy` by `1/s`;
//! - times are in `[0, 1]`;
//! - images are row-major `H×W×3` f32 in `[0, 1]` (8-bit code value / 255, no transfer-function
//!   change); motion masks are row-major `H×W` u8 with moving = 1.

pub mod background;
pub mod blender;
pub mod builtin;
pub mod camera;
pub mod check;
pub mod cli;
pub mod image;
mod json;
pub mod nerfies;
pub mod points;
pub mod synthetic;

use std::path::{Path, PathBuf};

pub use camera::{Camera, Distortion};
pub use image::Image;
pub use points::{InitPoints, PointSource, PointsPreference};

/// Errors from loading or generating datasets: each names the file, the field and what was expected.
#[derive(Debug, thiserror::Error)]
pub enum DataError {
    /// A file could not be opened or read (missing, permission, ...).
    #[error("{path}: cannot read: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// A file could not be written (generator, caches).
    #[error("{path}: cannot write: {source}")]
    Write {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// A JSON file is not valid JSON.
    #[error("{path}: invalid JSON: {msg}")]
    Json { path: String, msg: String },
    /// A field is missing, of the wrong type or out of range.
    #[error("{path}: field \"{field}\": expected {expected}, found {found}")]
    Field {
        path: String,
        field: String,
        expected: String,
        found: String,
    },
    /// Anything else about one file (unreadable PNG, wrong image size, NaN in points, ...).
    #[error("{path}: {msg}")]
    File { path: String, msg: String },
    /// The directory is neither a nerfies nor a blender dataset.
    #[error("{path}: unknown dataset format: {msg}")]
    UnknownFormat { path: String, msg: String },
}

impl DataError {
    pub(crate) fn io(path: &Path, source: std::io::Error) -> Self {
        DataError::Io {
            path: path.display().to_string(),
            source,
        }
    }
    pub(crate) fn write(path: &Path, source: std::io::Error) -> Self {
        DataError::Write {
            path: path.display().to_string(),
            source,
        }
    }
    pub(crate) fn file(path: &Path, msg: impl Into<String>) -> Self {
        DataError::File {
            path: path.display().to_string(),
            msg: msg.into(),
        }
    }
}

/// Result alias for this module.
pub type DataResult<T> = std::result::Result<T, DataError>;

/// Which on-disk format a dataset directory holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// `dataset.json` + `camera/*.json` + `rgb/<s>x/*.png` (NeRF-DS, HyperNeRF, Nerfies).
    Nerfies,
    /// `transforms_{train,val,test}.json` (D-NeRF, blender).
    Blender,
}

impl std::fmt::Display for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Format::Nerfies => write!(f, "nerfies (dataset.json, camera/*.json)"),
            Format::Blender => write!(f, "D-NeRF/blender (transforms_*.json)"),
        }
    }
}

/// Detects the format of a dataset directory.
pub fn detect_format(dir: &Path) -> DataResult<Format> {
    if !dir.exists() {
        return Err(DataError::File {
            path: dir.display().to_string(),
            msg: "no such directory; expected a dataset directory (nerfies or D-NeRF format)"
                .into(),
        });
    }
    if !dir.is_dir() {
        return Err(DataError::File {
            path: dir.display().to_string(),
            msg: "not a directory; expected a dataset directory (nerfies or D-NeRF format)".into(),
        });
    }
    if dir.join("dataset.json").is_file() {
        Ok(Format::Nerfies)
    } else if dir.join("transforms_train.json").is_file() {
        Ok(Format::Blender)
    } else {
        Err(DataError::UnknownFormat {
            path: dir.display().to_string(),
            msg: "expected dataset.json (nerfies format) or transforms_train.json (D-NeRF/blender \
                  format)"
                .into(),
        })
    }
}

/// Options for [`load`]. `Default` gives: highest resolution available, no size limit, black
/// background, automatic initial points (100 000 random points when no file is found), seed 0,
/// progress bar only on a terminal, images decoded and kept.
#[derive(Clone, Debug)]
pub struct LoadOptions {
    /// nerfies: load `rgb/<s>x` for this `s` (error if absent). blender: box-downscale by `s`.
    /// `None`: the highest resolution available (then `max_size` applies).
    pub downscale: Option<u32>,
    /// Largest allowed image side in pixels: images are box-downscaled by the smallest integer
    /// factor that brings both sides within it (nerfies first picks the best `rgb/<s>x`).
    pub max_size: Option<u32>,
    /// Background colour (RGB in `[0,1]`) used to composite RGBA images and to fill pixels that
    /// undistortion maps outside the source image.
    pub background: [f32; 3],
    /// The background was picked from the images' alpha ([`background::pick_background`]), so
    /// the loader does not warn that views disagree about what is transparent.
    pub background_from_data: bool,
    /// Where the initial points come from.
    pub points: PointsPreference,
    /// Number of random points when falling back to random initialisation.
    pub random_points: usize,
    /// Seed for random points.
    pub seed: u64,
    /// Show a progress bar (only drawn when stderr is a terminal).
    pub progress: bool,
    /// Keep decoded pixels. `false` still decodes and validates every image and mask (sizes,
    /// readability) but leaves `Image::data`, masks and flows empty: what `data check` uses to
    /// inspect large datasets without holding them in memory.
    pub keep_pixels: bool,
}

impl Default for LoadOptions {
    fn default() -> Self {
        LoadOptions {
            downscale: None,
            max_size: None,
            background: [0.0; 3],
            background_from_data: false,
            points: PointsPreference::Auto,
            random_points: 100_000,
            seed: 0,
            progress: true,
            keep_pixels: true,
        }
    }
}

/// One training or evaluation view.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Image id (nerfies id, or the blender `file_path`).
    pub id: String,
    /// The image file the pixels came from.
    pub image_path: PathBuf,
    /// Pinhole camera (with principal point) at the loaded resolution, after undistortion.
    pub camera: Camera,
    /// Time in `[0, 1]`.
    pub time: f32,
    /// `H×W×3` RGB in `[0,1]` (empty data when loaded with `keep_pixels = false`).
    pub image: Image,
    /// `H×W` motion mask, moving = 1, when the dataset provides one.
    pub mask: Option<Vec<u8>>,
    /// `H×W×2` ground-truth 2D scene flow in pixels (synthetic scenes: `flow/<id>.npy`).
    pub flow: Option<Vec<f32>>,
}

/// Axis-aligned scene bounds in the normalised world frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    pub min: glam::Vec3,
    pub max: glam::Vec3,
}

impl Bounds {
    /// Bounds of a non-empty set of points; `None` when empty.
    pub fn of(points: &[glam::Vec3]) -> Option<Bounds> {
        let first = *points.first()?;
        let mut b = Bounds {
            min: first,
            max: first,
        };
        for p in points {
            b.min = b.min.min(*p);
            b.max = b.max.max(*p);
        }
        Some(b)
    }
    pub fn extent(&self) -> glam::Vec3 {
        self.max - self.min
    }
    pub fn center(&self) -> glam::Vec3 {
        0.5 * (self.min + self.max)
    }
}

/// A fully loaded dataset (never half-loaded: [`load`] returns this or an error).
#[derive(Clone, Debug)]
pub struct Dataset {
    pub format: Format,
    pub root: PathBuf,
    pub train: Vec<Frame>,
    /// Evaluation frames (nerfies `val_ids`; blender `transforms_test.json`, else `_val`).
    pub val: Vec<Frame>,
    /// Initial points in the normalised world frame.
    pub points: InitPoints,
    /// Scene bounds in the normalised world frame.
    pub bounds: Bounds,
    /// Background colour used at load.
    pub background: [f32; 3],
    /// Near/far planes when the dataset gives them (nerfies `scene.json`, normalised).
    pub near_far: Option<(f32, f32)>,
    /// Extra downscale factor applied at load on top of the chosen source resolution.
    pub downscale: u32,
    /// Things a user should know (distortion removed, no val split, ...).
    pub warnings: Vec<String>,
    /// What the loader did (source resolution, undistortion, split rule, ...).
    pub notes: Vec<String>,
}

impl Dataset {
    /// All frames, train first.
    pub fn frames(&self) -> impl Iterator<Item = &Frame> {
        self.train.iter().chain(self.val.iter())
    }
}

/// Loads a dataset directory, detecting its format.
pub fn load(dir: &Path, opts: &LoadOptions) -> DataResult<Dataset> {
    match detect_format(dir)? {
        Format::Nerfies => nerfies::load(dir, opts),
        Format::Blender => blender::load(dir, opts),
    }
}

/// A progress bar drawn on stderr only when it is a terminal and `enabled`.
pub(crate) fn progress_bar(len: u64, msg: &str, enabled: bool) -> indicatif::ProgressBar {
    use std::io::IsTerminal;
    if !enabled || !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let pb = indicatif::ProgressBar::new(len);
    if let Ok(style) =
        indicatif::ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} ({eta})")
    {
        pb.set_style(style.progress_chars("=> "));
    }
    pb.set_message(msg.to_string());
    pb
}

/// The smallest integer factor that brings `(w, h)` within `max_size` (1 when `None`).
pub(crate) fn factor_for_max(w: u32, h: u32, max_size: Option<u32>) -> u32 {
    match max_size {
        Some(m) if m > 0 => w.max(h).div_ceil(m).max(1),
        _ => 1,
    }
}
