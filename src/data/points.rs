//! Initial points: `points.npy`, COLMAP `points3D.bin` (aligned to the JSON cameras), PLY, or
//! random points in the scene bounds. Also the `.npy` helpers shared with the flow files.
//!
//! Over 600 lines: four point sources with their format checks (npy, COLMAP binary, PLY,
//! random) and the COLMAP-to-JSON alignment, each a separate section below.

use std::path::{Path, PathBuf};

use glam::{DMat3, DQuat, DVec3, Vec3};
use rand::{Rng, SeedableRng};

use super::{Bounds, DataError, DataResult};

/// Which source of initial points to use.
#[derive(
    Clone,
    Copy,
    Debug,
    Default,
    PartialEq,
    Eq,
    clap::ValueEnum,
    serde::Serialize,
    serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum PointsPreference {
    /// The first available of: points.npy, COLMAP points3D.bin, PLY, random.
    #[default]
    Auto,
    /// `points.npy` (error if absent).
    Npy,
    /// COLMAP `points3D.bin` aligned to the cameras (error if absent or alignment fails).
    Colmap,
    /// `points3d.ply` / `fused.ply` (error if absent).
    Ply,
    /// Uniformly random points in the scene bounds.
    Random,
    /// The official Deformable-3DGS rule: D-NeRF scenes read `points3d.ply` alone, else
    /// 100 000 points uniform in the cube ±1.3 (other files such as `fused.ply` are ignored);
    /// nerfies captures `points.npy` (as `auto`, which tries it first).
    Official,
}

/// Points and half-size of the official Deformable-3DGS's random D-NeRF initialisation.
pub const OFFICIAL_RANDOM_POINTS: usize = 100_000;
pub const OFFICIAL_RANDOM_HALF: f32 = 1.3;

/// Where the initial points came from.
#[derive(Clone, Debug, PartialEq)]
pub enum PointSource {
    Npy(PathBuf),
    /// COLMAP points mapped into the JSON frame by a similarity fitted on the camera centres.
    Colmap {
        path: PathBuf,
        /// RMS distance between the aligned COLMAP centres and the JSON positions (raw units).
        rms_residual: f64,
        /// Number of cameras matched by name.
        matched: usize,
    },
    Ply(PathBuf),
    Random,
}

impl std::fmt::Display for PointSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            PointSource::Npy(p) => write!(f, "{}", p.display()),
            PointSource::Colmap {
                path,
                rms_residual,
                matched,
            } => write!(
                f,
                "{} (aligned on {matched} camera centres, rms residual {rms_residual:.2e})",
                path.display()
            ),
            PointSource::Ply(p) => write!(f, "{}", p.display()),
            PointSource::Random => write!(f, "random in the scene bounds"),
        }
    }
}

/// Initial points in the normalised world frame.
#[derive(Clone, Debug)]
pub struct InitPoints {
    pub positions: Vec<Vec3>,
    /// RGB in `[0,1]` when the source has colours.
    pub colors: Option<Vec<[f32; 3]>>,
    pub source: PointSource,
}

/// Uniformly random points in `bounds` (deterministic by seed).
pub fn random_points(bounds: &Bounds, n: usize, seed: u64) -> InitPoints {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed ^ 0x5eed_9017);
    let e = bounds.extent();
    let positions = (0..n)
        .map(|_| bounds.min + Vec3::new(rng.gen(), rng.gen(), rng.gen()) * e)
        .collect();
    InitPoints {
        positions,
        colors: None,
        source: PointSource::Random,
    }
}

