//! nerfies-format loader (NeRF-DS, HyperNeRF, Nerfies captures).
//! Over 600 lines: each of the format's files has its reader with its own field-by-field
//! error messages; they share the normalisation and split rules documented here.
//!
//! Reads `dataset.json`, `metadata.json`, `scene.json`, `camera/<id>.json`, `rgb/<s>x/<id>.png`,
//! optional `mask/<s>x/<id>.png.png` (moving = white), optional `flow/<id>.npy` (synthetic
//! scenes: full-resolution `H×W×2` pixels), and initial points (see [`super::points`]).
//!
//! - Time: `time_id` of `metadata.json`, else `warp_id`, normalised over the dataset to `[0,1]`.
//! - Positions (cameras and points) are normalised `p' = (p − center)·scale` with `scene.json`;
//!   rotations are unchanged; `near`/`far` are taken as given (already in normalised units).
//! - Split: `train_ids` / `val_ids` of `dataset.json`. When only one is given the other is the
//!   rest of `ids`; when neither is, every 8th id (index % 8 == 0, the LLFF hold-out rule) is
//!   validation and the others train.
//! - Images at `rgb/<s>x` use intrinsics divided by `s`. Distortion and skew are removed at load:
//!   each image is resampled to the pinhole camera with the same `fx, fy, cx, cy`
//!   ([`super::image::undistort`]); masks and flows are resampled by nearest neighbour.
//!
//! Over 600 lines: the format has five JSON files plus per-frame cameras and images, each
//! validated with errors naming file and field.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};

use glam::{DVec3, Mat3, Vec3};
use rayon::prelude::*;

use super::camera::{mat3_from_rows, rotation_defect, Camera, Distortion};
use super::image::{self as img, Image};
use super::json::{self, field_err, Obj};
use super::points::{self, InitPoints, PointSource, PointsPreference};
use super::{
    factor_for_max, progress_bar, Bounds, DataError, DataResult, Dataset, Format, Frame,
    LoadOptions,
};

/// A parsed `camera/<id>.json` (raw world units, full resolution).
#[derive(Clone, Debug)]
pub struct NerfiesCamera {
    /// World-to-camera rotation.
    pub orientation: glam::DMat3,
    /// Camera centre (raw world units).
    pub position: DVec3,
    pub focal_length: f64,
    pub pixel_aspect_ratio: f64,
    pub principal_point: [f64; 2],
    pub distortion: Distortion,
    /// `[width, height]` at full resolution.
    pub image_size: [u32; 2],
}

/// Parses one `camera/<id>.json`. Older files name the tangential field `tangential`.
pub fn read_camera(path: &Path) -> DataResult<NerfiesCamera> {
    let v = json::read(path)?;
    let o = Obj::root(path, &v)?;
    let rows = o.matrix("orientation", 3, 3)?;
    let orientation = mat3_from_rows(&rows);
    let (defect, det) = rotation_defect(&orientation);
    if defect > 1e-3 || det < 0.0 {
        return Err(field_err(
            path,
            "orientation",
            "a rotation matrix (orthonormal rows, determinant +1)",
            format!("a matrix with |RᵀR − I| = {defect:.2e} and determinant {det:.3}"),
        ));
    }
    let p = o.nums("position", &[3])?;
    let focal_length = o.positive("focal_length")?;
    let pixel_aspect_ratio = match o.opt_f64("pixel_aspect_ratio")? {
        None => 1.0,
        Some(a) if a > 0.0 => a,
        Some(a) => {
            return Err(field_err(
                path,
                "pixel_aspect_ratio",
                "a positive number",
                format!("{a}"),
            ))
        }
    };
    let pp = o.nums("principal_point", &[2])?;
    let skew = o.opt_f64("skew")?.unwrap_or(0.0);
    let radial = o
        .opt_nums("radial_distortion", &[0, 1, 2, 3])?
        .unwrap_or_default();
    let tangential = match o.opt_nums("tangential_distortion", &[0, 2])? {
        Some(t) => t,
        None => o.opt_nums("tangential", &[0, 2])?.unwrap_or_default(),
    };
    let size = o.nums("image_size", &[2])?;
    let mut image_size = [0u32; 2];
    for (i, s) in size.iter().enumerate() {
        if !(*s >= 1.0 && s.fract() == 0.0 && *s <= 65536.0) {
            return Err(field_err(
                path,
                &format!("image_size[{i}]"),
                "a positive integer number of pixels",
                format!("{s}"),
            ));
        }
        image_size[i] = *s as u32;
    }
    let r = |i: usize| radial.get(i).copied().unwrap_or(0.0);
    let t = |i: usize| tangential.get(i).copied().unwrap_or(0.0);
    Ok(NerfiesCamera {
        orientation,
        position: DVec3::new(p[0], p[1], p[2]),
        focal_length,
        pixel_aspect_ratio,
        principal_point: [pp[0], pp[1]],
        distortion: Distortion {
            k1: r(0),
            k2: r(1),
            k3: r(2),
            p1: t(0),
            p2: t(1),
            skew,
        },
        image_size,
    })
}

