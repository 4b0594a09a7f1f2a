//! Pinhole cameras with OpenCV radial-tangential distortion, and the rays through their
//! pixels.
//!
//! Conventions (those of [`crate::volume`]):
//!
//! * **Pose**: `c2w` maps camera coordinates to world coordinates (world units of the
//!   dataset). Camera axes follow OpenGL/Blender: +X right, +Y up, looking down −Z. The
//!   rotation part must be orthonormal with determinant +1 (`check_pose`).
//! * **Pixels**: image x right, y down; pixel `(x, y)` covers `[x, x+1] × [y, y+1]` and
//!   its center is `(u, v) = (x + 0.5, y + 0.5)`. Intrinsics `fx, fy, cx, cy` are in
//!   pixels of this image.
//! * **Distortion**: the OpenCV model (`k1, k2` radial, `p1, p2` tangential) acts on
//!   OpenCV normalized coordinates `(x', y') = ((u − cx)/fx, (v − cy)/fy)` (y down), as
//!   COLMAP and instant-ngp write them. The undistorted point `(x, y)` gives the
//!   camera-space direction `(x, −y, −1)` (y flipped to the OpenGL axes), normalized.

use glam::{Affine3A, Mat3A, Vec2, Vec3, Vec3A};
use rayon::prelude::*;

use super::Ray;

/// Largest tolerated `max |RᵀR − I|` entry for a pose's rotation part.
pub(crate) const ORTHONORMAL_TOLERANCE: f64 = 1e-2;

/// Smallest focal length as a multiple of the image side it spans (`fx / width`,
/// `fy / height`): a field of view of at most 2·atan(500) ≈ 179.8°.
pub(crate) const MIN_FOCAL_RATIO: f64 = 1e-3;

/// Largest focal length as a multiple of the image side it spans: a field of view of at
/// least 2·atan(1/20000) = 10⁻⁴ rad (0.006°). Beyond it every ray of an image is the
/// same ray in `f32`, and a model fitted to it is meaningless.
pub(crate) const MAX_FOCAL_RATIO: f64 = 1e4;

/// Largest magnitude of the radial distortion coefficients `k1`, `k2` (real lenses stay
/// well below 1; fisheye models are not supported).
pub(crate) const MAX_RADIAL_DISTORTION: f64 = 10.0;

/// Largest magnitude of the tangential distortion coefficients `p1`, `p2`.
pub(crate) const MAX_TANGENTIAL_DISTORTION: f64 = 1.0;

/// The field-of-view range (radians) that [`MIN_FOCAL_RATIO`] and [`MAX_FOCAL_RATIO`]
/// allow: `(smallest, largest)`.
pub(crate) fn fov_range() -> (f64, f64) {
    (
        2.0 * (0.5 / MAX_FOCAL_RATIO).atan(),
        2.0 * (0.5 / MIN_FOCAL_RATIO).atan(),
    )
}

/// Why a camera or pose is unusable.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum CameraError {
    /// An entry of the pose is NaN or infinite.
    #[error("pose has a non-finite entry")]
    NonFinite,
    /// The rotation part is not orthonormal (scaled, sheared or singular).
    #[error(
        "degenerate pose: rotation part is not orthonormal (max |RᵀR − I| = {deviation:.2e}, tolerance {ORTHONORMAL_TOLERANCE:.0e})"
    )]
    NotOrthonormal {
        /// Largest entry of `|RᵀR − I|`.
        deviation: f64,
    },
    /// The rotation part is a reflection (determinant −1): a left-handed frame.
    #[error("degenerate pose: rotation part is a reflection (determinant {det:.3})")]
    Reflection {
        /// Determinant of the rotation part.
        det: f64,
    },
    /// A 4×4 pose whose last row is not `0 0 0 1`.
    #[error("pose's last row must be 0 0 0 1, got {row:?}")]
    BottomRow {
        /// The row as given.
        row: [f64; 4],
    },
    /// A pose given as rows is not 3×4 or 4×4.
    #[error("pose must be 4×4 (or 3×4), got {rows} rows")]
    Shape {
        /// Number of rows given.
        rows: usize,
    },
    /// Intrinsics out of range: size zero, focal length not positive, non-finite values.
    #[error("invalid intrinsics: {0}")]
    Intrinsics(String),
    /// `look_at` or `orbit` was given coincident points or a parallel up vector.
    #[error("degenerate view: {0}")]
    Degenerate(&'static str),
}

