//! D-NeRF / blender loader: `transforms_{train,val,test}.json`.
//!
//! - `transform_matrix` is camera-to-world in the OpenGL/Blender convention (x right, y up,
//!   z backward); it is converted to OpenCV world-to-camera by flipping the camera y and z axes.
//! - Intrinsics: per-frame `fl_x, fl_y, cx, cy, w, h` when present, else the same fields at the top
//!   level, else `fx = fy = 0.5·w / tan(0.5·camera_angle_x)` and a centred principal point.
//! - RGBA images are composited over [`LoadOptions::background`].
//! - Masks: when `<split dir>/masks/` exists, every frame needs `<split dir>/masks/<name>.png`;
//!   8-bit labels (mujoco: object instance ids), motion mask = label > 0.
//! - Time: per-frame `time`; kept as is when all times lie in `[0,1]`, otherwise rescaled over all
//!   splits to `[0,1]`.
//! - Validation frames: `transforms_test.json` when present (what D-NeRF papers report), else
//!   `transforms_val.json`.
//! - Initial points (`auto`): `points.npy`, then `points3d.ply` / `fused.ply`, then random in the
//!   bounds (the bbox of the file points, else a cube around the origin of half-size half the
//!   mean camera distance). `official` (the paper preset): `points3d.ply`, else 100 000 random
//!   points in ±1.3, as the official Deformable-3DGS reader. No normalisation is applied
//!   (blender scenes are already centred).

use std::path::{Path, PathBuf};

use glam::{DMat3, DVec3, Mat3, Vec3};
use rayon::prelude::*;

use super::camera::{rotation_defect, Camera};
use super::image::{self as img, Image};
use super::json::{self, field_err, Obj};
use super::points::{self, InitPoints, PointSource, PointsPreference};
use super::{
    factor_for_max, progress_bar, Bounds, DataError, DataResult, Dataset, Format, Frame,
    LoadOptions,
};

/// One frame of a transforms file, before its image is read.
#[derive(Clone, Debug)]
pub struct BlenderFrame {
    pub file_path: String,
    pub image: PathBuf,
    pub mask: Option<PathBuf>,
    pub time: f64,
    /// World-to-camera rotation (OpenCV).
    pub rotation: DMat3,
    pub centre: DVec3,
    /// Focal lengths / principal point when given explicitly (else derived from the image size).
    pub fl: Option<(f64, Option<f64>)>,
    pub c: (Option<f64>, Option<f64>),
    pub wh: (Option<u32>, Option<u32>),
    pub camera_angle_x: Option<f64>,
    /// JSON file and field prefix for messages.
    pub json: PathBuf,
    pub field: String,
}