/// `scene.json`: normalisation and bounds.
#[derive(Clone, Debug)]
pub struct SceneNorm {
    pub scale: f64,
    pub center: DVec3,
    pub near_far: Option<(f64, f64)>,
    /// Raw-unit bbox when given.
    pub bbox: Option<(DVec3, DVec3)>,
}

impl SceneNorm {
    pub fn apply(&self, p: DVec3) -> DVec3 {
        (p - self.center) * self.scale
    }
}

pub fn read_scene(path: &Path) -> DataResult<SceneNorm> {
    let v = json::read(path)?;
    let o = Obj::root(path, &v)?;
    let scale = o.positive("scale")?;
    let c = o.nums("center", &[3])?;
    let near = o.opt_f64("near")?;
    let far = o.opt_f64("far")?;
    let near_far = match (near, far) {
        (Some(n), Some(f)) if n >= 0.0 && f > n => Some((n, f)),
        (None, None) => None,
        (n, f) => {
            return Err(field_err(
                path,
                "near/far",
                "0 ≤ near < far",
                format!("near {n:?}, far {f:?}"),
            ))
        }
    };
    let bbox = match o.opt("bbox") {
        None => None,
        Some(_) => {
            let b = o.matrix("bbox", 2, 3)?;
            Some((
                DVec3::new(b[0][0], b[0][1], b[0][2]),
                DVec3::new(b[1][0], b[1][1], b[1][2]),
            ))
        }
    };
    Ok(SceneNorm {
        scale,
        center: DVec3::new(c[0], c[1], c[2]),
        near_far,
        bbox,
    })
}

/// The `train_ids` / `val_ids` split of `dataset.json` (see the module docs for the rule).
pub struct Split {
    pub ids: Vec<String>,
    pub train: Vec<String>,
    pub val: Vec<String>,
    pub rule: String,
}

pub fn read_split(path: &Path) -> DataResult<Split> {
    let v = json::read(path)?;
    let o = Obj::root(path, &v)?;
    let ids = o.strings("ids")?;
    if ids.is_empty() {
        return Err(field_err(
            path,
            "ids",
            "a non-empty array of ids",
            "an empty array",
        ));
    }
    let mut seen = HashSet::new();
    for (i, id) in ids.iter().enumerate() {
        if !seen.insert(id.as_str()) {
            return Err(field_err(
                path,
                &format!("ids[{i}]"),
                "unique ids",
                format!("a second {id:?}"),
            ));
        }
        if id.is_empty() || id.contains(['/', '\\']) || id.starts_with('.') {
            return Err(field_err(
                path,
                &format!("ids[{i}]"),
                "a plain file stem",
                format!("{id:?}"),
            ));
        }
    }
    let listed = |field: &str| -> DataResult<Option<Vec<String>>> {
        if !o.has(field) {
            return Ok(None);
        }
        let v = o.strings(field)?;
        for (i, id) in v.iter().enumerate() {
            if !seen.contains(id.as_str()) {
                return Err(field_err(
                    path,
                    &format!("{field}[{i}]"),
                    "an id listed in \"ids\"",
                    format!("{id:?}"),
                ));
            }
        }
        Ok(Some(v))
    };
    let rest = |given: &[String]| -> Vec<String> {
        let g: HashSet<&str> = given.iter().map(String::as_str).collect();
        ids.iter()
            .filter(|i| !g.contains(i.as_str()))
            .cloned()
            .collect()
    };
    let (train, val, rule) = match (listed("train_ids")?, listed("val_ids")?) {
        (Some(t), Some(v)) => (t, v, "train_ids / val_ids of dataset.json".to_string()),
        (Some(t), None) => {
            let v = rest(&t);
            (t, v, "train_ids; val = the other ids".into())
        }
        (None, Some(v)) => (rest(&v), v, "val_ids; train = the other ids".into()),
        (None, None) => {
            let (mut t, mut v) = (Vec::new(), Vec::new());
            for (i, id) in ids.iter().enumerate() {
                if i % 8 == 0 && ids.len() > 1 {
                    v.push(id.clone());
                } else {
                    t.push(id.clone());
                }
            }
            (
                t,
                v,
                "no train_ids/val_ids: every 8th id (index % 8 == 0) is val".into(),
            )
        }
    };
    if train.is_empty() {
        return Err(field_err(
            path,
            "train_ids",
            "at least one training frame",
            "an empty split",
        ));
    }
    Ok(Split {
        ids,
        train,
        val,
        rule,
    })
}