/// A pinhole camera with optional OpenCV radial-tangential distortion (see the module
/// documentation for the conventions).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Horizontal focal length, pixels.
    pub fx: f32,
    /// Vertical focal length, pixels.
    pub fy: f32,
    /// Principal point x, pixels from the image's left edge (`width / 2` when centered).
    pub cx: f32,
    /// Principal point y, pixels from the image's top edge (`height / 2` when centered).
    pub cy: f32,
    /// First radial distortion coefficient (OpenCV `k1`), unitless.
    pub k1: f32,
    /// Second radial distortion coefficient (OpenCV `k2`), unitless.
    pub k2: f32,
    /// First tangential distortion coefficient (OpenCV `p1`), unitless.
    pub p1: f32,
    /// Second tangential distortion coefficient (OpenCV `p2`), unitless.
    pub p2: f32,
    /// Camera-to-world pose, OpenGL camera axes (+X right, +Y up, looking down −Z).
    pub c2w: Affine3A,
}

impl Camera {
    /// A centered or off-center pinhole camera without distortion; validates the
    /// intrinsics and the pose.
    pub fn new(
        width: u32,
        height: u32,
        fx: f32,
        fy: f32,
        cx: f32,
        cy: f32,
        c2w: Affine3A,
    ) -> Result<Camera, CameraError> {
        let cam = Camera {
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            k1: 0.0,
            k2: 0.0,
            p1: 0.0,
            p2: 0.0,
            c2w,
        };
        cam.validate()?;
        Ok(cam)
    }

    /// A centered camera with square pixels and horizontal field of view `fov_x`
    /// (radians, in `(0, π)`): `fx = fy = width / (2 tan(fov_x / 2))`.
    pub fn from_fov_x(
        width: u32,
        height: u32,
        fov_x: f32,
        c2w: Affine3A,
    ) -> Result<Camera, CameraError> {
        if !(fov_x > 0.0 && fov_x < std::f32::consts::PI) {
            return Err(CameraError::Intrinsics(format!(
                "field of view {fov_x} rad is not in (0, π)"
            )));
        }
        let f = focal_from_fov(width as f32, fov_x);
        Camera::new(
            width,
            height,
            f,
            f,
            width as f32 / 2.0,
            height as f32 / 2.0,
            c2w,
        )
    }

    /// The same camera with OpenCV distortion coefficients `k1, k2` (radial) and `p1, p2`
    /// (tangential).
    pub fn with_distortion(mut self, k1: f32, k2: f32, p1: f32, p2: f32) -> Camera {
        self.k1 = k1;
        self.k2 = k2;
        self.p1 = p1;
        self.p2 = p2;
        self
    }

    /// Checks the size (non-zero), focal lengths (finite, between `MIN_FOCAL_RATIO` and
    /// `MAX_FOCAL_RATIO` times the image side), principal point (finite), distortion
    /// (within `MAX_RADIAL_DISTORTION` and `MAX_TANGENTIAL_DISTORTION`, and radially
    /// one-to-one out to the image's corners, so that every pixel has one ray) and the
    /// pose (`check_pose`).
    pub fn validate(&self) -> Result<(), CameraError> {
        if self.width == 0 || self.height == 0 {
            return Err(CameraError::Intrinsics(format!(
                "image size {}×{} is empty",
                self.width, self.height
            )));
        }
        for (name, f) in [("fx", self.fx), ("fy", self.fy)] {
            if !(f.is_finite() && f > 0.0) {
                return Err(CameraError::Intrinsics(format!(
                    "focal length {name} = {f} must be finite and positive"
                )));
            }
        }
        for (name, f, side, what) in [
            ("fx", self.fx, self.width, "width"),
            ("fy", self.fy, self.height, "height"),
        ] {
            let (lo, hi) = (MIN_FOCAL_RATIO * side as f64, MAX_FOCAL_RATIO * side as f64);
            if !(lo..=hi).contains(&(f as f64)) {
                return Err(CameraError::Intrinsics(format!(
                    "focal length {name} = {f:?} px must be between {lo} and {hi} px \
                     ({MIN_FOCAL_RATIO:e} to {MAX_FOCAL_RATIO:e} times the image {what}, {side} px)"
                )));
            }
        }
        for (name, v) in [
            ("cx", self.cx),
            ("cy", self.cy),
            ("k1", self.k1),
            ("k2", self.k2),
            ("p1", self.p1),
            ("p2", self.p2),
        ] {
            if !v.is_finite() {
                return Err(CameraError::Intrinsics(format!(
                    "{name} = {v} is not finite"
                )));
            }
        }
        for (name, v, max) in [
            ("k1", self.k1, MAX_RADIAL_DISTORTION),
            ("k2", self.k2, MAX_RADIAL_DISTORTION),
            ("p1", self.p1, MAX_TANGENTIAL_DISTORTION),
            ("p2", self.p2, MAX_TANGENTIAL_DISTORTION),
        ] {
            if (v as f64).abs() > max {
                return Err(CameraError::Intrinsics(format!(
                    "{name} = {v:?} is outside [-{max}, {max}]"
                )));
            }
        }
        self.check_radial_one_to_one()?;
        check_pose(&self.c2w)
    }