fn check_finite(path: &Path, pts: &[DVec3]) -> DataResult<()> {
    if let Some(i) = pts.iter().position(|p| !p.is_finite()) {
        return Err(DataError::file(
            path,
            format!(
                "point {i} is not finite ({:?}); expected finite coordinates",
                pts[i]
            ),
        ));
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// .npy

/// Reads a C-order float32/float64 `.npy` array: `(shape, values as f32)`.
pub(crate) fn read_npy_f32(path: &Path) -> DataResult<(Vec<u64>, Vec<f32>)> {
    let (shape, v) = read_npy(path)?;
    Ok((shape, v.into_iter().map(|x| x as f32).collect()))
}

fn read_npy(path: &Path) -> DataResult<(Vec<u64>, Vec<f64>)> {
    use npyz::{DType, TypeChar};
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    let bad = |msg: String| DataError::file(path, msg);
    let file =
        npyz::NpyFile::new(&bytes[..]).map_err(|e| bad(format!("not a valid .npy file: {e}")))?;
    if file.order() != npyz::Order::C {
        return Err(bad(
            "Fortran-order array; expected a C-order (row-major) array".into(),
        ));
    }
    let size = match file.dtype() {
        DType::Plain(ts) if ts.type_char() == TypeChar::Float => ts.size_field(),
        other => {
            return Err(bad(format!(
                "dtype {}; expected float32 or float64",
                other.descr()
            )))
        }
    };
    let shape = file.shape().to_vec();
    let len = shape
        .iter()
        .try_fold(1u64, |a, &d| a.checked_mul(d))
        .ok_or_else(|| bad(format!("shape {shape:?} overflows")))?;
    if len.saturating_mul(size) > bytes.len() as u64 {
        return Err(bad(format!(
            "shape {shape:?} needs {} bytes of data but the file has {}; truncated?",
            len.saturating_mul(size),
            bytes.len()
        )));
    }
    let data: Vec<f64> = match size {
        4 => file
            .into_vec::<f32>()
            .map(|v| v.into_iter().map(f64::from).collect()),
        8 => file.into_vec::<f64>(),
        s => {
            return Err(bad(format!(
                "float of {s} bytes; expected float32 or float64"
            )))
        }
    }
    .map_err(|e| bad(format!("cannot read the array data: {e}")))?;
    if data.len() as u64 != len {
        return Err(bad(format!(
            "{} values for shape {shape:?}; truncated?",
            data.len()
        )));
    }
    Ok((shape, data))
}

/// Writes a C-order float32 `.npy` array.
pub(crate) fn write_npy_f32(path: &Path, shape: &[u64], data: &[f32]) -> DataResult<()> {
    use npyz::WriterBuilder;
    use std::io::Write;
    let file = std::fs::File::create(path).map_err(|e| DataError::write(path, e))?;
    let mut buf = std::io::BufWriter::new(file);
    let mut w = npyz::WriteOptions::new()
        .default_dtype()
        .shape(shape)
        .writer(&mut buf)
        .begin_nd()
        .map_err(|e| DataError::write(path, e))?;
    w.extend(data.iter().copied())
        .map_err(|e| DataError::write(path, e))?;
    w.finish().map_err(|e| DataError::write(path, e))?;
    buf.flush().map_err(|e| DataError::write(path, e))
}

/// Reads `points.npy`: an `N×3` (or `N×≥3`, extra columns ignored) float array of raw world
/// positions. NaN/Inf is an error.
pub fn read_points_npy(path: &Path) -> DataResult<Vec<DVec3>> {
    let (shape, v) = read_npy(path)?;
    if shape.len() != 2 || shape[1] < 3 {
        return Err(DataError::file(
            path,
            format!("array of shape {shape:?}; expected N×3 point positions"),
        ));
    }
    let cols = shape[1] as usize;
    let pts: Vec<DVec3> = v
        .chunks_exact(cols)
        .map(|c| DVec3::new(c[0], c[1], c[2]))
        .collect();
    if pts.is_empty() {
        return Err(DataError::file(path, "0 points; expected at least one"));
    }
    check_finite(path, &pts)?;
    Ok(pts)
}

// ---------------------------------------------------------------------------------------------
// COLMAP binary model

struct Bin<'a> {
    b: &'a [u8],
    pos: usize,
    path: &'a Path,
}

impl<'a> Bin<'a> {
    fn take(&mut self, n: usize, what: &str) -> DataResult<&'a [u8]> {
        if self.b.len() - self.pos < n {
            return Err(DataError::file(
                self.path,
                format!(
                    "truncated at byte {} while reading {what}; expected {n} more bytes",
                    self.pos
                ),
            ));
        }
        let s = &self.b[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn u64(&mut self, what: &str) -> DataResult<u64> {
        let s = self.take(8, what)?;
        Ok(u64::from_le_bytes(s.try_into().unwrap_or_default()))
    }
    fn u32(&mut self, what: &str) -> DataResult<u32> {
        let s = self.take(4, what)?;
        Ok(u32::from_le_bytes(s.try_into().unwrap_or_default()))
    }
    fn f64(&mut self, what: &str) -> DataResult<f64> {
        let s = self.take(8, what)?;
        Ok(f64::from_le_bytes(s.try_into().unwrap_or_default()))
    }
    fn skip(&mut self, count: u64, size: u64, what: &str) -> DataResult<()> {
        let n = count
            .checked_mul(size)
            .filter(|n| *n <= (self.b.len() - self.pos) as u64)
            .ok_or_else(|| {
                DataError::file(
                    self.path,
                    format!("{what}: {count} entries do not fit in the file; truncated or corrupt"),
                )
            })?;
        self.pos += n as usize;
        Ok(())
    }
}

/// A COLMAP image: name and camera centre `−Rᵀt`.
#[derive(Clone, Debug)]
pub struct ColmapImage {
    pub name: String,
    pub centre: DVec3,
}

/// Reads COLMAP `images.bin`: names and camera centres.
pub fn read_colmap_images(path: &Path) -> DataResult<Vec<ColmapImage>> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    let mut r = Bin {
        b: &bytes,
        pos: 0,
        path,
    };
    let n = r.u64("the image count")?;
    let mut out = Vec::new();
    for _ in 0..n {
        r.u32("image_id")?;
        let q: Vec<f64> = (0..4).map(|_| r.f64("qvec")).collect::<DataResult<_>>()?;
        let t: Vec<f64> = (0..3).map(|_| r.f64("tvec")).collect::<DataResult<_>>()?;
        r.u32("camera_id")?;
        let start = r.pos;
        let len = r.b[start..]
            .iter()
            .position(|&c| c == 0)
            .ok_or_else(|| DataError::file(path, "unterminated image name"))?;
        let name = String::from_utf8_lossy(&r.b[start..start + len]).into_owned();
        r.pos = start + len + 1;
        let n2d = r.u64("num_points2D")?;
        r.skip(n2d, 24, "points2D")?;
        let quat = DQuat::from_xyzw(q[1], q[2], q[3], q[0]);
        if !quat.is_finite() || quat.length() < 1e-9 || !t.iter().all(|x| x.is_finite()) {
            return Err(DataError::file(
                path,
                format!("image {name:?}: non-finite or zero pose"),
            ));
        }
        let rot = DMat3::from_quat(quat.normalize());
        let centre = -(rot.transpose() * DVec3::new(t[0], t[1], t[2]));
        out.push(ColmapImage { name, centre });
    }
    Ok(out)
}

/// Reads COLMAP `points3D.bin`: positions and colours (RGB in `[0,1]`).
pub fn read_colmap_points(path: &Path) -> DataResult<(Vec<DVec3>, Vec<[f32; 3]>)> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    let mut r = Bin {
        b: &bytes,
        pos: 0,
        path,
    };
    let n = r.u64("the point count")?;
    let mut pts = Vec::new();
    let mut cols = Vec::new();
    for _ in 0..n {
        r.u64("point3D_id")?;
        let p = DVec3::new(r.f64("xyz")?, r.f64("xyz")?, r.f64("xyz")?);
        let c = r.take(3, "rgb")?;
        r.f64("error")?;
        let track = r.u64("track_length")?;
        r.skip(track, 8, "track")?;
        pts.push(p);
        cols.push([
            c[0] as f32 / 255.0,
            c[1] as f32 / 255.0,
            c[2] as f32 / 255.0,
        ]);
    }
    if pts.is_empty() {
        return Err(DataError::file(path, "0 points; expected at least one"));
    }
    check_finite(path, &pts)?;
    Ok((pts, cols))
}

