//! Checkpoints (atomic: temp file + fsync + rename) and the standard 3DGS PLY export.
//!
//! Checkpoint layout: magic `DFVKCKPT`, u64 little-endian length of a JSON header, the header
//! (iteration, counts, blob names and lengths), then each blob as little-endian f32 in header
//! order. Small, dependency-free, and every length is checked on read.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::model::gaussians::HostGaussians;
use crate::model::state::ModelSnapshot;

const MAGIC: &[u8; 8] = b"DFVKCKPT";

/// Everything needed to continue a run exactly where it stopped.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Checkpoint {
    /// Iterations completed.
    pub iteration: u32,
    /// Parameters and Adam moments of the Gaussians and the MLP.
    pub model: ModelSnapshot,
    /// Densification statistics per Gaussian: gradient accumulator, count, max radius.
    pub densify_stats: [Vec<f32>; 3],
}

#[derive(Serialize, Deserialize)]
struct Header {
    version: u32,
    iteration: u32,
    sh_coeffs: u32,
    blobs: Vec<(String, u64)>,
}

fn io_err(path: &Path, source: std::io::Error) -> Error {
    Error::Io {
        path: path.display().to_string(),
        source,
    }
}

fn gauss_blobs<'a>(prefix: &str, g: &'a HostGaussians, out: &mut Vec<(String, &'a [f32])>) {
    out.push((format!("{prefix}means"), g.means.as_flattened()));
    out.push((format!("{prefix}log_scales"), g.log_scales.as_flattened()));
    out.push((format!("{prefix}quats"), g.quats.as_flattened()));
    out.push((format!("{prefix}opacity"), &g.opacity));
    out.push((format!("{prefix}sh_dc"), g.sh_dc.as_flattened()));
    out.push((format!("{prefix}sh_rest"), &g.sh_rest));
}

fn take_gauss(
    prefix: &str,
    m: &mut BTreeMap<String, Vec<f32>>,
    sh_coeffs: u32,
    path: &Path,
) -> Result<HostGaussians> {
    let mut get = |k: &str| {
        m.remove(&format!("{prefix}{k}"))
            .ok_or_else(|| bad(path, &format!("blob {prefix}{k} missing")))
    };
    fn arr<const N: usize>(v: Vec<f32>) -> Vec<[f32; N]> {
        v.chunks_exact(N).map(|c| c.try_into().unwrap()).collect()
    }
    let g = HostGaussians {
        sh_coeffs,
        means: arr::<3>(get("means")?),
        log_scales: arr::<3>(get("log_scales")?),
        quats: arr::<4>(get("quats")?),
        opacity: get("opacity")?,
        sh_dc: arr::<3>(get("sh_dc")?),
        sh_rest: get("sh_rest")?,
    };
    let n = g.means.len();
    if g.log_scales.len() != n
        || g.quats.len() != n
        || g.opacity.len() != n
        || g.sh_dc.len() != n
        || g.sh_rest.len() != n * 3 * (sh_coeffs as usize - 1)
    {
        return Err(bad(
            path,
            &format!("{prefix}Gaussian blobs disagree on the count ({n})"),
        ));
    }
    Ok(g)
}

fn bad(path: &Path, why: &str) -> Error {
    Error::Invalid(format!("{}: not a valid checkpoint: {why}", path.display()))
}

/// Writes `bytes` to `path` atomically: a killed process leaves the old file or the new one.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = path.with_extension("tmp");
    {
        let mut f = std::fs::File::create(&tmp).map_err(|e| io_err(&tmp, e))?;
        f.write_all(bytes).map_err(|e| io_err(&tmp, e))?;
        f.sync_all().map_err(|e| io_err(&tmp, e))?;
    }
    std::fs::rename(&tmp, path).map_err(|e| io_err(path, e))?;
    if let Some(dir) = path.parent().and_then(|d| std::fs::File::open(d).ok()) {
        let _ = dir.sync_all(); // make the rename itself durable where the platform allows
    }
    Ok(())
}