    /// Errors unless the radial distortion `r ↦ r (1 + k1 r² + k2 r⁴)` increases until it
    /// reaches the farthest image corner (normalized coordinates): otherwise pixels near
    /// the border have no ray or two.
    fn check_radial_one_to_one(&self) -> Result<(), CameraError> {
        if self.k1 == 0.0 && self.k2 == 0.0 {
            return Ok(());
        }
        let (k1, k2) = (self.k1 as f64, self.k2 as f64);
        let corner = [0.0, self.width as f64]
            .iter()
            .flat_map(|&u| [0.0, self.height as f64].map(|v| (u, v)))
            .map(|(u, v)| {
                let x = (u - self.cx as f64) / self.fx as f64;
                let y = (v - self.cy as f64) / self.fy as f64;
                (x * x + y * y).sqrt()
            })
            .fold(0.0f64, f64::max);
        let rd = |r: f64| r * (1.0 + r * r * (k1 + k2 * r * r));
        let slope = |r: f64| 1.0 + r * r * (3.0 * k1 + 5.0 * k2 * r * r);
        let step = (corner / 512.0).max(1e-6);
        let mut r = 0.0;
        // Walk out until the distorted radius passes the corner (at most 4096 steps: 8×
        // the corner radius, far more than any lens compresses).
        for _ in 0..4096 {
            if rd(r) >= corner {
                return Ok(());
            }
            if slope(r) <= 0.0 {
                break;
            }
            r += step;
        }
        Err(CameraError::Intrinsics(format!(
            "distortion k1 = {}, k2 = {} folds over before the image corners \
             (normalized radius {corner:.3}): not one-to-one",
            self.k1, self.k2
        )))
    }

    /// A camera at `eye` looking at `target`, with `up` (world direction) pointing up in
    /// the image as far as possible; horizontal field of view `fov_x` in radians,
    /// centered principal point, no distortion.
    pub fn look_at(
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        fov_x: f32,
        width: u32,
        height: u32,
    ) -> Result<Camera, CameraError> {
        let forward = (target - eye)
            .try_normalize()
            .ok_or(CameraError::Degenerate("eye and target coincide"))?;
        // Within about 0.06° of parallel, round-off leaves a cross product too short to
        // give an orthonormal frame.
        let right = forward.cross(up);
        let right = (right.length() > 1e-3 * up.length())
            .then(|| right.try_normalize())
            .flatten()
            .ok_or(CameraError::Degenerate(
                "up is zero or parallel to the view direction",
            ))?;
        let cam_up = right.cross(forward);
        // Camera +X = right, +Y = up, +Z = −forward (the camera looks down −Z).
        let c2w = Affine3A::from_cols(
            Vec3A::from(right),
            Vec3A::from(cam_up),
            Vec3A::from(-forward),
            Vec3A::from(eye),
        );
        Camera::from_fov_x(width, height, fov_x, c2w)
    }

    /// Horizontal field of view in radians (of the pinhole, ignoring distortion and an
    /// off-center principal point).
    pub fn fov_x(&self) -> f32 {
        2.0 * (0.5 * self.width as f32 / self.fx).atan()
    }