/// Times from `metadata.json` for `ids` (`time_id`, else `warp_id`), normalised to `[0, 1]`.
/// Returns the times and which field was used.
pub fn read_times(path: &Path, ids: &[String]) -> DataResult<(Vec<f32>, &'static str)> {
    let v = json::read(path)?;
    let o = Obj::root(path, &v)?;
    let mut raw = Vec::with_capacity(ids.len());
    let mut used = "time_id";
    for (k, id) in ids.iter().enumerate() {
        let entry = o.req(id, "an object with time_id or warp_id")?;
        let e = Obj::of(path, id, entry, id)?;
        let (name, val) = if let Some(t) = e.opt("time_id") {
            ("time_id", t)
        } else if let Some(t) = e.opt("warp_id") {
            ("warp_id", t)
        } else {
            return Err(field_err(
                path,
                &format!("{id}.time_id"),
                "a number (time_id, or warp_id when time_id is absent)",
                "nothing (missing)",
            ));
        };
        if k == 0 {
            used = name;
        }
        raw.push(json::num(path, &format!("{id}.{name}"), val)?);
    }
    let lo = raw.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = raw.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let times = raw
        .iter()
        .map(|t| {
            if hi > lo {
                ((t - lo) / (hi - lo)) as f32
            } else {
                0.0
            }
        })
        .collect();
    Ok((times, used))
}

/// The `rgb/<s>x` scales present.
fn available_scales(dir: &Path) -> DataResult<Vec<u32>> {
    let rgb = dir.join("rgb");
    let rd = std::fs::read_dir(&rgb).map_err(|e| DataError::io(&rgb, e))?;
    let mut s: Vec<u32> = rd
        .filter_map(|e| e.ok())
        .filter(|e| e.path().is_dir())
        .filter_map(|e| {
            let n = e.file_name().to_string_lossy().into_owned();
            n.strip_suffix('x')?.parse::<u32>().ok().filter(|s| *s > 0)
        })
        .collect();
    s.sort_unstable();
    if s.is_empty() {
        return Err(DataError::file(
            &rgb,
            "no image folders; expected rgb/<s>x/ (e.g. rgb/1x, rgb/4x)",
        ));
    }
    Ok(s)
}

fn choose_scale(dir: &Path, opts: &LoadOptions, full: [u32; 2]) -> DataResult<u32> {
    let avail = available_scales(dir)?;
    if let Some(s) = opts.downscale {
        if !avail.contains(&s) {
            return Err(DataError::file(
                &dir.join(format!("rgb/{s}x")),
                format!("missing; the capture has rgb/{{{avail:?}}}x"),
            ));
        }
        return Ok(s);
    }
    if let Some(m) = opts.max_size.filter(|m| *m > 0) {
        let longest = full[0].max(full[1]);
        if let Some(s) = avail.iter().find(|s| longest.div_ceil(**s) <= m) {
            return Ok(*s);
        }
        return Ok(*avail.last().unwrap_or(&1));
    }
    Ok(avail[0])
}

struct FrameSpec<'a> {
    id: &'a str,
    time: f32,
    cam: &'a NerfiesCamera,
    centre: Vec3,
}

struct FrameCtx<'a> {
    dir: &'a Path,
    scale: u32,
    masks: bool,
    flows: bool,
    opts: &'a LoadOptions,
}