/// A similarity transform `y = s·R·x + t`.
#[derive(Clone, Copy, Debug)]
pub struct Similarity {
    pub scale: f64,
    pub rotation: DMat3,
    pub translation: DVec3,
}

impl Similarity {
    pub fn apply(&self, x: DVec3) -> DVec3 {
        self.scale * (self.rotation * x) + self.translation
    }
}

/// Least-squares similarity mapping `src[i]` onto `dst[i]` (Umeyama; the rotation is found by
/// Horn's quaternion method, so it is always proper). Returns the transform and the RMS residual,
/// or `None` for fewer than 3 pairs or degenerate (collinear) input.
pub fn umeyama(src: &[DVec3], dst: &[DVec3]) -> Option<(Similarity, f64)> {
    let n = src.len();
    if n < 3 || dst.len() != n {
        return None;
    }
    let ma = src.iter().copied().sum::<DVec3>() / n as f64;
    let mb = dst.iter().copied().sum::<DVec3>() / n as f64;
    let mut s = [[0.0f64; 3]; 3];
    let mut var_a = 0.0;
    for (a, b) in src.iter().zip(dst) {
        let (a, b) = ((*a - ma).to_array(), (*b - mb).to_array());
        for i in 0..3 {
            for j in 0..3 {
                s[i][j] += a[i] * b[j];
            }
        }
        var_a += a.iter().map(|x| x * x).sum::<f64>();
    }
    if var_a < 1e-18 {
        return None;
    }
    let [[sxx, sxy, sxz], [syx, syy, syz], [szx, szy, szz]] = s;
    let nm = [
        [sxx + syy + szz, syz - szy, szx - sxz, sxy - syx],
        [syz - szy, sxx - syy - szz, sxy + syx, szx + sxz],
        [szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy],
        [sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz],
    ];
    let (vals, vecs) = crate::linalg::jacobi(nm);
    let k = (0..4).max_by(|&i, &j| vals[i].total_cmp(&vals[j]))?;
    let q = DQuat::from_xyzw(vecs[1][k], vecs[2][k], vecs[3][k], vecs[0][k]);
    if !q.is_finite() || q.length() < 1e-9 {
        return None;
    }
    let rotation = DMat3::from_quat(q.normalize());
    let num: f64 = src
        .iter()
        .zip(dst)
        .map(|(a, b)| (*b - mb).dot(rotation * (*a - ma)))
        .sum();
    let scale = num / var_a;
    if !(scale.is_finite() && scale > 0.0) {
        return None;
    }
    let translation = mb - scale * (rotation * ma);
    let sim = Similarity {
        scale,
        rotation,
        translation,
    };
    let rms = (src
        .iter()
        .zip(dst)
        .map(|(a, b)| (sim.apply(*a) - *b).length_squared())
        .sum::<f64>()
        / n as f64)
        .sqrt();
    Some((sim, rms))
}