impl Checkpoint {
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut blobs: Vec<(String, &[f32])> = Vec::new();
        gauss_blobs("", &self.model.gaussians, &mut blobs);
        gauss_blobs("m.", &self.model.gauss_m, &mut blobs);
        gauss_blobs("v.", &self.model.gauss_v, &mut blobs);
        for (k, v) in ["grad_accum", "denom", "max_radii"]
            .iter()
            .zip(&self.densify_stats)
        {
            blobs.push((k.to_string(), v));
        }
        blobs.push(("mlp_params".into(), &self.model.mlp_params));
        blobs.push(("mlp_m".into(), &self.model.mlp_m));
        blobs.push(("mlp_v".into(), &self.model.mlp_v));
        let header = Header {
            version: 1,
            iteration: self.iteration,
            sh_coeffs: self.model.gaussians.sh_coeffs,
            blobs: blobs
                .iter()
                .map(|(k, v)| (k.clone(), v.len() as u64))
                .collect(),
        };
        let h = serde_json::to_vec(&header).expect("header serialises");
        let mut out =
            Vec::with_capacity(16 + h.len() + blobs.iter().map(|b| b.1.len() * 4).sum::<usize>());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&(h.len() as u64).to_le_bytes());
        out.extend_from_slice(&h);
        for (_, v) in &blobs {
            out.extend_from_slice(bytemuck::cast_slice(v));
        }
        out
    }

    pub fn save(&self, path: &Path) -> Result<()> {
        write_atomic(path, &self.to_bytes())
    }

    pub fn load(path: &Path) -> Result<Checkpoint> {
        let bytes = std::fs::read(path).map_err(|e| io_err(path, e))?;
        if bytes.len() < 16 || &bytes[..8] != MAGIC {
            return Err(bad(path, "wrong magic (expected DFVKCKPT)"));
        }
        let hl = u64::from_le_bytes(bytes[8..16].try_into().unwrap()) as usize;
        let hdr = bytes
            .get(16..16usize.saturating_add(hl))
            .ok_or_else(|| bad(path, "truncated header"))?;
        let header: Header =
            serde_json::from_slice(hdr).map_err(|e| bad(path, &format!("header: {e}")))?;
        if header.version != 1 || !matches!(header.sh_coeffs, 1 | 4 | 9 | 16) {
            return Err(bad(path, "unsupported version or SH coefficient count"));
        }
        let mut at = 16 + hl;
        let mut m = BTreeMap::new();
        for (k, len) in header.blobs {
            let end = (len as usize)
                .checked_mul(4)
                .and_then(|b| b.checked_add(at))
                .filter(|&e| e <= bytes.len());
            let end = end.ok_or_else(|| bad(path, &format!("blob {k} truncated")))?;
            m.insert(k, bytemuck::pod_collect_to_vec::<u8, f32>(&bytes[at..end]));
            at = end;
        }
        if at != bytes.len() {
            return Err(bad(path, "trailing bytes"));
        }
        let sc = header.sh_coeffs;
        let gaussians = take_gauss("", &mut m, sc, path)?;
        let gauss_m = take_gauss("m.", &mut m, sc, path)?;
        let gauss_v = take_gauss("v.", &mut m, sc, path)?;
        let mut get = |k: &str| {
            m.remove(k)
                .ok_or_else(|| bad(path, &format!("blob {k} missing")))
        };
        let densify_stats = [get("grad_accum")?, get("denom")?, get("max_radii")?];
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
        Ok(Checkpoint {
            iteration: header.iteration,
            model: ModelSnapshot {
                gaussians,
                gauss_m,
                gauss_v,
                mlp_params,
                mlp_m,
                mlp_v,
            },
            densify_stats,
        })
    }
}

/// `DIR/checkpoints/last.ckpt`
pub fn last_checkpoint(out_dir: &Path) -> PathBuf {
    out_dir.join("checkpoints").join("last.ckpt")
}

/// Writes canonical Gaussians as the standard 3DGS PLY (binary little endian): x y z, nx ny nz
/// (zeros), f_dc_0..2, f_rest_* (channel-major, as 3DGS stores them), opacity (logit),
/// scale_0..2 (log), rot_0..3 (w x y z). Common splat viewers read this layout.
pub fn write_ply(path: &Path, g: &HostGaussians) -> Result<()> {
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
        out.extend_from_slice(bytemuck::cast_slice(&row));
    }
    write_atomic(path, &out)
}

/// Reads a PLY written by [`write_ply`] (or by 3DGS) back into Gaussians.
pub fn read_ply(path: &Path) -> Result<HostGaussians> {
    let bytes = std::fs::read(path).map_err(|e| io_err(path, e))?;
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
    let mut g = HostGaussians {
        sh_coeffs: (k + 1) as u32,
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
    }
    Ok(g)
}
