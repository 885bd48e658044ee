//! Pinhole camera with a principal point (OpenCV convention) and the Brown–Conrady distortion
//! model used by nerfies captures.

use glam::{DMat3, DVec2, DVec3, Mat3, Vec2, Vec3};

/// OpenCV pinhole camera: x right, y down, z forward. World to camera is `p_cam = R·p + t`,
/// pixel = `(fx·x/z + cx, fy·y/z + cy)` with the pixel-centre of `(i, j)` at `(i+0.5, j+0.5)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// World-to-camera rotation (rows are the camera axes in world coordinates).
    pub rotation: Mat3,
    /// World-to-camera translation `t = −R·c`.
    pub translation: Vec3,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    pub width: u32,
    pub height: u32,
}

impl Camera {
    /// Builds a camera from its world-to-camera rotation and its centre in world coordinates.
    pub fn from_centre(
        rotation: Mat3,
        centre: Vec3,
        [fx, fy, cx, cy]: [f32; 4],
        width: u32,
        height: u32,
    ) -> Self {
        Camera {
            rotation,
            translation: -(rotation * centre),
            fx,
            fy,
            cx,
            cy,
            width,
            height,
        }
    }

    /// Camera centre in world coordinates (`−Rᵀt`).
    pub fn centre(&self) -> Vec3 {
        -(self.rotation.transpose() * self.translation)
    }

    /// Viewing direction (camera +z) in world coordinates.
    pub fn forward(&self) -> Vec3 {
        self.rotation.row(2)
    }

    /// World point to camera coordinates.
    pub fn to_camera(&self, p: Vec3) -> Vec3 {
        self.rotation * p + self.translation
    }

    /// Projects a world point: pixel position and depth, `None` when behind the camera.
    pub fn project(&self, p: Vec3) -> Option<(Vec2, f32)> {
        let q = self.to_camera(p);
        if q.z <= 1e-8 {
            return None;
        }
        Some((
            Vec2::new(self.fx * q.x / q.z + self.cx, self.fy * q.y / q.z + self.cy),
            q.z,
        ))
    }

    /// Whether a pixel position lies inside the image.
    pub fn contains(&self, px: Vec2) -> bool {
        px.x >= 0.0 && px.y >= 0.0 && px.x < self.width as f32 && px.y < self.height as f32
    }

    /// The same camera for an image resampled to `width × height` by a factor `k` (e.g. 0.25 for
    /// a 4× downscale): intrinsics are multiplied by `k`.
    pub fn scaled(&self, k: f32, width: u32, height: u32) -> Camera {
        Camera {
            fx: self.fx * k,
            fy: self.fy * k,
            cx: self.cx * k,
            cy: self.cy * k,
            width,
            height,
            ..*self
        }
    }
}

/// Brown–Conrady (OpenCV) lens distortion on normalised image coordinates, with skew, as in the
/// nerfies camera model: `pixel = (fx·xd + skew·yd + cx, fy·yd + cy)` with
/// `(xd, yd) = distort(x/z, y/z)`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Distortion {
    pub k1: f64,
    pub k2: f64,
    pub k3: f64,
    pub p1: f64,
    pub p2: f64,
    /// Skew in pixels (at the resolution the camera is defined at).
    pub skew: f64,
}

impl Distortion {
    /// True when every coefficient is zero (the mapping is the identity).
    pub fn is_identity(&self) -> bool {
        self.k1 == 0.0
            && self.k2 == 0.0
            && self.k3 == 0.0
            && self.p1 == 0.0
            && self.p2 == 0.0
            && self.skew == 0.0
    }

    /// Applies the radial and tangential distortion to a normalised point.
    pub fn distort(&self, p: DVec2) -> DVec2 {
        let (x, y) = (p.x, p.y);
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (self.k1 + r2 * (self.k2 + r2 * self.k3));
        let dx = 2.0 * self.p1 * x * y + self.p2 * (r2 + 2.0 * x * x);
        let dy = self.p1 * (r2 + 2.0 * y * y) + 2.0 * self.p2 * x * y;
        DVec2::new(x * radial + dx, y * radial + dy)
    }

    /// Inverts [`Self::distort`] by fixed-point iteration (for tests and diagnostics).
    pub fn undistort(&self, pd: DVec2) -> DVec2 {
        let mut p = pd;
        for _ in 0..50 {
            let d = self.distort(p);
            p += pd - d;
        }
        p
    }
}

/// Rotation matrix from rows (world-to-camera rows = camera axes).
pub(crate) fn mat3_from_rows(r: &[Vec<f64>]) -> DMat3 {
    DMat3::from_cols(
        DVec3::new(r[0][0], r[0][1], r[0][2]),
        DVec3::new(r[1][0], r[1][1], r[1][2]),
        DVec3::new(r[2][0], r[2][1], r[2][2]),
    )
    .transpose()
}

/// How far a matrix is from a rotation: max |RᵀR − I| and det.
pub(crate) fn rotation_defect(r: &DMat3) -> (f64, f64) {
    let m = r.transpose() * *r - DMat3::IDENTITY;
    let e = m.to_cols_array().iter().fold(0.0f64, |a, b| a.max(b.abs()));
    (e, r.determinant())
}
