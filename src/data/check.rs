//! The `data check` report: what a loader sees in a dataset directory.

use std::collections::BTreeMap;
use std::fmt::Write;
use std::path::Path;

use glam::Vec3;

use super::{load, Bounds, DataResult, Dataset, LoadOptions};

/// Loads `dir` (validating every file; pixels are decoded then dropped) and returns the report.
pub fn report(dir: &Path, opts: &LoadOptions) -> DataResult<String> {
    let opts = LoadOptions {
        keep_pixels: false,
        ..opts.clone()
    };
    let ds = load(dir, &opts)?;
    let pick = super::background::pick_background(dir)?;
    Ok(format!(
        "{}background:  `--background auto` would pick {} ({})\n",
        summarise(&ds),
        pick.name(),
        pick.reason
    ))
}

fn v3(v: Vec3) -> String {
    format!("({:.3}, {:.3}, {:.3})", v.x, v.y, v.z)
}

/// Formats the report for a loaded dataset.
pub fn summarise(ds: &Dataset) -> String {
    let mut s = String::new();
    let all: Vec<_> = ds.frames().collect();
    let _ = writeln!(s, "dataset:     {}", ds.root.display());
    let _ = writeln!(s, "format:      {}", ds.format);
    let _ = writeln!(
        s,
        "frames:      train {}, val {} (total {})",
        ds.train.len(),
        ds.val.len(),
        all.len()
    );
    let tmin = all.iter().map(|f| f.time).fold(f32::INFINITY, f32::min);
    let tmax = all.iter().map(|f| f.time).fold(f32::NEG_INFINITY, f32::max);
    let mut distinct: Vec<f32> = all.iter().map(|f| f.time).collect();
    distinct.sort_by(f32::total_cmp);
    distinct.dedup();
    let _ = writeln!(
        s,
        "time:        [{tmin:.4}, {tmax:.4}], {} distinct values",
        distinct.len()
    );
    let mut res: BTreeMap<(u32, u32), usize> = BTreeMap::new();
    for f in &all {
        *res.entry((f.camera.width, f.camera.height)).or_default() += 1;
    }
    let res: Vec<String> = res
        .iter()
        .map(|((w, h), n)| format!("{w}×{h} ({n} frames)"))
        .collect();
    let _ = writeln!(
        s,
        "resolution:  {} (extra downscale {})",
        res.join(", "),
        ds.downscale
    );
    if let Some(f) = all.first() {
        let c = &f.camera;
        let _ = writeln!(
            s,
            "intrinsics:  first frame fx {:.2} fy {:.2} cx {:.2} cy {:.2} (principal point offset from centre {:+.2}, {:+.2} px)",
            c.fx,
            c.fy,
            c.cx,
            c.cy,
            c.cx - 0.5 * c.width as f32,
            c.cy - 0.5 * c.height as f32
        );
    }
    let centres: Vec<Vec3> = all.iter().map(|f| f.camera.centre()).collect();
    if let Some(b) = Bounds::of(&centres) {
        let mean = centres.iter().copied().sum::<Vec3>() / centres.len() as f32;
        let rms = (centres
            .iter()
            .map(|c| (*c - mean).length_squared())
            .sum::<f32>()
            / centres.len() as f32)
            .sqrt();
        let _ = writeln!(
            s,
            "cameras:     centres in {} .. {} (extent {}), rms distance to their mean {:.4}",
            v3(b.min),
            v3(b.max),
            v3(b.extent()),
            rms
        );
        let fwd: Vec<Vec3> = all.iter().map(|f| f.camera.forward()).collect();
        let mean_fwd = fwd.iter().copied().sum::<Vec3>().normalize_or_zero();
        let angles: Vec<f32> = fwd
            .iter()
            .map(|d| d.dot(mean_fwd).clamp(-1.0, 1.0).acos().to_degrees())
            .collect();
        let max_a = angles.iter().copied().fold(0.0f32, f32::max);
        let mean_a = angles.iter().sum::<f32>() / angles.len() as f32;
        let _ = writeln!(
            s,
            "look dirs:   mean {}, angle to mean: mean {:.1}°, max {:.1}°",
            v3(mean_fwd),
            mean_a,
            max_a
        );
    }
    let masks = all.iter().filter(|f| f.mask.is_some()).count();
    let flows = all.iter().filter(|f| f.flow.is_some()).count();
    let _ = writeln!(
        s,
        "masks:       {masks} of {} frames{}",
        all.len(),
        if masks > 0 { " (moving = 1)" } else { "" }
    );
    if flows > 0 {
        let _ = writeln!(s, "scene flow:  {flows} of {} frames", all.len());
    }
    let _ = writeln!(
        s,
        "points:      {} from {}{}",
        ds.points.positions.len(),
        ds.points.source,
        if ds.points.colors.is_some() {
            ", with colours"
        } else {
            ""
        }
    );
    let _ = writeln!(
        s,
        "bounds:      {} .. {}",
        v3(ds.bounds.min),
        v3(ds.bounds.max)
    );
    if let Some((n, f)) = ds.near_far {
        let _ = writeln!(s, "near/far:    {n:.4} / {f:.4}");
    }
    for n in &ds.notes {
        let _ = writeln!(s, "note:        {n}");
    }
    if ds.warnings.is_empty() {
        let _ = writeln!(s, "warnings:    none");
    }
    for w in &ds.warnings {
        let _ = writeln!(s, "warning:     {w}");
    }
    s
}