// ---------------------------------------------------------------------------------------------
// PLY

/// Positions and optional colours read from a point file.
pub type PointsAndColors = (Vec<DVec3>, Option<Vec<[f32; 3]>>);

/// Initial points from a PLY file (positions mapped by `place`), shared by both loaders:
/// `None` when there is no file and the preference allows falling through, an error naming the
/// expected files when PLY was asked for explicitly.
pub fn ply_points(
    dir: &Path,
    ply: Option<&Path>,
    pref: PointsPreference,
    place: impl Fn(&[DVec3]) -> Vec<Vec3>,
) -> DataResult<Option<InitPoints>> {
    match ply {
        Some(p) => {
            let (pts, cols) = read_ply(p)?;
            Ok(Some(InitPoints {
                positions: place(&pts),
                colors: cols,
                source: PointSource::Ply(p.to_path_buf()),
            }))
        }
        None if pref == PointsPreference::Ply => Err(DataError::file(
            &dir.join("points3d.ply"),
            "missing; expected points3d.ply or fused.ply",
        )),
        None => Ok(None),
    }
}

/// Reads the `vertex` element of a PLY file (ascii or binary): positions and colours when the
/// file has `red green blue` properties.
pub fn read_ply(path: &Path) -> DataResult<PointsAndColors> {
    let bytes = std::fs::read(path).map_err(|e| DataError::io(path, e))?;
    let bad = |msg: String| DataError::file(path, msg);
    let end = b"end_header";
    let hpos = bytes
        .windows(end.len())
        .position(|w| w == end)
        .ok_or_else(|| bad("no \"end_header\"; expected a PLY header".into()))?;
    let mut body = hpos + end.len();
    if bytes.get(body) == Some(&b'\r') {
        body += 1;
    }
    if bytes.get(body) == Some(&b'\n') {
        body += 1;
    }
    let header = String::from_utf8_lossy(&bytes[..hpos]);
    let mut lines = header.lines();
    if lines.next().map(str::trim) != Some("ply") {
        return Err(bad("does not start with \"ply\"".into()));
    }
    let mut format = None;
    let mut count: Option<usize> = None;
    let mut in_vertex = false;
    let mut seen_element = false;
    let mut props: Vec<(String, String)> = Vec::new();
    for line in lines {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["format", f, _] => format = Some(f.to_string()),
            ["element", name, n] => {
                if *name == "vertex" {
                    if seen_element {
                        return Err(bad("the vertex element must come first".into()));
                    }
                    count = Some(
                        n.parse()
                            .map_err(|_| bad(format!("vertex count {n:?} is not an integer")))?,
                    );
                    in_vertex = true;
                } else {
                    in_vertex = false;
                }
                seen_element = true;
            }
            ["property", "list", ..] if in_vertex => {
                return Err(bad("list property in the vertex element".into()))
            }
            ["property", ty, name] if in_vertex => props.push((ty.to_string(), name.to_string())),
            _ => {}
        }
    }
    let n = count.ok_or_else(|| bad("no \"element vertex\" in the header".into()))?;
    let idx = |name: &str| props.iter().position(|(_, p)| p == name);
    let (ix, iy, iz) = match (idx("x"), idx("y"), idx("z")) {
        (Some(x), Some(y), Some(z)) => (x, y, z),
        _ => return Err(bad("vertex element lacks x, y, z properties".into())),
    };
    let color = match (idx("red"), idx("green"), idx("blue")) {
        (Some(r), Some(g), Some(b)) => Some([r, g, b]),
        _ => None,
    };
    let mut rows: Vec<Vec<f64>> = Vec::new();
    match format.as_deref() {
        Some("ascii") => {
            let text = String::from_utf8_lossy(&bytes[body..]);
            for (i, line) in text
                .lines()
                .filter(|l| !l.trim().is_empty())
                .take(n)
                .enumerate()
            {
                let vals: Vec<f64> = line
                    .split_whitespace()
                    .map(|t| t.parse::<f64>())
                    .collect::<Result<_, _>>()
                    .map_err(|_| bad(format!("vertex {i}: not a list of numbers")))?;
                if vals.len() < props.len() {
                    return Err(bad(format!(
                        "vertex {i}: {} values, expected {}",
                        vals.len(),
                        props.len()
                    )));
                }
                rows.push(vals);
            }
        }
        Some(f @ ("binary_little_endian" | "binary_big_endian")) => {
            let le = f == "binary_little_endian";
            let sizes: Vec<usize> = props
                .iter()
                .map(|(t, name)| {
                    ply_size(t).ok_or_else(|| bad(format!("property {name}: unknown type {t:?}")))
                })
                .collect::<DataResult<_>>()?;
            let stride: usize = sizes.iter().sum();
            if n.checked_mul(stride)
                .map_or(true, |total| total > bytes.len() - body)
            {
                return Err(bad(format!(
                    "{n} vertices of {stride} bytes do not fit in the file; truncated?"
                )));
            }
            for i in 0..n {
                let mut off = body + i * stride;
                let mut row = Vec::with_capacity(props.len());
                for ((t, _), sz) in props.iter().zip(&sizes) {
                    row.push(ply_value(t, &bytes[off..off + sz], le));
                    off += sz;
                }
                rows.push(row);
            }
        }
        other => {
            return Err(bad(format!(
                "format {other:?}; expected ascii, binary_little_endian or binary_big_endian"
            )))
        }
    }
    if rows.len() != n {
        return Err(bad(format!(
            "{} vertices, header says {n}; truncated?",
            rows.len()
        )));
    }
    if n == 0 {
        return Err(bad("0 vertices; expected at least one".into()));
    }
    let pts: Vec<DVec3> = rows
        .iter()
        .map(|r| DVec3::new(r[ix], r[iy], r[iz]))
        .collect();
    check_finite(path, &pts)?;
    let colors = color.map(|[r, g, b]| {
        let norm = if props[r].0.contains("char") || props[r].0.contains("int8") {
            255.0
        } else {
            1.0
        };
        rows.iter()
            .map(|row| {
                [
                    (row[r] / norm) as f32,
                    (row[g] / norm) as f32,
                    (row[b] / norm) as f32,
                ]
            })
            .collect()
    });
    Ok((pts, colors))
}

fn ply_size(t: &str) -> Option<usize> {
    Some(match t {
        "char" | "uchar" | "int8" | "uint8" => 1,
        "short" | "ushort" | "int16" | "uint16" => 2,
        "int" | "uint" | "int32" | "uint32" | "float" | "float32" => 4,
        "double" | "float64" => 8,
        _ => return None,
    })
}

fn ply_value(t: &str, b: &[u8], le: bool) -> f64 {
    macro_rules! rd {
        ($ty:ty) => {{
            let a = b.try_into().unwrap_or_default();
            (if le {
                <$ty>::from_le_bytes(a)
            } else {
                <$ty>::from_be_bytes(a)
            }) as f64
        }};
    }
    match t {
        "char" | "int8" => rd!(i8),
        "uchar" | "uint8" => rd!(u8),
        "short" | "int16" => rd!(i16),
        "ushort" | "uint16" => rd!(u16),
        "int" | "int32" => rd!(i32),
        "uint" | "uint32" => rd!(u32),
        "float" | "float32" => rd!(f32),
        _ => rd!(f64),
    }
}
