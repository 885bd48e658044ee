//! Checkpoints (atomic: temp file + fsync + rename) and the standard 3DGS PLY export.
//! (Over 600 lines: the checkpoint and the PLY share the blob names, the population split and
//! the field-by-field checks of one model's sections; each reader has its tests here.)
//!
//! Checkpoint layout (format version [`CHECKPOINT_VERSION`]): magic `DFVKCKPT`, u64
//! little-endian length of a JSON header, the header, u64 little-endian FNV-1a 64 of the
//! header bytes, then each blob as little-endian f32 in header order. The header holds the
//! format version, the iteration, the model's shape (SH coefficients, MLP depth and width,
//! Gaussian budget) and per blob its name, length in floats and FNV-1a 64 of its bytes (hex).
//! Every length and checksum is checked on read; a mismatch names the file and the blob.
//! The optional blobs `dynamic` (0.0/1.0 per canonical Gaussian) and `dynamic_fixed` (10 per
//! canonical Gaussian) are the model's dynamic/static split (transients are never split).
//! Version 4 adds the transient Gaussians: the header's `transients` (the last rows) and the
//! blobs `time` (c, τ per Gaussian) and `velocity` (with their moments `m.`/`v.`), present
//! only when there are transients. The header's optional `spawns` (also version 4) is the
//! spawn rounds' state: which candidate frames come next, each frame's last residual, and the
//! depth hypotheses waiting to be resolved (`train::transients::SpawnState`).
//! Small and dependency-free.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::kernels::nodes::NO_NODE;
use crate::model::dynamic::SplitSnapshot;
use crate::model::gaussians::HostGaussians;
use crate::model::nodes::NodeSnapshot;
use crate::model::rows::Populations;
use crate::model::state::{ModelShape, ModelSnapshot};
use crate::train::transients::SpawnState;

const MAGIC: &[u8; 8] = b"DFVKCKPT";

/// The checkpoint format this build writes and reads. Version 1 (no checksums, no model
/// shape) is refused with a message that says so.
pub const CHECKPOINT_VERSION: u32 = 4;
/// Older formats this build still reads: version 3 lacks only the transients (a run without
/// them), version 2 also the optional control-node blobs and shape fields (an MLP-field run).
const READS_VERSIONS: [u32; 3] = [2, 3, 4];

/// Names of the densification statistics blobs, in [`Checkpoint::densify_stats`] order.
pub const DENSIFY_STATS: [&str; 3] = ["grad_accum", "denom", "max_radii"];

/// Everything needed to continue a run exactly where it stopped.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Checkpoint {
    /// Iterations completed.
    pub iteration: u32,
    /// Parameters and Adam moments of the Gaussians and the MLP.
    pub model: ModelSnapshot,
    /// Densification statistics per Gaussian: gradient accumulator, count, max radius.
    pub densify_stats: [Vec<f32>; 3],
    /// The deformation rate's multiplier after collapse rollbacks (`None`: 1, never rolled
    /// back), so a resumed run keeps the rate the rollback chose.
    pub deform_lr_scale: Option<f64>,
    /// The spawns' state (`None` before any spawn round), so a resumed run spawns as the
    /// uninterrupted one.
    pub spawns: Option<SpawnState>,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Header {
    version: u32,
    iteration: u32,
    sh_coeffs: u32,
    shape: ModelShape,
    blobs: Vec<BlobEntry>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    deform_lr_scale: Option<f64>,
    /// The last rows that are transient Gaussians (version 4; 0 before).
    #[serde(default, skip_serializing_if = "is_zero")]
    transients: u32,
    /// The spawns' looks and pending depth hypotheses (version 4, after any spawn round).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    spawns: Option<SpawnState>,
}