    /// The camera center in world coordinates.
    pub fn position(&self) -> Vec3 {
        Vec3::from(self.c2w.translation)
    }

    /// The viewing direction (camera −Z) in world coordinates, unit length.
    pub fn forward(&self) -> Vec3 {
        -Vec3::from(self.c2w.matrix3.z_axis).normalize()
    }

    /// Whether any distortion coefficient is non-zero.
    pub fn has_distortion(&self) -> bool {
        self.k1 != 0.0 || self.k2 != 0.0 || self.p1 != 0.0 || self.p2 != 0.0
    }

    /// Applies the OpenCV radial-tangential model to an undistorted point in OpenCV
    /// normalized coordinates (`z = 1` plane, y down), giving the distorted point.
    pub fn distort(&self, p: Vec2) -> Vec2 {
        let (x, y) = distort64(self.coeffs(), p.x as f64, p.y as f64);
        Vec2::new(x as f32, y as f32)
    }

    /// Inverts [`distort`](Self::distort) by Newton iterations (at most 20, stopping
    /// below 1e-12): the undistorted normalized point whose distortion is `p`.
    pub fn undistort(&self, p: Vec2) -> Vec2 {
        let (x, y) = undistort64(self.coeffs(), p.x as f64, p.y as f64);
        Vec2::new(x as f32, y as f32)
    }

    /// The ray through pixel coordinates `(u, v)` (continuous: the center of pixel
    /// `(x, y)` is `(x + 0.5, y + 0.5)`), undistorted when the camera has distortion.
    /// Its origin is the camera center; its direction has unit length.
    pub fn ray(&self, u: f32, v: f32) -> Ray {
        let xd = (u as f64 - self.cx as f64) / self.fx as f64;
        let yd = (v as f64 - self.cy as f64) / self.fy as f64;
        let (x, y) = if self.has_distortion() {
            undistort64(self.coeffs(), xd, yd)
        } else {
            (xd, yd)
        };
        let d_cam = Vec3::new(x as f32, -(y as f32), -1.0);
        Ray {
            origin: self.position(),
            dir: self.c2w.transform_vector3(d_cam).normalize(),
        }
    }

    /// The ray through the center of pixel `(x, y)`.
    pub fn pixel_ray(&self, x: u32, y: u32) -> Ray {
        self.ray(x as f32 + 0.5, y as f32 + 0.5)
    }

    /// Rays through all pixel centers, row-major (`index = y · width + x`).
    pub fn rays(&self) -> Vec<Ray> {
        let w = self.width as usize;
        let mut out = vec![
            Ray {
                origin: Vec3::ZERO,
                dir: Vec3::ZERO,
            };
            w * self.height as usize
        ];
        if w == 0 {
            return out;
        }
        out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
            for (x, r) in row.iter_mut().enumerate() {
                *r = self.pixel_ray(x as u32, y as u32);
            }
        });
        out
    }

    /// Projects a world point to continuous pixel coordinates `(u, v)` (distortion
    /// applied); `None` when the point is not in front of the camera.
    pub fn project(&self, p: Vec3) -> Option<Vec2> {
        let q = self.c2w.inverse().transform_point3(p);
        if q.z >= 0.0 {
            return None;
        }
        // OpenCV normalized coordinates: x right, y down, on the z = 1 plane.
        let x = q.x as f64 / -q.z as f64;
        let y = q.y as f64 / q.z as f64;
        let (xd, yd) = if self.has_distortion() {
            distort64(self.coeffs(), x, y)
        } else {
            (x, y)
        };
        Some(Vec2::new(
            (xd * self.fx as f64 + self.cx as f64) as f32,
            (yd * self.fy as f64 + self.cy as f64) as f32,
        ))
    }

    /// The camera for an image resampled by `factor` (e.g. `1.0 / K`): `fx, fy, cx, cy`
    /// multiplied by `factor`, sizes multiplied and rounded down; distortion and pose
    /// unchanged. Prefer [`downscaled`](Self::downscaled) for integer factors.
    pub fn scaled(&self, factor: f32) -> Camera {
        let f = factor as f64;
        // A hair of slack so that e.g. 300 · (1/3 in f32) still gives 100.
        let size = |n: u32| ((n as f64 * f) * (1.0 + 1e-6)).floor().max(0.0) as u32;
        Camera {
            width: size(self.width),
            height: size(self.height),
            fx: (self.fx as f64 * f) as f32,
            fy: (self.fy as f64 * f) as f32,
            cx: (self.cx as f64 * f) as f32,
            cy: (self.cy as f64 * f) as f32,
            ..*self
        }
    }

    /// The camera for an image downscaled by an integer `k ≥ 1` (each output pixel the
    /// average of a `k × k` block): `fx, fy, cx, cy` divided by `k`, sizes divided by `k`
    /// and rounded down (the uncovered right and bottom remainder is dropped, so pixel
    /// geometry stays exact). Panics if `k == 0`.
    pub fn downscaled(&self, k: u32) -> Camera {
        assert!(k > 0, "downscale factor must be at least 1");
        let kf = k as f32;
        Camera {
            width: self.width / k,
            height: self.height / k,
            fx: self.fx / kf,
            fy: self.fy / kf,
            cx: self.cx / kf,
            cy: self.cy / kf,
            ..*self
        }
    }

    fn coeffs(&self) -> [f64; 4] {
        [
            self.k1 as f64,
            self.k2 as f64,
            self.p1 as f64,
            self.p2 as f64,
        ]
    }
}