fn load_frame(ctx: &FrameCtx, f: &FrameSpec) -> DataResult<Frame> {
    let s = ctx.scale as f64;
    let path = ctx.dir.join(format!("rgb/{}x/{}.png", ctx.scale, f.id));
    let image = img::load_rgb(&path, ctx.opts.background)?;
    let [fw, fh] = f.cam.image_size;
    let near = |a: u32, full: u32| (a as f64 - full as f64 / s).abs() < 1.0;
    if !near(image.width, fw) || !near(image.height, fh) {
        return Err(DataError::file(
            &path,
            format!(
                "image is {}×{}; expected {}×{} (camera image_size {fw}×{fh} divided by {})",
                image.width,
                image.height,
                (fw as f64 / s).round(),
                (fh as f64 / s).round(),
                ctx.scale
            ),
        ));
    }
    let (w, h) = (image.width, image.height);
    let fx = f.cam.focal_length / s;
    let fy = f.cam.focal_length * f.cam.pixel_aspect_ratio / s;
    let k = [
        fx,
        fy,
        f.cam.principal_point[0] / s,
        f.cam.principal_point[1] / s,
    ];
    let dist = Distortion {
        skew: f.cam.distortion.skew / s,
        ..f.cam.distortion
    };
    let image = img::undistort(&image, k, &dist, ctx.opts.background);
    let extra = factor_for_max(w, h, ctx.opts.max_size);
    let image = img::downscale(&image, extra);
    let camera = Camera::from_centre(
        Mat3::from_cols_array(&f.cam.orientation.as_mat3().to_cols_array()),
        f.centre,
        [k[0] as f32, k[1] as f32, k[2] as f32, k[3] as f32],
        w,
        h,
    )
    .scaled(1.0 / extra as f32, image.width, image.height);

    let mask = if ctx.masks {
        let mp = ctx
            .dir
            .join(format!("mask/{}x/{}.png.png", ctx.scale, f.id));
        let (mw, mh, m) = img::load_gray(&mp)?;
        if (mw, mh) != (w, h) {
            return Err(DataError::file(
                &mp,
                format!("mask is {mw}×{mh}; expected {w}×{h} like its image"),
            ));
        }
        let m: Vec<u8> = m.into_iter().map(|v| u8::from(v >= 128)).collect();
        let m = img::undistort_nearest(&m, 1, w, h, k, &dist, 0u8);
        Some(img::downscale_mask(&m, w, h, extra))
    } else {
        None
    };

    let fp = ctx.dir.join(format!("flow/{}.npy", f.id));
    let flow = if ctx.flows && fp.is_file() {
        let (shape, v) = points::read_npy_f32(&fp)?;
        if shape != [fh as u64, fw as u64, 2] {
            return Err(DataError::file(
                &fp,
                format!("array of shape {shape:?}; expected [{fh}, {fw}, 2] (full-resolution H×W×2 flow)"),
            ));
        }
        if v.iter().any(|x| !x.is_finite()) {
            return Err(DataError::file(
                &fp,
                "non-finite flow value; expected finite pixels",
            ));
        }
        let v = img::downscale_flow(&v, fw, fh, ctx.scale);
        let (vw, vh) = (fw / ctx.scale, fh / ctx.scale);
        if (vw, vh) != (w, h) {
            None
        } else {
            let v = img::undistort_nearest(&v, 2, w, h, k, &dist, 0.0f32);
            Some(img::downscale_flow(&v, w, h, extra))
        }
    } else {
        None
    };

    let keep = ctx.opts.keep_pixels;
    Ok(Frame {
        id: f.id.to_string(),
        image_path: path,
        camera,
        time: f.time,
        image: if keep {
            image
        } else {
            Image {
                data: Vec::new(),
                ..image
            }
        },
        mask: mask.map(|m| if keep { m } else { Vec::new() }),
        flow: flow.map(|v| if keep { v } else { Vec::new() }),
    })
}