/// Parses `transforms_<split>.json`.
pub fn read_transforms(dir: &Path, split: &str) -> DataResult<Vec<BlenderFrame>> {
    let path = dir.join(format!("transforms_{split}.json"));
    let v = json::read(&path)?;
    let o = Obj::root(&path, &v)?;
    let angle = o.opt_f64("camera_angle_x")?;
    let top = |f: &str| o.opt_f64(f);
    let (tfx, tfy, tcx, tcy) = (top("fl_x")?, top("fl_y")?, top("cx")?, top("cy")?);
    let (tw, th) = (top("w")?, top("h")?);
    let frames = o.array("frames")?;
    if frames.is_empty() {
        return Err(field_err(
            &path,
            "frames",
            "a non-empty array of frames",
            "an empty array (empty split)",
        ));
    }
    let mut out = Vec::with_capacity(frames.len());
    for (i, fv) in frames.iter().enumerate() {
        let name = format!("frames[{i}]");
        let f = Obj::of(&path, &name, fv, &name)?;
        let fp = f.str("file_path")?;
        if fp.is_empty() || fp.contains("..") {
            return Err(field_err(
                &path,
                &f.name("file_path"),
                "a relative image path inside the dataset",
                format!("{fp:?}"),
            ));
        }
        let mut image = dir.join(fp.trim_start_matches("./"));
        if image.extension().is_none() {
            image.set_extension("png");
        }
        let time = f.f64("time")?;
        let m = f.matrix("transform_matrix", 4, 4)?;
        let r_gl = DMat3::from_cols(
            DVec3::new(m[0][0], m[1][0], m[2][0]),
            DVec3::new(m[0][1], m[1][1], m[2][1]),
            DVec3::new(m[0][2], m[1][2], m[2][2]),
        );
        let (defect, det) = rotation_defect(&r_gl);
        if defect > 1e-3 || det < 0.0 {
            return Err(field_err(
                &path,
                &f.name("transform_matrix"),
                "a rigid camera-to-world matrix (rotation part orthonormal, determinant +1)",
                format!("|RᵀR − I| = {defect:.2e}, determinant {det:.3}"),
            ));
        }
        // OpenGL camera axes (x right, y up, z back) → OpenCV (x right, y down, z forward).
        let c2w_cv = DMat3::from_cols(r_gl.x_axis, -r_gl.y_axis, -r_gl.z_axis);
        let positive = |field: &str, v: Option<f64>| -> DataResult<Option<f64>> {
            match v {
                Some(x) if x <= 0.0 => {
                    Err(field_err(&path, field, "a positive number", format!("{x}")))
                }
                other => Ok(other),
            }
        };
        let fx = positive(&f.name("fl_x"), f.opt_f64("fl_x")?.or(tfx))?;
        let fy = positive(&f.name("fl_y"), f.opt_f64("fl_y")?.or(tfy))?;
        let size = |field: &str, v: Option<f64>| -> DataResult<Option<u32>> {
            match v {
                None => Ok(None),
                Some(x) if x >= 1.0 && x.fract() == 0.0 && x <= 65536.0 => Ok(Some(x as u32)),
                Some(x) => Err(field_err(
                    &path,
                    &f.name(field),
                    "a positive integer number of pixels",
                    format!("{x}"),
                )),
            }
        };
        let w = size("w", f.opt_f64("w")?.or(tw))?;
        let h = size("h", f.opt_f64("h")?.or(th))?;
        if fx.is_none() {
            match angle {
                Some(a) if a > 0.0 && a < std::f64::consts::PI => {}
                Some(a) => {
                    return Err(field_err(
                        &path,
                        "camera_angle_x",
                        "an angle in (0, π) radians",
                        format!("{a}"),
                    ))
                }
                None => {
                    return Err(field_err(
                        &path,
                        &f.name("fl_x"),
                        "a focal length (fl_x per frame or at the top level, or camera_angle_x)",
                        "nothing (missing)",
                    ))
                }
            }
        }
        let mask = image
            .parent()
            .map(|p| p.join("masks"))
            .filter(|m| m.is_dir())
            .and_then(|m| image.file_name().map(|n| m.join(n)))
            .map(|m| m.with_extension("png"));
        out.push(BlenderFrame {
            file_path: fp.to_string(),
            image,
            mask,
            time,
            rotation: c2w_cv.transpose(),
            centre: DVec3::new(m[0][3], m[1][3], m[2][3]),
            fl: fx.map(|x| (x, fy)),
            c: (f.opt_f64("cx")?.or(tcx), f.opt_f64("cy")?.or(tcy)),
            wh: (w, h),
            camera_angle_x: angle,
            json: path.clone(),
            field: name,
        });
    }
    Ok(out)
}

/// A loaded frame, the downscale factor and its transparent fraction (RGBA images).
type Loaded = (Frame, u32, Option<f32>);

fn load_frame(f: &BlenderFrame, time: f32, opts: &LoadOptions) -> DataResult<Loaded> {
    let (image, clear) = img::load_rgb_alpha(&f.image, opts.background)?;
    let (w, h) = (image.width, image.height);
    for (want, got, name) in [(f.wh.0, w, "w"), (f.wh.1, h, "h")] {
        if let Some(want) = want {
            if want != got {
                return Err(DataError::file(
                    &f.image,
                    format!(
                        "image is {w}×{h}; expected {name} = {want} ({} {}.{name})",
                        f.json.display(),
                        f.field
                    ),
                ));
            }
        }
    }
    let (fx, fy) = match f.fl {
        Some((fx, fy)) => (fx, fy.unwrap_or(fx)),
        None => {
            let a = f.camera_angle_x.unwrap_or(std::f64::consts::FRAC_PI_2);
            let fx = 0.5 * w as f64 / (0.5 * a).tan();
            (fx, fx)
        }
    };
    let cx = f.c.0.unwrap_or(0.5 * w as f64);
    let cy = f.c.1.unwrap_or(0.5 * h as f64);
    let factor = match opts.downscale {
        Some(d) if d > 1 => d * factor_for_max(w / d, h / d, opts.max_size),
        _ => factor_for_max(w, h, opts.max_size),
    };
    let image = img::downscale(&image, factor);
    let camera = Camera::from_centre(
        Mat3::from_cols_array(&f.rotation.as_mat3().to_cols_array()),
        f.centre.as_vec3(),
        [fx as f32, fy as f32, cx as f32, cy as f32],
        w,
        h,
    )
    .scaled(1.0 / factor as f32, image.width, image.height);
    let mask = match &f.mask {
        None => None,
        Some(mp) => {
            let (mw, mh, labels) = img::load_gray(mp)?;
            if (mw, mh) != (w, h) {
                return Err(DataError::file(
                    mp,
                    format!("mask is {mw}×{mh}; expected {w}×{h} like its image"),
                ));
            }
            let m: Vec<u8> = labels.into_iter().map(|l| u8::from(l > 0)).collect();
            Some(img::downscale_mask(&m, w, h, factor))
        }
    };
    let keep = opts.keep_pixels;
    let frame = Frame {
        id: f.file_path.clone(),
        image_path: f.image.clone(),
        camera,
        time,
        image: if keep {
            image
        } else {
            Image {
                data: Vec::new(),
                ..image
            }
        },
        mask: mask.map(|m| if keep { m } else { Vec::new() }),
        flow: None,
    };
    Ok((frame, factor, clear))
}