/// Focal length in pixels of a pinhole whose field of view across `size` pixels is `fov`
/// radians: `size / (2 tan(fov / 2))`.
pub(crate) fn focal_from_fov(size: f32, fov: f32) -> f32 {
    (0.5 * size as f64 / (0.5 * fov as f64).tan()) as f32
}

/// `n` cameras evenly spaced in azimuth on a circle around `center`, at distance `radius`
/// (world units) and `elevation` radians above the plane perpendicular to `up`, each
/// looking at `center` with horizontal field of view `fov_x` (radians) and the given
/// image size. The first camera lies in the direction of world +X projected onto that
/// plane (+Y when `up` is along X); azimuth grows counter-clockwise seen from `up`.
#[allow(clippy::too_many_arguments)]
pub fn orbit(
    n: usize,
    center: Vec3,
    radius: f32,
    elevation: f32,
    up: Vec3,
    fov_x: f32,
    width: u32,
    height: u32,
) -> Result<Vec<Camera>, CameraError> {
    let up = up
        .try_normalize()
        .ok_or(CameraError::Degenerate("up vector is zero"))?;
    let e1 = (Vec3::X - up * up.dot(Vec3::X))
        .try_normalize()
        .filter(|_| up.dot(Vec3::X).abs() < 0.999)
        .unwrap_or_else(|| (Vec3::Y - up * up.dot(Vec3::Y)).normalize());
    let e2 = up.cross(e1);
    (0..n)
        .map(|i| {
            let az = std::f32::consts::TAU * i as f32 / n as f32;
            let horiz = e1 * az.cos() + e2 * az.sin();
            let eye = center + radius * (horiz * elevation.cos() + up * elevation.sin());
            Camera::look_at(eye, center, up, fov_x, width, height)
        })
        .collect()
}

/// Checks that a camera-to-world pose is usable: finite entries, and a rotation part that
/// is orthonormal (within [`ORTHONORMAL_TOLERANCE`]) with determinant +1.
pub(crate) fn check_pose(c2w: &Affine3A) -> Result<(), CameraError> {
    if !c2w.is_finite() {
        return Err(CameraError::NonFinite);
    }
    let m = c2w.matrix3.as_dmat3();
    let g = m.transpose() * m;
    let mut deviation = 0.0f64;
    for c in 0..3 {
        for r in 0..3 {
            let want = if c == r { 1.0 } else { 0.0 };
            deviation = deviation.max((g.col(c)[r] - want).abs());
        }
    }
    if deviation > ORTHONORMAL_TOLERANCE {
        return Err(CameraError::NotOrthonormal { deviation });
    }
    let det = m.determinant();
    if det < 0.0 {
        return Err(CameraError::Reflection { det });
    }
    Ok(())
}