/// Loads a nerfies-format capture.
pub fn load(dir: &Path, opts: &LoadOptions) -> DataResult<Dataset> {
    let split = read_split(&dir.join("dataset.json"))?;
    let (times, time_field) = read_times(&dir.join("metadata.json"), &split.ids)?;
    let scene = read_scene(&dir.join("scene.json"))?;
    let cams: Vec<NerfiesCamera> = split
        .ids
        .par_iter()
        .map(|id| read_camera(&dir.join(format!("camera/{id}.json"))))
        .collect::<DataResult<_>>()?;

    let mut warnings = Vec::new();
    let mut notes = vec![
        format!("split: {}", split.rule),
        format!("time from metadata.json {time_field}, normalised to [0,1]"),
    ];
    let scale = choose_scale(dir, opts, cams[0].image_size)?;
    notes.push(format!("images from rgb/{scale}x (intrinsics / {scale})"));
    let mask_dir = dir.join(format!("mask/{scale}x"));
    let masks = mask_dir.is_dir();
    let flows = dir.join("flow").is_dir();
    let n_dist = cams.iter().filter(|c| !c.distortion.is_identity()).count();
    if n_dist > 0 {
        let d = cams
            .iter()
            .find(|c| !c.distortion.is_identity())
            .map(|c| c.distortion)
            .unwrap_or_default();
        warnings.push(format!(
            "distortion present in {n_dist} of {} cameras (e.g. k1 {:.4} k2 {:.4} k3 {:.4} p1 {:.4} \
             p2 {:.4} skew {:.3}): images undistorted to pinhole at load, out-of-image pixels filled \
             with the background",
            cams.len(),
            d.k1,
            d.k2,
            d.k3,
            d.p1,
            d.p2,
            d.skew
        ));
    }
    if split.val.is_empty() {
        warnings.push("no validation frames".into());
    }
    if times.windows(2).any(|w| w[1] < w[0]) {
        warnings.push("time is not monotone in id order".into());
    }

    let specs: Vec<FrameSpec> = split
        .ids
        .iter()
        .zip(&cams)
        .zip(&times)
        .map(|((id, cam), &time)| FrameSpec {
            id,
            time,
            cam,
            centre: scene.apply(cam.position).as_vec3(),
        })
        .collect();
    let ctx = FrameCtx {
        dir,
        scale,
        masks,
        flows,
        opts,
    };
    let pb = progress_bar(specs.len() as u64, "loading frames", opts.progress);
    let frames: Vec<Frame> = specs
        .par_iter()
        .map(|f| {
            let r = load_frame(&ctx, f);
            pb.inc(1);
            r
        })
        .collect::<DataResult<_>>()?;
    pb.finish_and_clear();
    let extra = factor_for_max(
        cams[0].image_size[0] / scale,
        cams[0].image_size[1] / scale,
        opts.max_size,
    );
    if extra > 1 {
        notes.push(format!("box-downscaled by {extra} to fit max size"));
    }
    if masks {
        notes.push(format!("motion masks from {}", mask_dir.display()));
    }

    // Split frames, in the order each split lists them (an id in both splits is cloned).
    let mut by_id: HashMap<String, Frame> = frames.into_iter().map(|f| (f.id.clone(), f)).collect();
    let train: Vec<Frame> = split
        .train
        .iter()
        .filter_map(|id| by_id.remove(id))
        .collect();
    let val: Vec<Frame> = split
        .val
        .iter()
        .filter_map(|id| {
            by_id
                .remove(id)
                .or_else(|| train.iter().find(|f| &f.id == id).cloned())
        })
        .collect();

    // Bounds and initial points.
    let centres: Vec<Vec3> = specs.iter().map(|s| s.centre).collect();
    let (points, bounds) = initial_points(
        dir,
        opts,
        &scene,
        &cams,
        &split.ids,
        &centres,
        &mut warnings,
    )?;

    Ok(Dataset {
        format: Format::Nerfies,
        root: dir.to_path_buf(),
        train,
        val,
        points,
        bounds,
        background: opts.background,
        near_far: scene.near_far.map(|(n, f)| (n as f32, f as f32)),
        downscale: extra,
        warnings,
        notes,
    })
}

fn colmap_dir(dir: &Path) -> Option<PathBuf> {
    ["colmap/sparse/0", "sparse/0", "colmap/sparse", "sparse"]
        .iter()
        .map(|d| dir.join(d))
        .find(|d| d.join("images.bin").is_file() && d.join("points3D.bin").is_file())
}

fn normalise_all(scene: &SceneNorm, pts: &[DVec3]) -> Vec<Vec3> {
    pts.iter().map(|p| scene.apply(*p).as_vec3()).collect()
}