/// Views that are almost all transparent beside views that are mostly opaque, as mujoco-scene5's:
/// its floor is transparent from the camera above (98 % of the pixels) and opaque from the
/// side (22 % transparent at least). A surface transparent in some views is drawn in the
/// background colour there and its own colour elsewhere; the model then builds a layer of
/// background-coloured Gaussians over it, which hides what moves below from the clear views.
/// D-NeRF's objects on a transparent background do not trip it (every view mostly clear).
pub fn transparency_warning(clear: &[(&str, f32)], background: [f32; 3]) -> Option<String> {
    let most = clear.iter().max_by(|a, b| a.1.total_cmp(&b.1))?;
    let least = clear.iter().min_by(|a, b| a.1.total_cmp(&b.1))?;
    (most.1 >= CLEAR_VIEW && least.1 <= OPAQUE_VIEW).then(|| {
        format!(
            "views disagree about what is transparent: {} is {:.0} % transparent, {} only {:.0} %; \
             a surface that some views see through (a floor) is drawn in the background colour \
             ({}) there and the model may hide what is under it from those views; if that \
             surface has one colour, train with it as --background (white for a white floor)",
            most.0,
            100.0 * most.1,
            least.0,
            100.0 * least.1,
            match background {
                [0.0, 0.0, 0.0] => "black".to_string(),
                [1.0, 1.0, 1.0] => "white".to_string(),
                [r, g, b] => format!("{r}, {g}, {b}"),
            }
        )
    })
}

/// A view at least this transparent beside one at most [`OPAQUE_VIEW`] transparent.
pub(crate) const CLEAR_VIEW: f32 = 0.9;
pub(crate) const OPAQUE_VIEW: f32 = 0.3;

/// The validation split used: `test` when `transforms_test.json` exists, else `val`, else none.
pub fn val_split_name(dir: &Path) -> Option<&'static str> {
    ["test", "val"]
        .into_iter()
        .find(|s| dir.join(format!("transforms_{s}.json")).is_file())
}