/// A camera-to-world pose from a row-major 3×4 or 4×4 matrix (as in `transforms.json`'s
/// `transform_matrix`), validated with [`check_pose`]. The last row of a 4×4 matrix must
/// be `0 0 0 1` (within 1e-4).
pub(crate) fn pose_from_rows(rows: &[[f64; 4]]) -> Result<Affine3A, CameraError> {
    if rows.len() != 3 && rows.len() != 4 {
        return Err(CameraError::Shape { rows: rows.len() });
    }
    if rows.iter().flatten().any(|v| !v.is_finite()) {
        return Err(CameraError::NonFinite);
    }
    if let Some(last) = rows.get(3) {
        let want = [0.0, 0.0, 0.0, 1.0];
        if last.iter().zip(want).any(|(a, b)| (a - b).abs() > 1e-4) {
            return Err(CameraError::BottomRow { row: *last });
        }
    }
    let col = |c: usize| Vec3A::new(rows[0][c] as f32, rows[1][c] as f32, rows[2][c] as f32);
    let c2w = Affine3A {
        matrix3: Mat3A::from_cols(col(0), col(1), col(2)),
        translation: col(3),
    };
    check_pose(&c2w)?;
    Ok(c2w)
}

/// OpenCV radial-tangential distortion of a normalized point, in `f64`.
fn distort64([k1, k2, p1, p2]: [f64; 4], x: f64, y: f64) -> (f64, f64) {
    let r2 = x * x + y * y;
    let radial = 1.0 + r2 * (k1 + k2 * r2);
    (
        x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
        y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
    )
}