/// COLMAP points aligned to the JSON cameras, or the reason they cannot be used.
fn colmap_points(
    sparse: &Path,
    scene: &SceneNorm,
    cams: &[NerfiesCamera],
    ids: &[String],
) -> DataResult<Result<InitPoints, String>> {
    let images = points::read_colmap_images(&sparse.join("images.bin"))?;
    let pos: HashMap<&str, DVec3> = ids
        .iter()
        .map(String::as_str)
        .zip(cams.iter().map(|c| c.position))
        .collect();
    let (mut src, mut dst) = (Vec::new(), Vec::new());
    for im in &images {
        let stem = Path::new(&im.name)
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        if let Some(p) = pos.get(stem.as_str()) {
            src.push(im.centre);
            dst.push(*p);
        }
    }
    let matched = src.len();
    let Some((sim, rms)) = points::umeyama(&src, &dst) else {
        return Ok(Err(format!(
            "cannot align {}: {matched} cameras matched by name (need ≥ 3, not collinear)",
            sparse.display()
        )));
    };
    let mean = dst.iter().copied().sum::<DVec3>() / matched as f64;
    let spread = (dst
        .iter()
        .map(|p| (*p - mean).length_squared())
        .sum::<f64>()
        / matched as f64)
        .sqrt();
    if rms > 1e-2 * spread.max(1e-12) {
        return Ok(Err(format!(
            "cannot align {}: residual {rms:.3e} is over 1% of the camera spread {spread:.3e}",
            sparse.display()
        )));
    }
    let pts_path = sparse.join("points3D.bin");
    let (pts, cols) = points::read_colmap_points(&pts_path)?;
    let aligned: Vec<DVec3> = pts.iter().map(|p| sim.apply(*p)).collect();
    Ok(Ok(InitPoints {
        positions: normalise_all(scene, &aligned),
        colors: Some(cols),
        source: PointSource::Colmap {
            path: pts_path,
            rms_residual: rms,
            matched,
        },
    }))
}

#[allow(clippy::too_many_arguments)]
fn initial_points(
    dir: &Path,
    opts: &LoadOptions,
    scene: &SceneNorm,
    cams: &[NerfiesCamera],
    ids: &[String],
    centres: &[Vec3],
    warnings: &mut Vec<String>,
) -> DataResult<(InitPoints, Bounds)> {
    let scene_bounds = scene.bbox.map(|(a, b)| {
        let (a, b) = (scene.apply(a).as_vec3(), scene.apply(b).as_vec3());
        Bounds {
            min: a.min(b),
            max: a.max(b),
        }
    });
    let cam_bounds = Bounds::of(centres).unwrap_or(Bounds {
        min: Vec3::splat(-1.0),
        max: Vec3::splat(1.0),
    });
    let npy = dir.join("points.npy");
    let ply = ["points3d.ply", "points3D.ply", "fused.ply"]
        .iter()
        .map(|n| dir.join(n))
        .find(|p| p.is_file());
    let pref = opts.points;
    let mut chosen: Option<InitPoints> = None;
    if (matches!(pref, PointsPreference::Auto | PointsPreference::Official) && npy.is_file())
        || pref == PointsPreference::Npy
    {
        let pts = points::read_points_npy(&npy)?;
        chosen = Some(InitPoints {
            positions: normalise_all(scene, &pts),
            colors: None,
            source: PointSource::Npy(npy.clone()),
        });
    }
    if chosen.is_none()
        && matches!(
            pref,
            PointsPreference::Auto | PointsPreference::Official | PointsPreference::Colmap
        )
    {
        match colmap_dir(dir) {
            Some(sparse) => match colmap_points(&sparse, scene, cams, ids)? {
                Ok(p) => chosen = Some(p),
                Err(why) if pref == PointsPreference::Colmap => {
                    return Err(DataError::file(&sparse, why))
                }
                Err(why) => warnings.push(format!("{why}; COLMAP points not used")),
            },
            None if pref == PointsPreference::Colmap => {
                return Err(DataError::file(
                    &dir.join("colmap/sparse/0"),
                    "missing; expected images.bin and points3D.bin",
                ))
            }
            None => {}
        }
    }
    if chosen.is_none()
        && matches!(
            pref,
            PointsPreference::Auto | PointsPreference::Official | PointsPreference::Ply
        )
    {
        chosen = points::ply_points(dir, ply.as_deref(), pref, |pts| normalise_all(scene, pts))?;
    }
    let bounds = scene_bounds
        .or_else(|| chosen.as_ref().and_then(|c| Bounds::of(&c.positions)))
        .unwrap_or(cam_bounds);
    let points = match chosen {
        Some(p) => p,
        None => points::random_points(&bounds, opts.random_points, opts.seed),
    };
    Ok((points, bounds))
}