fn is_zero(v: &u32) -> bool {
    *v == 0
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct BlobEntry {
    name: String,
    floats: u64,
    /// FNV-1a 64 of the blob's bytes, 16 hex digits.
    fnv1a64: String,
}

/// 64-bit FNV-1a of `bytes`.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

fn take_gauss(
    prefix: &str,
    m: &mut BTreeMap<String, Vec<f32>>,
    sh_coeffs: u32,
    transients: u32,
    path: &Path,
) -> Result<HostGaussians> {
    let mut get = |k: &str| {
        m.remove(&format!("{prefix}{k}"))
            .ok_or_else(|| bad(path, &format!("blob {prefix}{k} missing")))
    };
    fn arr<const N: usize>(v: Vec<f32>) -> Vec<[f32; N]> {
        v.chunks_exact(N)
            .map(|c| c.try_into().expect("chunks of N"))
            .collect()
    }
    let raw = [
        get("means")?,
        get("log_scales")?,
        get("quats")?,
        get("opacity")?,
        get("sh_dc")?,
        get("sh_rest")?,
    ];
    let n = raw[0].len() / 3;
    let rest = 3 * (sh_coeffs as usize - 1);
    for (v, (k, row)) in raw.iter().zip([
        ("means", 3),
        ("log_scales", 3),
        ("quats", 4),
        ("opacity", 1),
        ("sh_dc", 3),
        ("sh_rest", rest),
    ]) {
        if v.len() != n * row {
            return Err(bad(
                path,
                &format!(
                    "blob {prefix}{k}: {} floats; {n} Gaussians need {}",
                    v.len(),
                    n * row
                ),
            ));
        }
    }
    let [means, log_scales, quats, opacity, sh_dc, sh_rest] = raw;
    if transients as usize > n {
        return Err(bad(
            path,
            &format!("header: {transients} transients among {n} Gaussians"),
        ));
    }
    let rows = Populations::split(n as u32, transients);
    let (mut time, mut velocity) = (Vec::new(), Vec::new());
    if rows.temporal() {
        for (k, row) in [("time", 2), ("velocity", 3)] {
            let v = m
                .remove(&format!("{prefix}{k}"))
                .ok_or_else(|| bad(path, &format!("blob {prefix}{k} missing")))?;
            if v.len() != n * row {
                return Err(bad(
                    path,
                    &format!(
                        "blob {prefix}{k}: {} floats; {n} Gaussians need {}",
                        v.len(),
                        n * row
                    ),
                ));
            }
            match row {
                2 => time = arr::<2>(v),
                _ => velocity = arr::<3>(v),
            }
        }
    }
    Ok(HostGaussians {
        sh_coeffs,
        means: arr::<3>(means),
        log_scales: arr::<3>(log_scales),
        quats: arr::<4>(quats),
        opacity,
        sh_dc: arr::<3>(sh_dc),
        sh_rest,
        transients: rows.transient.len() as usize,
        time,
        velocity,
    })
}

fn bad(path: &Path, why: &str) -> Error {
    Error::Invalid(format!("{}: not a valid checkpoint: {why}", path.display()))
}

/// Writes `bytes` to `path` atomically: a killed process leaves the old file or the new one
/// (and at worst a stale `<name>.tmp` beside it, which the next write replaces).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = temp_path(path);
    let write = || -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()
    };
    if let Err(e) = write() {
        let _ = std::fs::remove_file(&tmp);
        return Err(Error::io(&tmp)(e));
    }
    if let Err(e) = std::fs::rename(&tmp, path) {
        let _ = std::fs::remove_file(&tmp);
        return Err(Error::io(path)(e));
    }
    if let Some(dir) = path.parent().and_then(|d| std::fs::File::open(d).ok()) {
        let _ = dir.sync_all(); // make the rename itself durable where the platform allows
    }
    Ok(())
}

/// The temp file [`write_atomic`] writes before the rename: `<name>.tmp` beside `path`.
pub fn temp_path(path: &Path) -> PathBuf {
    let mut name = path.file_name().unwrap_or_default().to_os_string();
    name.push(".tmp");
    path.with_file_name(name)
}