/// Newton's method on `distort(x, y) = (xd, yd)`, starting at the distorted point.
fn undistort64(k: [f64; 4], xd: f64, yd: f64) -> (f64, f64) {
    let [k1, k2, p1, p2] = k;
    let (mut x, mut y) = (xd, yd);
    for _ in 0..20 {
        let (fx, fy) = distort64(k, x, y);
        let (ex, ey) = (fx - xd, fy - yd);
        if ex.abs().max(ey.abs()) < 1e-12 {
            break;
        }
        let r2 = x * x + y * y;
        let radial = 1.0 + r2 * (k1 + k2 * r2);
        let dr = 2.0 * (k1 + 2.0 * k2 * r2); // ∂radial/∂x = x·dr, ∂radial/∂y = y·dr
        let j00 = radial + x * x * dr + 2.0 * p1 * y + 6.0 * p2 * x;
        let j01 = x * y * dr + 2.0 * p1 * x + 2.0 * p2 * y;
        let j10 = j01;
        let j11 = radial + y * y * dr + 6.0 * p1 * y + 2.0 * p2 * x;
        let det = j00 * j11 - j01 * j10;
        if !det.is_finite() || det.abs() < 1e-12 {
            break;
        }
        let nx = x - (j11 * ex - j01 * ey) / det;
        let ny = y - (-j10 * ex + j00 * ey) / det;
        if !(nx.is_finite() && ny.is_finite()) {
            break;
        }
        x = nx;
        y = ny;
    }
    (x, y)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tilted_pose() -> Affine3A {
        Affine3A::from_rotation_translation(
            glam::Quat::from_euler(glam::EulerRot::YXZ, 0.7, -0.4, 0.2),
            Vec3::new(1.0, -2.0, 3.0),
        )
    }

    #[test]
    fn center_pixel_ray_is_minus_z_rotated_into_world() {
        let pose = tilted_pose();
        let cam = Camera::new(64, 48, 50.0, 52.0, 32.0, 24.0, pose).unwrap();
        let r = cam.pixel_ray(31, 23); // center at (31.5, 23.5): half a pixel off
        let exact = cam.ray(32.0, 24.0);
        let want = pose.transform_vector3(-Vec3::Z);
        assert!(
            (exact.dir - want).length() < 1e-6,
            "{:?} vs {want:?}",
            exact.dir
        );
        assert!((exact.origin - Vec3::new(1.0, -2.0, 3.0)).length() < 1e-6);
        assert!((exact.dir.length() - 1.0).abs() < 1e-6);
        // Half a pixel left and up of the center: camera-space (−0.5/50, +0.5/52, −1).
        let want = pose
            .transform_vector3(Vec3::new(-0.5 / 50.0, 0.5 / 52.0, -1.0))
            .normalize();
        assert!((r.dir - want).length() < 1e-6);
        assert_eq!(cam.forward(), want_forward(&pose));
    }

    fn want_forward(pose: &Affine3A) -> Vec3 {
        -Vec3::from(pose.matrix3.z_axis).normalize()
    }

    #[test]
    fn image_y_down_is_camera_y_up() {
        let cam = Camera::from_fov_x(100, 100, 1.0, Affine3A::IDENTITY).unwrap();
        // Top row of the image looks up (+Y), left column looks left (−X).
        assert!(cam.pixel_ray(50, 0).dir.y > 0.0);
        assert!(cam.pixel_ray(0, 50).dir.x < 0.0);
    }

    #[test]
    fn ray_through_projected_point_passes_through_it() {
        for distortion in [[0.0; 4], [0.06, -0.08, -0.001, 0.0002]] {
            let [k1, k2, p1, p2] = distortion;
            let cam = Camera::new(120, 90, 80.0, 82.0, 61.3, 44.1, tilted_pose())
                .unwrap()
                .with_distortion(k1, k2, p1, p2);
            for p in [
                Vec3::new(0.3, 0.2, -0.5),
                Vec3::new(-1.0, 0.5, 0.1),
                Vec3::new(0.0, 0.0, 0.0),
            ] {
                let p = cam.c2w.transform_point3(p + Vec3::new(0.0, 0.0, -4.0));
                let uv = cam.project(p).expect("in front");
                let r = cam.ray(uv.x, uv.y);
                let t = (p - r.origin).dot(r.dir);
                assert!(t > 0.0);
                let miss = (r.at(t) - p).length();
                assert!(miss < 1e-4, "distortion {distortion:?}: miss {miss}");
            }
            // Behind the camera: no projection.
            assert!(cam.project(cam.c2w.transform_point3(Vec3::Z)).is_none());
        }
    }

    #[test]
    fn distort_then_undistort_round_trips() {
        // The fox dataset's coefficients, and stronger ones.
        for k in [
            [0.0578421, -0.0805099, -0.000980296, 0.00015575],
            [-0.25, 0.08, 0.002, -0.003],
        ] {
            let cam = Camera::from_fov_x(100, 100, 1.2, Affine3A::IDENTITY)
                .unwrap()
                .with_distortion(k[0], k[1], k[2], k[3]);
            assert!(cam.has_distortion());
            for i in -5..=5 {
                for j in -5..=5 {
                    let p = Vec2::new(i as f32 * 0.1, j as f32 * 0.1);
                    let d = cam.distort(p);
                    if i != 0 || j != 0 {
                        assert!((d - p).length() > 0.0);
                    }
                    let back = cam.undistort(d);
                    assert!((back - p).length() < 1e-6, "{p:?} → {d:?} → {back:?}");
                }
            }
        }
    }

    #[test]
    fn look_at_looks_at_its_target() {
        let eye = Vec3::new(3.0, -2.0, 1.5);
        let target = Vec3::new(0.2, 0.1, -0.3);
        let cam = Camera::look_at(eye, target, Vec3::Z, 0.8, 80, 60).unwrap();
        let center = cam.ray(40.0, 30.0);
        assert!((center.origin - eye).length() < 1e-6);
        assert!((center.dir - (target - eye).normalize()).length() < 1e-6);
        let uv = cam.project(target).unwrap();
        assert!((uv - Vec2::new(40.0, 30.0)).length() < 1e-3);
        // World up appears up in the image (smaller v).
        let above = cam.project(target + Vec3::Z * 0.1).unwrap();
        assert!(above.y < 30.0);
        assert!((cam.fov_x() - 0.8).abs() < 1e-6);
        assert!(Camera::look_at(eye, eye, Vec3::Z, 0.8, 8, 8).is_err());
        assert!(Camera::look_at(Vec3::ZERO, Vec3::Z, Vec3::Z, 0.8, 8, 8).is_err());
    }

    #[test]
    fn orbit_cameras_circle_the_center() {
        let center = Vec3::new(0.0, 0.0, 0.5);
        let cams = orbit(8, center, 4.0, 0.5, Vec3::Z, 0.7, 32, 32).unwrap();
        assert_eq!(cams.len(), 8);
        for c in &cams {
            assert!(((c.position() - center).length() - 4.0).abs() < 1e-5);
            assert!(((c.position().z - center.z) - 4.0 * 0.5f32.sin()).abs() < 1e-5);
            let uv = c.project(center).unwrap();
            assert!((uv - Vec2::new(16.0, 16.0)).length() < 1e-3);
        }
        assert!(cams[0].position().x > 3.0);
        assert!(cams[2].position().y > 3.0);
    }

    #[test]
    fn rays_are_row_major_pixel_centers() {
        let cam = Camera::new(5, 3, 4.0, 4.0, 2.5, 1.5, tilted_pose()).unwrap();
        let rays = cam.rays();
        assert_eq!(rays.len(), 15);
        assert_eq!(rays[7], cam.ray(2.5, 1.5));
        assert_eq!(rays[5 + 4], cam.pixel_ray(4, 1));
    }

    #[test]
    fn downscaling_divides_intrinsics_and_rounds_sizes_down() {
        let cam = Camera::new(401, 300, 500.0, 400.0, 200.5, 150.0, tilted_pose()).unwrap();
        let d = cam.downscaled(2);
        assert_eq!((d.width, d.height), (200, 150));
        assert_eq!((d.fx, d.fy, d.cx, d.cy), (250.0, 200.0, 100.25, 75.0));
        let s = cam.scaled(1.0 / 3.0);
        assert_eq!((s.width, s.height), (133, 100));
        assert!((s.fx - 500.0 / 3.0).abs() < 1e-3);
        // Pixel-center rays of a 2× downscale are those through block centers.
        let a = d.pixel_ray(10, 20);
        let b = cam.ray(21.0, 41.0);
        assert!((a.dir - b.dir).length() < 1e-6);
    }

    #[test]
    fn degenerate_poses_are_rejected() {
        let mut rows = [
            [1.0, 0.0, 0.0, 1.0],
            [0.0, 1.0, 0.0, 2.0],
            [0.0, 0.0, 1.0, 3.0],
            [0.0, 0.0, 0.0, 1.0],
        ];
        let ok = pose_from_rows(&rows).unwrap();
        assert_eq!(Vec3::from(ok.translation), Vec3::new(1.0, 2.0, 3.0));
        assert!(pose_from_rows(&rows[..3]).is_ok());
        assert!(matches!(
            pose_from_rows(&rows[..2]),
            Err(CameraError::Shape { rows: 2 })
        ));
        rows[0][0] = 2.0;
        assert!(matches!(
            pose_from_rows(&rows),
            Err(CameraError::NotOrthonormal { .. })
        ));
        rows[0][0] = -1.0;
        assert!(matches!(
            pose_from_rows(&rows),
            Err(CameraError::Reflection { .. })
        ));
        rows[0][0] = f64::NAN;
        assert_eq!(pose_from_rows(&rows), Err(CameraError::NonFinite));
        rows[0][0] = 1.0;
        rows[3][0] = 0.5;
        assert!(matches!(
            pose_from_rows(&rows),
            Err(CameraError::BottomRow { .. })
        ));
        let zero = Affine3A::from_mat3(glam::Mat3::ZERO);
        assert!(Camera::new(4, 4, 1.0, 1.0, 2.0, 2.0, zero).is_err());
        assert!(Camera::new(4, 4, -1.0, 1.0, 2.0, 2.0, Affine3A::IDENTITY).is_err());
        assert!(Camera::new(0, 4, 1.0, 1.0, 2.0, 2.0, Affine3A::IDENTITY).is_err());
        // Looking straight down the up vector, also after round-off (an orbit at 90°).
        let parallel = CameraError::Degenerate("up is zero or parallel to the view direction");
        let down = Camera::look_at(Vec3::Z, Vec3::ZERO, Vec3::Z, 0.7, 8, 8);
        assert_eq!(down.unwrap_err(), parallel);
        let top = orbit(4, Vec3::ZERO, 3.0, 90f32.to_radians(), Vec3::Z, 0.7, 8, 8);
        assert_eq!(top.unwrap_err(), parallel);
        assert!(orbit(4, Vec3::ZERO, 3.0, 89f32.to_radians(), Vec3::Z, 0.7, 8, 8).is_ok());
    }
}