/// Loads a D-NeRF / blender scene.
pub fn load(dir: &Path, opts: &LoadOptions) -> DataResult<Dataset> {
    let train = read_transforms(dir, "train")?;
    let val_name = val_split_name(dir);
    let val = match val_name {
        Some(s) => read_transforms(dir, s)?,
        None => Vec::new(),
    };
    let mut warnings = Vec::new();
    let mut notes = vec![format!(
        "val split: {}",
        val_name
            .map(|s| format!("transforms_{s}.json"))
            .unwrap_or_else(|| "none".into())
    )];
    if val.is_empty() {
        warnings
            .push("no validation frames (no transforms_test.json or transforms_val.json)".into());
    }
    let all: Vec<&BlenderFrame> = train.iter().chain(&val).collect();
    let lo = all.iter().map(|f| f.time).fold(f64::INFINITY, f64::min);
    let hi = all.iter().map(|f| f.time).fold(f64::NEG_INFINITY, f64::max);
    let norm = |t: f64| -> f32 {
        if lo >= 0.0 && hi <= 1.0 {
            t as f32
        } else if hi > lo {
            ((t - lo) / (hi - lo)) as f32
        } else {
            0.0
        }
    };
    if !(lo >= 0.0 && hi <= 1.0) {
        notes.push(format!("time rescaled from [{lo}, {hi}] to [0,1]"));
    }
    if train.windows(2).any(|w| w[1].time < w[0].time) {
        warnings.push("train time is not monotone in file order".into());
    }
    let n_masks = all.iter().filter(|f| f.mask.is_some()).count();
    if n_masks > 0 {
        notes.push(format!("{n_masks} frames with motion masks (label > 0)"));
    }

    let pb = progress_bar(all.len() as u64, "loading frames", opts.progress);
    let load_all = |frames: &[BlenderFrame]| -> DataResult<Vec<Loaded>> {
        frames
            .par_iter()
            .map(|f| {
                let r = load_frame(f, norm(f.time), opts);
                pb.inc(1);
                r
            })
            .collect()
    };
    let train_frames = load_all(&train)?;
    let val_frames = load_all(&val)?;
    pb.finish_and_clear();
    let downscale = train_frames.first().map(|f| f.1).unwrap_or(1);
    let clear: Vec<(&str, f32)> = (train_frames.iter().chain(&val_frames))
        .filter_map(|f| f.2.map(|c| (f.0.id.as_str(), c)))
        .collect();
    if !opts.background_from_data {
        warnings.extend(transparency_warning(&clear, opts.background));
    }
    let train_frames: Vec<Frame> = train_frames.into_iter().map(|f| f.0).collect();
    let val_frames: Vec<Frame> = val_frames.into_iter().map(|f| f.0).collect();

    // Initial points and bounds.
    let centres: Vec<Vec3> = all.iter().map(|f| f.centre.as_vec3()).collect();
    let mean_dist = centres.iter().map(|c| c.length()).sum::<f32>() / centres.len().max(1) as f32;
    let half = (0.5 * mean_dist).max(1e-3);
    let cube = Bounds {
        min: Vec3::splat(-half),
        max: Vec3::splat(half),
    };
    let npy = dir.join("points.npy");
    let pref = opts.points;
    let names: &[&str] = if pref == PointsPreference::Official {
        &["points3d.ply"]
    } else {
        &["points3d.ply", "points3D.ply", "fused.ply"]
    };
    let ply = names.iter().map(|n| dir.join(n)).find(|p| p.is_file());
    let mut chosen: Option<InitPoints> = None;
    if (pref == PointsPreference::Auto && npy.is_file()) || pref == PointsPreference::Npy {
        let pts = points::read_points_npy(&npy)?;
        chosen = Some(InitPoints {
            positions: pts.iter().map(|p| p.as_vec3()).collect(),
            colors: None,
            source: PointSource::Npy(npy.clone()),
        });
    }
    if pref == PointsPreference::Colmap {
        return Err(DataError::file(
            dir,
            "no COLMAP model in a D-NeRF/blender scene; choose npy, ply, random or auto",
        ));
    }
    let from_ply = matches!(
        pref,
        PointsPreference::Auto | PointsPreference::Ply | PointsPreference::Official
    );
    if chosen.is_none() && from_ply {
        chosen = points::ply_points(dir, ply.as_deref(), pref, |pts| {
            pts.iter().map(|p| p.as_vec3()).collect()
        })?;
    }
    let (cube, n_random) = if pref == PointsPreference::Official {
        let h = points::OFFICIAL_RANDOM_HALF;
        let b = Bounds {
            min: Vec3::splat(-h),
            max: Vec3::splat(h),
        };
        (b, points::OFFICIAL_RANDOM_POINTS)
    } else {
        (cube, opts.random_points)
    };
    let bounds = chosen
        .as_ref()
        .and_then(|c| Bounds::of(&c.positions))
        .unwrap_or(cube);
    let points = match chosen {
        Some(p) => p,
        None => points::random_points(&bounds, n_random, opts.seed),
    };
    if let Some(name) = ply.as_ref().and_then(|p| p.file_name()) {
        if name == "fused.ply" {
            notes.push(
                "fused.ply in D-NeRF scenes is a random initialisation, not a reconstruction"
                    .into(),
            );
        }
    }

    Ok(Dataset {
        format: Format::Blender,
        root: dir.to_path_buf(),
        train: train_frames,
        val: val_frames,
        points,
        bounds,
        background: opts.background,
        near_far: None,
        downscale,
        warnings,
        notes,
    })
}

#[cfg(test)]
mod tests {
    use super::transparency_warning;

    #[test]
    fn views_that_disagree_about_transparency_are_named() {
        let bg = [0.0; 3];
        // mujoco-scene5: the camera above sees through the floor, a 45° one does not.
        let w = transparency_warning(&[("r_0002", 0.977), ("r_0003", 0.224)], bg).unwrap();
        assert!(
            w.contains("r_0002 is 98 %") && w.contains("r_0003 only 22 %"),
            "{w}"
        );
        // An object on a transparent background (D-NeRF) or a floor opaque from every view
        // (mujoco-scene7), or no RGBA frame at all: nothing to say.
        assert_eq!(transparency_warning(&[("a", 0.95), ("b", 0.62)], bg), None);
        assert_eq!(transparency_warning(&[("a", 0.45), ("b", 0.005)], bg), None);
        assert_eq!(transparency_warning(&[], bg), None);
    }
}