impl Checkpoint {
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut blobs: Vec<(String, &[f32])> = self
            .model
            .blobs()
            .into_iter()
            .map(|b| (b.name, b.data))
            .collect();
        // Node indices as f32 (exact below 2^24), an empty slot as −1.
        let knn: Option<Vec<f32>> = (self.model.nodes.as_ref())
            .filter(|n| !n.knn.is_empty())
            .map(|n| {
                let f = |j: u32| if j == NO_NODE { -1.0 } else { j as f32 };
                n.knn.iter().map(|&j| f(j)).collect()
            });
        if let Some(k) = &knn {
            blobs.push(("node_knn".to_string(), k));
        }
        for (k, v) in DENSIFY_STATS.iter().zip(&self.densify_stats) {
            blobs.push((k.to_string(), v));
        }
        // Flags as 0.0/1.0 (every blob is f32); absent while the model is dense.
        let dynamic: Option<Vec<f32>> =
            (self.model.dynamic.as_ref()).map(|d| d.flags.iter().map(|&v| v as f32).collect());
        if let (Some(f), Some(d)) = (&dynamic, &self.model.dynamic) {
            blobs.push(("dynamic".to_string(), f));
            blobs.push(("dynamic_fixed".to_string(), &d.fixed));
        }
        let header = Header {
            version: CHECKPOINT_VERSION,
            iteration: self.iteration,
            sh_coeffs: self.model.gaussians.sh_coeffs,
            shape: self.model.shape,
            deform_lr_scale: self.deform_lr_scale,
            transients: self.model.gaussians.transient_rows().len(),
            spawns: self.spawns.clone(),
            blobs: blobs
                .iter()
                .map(|(k, v)| BlobEntry {
                    name: k.clone(),
                    floats: v.len() as u64,
                    fnv1a64: format!("{:016x}", fnv1a64(bytemuck::cast_slice(v))),
                })
                .collect(),
        };
        let h = serde_json::to_vec(&header).expect("header serialises");
        let mut out =
            Vec::with_capacity(24 + h.len() + blobs.iter().map(|b| b.1.len() * 4).sum::<usize>());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&(h.len() as u64).to_le_bytes());
        out.extend_from_slice(&h);
        out.extend_from_slice(&fnv1a64(&h).to_le_bytes());
        for (_, v) in &blobs {
            out.extend_from_slice(bytemuck::cast_slice(v));
        }
        out
    }

    pub fn save(&self, path: &Path) -> Result<()> {
        write_atomic(path, &self.to_bytes())
    }

    /// Reads and checks a checkpoint: magic, format version, header checksum, every blob's
    /// length and checksum, counts that agree. Values are checked by the restore.
    pub fn load(path: &Path) -> Result<Checkpoint> {
        let bytes = std::fs::read(path).map_err(Error::io(path))?;
        if bytes.len() < 16 || &bytes[..8] != MAGIC {
            return Err(bad(path, "wrong magic (expected DFVKCKPT)"));
        }
        let hl = u64::from_le_bytes(bytes[8..16].try_into().expect("8 bytes"));
        let hdr = usize::try_from(hl)
            .ok()
            .and_then(|hl| bytes.get(16..16usize.checked_add(hl)?))
            .ok_or_else(|| bad(path, "truncated header"))?;
        // The version first, so a checkpoint of another format says which it is.
        let any: serde_json::Value =
            serde_json::from_slice(hdr).map_err(|e| bad(path, &format!("header: {e}")))?;
        match any.get("version").and_then(|v| v.as_u64()) {
            Some(v) if READS_VERSIONS.iter().any(|&r| r as u64 == v) => {}
            Some(v) => {
                return Err(bad(
                    path,
                    &format!(
                        "format version {v}; this build reads version {CHECKPOINT_VERSION} (and 3, \
                         written before transients, and 2, before the control-node field) \
                         (start the run again without --resume, or resume with the build \
                         that wrote it)"
                    ),
                ))
            }
            None => return Err(bad(path, "header: no format version")),
        }
        let mut at = 16 + hdr.len();
        let stored = bytes
            .get(at..at + 8)
            .ok_or_else(|| bad(path, "truncated header checksum"))?;
        if u64::from_le_bytes(stored.try_into().expect("8 bytes")) != fnv1a64(hdr) {
            return Err(bad(
                path,
                "header checksum mismatch (the header is corrupt)",
            ));
        }
        at += 8;
        let header: Header =
            serde_json::from_slice(hdr).map_err(|e| bad(path, &format!("header: {e}")))?;
        let sc = header.sh_coeffs;
        if !matches!(sc, 1 | 4 | 9 | 16) {
            return Err(bad(
                path,
                &format!("header: sh_coeffs = {sc}; expected 1, 4, 9 or 16"),
            ));
        }
        let mut m = BTreeMap::new();
        for b in header.blobs {
            let end = usize::try_from(b.floats)
                .ok()
                .and_then(|n| n.checked_mul(4))
                .and_then(|n| n.checked_add(at))
                .filter(|&e| e <= bytes.len())
                .ok_or_else(|| bad(path, &format!("blob {} truncated", b.name)))?;
            let data = &bytes[at..end];
            let sum = format!("{:016x}", fnv1a64(data));
            if sum != b.fnv1a64 {
                return Err(bad(
                    path,
                    &format!(
                        "blob {}: checksum mismatch (stored {}, computed {sum}); the file is \
                         corrupt",
                        b.name, b.fnv1a64
                    ),
                ));
            }
            if m.insert(
                b.name.clone(),
                bytemuck::pod_collect_to_vec::<u8, f32>(data),
            )
            .is_some()
            {
                return Err(bad(path, &format!("blob {} appears twice", b.name)));
            }
            at = end;
        }
        if at != bytes.len() {
            return Err(bad(
                path,
                &format!("{} trailing bytes after the last blob", bytes.len() - at),
            ));
        }
        let tr = header.transients;
        let gaussians = take_gauss("", &mut m, sc, tr, path)?;
        let gauss_m = take_gauss("m.", &mut m, sc, tr, path)?;
        let gauss_v = take_gauss("v.", &mut m, sc, tr, path)?;
        let mut get = |k: &str| {
            m.remove(k)
                .ok_or_else(|| bad(path, &format!("blob {k} missing")))
        };
        let densify_stats = DENSIFY_STATS.map(&mut get);
        let [a, b, c] = densify_stats;
        let densify_stats = [a?, b?, c?];
        let n = gaussians.len();
        if gauss_m.len() != n || gauss_v.len() != n || densify_stats.iter().any(|s| s.len() != n) {
            return Err(bad(
                path,
                "moment or statistics blobs disagree with the Gaussian count",
            ));
        }
        let (mlp_params, mlp_m, mlp_v) = (get("mlp_params")?, get("mlp_m")?, get("mlp_v")?);
        if mlp_m.len() != mlp_params.len() || mlp_v.len() != mlp_params.len() {
            return Err(bad(path, "MLP moments disagree with the parameter count"));
        }
        // The split covers the canonical rows only (transients never go through D).
        let c = gaussians.canonical_rows().len() as usize;
        let fixed = m.remove("dynamic_fixed");
        let dynamic = match m.remove("dynamic") {
            None => None,
            Some(d) if d.len() != c => {
                return Err(bad(
                    path,
                    &format!(
                        "blob dynamic: {} flags; {c} canonical Gaussians need {c}",
                        d.len()
                    ),
                ))
            }
            Some(d) => Some(
                d.iter()
                    .enumerate()
                    .map(|(i, &v)| match v {
                        0.0 => Ok(0),
                        1.0 => Ok(1),
                        _ => Err(bad(
                            path,
                            &format!("blob dynamic: element {i} is {v}; expected 0 or 1"),
                        )),
                    })
                    .collect::<Result<Vec<u32>>>()?,
            ),
        };
        let dynamic = match (dynamic, fixed) {
            (None, None) => None,
            (Some(flags), Some(fixed)) if fixed.len() == 10 * c => {
                Some(SplitSnapshot { flags, fixed })
            }
            _ => {
                return Err(bad(
                    path,
                    &format!(
                        "blobs dynamic and dynamic_fixed: both or neither, with {c} and {} \
                         floats",
                        10 * c
                    ),
                ))
            }
        };
        let nodes = match (
            m.remove("node_params"),
            m.remove("node_m"),
            m.remove("node_v"),
        ) {
            (None, None, None) => None,
            (Some(params), Some(nm), Some(nv))
                if nm.len() == params.len() && nv.len() == params.len() =>
            {
                let knn = m.remove("node_knn").unwrap_or_default();
                let bad_entry = knn.iter().position(|&v| {
                    !(v == -1.0 || ((0.0..16_777_216.0).contains(&v) && v.fract() == 0.0))
                });
                if let Some(i) = bad_entry {
                    return Err(bad(
                        path,
                        &format!(
                            "blob node_knn: entry {i} is {}; expected a node index or -1",
                            knn[i]
                        ),
                    ));
                }
                Some(NodeSnapshot {
                    params,
                    m: nm,
                    v: nv,
                    knn: knn
                        .iter()
                        .map(|&v| if v < 0.0 { NO_NODE } else { v as u32 })
                        .collect(),
                })
            }
            _ => {
                return Err(bad(
                    path,
                    "blobs node_params, node_m and node_v: all three of one length, or none",
                ))
            }
        };
        if let Some(k) = m.keys().next() {
            return Err(bad(path, &format!("unexpected blob {k}")));
        }
        if let Some(v) = header.deform_lr_scale {
            if !(v.is_finite() && v > 0.0) {
                return Err(bad(
                    path,
                    &format!("header: deform_lr_scale {v}; expected a positive finite number"),
                ));
            }
        }
        if let Some(p) =
            (header.spawns.as_ref()).and_then(|s| s.problem(gaussians.populations(), None))
        {
            return Err(bad(path, &format!("header: {p}")));
        }
        Ok(Checkpoint {
            iteration: header.iteration,
            deform_lr_scale: header.deform_lr_scale,
            spawns: header.spawns,
            model: ModelSnapshot {
                shape: header.shape,
                gaussians,
                gauss_m,
                gauss_v,
                mlp_params,
                mlp_m,
                mlp_v,
                dynamic,
                nodes,
            },
            densify_stats,
        })
    }
}

/// `DIR/checkpoints/last.ckpt`
pub fn last_checkpoint(out_dir: &Path) -> PathBuf {
    out_dir.join("checkpoints").join("last.ckpt")
}

/// `DIR/checkpoints/NNNNNN.ckpt`: a checkpoint kept by `--keep-checkpoints`.
pub fn kept_checkpoint(out_dir: &Path, iteration: u32) -> PathBuf {
    out_dir
        .join("checkpoints")
        .join(format!("{iteration:06}.ckpt"))
}

/// Whether `p` is named like a kept checkpoint (digits, then `.ckpt`).
pub fn is_kept_checkpoint(p: &Path) -> bool {
    p.extension().is_some_and(|x| x == "ckpt")
        && p.file_stem().is_some_and(|s| {
            let s = s.to_string_lossy();
            !s.is_empty() && s.bytes().all(|b| b.is_ascii_digit())
        })
}

/// Writes canonical Gaussians as the standard 3DGS PLY (binary little endian): x y z, nx ny nz
/// (zeros), f_dc_0..2, f_rest_* (channel-major, as 3DGS stores them), opacity (logit),
/// scale_0..2 (log), rot_0..3 (w x y z). Common splat viewers read this layout. Transient
/// Gaussians (all of `g`'s rows must then be transients) add t_centre, t_log_width and vx, vy,
/// vz: a run writes them apart, to `transients.ply`.
pub fn write_ply(path: &Path, g: &HostGaussians) -> Result<()> {
    let rows = g.populations();
    let temporal = rows.temporal();
    if temporal && !rows.canonical.is_empty() {
        return Err(Error::Invalid(format!(
            "{}: a PLY holds canonical or transient Gaussians, not both ({} of {} transient)",
            path.display(),
            rows.transient.len(),
            g.len()
        )));
    }
    let (time, vel) = (g.time_or_zeros(), g.velocity_or_zeros());
    let rest = 3 * (g.sh_coeffs as usize - 1);
    let mut h = String::from("ply\nformat binary_little_endian 1.0\n");
    h += &format!("element vertex {}\n", g.len());
    let mut props: Vec<String> = [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
    ]
    .map(String::from)
    .to_vec();
    props.extend((0..rest).map(|i| format!("f_rest_{i}")));
    props.extend(
        [
            "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        ]
        .map(String::from),
    );
    if temporal {
        props.extend(["t_centre", "t_log_width", "vx", "vy", "vz"].map(String::from));
    }
    for p in &props {
        h += &format!("property float {p}\n");
    }
    h += "end_header\n";
    let mut out = h.into_bytes();
    let k = g.sh_coeffs as usize - 1;
    for i in 0..g.len() {
        let mut row: Vec<f32> = Vec::with_capacity(props.len());
        row.extend(g.means[i]);
        row.extend([0.0; 3]);
        row.extend(g.sh_dc[i]);
        // ours: [coefficient][channel]; 3DGS PLY: [channel][coefficient]
        for c in 0..3 {
            row.extend((0..k).map(|j| g.sh_rest[i * rest + 3 * j + c]));
        }
        row.push(g.opacity[i]);
        row.extend(g.log_scales[i]);
        row.extend(g.quats[i]);
        if temporal {
            row.extend(time[i]);
            row.extend(vel[i]);
        }
        out.extend_from_slice(bytemuck::cast_slice(&row));
    }
    write_atomic(path, &out)
}

/// Reads a PLY written by [`write_ply`] (or by 3DGS) back into Gaussians.
pub fn read_ply(path: &Path) -> Result<HostGaussians> {
    let bytes = std::fs::read(path).map_err(Error::io(path))?;
    let bad = |why: &str| Error::Invalid(format!("{}: {why}", path.display()));
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .ok_or_else(|| bad("no end_header"))?
        + 11;
    let header = std::str::from_utf8(&bytes[..end]).map_err(|_| bad("header is not text"))?;
    if !header.contains("format binary_little_endian 1.0") {
        return Err(bad("expected format binary_little_endian 1.0"));
    }
    let mut n = None;
    let mut props = Vec::new();
    for line in header.lines() {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["element", "vertex", c] => n = c.parse::<usize>().ok(),
            ["property", "float", name] => props.push(name.to_string()),
            ["property", ty, name] => {
                return Err(bad(&format!("property {name}: expected float, found {ty}")))
            }
            _ => {}
        }
    }
    let n = n.ok_or_else(|| bad("no `element vertex N` line"))?;
    let idx = |name: &str| {
        props
            .iter()
            .position(|p| p == name)
            .ok_or_else(|| bad(&format!("property {name} missing")))
    };
    let rest = props.iter().filter(|p| p.starts_with("f_rest_")).count();
    if rest % 3 != 0 || !matches!(rest / 3 + 1, 1 | 4 | 9 | 16) {
        return Err(bad(&format!(
            "{rest} f_rest properties: expected 0, 9, 24 or 45"
        )));
    }
    let stride = props.len();
    let data = bytes
        .get(end..end + n * stride * 4)
        .ok_or_else(|| bad("truncated vertex data"))?;
    let f: Vec<f32> = bytemuck::pod_collect_to_vec(data);
    let (x, dc, op, sc, rot) = (
        idx("x")?,
        idx("f_dc_0")?,
        idx("opacity")?,
        idx("scale_0")?,
        idx("rot_0")?,
    );
    let r0 = if rest > 0 { idx("f_rest_0")? } else { 0 };
    let k = rest / 3;
    // A transients file (`write_ply` with temporal properties): every row is a transient.
    let temporal = match props.iter().position(|p| p == "t_centre") {
        Some(c) => Some((c, idx("t_log_width")?, idx("vx")?)),
        None => None,
    };
    let mut g = HostGaussians {
        sh_coeffs: (k + 1) as u32,
        transients: if temporal.is_some() { n } else { 0 },
        ..Default::default()
    };
    for i in 0..n {
        let row = &f[i * stride..(i + 1) * stride];
        g.means.push([row[x], row[x + 1], row[x + 2]]);
        g.sh_dc.push([row[dc], row[dc + 1], row[dc + 2]]);
        for j in 0..k {
            for c in 0..3 {
                g.sh_rest.push(row[r0 + c * k + j]);
            }
        }
        g.opacity.push(row[op]);
        g.log_scales.push([row[sc], row[sc + 1], row[sc + 2]]);
        g.quats
            .push([row[rot], row[rot + 1], row[rot + 2], row[rot + 3]]);
        if let Some((c, w, v)) = temporal {
            g.time.push([row[c], row[w]]);
            g.velocity.push([row[v], row[v + 1], row[v + 2]]);
        }
    }
    Ok(g)
}
