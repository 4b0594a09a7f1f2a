//! COLMAP sparse models (`cameras`, `images`, `points3D`, binary `.bin` or text `.txt`):
//! reading them into a [`Dataset`], and writing them (the
//! converter [`convert`], which turns a NeRF-synthetic or instant-ngp folder into one).
//!
//! **Layout**: the model is in `DIR/sparse/0/` or `DIR/sparse/`; the binary form is used
//! when `cameras.bin` and `images.bin` are both there, the text form otherwise
//! (`cameras.txt`, `images.txt`). `points3D` of the same form is optional. Photos are
//! `DIR/images/NAME` (`NAME` as written in `images`, subfolders allowed, never outside
//! `DIR`); with `downscale` K > 1 and a folder `DIR/images_K/` (the Mip-NeRF 360
//! convention) the photos are read from there as they are, otherwise from `images/`
//! averaged over K×K blocks.
//!
//! **Conventions** (COLMAP's, converted on load):
//!
//! * A pose is world-to-camera: `X_cam = R(q) X_world + t`, `q = (qw, qx, qy, qz)` a
//!   Hamilton quaternion (normalized on load), `t` in world units; camera axes are
//!   OpenCV's (+X right, +Y down, +Z forward). The loaded [`Camera::c2w`] is the inverse
//!   with the Y and Z axes flipped to OpenGL's (+Y up, looking down −Z): its columns are
//!   `Rᵀ·(1, −1, −1)` and its translation is the camera center `−Rᵀ t`
//!   ([`pose_from_colmap`]).
//! * Pixel coordinates put the upper-left corner of the image at `(0, 0)` and the center
//!   of its first pixel at `(0.5, 0.5)`, as diffsvg's do, so `cx, cy` carry over.
//! * Camera models: `SIMPLE_PINHOLE (f, cx, cy)`, `PINHOLE (fx, fy, cx, cy)`,
//!   `SIMPLE_RADIAL (f, cx, cy, k)`, `RADIAL (f, cx, cy, k1, k2)` and
//!   `OPENCV (fx, fy, cx, cy, k1, k2, p1, p2)`, all in pixels of the full-size photo,
//!   become [`Camera`]s with OpenCV `k1 k2 p1 p2` distortion (photos with distortion are
//!   undistorted once before splatting). Fisheye and the other models are refused, naming
//!   the camera: undistort the photos first (`colmap image_undistorter`).
//! * Photos read from `images_K/` give the camera scaled by the photo's size over the
//!   camera's (`fx · w'/w`, `cx · w'/w`, and the same vertically); that size must be the
//!   camera's divided by K, rounded either way.
//! * `points3D` gives the sparse points ([`Dataset::points`](super::dataset::Dataset)):
//!   positions in world units, colors `rgb / 255`.
//!
//! **Split**: images sorted by name; those at positions 0, N, 2N, … are test views, with
//! N = 8 by default (the reference 3DGS code's `llffhold`), or none when N = 0; or the
//! images named in a test list ([`Loading::test_list`](super::dataset::Loading::test_list), such as the `test.txt` that
//! [`convert`] writes). Either way each split keeps `images`' id order (which the
//! reference code's random draws make irrelevant there; here it fixes the sequence of
//! views a seed gives, so that a converted folder trains as its source did).
//!
//! **Background**: the photos are real (no white background) unless every photo has an
//! alpha channel (then it is composited over white, as NeRF-synthetic's are).
//!
//! **Limits**, checked before anything is allocated: a binary file's counts (cameras,
//! images, each image's 2D points, points, each point's track) times their smallest
//! record size must fit in what is left of the file; at most
//! [`MAX_FRAMES`](super::dataset::MAX_FRAMES) cameras and images and
//! [`MAX_GAUSSIANS`] points; names at most
//! [`MAX_NAME_BYTES`]; text lines are kept up to [`MAX_LINE_BYTES`] (the rest of a longer
//! line, such as a long list of 2D points, is skipped unread). Image sizes 1 to
//! [`MAX_SIDE`]. Files are streamed, never read whole. Each
//! problem is one error naming the file and the entry (`images.bin: image 3 (id 7,
//! "a.jpg"): camera 9 does not exist in cameras.bin`).
//!
//! ```
//! use diffsvg::glam::{DQuat, DVec3, Vec3};
//! use diffsvg::volume::colmap::pose_from_colmap;
//! // A camera at (0, 0, -4) (world), looking toward +Z, image y down along world −Y:
//! // COLMAP's R is the identity and t = −R·center = (0, 0, 4).
//! let c2w = pose_from_colmap(DQuat::IDENTITY, DVec3::new(0.0, 0.0, 4.0)).unwrap();
//! assert!((Vec3::from(c2w.translation) - Vec3::new(0.0, 0.0, -4.0)).length() < 1e-6);
//! // OpenGL: the camera looks down its −Z, which is world +Z here.
//! assert!((c2w.transform_vector3(-Vec3::Z) - Vec3::Z).length() < 1e-6);
//! ```

use std::collections::HashMap;
use std::io::{BufRead, BufReader, Read, Write};
use std::path::{Path, PathBuf};

use glam::{Affine3A, DMat3, DQuat, DVec3, Mat3A, Vec3A};

use super::camera::{Camera, check_pose};
use super::dataset::{Dataset, Holdout, View, decode_all};
use super::splat::PointCloud;
use crate::error::{Error, Result};
use crate::limits::{MAX_GAUSSIANS, MAX_SIDE};

/// Most bytes of an image name in `images.bin` (its terminating NUL must come within).
pub const MAX_NAME_BYTES: usize = 4096;

/// Most bytes kept of one line of a text file; the rest of a longer line is skipped.
pub const MAX_LINE_BYTES: usize = 64 << 10;

/// The most cameras and images one model may list.
const MAX_ENTRIES: usize = super::dataset::MAX_FRAMES;

/// COLMAP's camera models, by their ids in `cameras.bin`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Model {
    SimplePinhole,
    Pinhole,
    SimpleRadial,
    Radial,
    Opencv,
    OpencvFisheye,
    FullOpencv,
    Fov,
    SimpleRadialFisheye,
    RadialFisheye,
    ThinPrismFisheye,
    RadTanThinPrismFisheye,
}

/// Every model with its name and parameter count, in id order.
const MODELS: [(Model, &str, usize); 12] = [
    (Model::SimplePinhole, "SIMPLE_PINHOLE", 3),
    (Model::Pinhole, "PINHOLE", 4),
    (Model::SimpleRadial, "SIMPLE_RADIAL", 4),
    (Model::Radial, "RADIAL", 5),
    (Model::Opencv, "OPENCV", 8),
    (Model::OpencvFisheye, "OPENCV_FISHEYE", 8),
    (Model::FullOpencv, "FULL_OPENCV", 12),
    (Model::Fov, "FOV", 5),
    (Model::SimpleRadialFisheye, "SIMPLE_RADIAL_FISHEYE", 4),
    (Model::RadialFisheye, "RADIAL_FISHEYE", 5),
    (Model::ThinPrismFisheye, "THIN_PRISM_FISHEYE", 12),
    (
        Model::RadTanThinPrismFisheye,
        "RAD_TAN_THIN_PRISM_FISHEYE",
        16,
    ),
];

impl Model {
    fn entry(self) -> (Model, &'static str, usize) {
        MODELS[MODELS.iter().position(|m| m.0 == self).expect("listed")]
    }
    fn name(self) -> &'static str {
        self.entry().1
    }
    fn params(self) -> usize {
        self.entry().2
    }
    fn id(self) -> i32 {
        MODELS.iter().position(|m| m.0 == self).expect("listed") as i32
    }
    fn from_id(id: i32) -> Option<Model> {
        usize::try_from(id)
            .ok()
            .and_then(|i| MODELS.get(i))
            .map(|m| m.0)
    }
    fn from_name(name: &str) -> Option<Model> {
        MODELS.iter().find(|m| m.1 == name).map(|m| m.0)
    }
}

/// One entry of `cameras`: intrinsics in pixels of the full-size photo.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct SparseCamera {
    pub id: u32,
    pub model: Model,
    pub width: u32,
    pub height: u32,
    pub params: Vec<f64>,
}

/// One entry of `images`: a world-to-camera pose (2D points are skipped).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct SparseImage {
    pub id: u32,
    /// `(w, x, y, z)` as read (non-zero; normalized when converted to a pose).
    pub qvec: [f64; 4],
    pub tvec: [f64; 3],
    pub camera_id: u32,
    pub name: String,
}

/// A whole sparse model.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Sparse {
    pub cameras: Vec<SparseCamera>,
    pub images: Vec<SparseImage>,
    /// Empty when the folder has no `points3D` file.
    pub points: PointCloud,
}

/// Binary or text files.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Form {
    /// `.bin`, little-endian, as COLMAP writes by default.
    Binary,
    /// `.txt`, one entry a line, `#` comments.
    Text,
}

impl Form {
    fn ext(self) -> &'static str {
        match self {
            Form::Binary => "bin",
            Form::Text => "txt",
        }
    }
}

/// The folder of a dataset's sparse model and its form, if `dir` has one:
/// `sparse/0/` before `sparse/`, binary before text.
pub(crate) fn find(dir: &Path) -> Option<(PathBuf, Form)> {
    for sub in [dir.join("sparse").join("0"), dir.join("sparse")] {
        for form in [Form::Binary, Form::Text] {
            let e = form.ext();
            if sub.join(format!("cameras.{e}")).is_file()
                && sub.join(format!("images.{e}")).is_file()
            {
                return Some((sub, form));
            }
        }
    }
    None
}

/// Reads the sparse model in `sparse` (see [`find`]).
pub(crate) fn read(sparse: &Path, form: Form) -> Result<Sparse> {
    let e = form.ext();
    let cams = sparse.join(format!("cameras.{e}"));
    let imgs = sparse.join(format!("images.{e}"));
    let pts = sparse.join(format!("points3D.{e}"));
    let (cameras, images) = match form {
        Form::Binary => (read_cameras_bin(&cams)?, read_images_bin(&imgs)?),
        Form::Text => (read_cameras_txt(&cams)?, read_images_txt(&imgs)?),
    };
    let mut ids = HashMap::with_capacity(cameras.len());
    for (i, c) in cameras.iter().enumerate() {
        if let Some(j) = ids.insert(c.id, i) {
            return Err(invalid(
                &cams,
                format!("cameras {j} and {i} have the same id {}", c.id),
            ));
        }
    }
    let mut image_ids = HashMap::with_capacity(images.len());
    for (i, im) in images.iter().enumerate() {
        if !ids.contains_key(&im.camera_id) {
            return Err(invalid(
                &imgs,
                format!(
                    "image {i} (id {}, {:?}): camera {} does not exist in {}",
                    im.id,
                    im.name,
                    im.camera_id,
                    cams.display()
                ),
            ));
        }
        if let Some(j) = image_ids.insert(im.name.as_str(), i) {
            return Err(invalid(
                &imgs,
                format!("images {j} and {i} have the same name {:?}", im.name),
            ));
        }
    }
    let points = if pts.is_file() {
        match form {
            Form::Binary => read_points_bin(&pts)?,
            Form::Text => read_points_txt(&pts)?,
        }
    } else {
        PointCloud::default()
    };
    Ok(Sparse {
        cameras,
        images,
        points,
    })
}

fn invalid(path: &Path, what: String) -> Error {
    Error::InvalidValue {
        path: path.to_path_buf(),
        what,
    }
}

// ---- poses and cameras ------------------------------------------------------------------

/// The camera-to-world pose (OpenGL camera axes) of a COLMAP world-to-camera pose
/// (rotation `q`, translation `t`, OpenCV camera axes); see the module doc. `q` is
/// normalized first; `None` when it is zero or not finite, or `t` is not finite.
pub fn pose_from_colmap(q: DQuat, t: DVec3) -> Option<Affine3A> {
    let n = q.length();
    if !(n.is_finite() && n > 1e-12 && t.is_finite()) {
        return None;
    }
    let r = DMat3::from_quat(q / n);
    let rt = r.transpose();
    let center = -(rt * t);
    // OpenCV → OpenGL camera axes: flip camera Y and Z.
    let rot = DMat3::from_cols(rt.x_axis, -rt.y_axis, -rt.z_axis);
    Some(Affine3A {
        matrix3: Mat3A::from(rot.as_mat3()),
        translation: Vec3A::from(center.as_vec3()),
    })
}

/// The COLMAP world-to-camera pose `(q, t)` of a camera-to-world pose with OpenGL camera
/// axes: the inverse of [`pose_from_colmap`]. `q` has `w ≥ 0`.
pub fn pose_to_colmap(c2w: &Affine3A) -> (DQuat, DVec3) {
    let m = c2w.matrix3.as_dmat3();
    let cv = DMat3::from_cols(m.x_axis, -m.y_axis, -m.z_axis);
    let r = cv.transpose();
    let mut q = DQuat::from_mat3(&r).normalize();
    if q.w < 0.0 {
        q = -q;
    }
    let t = -(r * c2w.translation.as_dvec3());
    (q, t)
}

impl SparseCamera {
    /// The [`Camera`] for this camera's photos at full size, with pose `c2w`; errors for
    /// a model diffsvg cannot represent or intrinsics [`Camera::validate`] refuses.
    fn camera(&self, c2w: Affine3A) -> std::result::Result<Camera, String> {
        let p = &self.params;
        let [fx, fy, cx, cy, k1, k2, p1, p2] = match self.model {
            Model::SimplePinhole => [p[0], p[0], p[1], p[2], 0.0, 0.0, 0.0, 0.0],
            Model::Pinhole => [p[0], p[1], p[2], p[3], 0.0, 0.0, 0.0, 0.0],
            Model::SimpleRadial => [p[0], p[0], p[1], p[2], p[3], 0.0, 0.0, 0.0],
            Model::Radial => [p[0], p[0], p[1], p[2], p[3], p[4], 0.0, 0.0],
            Model::Opencv => [p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7]],
            other => {
                return Err(format!(
                    "model {} is not supported: diffsvg's cameras are pinholes with OpenCV \
                     k1 k2 p1 p2 distortion (SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL, \
                     OPENCV); undistort the photos first (colmap image_undistorter)",
                    other.name()
                ));
            }
        };
        let cam = Camera {
            width: self.width,
            height: self.height,
            fx: fx as f32,
            fy: fy as f32,
            cx: cx as f32,
            cy: cy as f32,
            k1: k1 as f32,
            k2: k2 as f32,
            p1: p1 as f32,
            p2: p2 as f32,
            c2w,
        };
        cam.validate().map_err(|e| e.to_string())?;
        Ok(cam)
    }
}

impl SparseImage {
    /// The camera-to-world pose with OpenGL camera axes.
    pub(crate) fn c2w(&self) -> std::result::Result<Affine3A, String> {
        let [w, x, y, z] = self.qvec;
        let c2w = pose_from_colmap(DQuat::from_xyzw(x, y, z, w), DVec3::from(self.tvec))
            .ok_or("the rotation quaternion is zero or not finite")?;
        check_pose(&c2w).map_err(|e| e.to_string())?;
        Ok(c2w)
    }
}

/// The cameras of every image of `sparse` at full size, in the order of
/// `sparse.images`: errors name `images_file` (poses) or `cameras_file` (intrinsics)
/// and the entry.
pub(crate) fn cameras(
    sparse: &Sparse,
    images_file: &Path,
    cameras_file: &Path,
) -> Result<Vec<Camera>> {
    let by_id: HashMap<u32, &SparseCamera> = sparse.cameras.iter().map(|c| (c.id, c)).collect();
    sparse
        .images
        .iter()
        .enumerate()
        .map(|(i, im)| {
            let c2w = im.c2w().map_err(|e| {
                invalid(
                    images_file,
                    format!("image {i} (id {}, {:?}): {e}", im.id, im.name),
                )
            })?;
            let cam = by_id[&im.camera_id];
            cam.camera(c2w).map_err(|e| Error::Unsupported {
                path: cameras_file.to_path_buf(),
                what: format!("camera {} (used by image {:?}): {e}", cam.id, im.name),
            })
        })
        .collect()
}

// ---- binary files ------------------------------------------------------------------------

/// A regular file opened for reading, and its length in bytes.
fn open_regular(path: &Path) -> Result<(std::fs::File, u64)> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let meta = file.metadata().map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(invalid(path, "not a regular file".into()));
    }
    Ok((file, meta.len()))
}

/// A little-endian reader that knows how much of its file is left.
struct Bin {
    r: BufReader<std::fs::File>,
    pos: u64,
    len: u64,
}

impl Bin {
    fn open(path: &Path) -> Result<Bin> {
        let (file, len) = open_regular(path)?;
        Ok(Bin {
            r: BufReader::new(file),
            pos: 0,
            len,
        })
    }

    fn left(&self) -> u64 {
        self.len.saturating_sub(self.pos)
    }

    fn short(&self, n: u64) -> String {
        format!(
            "file ends at byte {} but {n} more bytes are needed at byte {} (truncated)",
            self.len, self.pos
        )
    }

    fn bytes<const N: usize>(&mut self) -> std::result::Result<[u8; N], String> {
        if self.left() < N as u64 {
            return Err(self.short(N as u64));
        }
        let mut b = [0u8; N];
        self.r.read_exact(&mut b).map_err(|e| e.to_string())?;
        self.pos += N as u64;
        Ok(b)
    }

    fn u32(&mut self) -> std::result::Result<u32, String> {
        self.bytes().map(u32::from_le_bytes)
    }

    fn i32(&mut self) -> std::result::Result<i32, String> {
        self.bytes().map(i32::from_le_bytes)
    }

    fn u64(&mut self) -> std::result::Result<u64, String> {
        self.bytes().map(u64::from_le_bytes)
    }

    fn f64s<const N: usize>(&mut self) -> std::result::Result<[f64; N], String> {
        let mut out = [0.0; N];
        for o in &mut out {
            *o = f64::from_le_bytes(self.bytes()?);
        }
        Ok(out)
    }

    fn skip(&mut self, n: u64) -> std::result::Result<(), String> {
        if self.left() < n {
            return Err(self.short(n));
        }
        let step = i64::try_from(n).map_err(|e| e.to_string())?;
        self.r.seek_relative(step).map_err(|e| e.to_string())?;
        self.pos += n;
        Ok(())
    }

    /// A count of records of at least `record` bytes each, at most `max`, that must fit
    /// in the rest of the file.
    fn count(&mut self, what: &str, record: u64, max: usize) -> std::result::Result<usize, String> {
        let n = self.u64().map_err(|e| format!("{what} count: {e}"))?;
        if n > max as u64 {
            return Err(format!("{n} {what}, more than the limit of {max}"));
        }
        if n.saturating_mul(record) > self.left() {
            return Err(format!(
                "{n} {what} need at least {} bytes but {} are left of the file (truncated or corrupt)",
                n.saturating_mul(record),
                self.left()
            ));
        }
        Ok(n as usize)
    }

    /// A NUL-terminated UTF-8 name of at most [`MAX_NAME_BYTES`].
    fn name(&mut self) -> std::result::Result<String, String> {
        let mut out = Vec::new();
        loop {
            let [b] = self.bytes::<1>()?;
            if b == 0 {
                break;
            }
            if out.len() == MAX_NAME_BYTES {
                return Err(format!("name longer than {MAX_NAME_BYTES} bytes (no NUL)"));
            }
            out.push(b);
        }
        String::from_utf8(out).map_err(|_| "name is not UTF-8".into())
    }
}

/// Smallest record of `cameras.bin` (the fewest parameters: 3).
const CAMERA_RECORD: u64 = 4 + 4 + 8 + 8 + 3 * 8;
/// Smallest record of `images.bin`: id, q, t, camera id, an empty name, no points.
const IMAGE_RECORD: u64 = 4 + 32 + 24 + 4 + 1 + 8;
/// One 2D point of `images.bin`: x, y, point id.
const POINT2D_RECORD: u64 = 24;
/// Smallest record of `points3D.bin`: id, xyz, rgb, error, empty track.
const POINT_RECORD: u64 = 8 + 24 + 3 + 8 + 8;
/// One track element of `points3D.bin`: image id, point index.
const TRACK_RECORD: u64 = 8;

fn read_cameras_bin(path: &Path) -> Result<Vec<SparseCamera>> {
    let mut b = Bin::open(path)?;
    let n = b
        .count("cameras", CAMERA_RECORD, MAX_ENTRIES)
        .map_err(|e| invalid(path, e))?;
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let at = |e: String| invalid(path, format!("camera {i}: {e}"));
        let id = b.u32().map_err(at)?;
        let at = |e: String| invalid(path, format!("camera {i} (id {id}): {e}"));
        let model_id = b.i32().map_err(at)?;
        let model = Model::from_id(model_id)
            .ok_or_else(|| at(format!("unknown camera model id {model_id}")))?;
        let [w, h] = [b.u64().map_err(at)?, b.u64().map_err(at)?];
        let mut params = Vec::with_capacity(model.params());
        for _ in 0..model.params() {
            params.push(b.f64s::<1>().map_err(at)?[0]);
        }
        out.push(checked_camera(id, model, w, h, params).map_err(at)?);
    }
    trailing(&b, path)?;
    Ok(out)
}

fn checked_camera(
    id: u32,
    model: Model,
    w: u64,
    h: u64,
    params: Vec<f64>,
) -> std::result::Result<SparseCamera, String> {
    for (key, v) in [("width", w), ("height", h)] {
        if v == 0 || v > MAX_SIDE as u64 {
            return Err(format!("{key} {v} must be 1 to {MAX_SIDE} pixels"));
        }
    }
    if let Some(p) = params.iter().find(|p| !p.is_finite()) {
        return Err(format!("parameter {p} is not finite"));
    }
    Ok(SparseCamera {
        id,
        model,
        width: w as u32,
        height: h as u32,
        params,
    })
}

fn checked_image(
    id: u32,
    q: [f64; 4],
    t: [f64; 3],
    camera_id: u32,
    name: String,
) -> std::result::Result<SparseImage, String> {
    if q.iter().chain(&t).any(|v| !v.is_finite()) {
        return Err("pose has a non-finite value".into());
    }
    let n = q.iter().map(|v| v * v).sum::<f64>().sqrt();
    if n < 1e-12 {
        return Err("rotation quaternion is zero".into());
    }
    if name.is_empty() {
        return Err("empty image name".into());
    }
    Ok(SparseImage {
        id,
        qvec: q,
        tvec: t,
        camera_id,
        name,
    })
}

fn read_images_bin(path: &Path) -> Result<Vec<SparseImage>> {
    let mut b = Bin::open(path)?;
    let n = b
        .count("images", IMAGE_RECORD, MAX_ENTRIES)
        .map_err(|e| invalid(path, e))?;
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let at = |e: String| invalid(path, format!("image {i}: {e}"));
        let id = b.u32().map_err(at)?;
        let at = |e: String| invalid(path, format!("image {i} (id {id}): {e}"));
        let q = b.f64s::<4>().map_err(at)?;
        let t = b.f64s::<3>().map_err(at)?;
        let camera_id = b.u32().map_err(at)?;
        let name = b.name().map_err(at)?;
        let at = |e: String| invalid(path, format!("image {i} (id {id}, {name:?}): {e}"));
        let points = b
            .count("2D points", POINT2D_RECORD, usize::MAX)
            .map_err(at)?;
        b.skip(points as u64 * POINT2D_RECORD).map_err(at)?;
        out.push(checked_image(id, q, t, camera_id, name.clone()).map_err(at)?);
    }
    trailing(&b, path)?;
    Ok(out)
}

fn read_points_bin(path: &Path) -> Result<PointCloud> {
    let mut b = Bin::open(path)?;
    let n = b
        .count("points", POINT_RECORD, MAX_GAUSSIANS)
        .map_err(|e| invalid(path, e))?;
    let mut positions = Vec::with_capacity(n);
    let mut colors = Vec::with_capacity(n);
    for i in 0..n {
        let at = |e: String| invalid(path, format!("point {i}: {e}"));
        let id = b.u64().map_err(at)?;
        let at = |e: String| invalid(path, format!("point {i} (id {id}): {e}"));
        let xyz = b.f64s::<3>().map_err(at)?;
        let rgb = b.bytes::<3>().map_err(at)?;
        b.skip(8).map_err(at)?; // reprojection error
        let track = b
            .count("track elements", TRACK_RECORD, usize::MAX)
            .map_err(at)?;
        b.skip(track as u64 * TRACK_RECORD).map_err(at)?;
        positions.push(checked_point(xyz).map_err(at)?);
        colors.push(rgb.map(|c| c as f32 / 255.0));
    }
    trailing(&b, path)?;
    Ok(PointCloud {
        positions,
        colors: Some(colors),
    })
}

fn checked_point(xyz: [f64; 3]) -> std::result::Result<[f32; 3], String> {
    let p = xyz.map(|v| v as f32);
    if p.iter().any(|v| !v.is_finite()) {
        return Err(format!("position {xyz:?} is not finite in f32"));
    }
    Ok(p)
}

/// Errors when bytes follow the last record (a count too small, or another format).
fn trailing(b: &Bin, path: &Path) -> Result<()> {
    if b.left() > 0 {
        return Err(invalid(
            path,
            format!(
                "{} bytes after the last entry (byte {} of {}): corrupt or not a COLMAP file",
                b.left(),
                b.pos,
                b.len
            ),
        ));
    }
    Ok(())
}

// ---- text files --------------------------------------------------------------------------

/// Lines of a text file, each kept up to [`MAX_LINE_BYTES`].
struct Lines {
    r: BufReader<std::fs::File>,
    /// Line number of the last line read, from 1.
    number: usize,
    buf: Vec<u8>,
    path: PathBuf,
}

impl Lines {
    fn open(path: &Path) -> Result<Lines> {
        let (file, _) = open_regular(path)?;
        Ok(Lines {
            r: BufReader::new(file),
            number: 0,
            buf: Vec::new(),
            path: path.to_path_buf(),
        })
    }

    /// The next line, trimmed (`None` at the end of the file).
    fn next(&mut self) -> Result<Option<&str>> {
        self.buf.clear();
        let mut any = false;
        loop {
            let avail = self.r.fill_buf().map_err(|e| Error::io(&self.path, e))?;
            if avail.is_empty() {
                break;
            }
            any = true;
            let (take, done) = match avail.iter().position(|&c| c == b'\n') {
                Some(i) => (i + 1, true),
                None => (avail.len(), false),
            };
            let room = MAX_LINE_BYTES.saturating_sub(self.buf.len());
            self.buf.extend_from_slice(&avail[..take.min(room)]);
            self.r.consume(take);
            if done {
                break;
            }
        }
        if !any {
            return Ok(None);
        }
        self.number += 1;
        let text = std::str::from_utf8(&self.buf)
            .map_err(|_| invalid(&self.path, format!("line {}: not UTF-8 text", self.number)))?;
        Ok(Some(text.trim()))
    }

    /// The next line that is neither empty nor a `#` comment, with its number.
    fn entry(&mut self) -> Result<Option<(usize, String)>> {
        while let Some(line) = self.next()? {
            if !line.is_empty() && !line.starts_with('#') {
                let line = line.to_string();
                return Ok(Some((self.number, line)));
            }
        }
        Ok(None)
    }

    fn err(&self, line: usize, what: impl std::fmt::Display) -> Error {
        invalid(&self.path, format!("line {line}: {what}"))
    }
}

/// The first `N` whitespace-separated fields parsed, naming the missing or bad one.
fn fields<T: std::str::FromStr, const N: usize>(
    words: &mut std::str::SplitWhitespace<'_>,
    names: [&str; N],
) -> std::result::Result<[T; N], String> {
    let mut out = Vec::with_capacity(N);
    for name in names {
        let w = words.next().ok_or_else(|| format!("no {name}"))?;
        out.push(
            w.parse()
                .map_err(|_| format!("{name} {w:?} is not a valid number"))?,
        );
    }
    Ok(out.try_into().ok().expect("N fields"))
}

fn read_cameras_txt(path: &Path) -> Result<Vec<SparseCamera>> {
    let mut lines = Lines::open(path)?;
    let mut out = Vec::new();
    while let Some((no, line)) = lines.entry()? {
        if out.len() == MAX_ENTRIES {
            return Err(lines.err(no, format!("more than {MAX_ENTRIES} cameras")));
        }
        let mut w = line.split_whitespace();
        let cam = (|| {
            let [id]: [u32; 1] = fields(&mut w, ["CAMERA_ID"])?;
            let name = w.next().ok_or("no MODEL")?;
            let model =
                Model::from_name(name).ok_or_else(|| format!("unknown camera model {name:?}"))?;
            let [width, height]: [u64; 2] = fields(&mut w, ["WIDTH", "HEIGHT"])?;
            let params: Vec<f64> = w
                .map(|p| {
                    p.parse()
                        .map_err(|_| format!("parameter {p:?} is not a valid number"))
                })
                .collect::<std::result::Result<_, String>>()?;
            if params.len() != model.params() {
                return Err(format!(
                    "model {name} takes {} parameters, got {}",
                    model.params(),
                    params.len()
                ));
            }
            checked_camera(id, model, width, height, params)
                .map_err(|e| format!("camera {id}: {e}"))
        })()
        .map_err(|e| lines.err(no, e))?;
        out.push(cam);
    }
    Ok(out)
}

fn read_images_txt(path: &Path) -> Result<Vec<SparseImage>> {
    let mut lines = Lines::open(path)?;
    let mut out = Vec::new();
    while let Some((no, line)) = lines.entry()? {
        if out.len() == MAX_ENTRIES {
            return Err(lines.err(no, format!("more than {MAX_ENTRIES} images")));
        }
        let mut w = line.split_whitespace();
        let image = (|| {
            let [id]: [u32; 1] = fields(&mut w, ["IMAGE_ID"])?;
            let q: [f64; 4] = fields(&mut w, ["QW", "QX", "QY", "QZ"])?;
            let t: [f64; 3] = fields(&mut w, ["TX", "TY", "TZ"])?;
            let [camera_id]: [u32; 1] = fields(&mut w, ["CAMERA_ID"])?;
            let name = w.collect::<Vec<_>>().join(" ");
            if name.is_empty() {
                return Err(format!("image {id}: no NAME"));
            }
            checked_image(id, q, t, camera_id, name).map_err(|e| format!("image {id}: {e}"))
        })()
        .map_err(|e| lines.err(no, e))?;
        out.push(image);
        // The image's 2D points: one line, possibly empty, never parsed.
        lines.next()?;
    }
    Ok(out)
}

fn read_points_txt(path: &Path) -> Result<PointCloud> {
    let mut lines = Lines::open(path)?;
    let mut cloud = PointCloud {
        positions: Vec::new(),
        colors: Some(Vec::new()),
    };
    let colors = cloud.colors.as_mut().expect("set");
    while let Some((no, line)) = lines.entry()? {
        if cloud.positions.len() == MAX_GAUSSIANS {
            return Err(lines.err(no, format!("more than {MAX_GAUSSIANS} points")));
        }
        let mut w = line.split_whitespace();
        let (p, c) = (|| {
            let [id]: [u64; 1] = fields(&mut w, ["POINT3D_ID"])?;
            let xyz: [f64; 3] = fields(&mut w, ["X", "Y", "Z"])?;
            let rgb: [u8; 3] = fields(&mut w, ["R", "G", "B"])
                .map_err(|e| format!("point {id}: {e} (colors are 0 to 255)"))?;
            let p = checked_point(xyz).map_err(|e| format!("point {id}: {e}"))?;
            Ok::<_, String>((p, rgb.map(|c| c as f32 / 255.0)))
        })()
        .map_err(|e| lines.err(no, e))?;
        cloud.positions.push(p);
        colors.push(c);
    }
    Ok(cloud)
}

// ---- writing -----------------------------------------------------------------------------

/// Writes `sparse` as `cameras`, `images` and `points3D` files of the given form in the
/// folder `out` (created). Images are written without 2D points, points without tracks
/// and with error 0; colors are rounded to 0–255.
pub(crate) fn write(sparse: &Sparse, out: &Path, form: Form) -> Result<()> {
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    let e = form.ext();
    let colors = |i: usize| -> [u8; 3] {
        let c = sparse.points.colors.as_ref().map_or([0.5; 3], |c| c[i]);
        c.map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
    };
    let mut cams = Vec::new();
    let mut imgs = Vec::new();
    let mut pts = Vec::new();
    match form {
        Form::Binary => {
            cams.extend((sparse.cameras.len() as u64).to_le_bytes());
            for c in &sparse.cameras {
                cams.extend(c.id.to_le_bytes());
                cams.extend(c.model.id().to_le_bytes());
                cams.extend((c.width as u64).to_le_bytes());
                cams.extend((c.height as u64).to_le_bytes());
                c.params.iter().for_each(|p| cams.extend(p.to_le_bytes()));
            }
            imgs.extend((sparse.images.len() as u64).to_le_bytes());
            for im in &sparse.images {
                imgs.extend(im.id.to_le_bytes());
                im.qvec
                    .iter()
                    .chain(&im.tvec)
                    .for_each(|v| imgs.extend(v.to_le_bytes()));
                imgs.extend(im.camera_id.to_le_bytes());
                imgs.extend(im.name.as_bytes());
                imgs.push(0);
                imgs.extend(0u64.to_le_bytes());
            }
            pts.extend((sparse.points.positions.len() as u64).to_le_bytes());
            for (i, p) in sparse.points.positions.iter().enumerate() {
                pts.extend((i as u64 + 1).to_le_bytes());
                p.iter().for_each(|v| pts.extend((*v as f64).to_le_bytes()));
                pts.extend(colors(i));
                pts.extend(0f64.to_le_bytes());
                pts.extend(0u64.to_le_bytes());
            }
        }
        Form::Text => {
            use std::fmt::Write as _;
            let mut s = String::from(
                "# Camera list with one line of data per camera:\n\
                 #   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]\n",
            );
            let _ = writeln!(s, "# Number of cameras: {}", sparse.cameras.len());
            for c in &sparse.cameras {
                let _ = write!(s, "{} {} {} {}", c.id, c.model.name(), c.width, c.height);
                c.params.iter().for_each(|p| {
                    let _ = write!(s, " {p:?}");
                });
                s.push('\n');
            }
            cams = s.into_bytes();
            let mut s = String::from(
                "# Image list with two lines of data per image:\n\
                 #   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME\n\
                 #   POINTS2D[] as (X, Y, POINT3D_ID)\n",
            );
            let _ = writeln!(s, "# Number of images: {}", sparse.images.len());
            for im in &sparse.images {
                let [qw, qx, qy, qz] = im.qvec;
                let [tx, ty, tz] = im.tvec;
                let _ = writeln!(
                    s,
                    "{} {qw:?} {qx:?} {qy:?} {qz:?} {tx:?} {ty:?} {tz:?} {} {}\n",
                    im.id, im.camera_id, im.name
                );
            }
            imgs = s.into_bytes();
            let mut s = String::from(
                "# 3D point list with one line of data per point:\n\
                 #   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)\n",
            );
            let _ = writeln!(s, "# Number of points: {}", sparse.points.positions.len());
            for (i, p) in sparse.points.positions.iter().enumerate() {
                let [r, g, b] = colors(i);
                let _ = writeln!(
                    s,
                    "{} {:?} {:?} {:?} {r} {g} {b} 0",
                    i + 1,
                    p[0] as f64,
                    p[1] as f64,
                    p[2] as f64
                );
            }
            pts = s.into_bytes();
        }
    }
    for (name, bytes) in [("cameras", cams), ("images", imgs), ("points3D", pts)] {
        let path = out.join(format!("{name}.{e}"));
        let mut f = std::fs::File::create(&path).map_err(|err| Error::io(&path, err))?;
        f.write_all(&bytes).map_err(|err| Error::io(&path, err))?;
    }
    Ok(())
}

// ---- datasets ----------------------------------------------------------------------------

/// Loads the COLMAP dataset in `dir` whose sparse model is in `sparse` (see the module
/// doc); `name` is the dataset's name.
pub(crate) fn load(
    dir: &Path,
    sparse: &Path,
    form: Form,
    k: u32,
    holdout: &Holdout,
    name: String,
) -> Result<Dataset> {
    let e = form.ext();
    let cams_file = sparse.join(format!("cameras.{e}"));
    let imgs_file = sparse.join(format!("images.{e}"));
    let model = read(sparse, form)?;
    if model.images.is_empty() {
        return Err(invalid(&imgs_file, "no images".into()));
    }
    let full = cameras(&model, &imgs_file, &cams_file)?;
    holdout.check_found(
        model.images.iter().map(|im| im.name.as_str()),
        &format!("an image of {}", imgs_file.display()),
    )?;
    let scaled_dir = dir.join(format!("images_{k}"));
    let (folder, from_scaled) = if k > 1 && scaled_dir.is_dir() {
        (scaled_dir, true)
    } else {
        (dir.join("images"), false)
    };
    let canonical = dir.canonicalize().map_err(|err| Error::io(dir, err))?;
    // The split counts positions in name order; each split is in id order.
    let mut by_name: Vec<usize> = (0..model.images.len()).collect();
    by_name.sort_by(|&a, &b| model.images[a].name.cmp(&model.images[b].name));
    let mut rank = vec![0; by_name.len()];
    for (position, &i) in by_name.iter().enumerate() {
        rank[i] = position;
    }
    let mut order: Vec<usize> = (0..model.images.len()).collect();
    order.sort_by_key(|&i| model.images[i].id);

    let mut paths = Vec::with_capacity(order.len());
    let mut sizes = Vec::with_capacity(order.len());
    for &i in &order {
        let im = &model.images[i];
        let at = |what: String| {
            invalid(
                &imgs_file,
                format!("image {i} (id {}, {:?}): {what}", im.id, im.name),
            )
        };
        if super::dataset::escapes(&im.name) {
            return Err(at("the name leads outside the images folder".into()));
        }
        let path = folder.join(&im.name);
        if !path.is_file() {
            return Err(super::dataset::not_found(
                &path,
                &format!(
                    "image {:?} (id {}) of {} does not exist",
                    im.name,
                    im.id,
                    imgs_file.display()
                ),
            ));
        }
        let real = path.canonicalize().map_err(|err| Error::io(&path, err))?;
        if !real.starts_with(&canonical) {
            return Err(at(format!(
                "resolves to {}, outside the dataset folder",
                real.display()
            )));
        }
        let (w, h) = super::dataset::header_size(&path)?;
        let cam = &full[i];
        let fits = if from_scaled {
            let near = |n: u32, full: u32| (n as f64 - full as f64 / k as f64).abs() < 1.0;
            near(w, cam.width) && near(h, cam.height)
        } else {
            (w, h) == (cam.width, cam.height)
        };
        if !fits {
            let want = if from_scaled {
                format!("{}×{} divided by {k}", cam.width, cam.height)
            } else {
                format!("{}×{}", cam.width, cam.height)
            };
            return Err(Error::Image {
                path,
                message: format!(
                    "image is {w}×{h} but its camera in {} is {want}",
                    cams_file.display()
                ),
            });
        }
        if !from_scaled && (w < k || h < k) {
            return Err(Error::InvalidValue {
                path,
                what: format!("downscale {k} leaves no pixels of a {w}×{h} image"),
            });
        }
        paths.push(path);
        sizes.push((w, h));
    }
    let refs: Vec<&Path> = paths.iter().map(PathBuf::as_path).collect();
    let decoded = decode_all(dir, &refs, &sizes, if from_scaled { 1 } else { k })?;
    let white_background = decoded.iter().all(|d| d.alpha);
    let (mut train, mut test) = (Vec::new(), Vec::new());
    for (&i, img) in order.iter().zip(decoded) {
        let cam = full[i];
        let camera = if from_scaled {
            let (sx, sy) = (
                img.width as f64 / cam.width as f64,
                img.height as f64 / cam.height as f64,
            );
            Camera {
                width: img.width,
                height: img.height,
                fx: (cam.fx as f64 * sx) as f32,
                cx: (cam.cx as f64 * sx) as f32,
                fy: (cam.fy as f64 * sy) as f32,
                cy: (cam.cy as f64 * sy) as f32,
                ..cam
            }
        } else {
            cam.downscaled(k)
        };
        debug_assert_eq!(img.rgb.len(), (camera.width * camera.height) as usize);
        let view = View {
            name: model.images[i].name.clone(),
            width: camera.width,
            height: camera.height,
            camera,
            rgb: img.rgb,
        };
        if holdout.is_test(rank[i], &view.name) {
            test.push(view);
        } else {
            train.push(view);
        }
    }
    let points = (!model.points.positions.is_empty()).then_some(model.points);
    Ok(Dataset {
        train,
        test,
        name,
        white_background,
        warnings: Vec::new(),
        points,
    })
}

/// The file [`convert`] writes beside `sparse/`: the source's test views, one name a
/// line, for [`Loading::test_list`](super::dataset::Loading::test_list).
pub const TEST_LIST: &str = "test.txt";

/// Options of [`convert`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Convert {
    /// Binary or text files.
    pub form: Form,
    /// When the source folder has no point-cloud file: this many points, uniform in the
    /// box around where the cameras look (half-side the cameras' median distance from it
    /// times 0.4 for NeRF-synthetic, 1 for instant-ngp), each colored by the first photo
    /// (in file order) it projects into (mid-grey if none).
    pub points: usize,
    /// Seed of the points' positions.
    pub seed: u64,
}

impl Default for Convert {
    fn default() -> Self {
        Convert {
            form: Form::Binary,
            points: 1000,
            seed: 0,
        }
    }
}

/// What [`convert`] wrote.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Converted {
    /// Entries of `cameras` (one per distinct set of intrinsics).
    pub cameras: usize,
    /// Entries of `images` (photos copied).
    pub images: usize,
    /// Entries of `points3D`.
    pub points: usize,
}

/// Writes the NeRF-synthetic or instant-ngp folder `src` as a COLMAP dataset in `dst`:
/// `dst/sparse/0/{cameras,images,points3D}.{bin|txt}`, the photos copied to
/// `dst/images/` under their paths relative to `src` (`train/r_0.png`), with image ids
/// in `src`'s order, and `dst/`[`TEST_LIST`] naming `src`'s test views (NeRF-synthetic:
/// those of `transforms_test.json`; instant-ngp: every 8th). Cameras with
/// distortion are `OPENCV`, others `PINHOLE`; poses are converted with
/// [`pose_to_colmap`]. Points: `src`'s point-cloud file (`points3d.ply`, `sparse_pc.ply`
/// or `points.ply`) when it has one, otherwise `opts.points` random points (see
/// [`Convert`]). Loading `dst` gives the same cameras as loading `src` (to `f32`
/// round-off), in the COLMAP split; with `test.txt` as the test list, in `src`'s split and
/// order.
///
/// # Errors
/// As [`Dataset::load`] for `src`; a `dst` that already holds a sparse model; I/O.
pub fn convert(src: &Path, dst: &Path, opts: &Convert) -> Result<Converted> {
    let (frames, synthetic) = super::dataset::source_frames(src)?;
    if find(dst).is_some() {
        return Err(Error::Output {
            path: dst.to_path_buf(),
            message: "already holds a COLMAP model (sparse/): choose an empty folder".into(),
        });
    }
    let mut model = Sparse::default();
    for (i, f) in frames.iter().enumerate() {
        let c = &f.camera;
        let (model_kind, params) = if c.has_distortion() {
            (
                Model::Opencv,
                [c.fx, c.fy, c.cx, c.cy, c.k1, c.k2, c.p1, c.p2]
                    .map(|v| v as f64)
                    .to_vec(),
            )
        } else {
            (
                Model::Pinhole,
                [c.fx, c.fy, c.cx, c.cy].map(|v| v as f64).to_vec(),
            )
        };
        let existing = model.cameras.iter().find(|s| {
            (s.model, s.width, s.height, &s.params) == (model_kind, c.width, c.height, &params)
        });
        let camera_id = match existing {
            Some(s) => s.id,
            None => {
                let id = model.cameras.len() as u32 + 1;
                model.cameras.push(SparseCamera {
                    id,
                    model: model_kind,
                    width: c.width,
                    height: c.height,
                    params,
                });
                id
            }
        };
        let (q, t) = pose_to_colmap(&c.c2w);
        model.images.push(SparseImage {
            id: i as u32 + 1,
            qvec: [q.w, q.x, q.y, q.z],
            tvec: t.to_array(),
            camera_id,
            name: f.name.clone(),
        });
    }
    model.points = match super::splat::find_point_cloud(src) {
        Some(path) => {
            super::splat::points::load_points(&path).map_err(|what| Error::InvalidValue {
                path: path.clone(),
                what,
            })?
        }
        None => random_points(&frames, synthetic, opts)?,
    };
    for f in &frames {
        let to = dst.join("images").join(&f.name);
        if let Some(parent) = to.parent() {
            std::fs::create_dir_all(parent).map_err(|e| Error::io(parent, e))?;
        }
        std::fs::copy(&f.image, &to).map_err(|e| Error::io(&to, e))?;
    }
    write(&model, &dst.join("sparse").join("0"), opts.form)?;
    let list: String = frames
        .iter()
        .filter(|f| f.test)
        .map(|f| format!("{}\n", f.name))
        .collect();
    let list_path = dst.join(TEST_LIST);
    crate::image_io::write_atomic(&list_path, list.as_bytes())?;
    Ok(Converted {
        cameras: model.cameras.len(),
        images: model.images.len(),
        points: model.points.positions.len(),
    })
}

/// `opts.points` random points for [`convert`].
fn random_points(
    frames: &[super::dataset::SourceFrame],
    synthetic: bool,
    opts: &Convert,
) -> Result<PointCloud> {
    use glam::Vec3;
    let (center, dist) = super::dataset::focus(frames.iter().map(|f| &f.camera));
    let half = dist * if synthetic { 0.4 } else { 1.0 };
    let mut rng = crate::rng::Rng::new(opts.seed);
    let positions: Vec<[f32; 3]> = (0..opts.points)
        .map(|_| {
            let o = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0 - 1.0;
            (center + o * half).to_array()
        })
        .collect();
    let mut colors = vec![[0.5f32; 3]; positions.len()];
    let mut todo: Vec<usize> = (0..positions.len()).collect();
    for f in frames {
        if todo.is_empty() {
            break;
        }
        let img = super::dataset::decode(&f.image, 1)?;
        let c = &f.camera;
        todo.retain(|&i| {
            let Some(uv) = c.project(Vec3::from_array(positions[i])) else {
                return true;
            };
            let (x, y) = (uv.x.floor(), uv.y.floor());
            if !(x >= 0.0 && y >= 0.0 && x < img.width as f32 && y < img.height as f32) {
                return true;
            }
            colors[i] = img.rgb[y as usize * img.width as usize + x as usize];
            false
        });
    }
    Ok(PointCloud {
        positions,
        colors: Some(colors),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::dataset::Loading;
    use glam::{Vec2, Vec3};
    use serde_json::json;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("diffsvg-colmap-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn tilted(i: usize) -> Affine3A {
        Affine3A::from_rotation_translation(
            glam::Quat::from_euler(glam::EulerRot::YXZ, 0.7 + i as f32, -0.4, 0.2 * i as f32),
            Vec3::new(1.0, -2.0 + i as f32, 3.0),
        )
    }

    /// COLMAP's own projection: `X_cam = R X + t`, `u = fx x/z + cx`, `v = fy y/z + cy`.
    fn colmap_project(q: DQuat, t: DVec3, f: [f64; 4], p: DVec3) -> Option<Vec2> {
        let c = DMat3::from_quat(q) * p + t;
        (c.z > 0.0).then(|| {
            Vec2::new(
                (f[0] * c.x / c.z + f[2]) as f32,
                (f[1] * c.y / c.z + f[3]) as f32,
            )
        })
    }

    #[test]
    fn colmap_poses_project_as_colmap_does_and_round_trip() {
        let f = [50.0, 52.0, 32.0, 24.0];
        for i in 0..5 {
            let c2w = tilted(i);
            let (q, t) = pose_to_colmap(&c2w);
            assert!(q.w >= 0.0 && (q.length() - 1.0).abs() < 1e-9);
            let back = pose_from_colmap(q, t).unwrap();
            for (a, b) in [
                (back.matrix3.x_axis, c2w.matrix3.x_axis),
                (back.matrix3.y_axis, c2w.matrix3.y_axis),
                (back.matrix3.z_axis, c2w.matrix3.z_axis),
                (back.translation, c2w.translation),
            ] {
                assert!((a - b).length() < 1e-5, "{a:?} vs {b:?}");
            }
            // A point in front of the camera lands on the same pixel by both conventions.
            let cam = Camera::new(64, 48, 50.0, 52.0, 32.0, 24.0, back).unwrap();
            for local in [Vec3::new(0.3, 0.2, -4.0), Vec3::new(-1.0, 0.5, -2.0)] {
                let p = back.transform_point3(local);
                let ours = cam.project(p).unwrap();
                let theirs = colmap_project(q, t, f, p.as_dvec3()).unwrap();
                assert!((ours - theirs).length() < 1e-3, "{ours:?} vs {theirs:?}");
            }
        }
        // Identity rotation: COLMAP's camera looks along world +Z with image y along +Y.
        let c2w = pose_from_colmap(DQuat::IDENTITY, DVec3::new(0.0, 0.0, 4.0)).unwrap();
        let cam = Camera::new(64, 48, 50.0, 50.0, 32.0, 24.0, c2w).unwrap();
        assert!((cam.position() - Vec3::new(0.0, 0.0, -4.0)).length() < 1e-6);
        let down = cam.project(Vec3::new(0.0, 1.0, 0.0)).unwrap();
        let right = cam.project(Vec3::new(1.0, 0.0, 0.0)).unwrap();
        assert!(down.y > 24.0 && (down.x - 32.0).abs() < 1e-4);
        assert!(right.x > 32.0 && (right.y - 24.0).abs() < 1e-4);
        assert!(pose_from_colmap(DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0), DVec3::ZERO).is_none());
        assert!(pose_from_colmap(DQuat::IDENTITY, DVec3::new(f64::NAN, 0.0, 0.0)).is_none());
    }

    /// A model with every supported camera model, two images and three points.
    fn sample() -> Sparse {
        let cameras = [
            (Model::SimplePinhole, vec![40.0, 16.0, 12.0]),
            (Model::Pinhole, vec![40.0, 41.0, 16.0, 12.0]),
            (Model::SimpleRadial, vec![40.0, 16.0, 12.0, 0.01]),
            (Model::Radial, vec![40.0, 16.0, 12.0, 0.01, -0.02]),
            (
                Model::Opencv,
                vec![40.0, 41.0, 16.5, 12.25, 0.01, -0.02, 0.001, -0.002],
            ),
        ]
        .into_iter()
        .enumerate()
        .map(|(i, (model, params))| SparseCamera {
            id: i as u32 + 3,
            model,
            width: 32,
            height: 24,
            params,
        })
        .collect();
        let images = (0..5)
            .map(|i| {
                let (q, t) = pose_to_colmap(&tilted(i));
                SparseImage {
                    id: 10 + i as u32,
                    qvec: [q.w, q.x, q.y, q.z],
                    tvec: t.to_array(),
                    camera_id: i as u32 + 3,
                    name: format!("sub/im {i}.png"),
                }
            })
            .collect();
        Sparse {
            cameras,
            images,
            points: PointCloud {
                positions: vec![[0.5, -1.25, 3.0], [1e-3, 2.0, -7.5], [0.0; 3]],
                colors: Some(vec![[1.0, 0.0, 0.2], [0.0, 1.0, 0.4], [0.2, 0.4, 0.6]]),
            },
        }
    }

    /// The sample with colors as they come back (rounded to 0–255).
    fn rounded(mut s: Sparse) -> Sparse {
        for c in s.points.colors.as_mut().unwrap() {
            *c = c.map(|v| (v * 255.0).round() / 255.0);
        }
        s
    }

    #[test]
    fn binary_and_text_files_read_back_what_was_written() {
        for form in [Form::Binary, Form::Text] {
            let dir = scratch(&format!("rw-{form:?}"));
            let sparse = dir.join("sparse/0");
            write(&sample(), &sparse, form).unwrap();
            assert_eq!(find(&dir), Some((sparse.clone(), form)));
            let got = read(&sparse, form).unwrap();
            assert_eq!(got, rounded(sample()), "{form:?}");
            let cams = cameras(&got, &sparse, &sparse).unwrap();
            assert_eq!(cams[4].k1, 0.01);
            assert_eq!((cams[4].p1, cams[4].p2, cams[4].cx), (0.001, -0.002, 16.5));
            assert_eq!((cams[0].fx, cams[0].fy, cams[0].k1), (40.0, 40.0, 0.0));
            assert_eq!((cams[3].k1, cams[3].k2), (0.01, -0.02));
            std::fs::remove_dir_all(&dir).unwrap();
        }
        // Binary is preferred; sparse/ directly is accepted.
        let dir = scratch("both");
        write(&sample(), &dir.join("sparse"), Form::Text).unwrap();
        assert_eq!(find(&dir), Some((dir.join("sparse"), Form::Text)));
        write(&sample(), &dir.join("sparse"), Form::Binary).unwrap();
        assert_eq!(find(&dir), Some((dir.join("sparse"), Form::Binary)));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    fn read_err(sparse: &Path, form: Form) -> String {
        read(sparse, form).unwrap_err().to_string()
    }

    #[test]
    fn truncated_and_corrupt_binary_files_are_errors_not_panics() {
        let dir = scratch("corrupt");
        let sparse = dir.join("sparse/0");
        write(&sample(), &sparse, Form::Binary).unwrap();
        for name in ["cameras.bin", "images.bin", "points3D.bin"] {
            let path = sparse.join(name);
            let good = std::fs::read(&path).unwrap();
            // Every truncation, and one byte too many.
            for len in (0..good.len()).chain([good.len() + 1]) {
                let mut bytes = good.clone();
                bytes.resize(len, 0);
                std::fs::write(&path, &bytes).unwrap();
                let e = read_err(&sparse, Form::Binary);
                assert!(e.contains(name), "{name} at {len}: {e}");
            }
            // A hostile count: refused before anything is allocated.
            let mut bytes = good.clone();
            bytes[..8].copy_from_slice(&(1u64 << 60).to_le_bytes());
            std::fs::write(&path, &bytes).unwrap();
            let e = read_err(&sparse, Form::Binary);
            assert!(e.contains("more than the limit"), "{e}");
            let mut bytes = good.clone();
            bytes[..8].copy_from_slice(&1000u64.to_le_bytes());
            std::fs::write(&path, &bytes).unwrap();
            let e = read_err(&sparse, Form::Binary);
            assert!(
                e.contains("1000") && e.contains("are left of the file"),
                "{e}"
            );
            std::fs::write(&path, &good).unwrap();
        }
        // A hostile count of 2D points (first image) and of track elements (first point).
        let path = sparse.join("images.bin");
        let good = std::fs::read(&path).unwrap();
        let at = 8 + 4 + 56 + 4 + "sub/im 0.png".len() + 1;
        let mut bytes = good.clone();
        bytes[at..at + 8].copy_from_slice(&u64::MAX.to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        let e = read_err(&sparse, Form::Binary);
        assert!(
            e.contains("image 0 (id 10, \"sub/im 0.png\")") && e.contains("2D points"),
            "{e}"
        );
        std::fs::write(&path, &good).unwrap();
        let path = sparse.join("points3D.bin");
        let good = std::fs::read(&path).unwrap();
        let mut bytes = good.clone();
        bytes[8 + 43..8 + 51].copy_from_slice(&(u64::MAX / 4).to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        let e = read_err(&sparse, Form::Binary);
        assert!(e.contains("point 0 (id 1)") && e.contains("track"), "{e}");
        // A NaN coordinate.
        let mut bytes = good.clone();
        bytes[16..24].copy_from_slice(&f64::NAN.to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        assert!(read_err(&sparse, Form::Binary).contains("not finite"));
        std::fs::write(&path, &good).unwrap();
        // An unknown camera model id, a zero width.
        let path = sparse.join("cameras.bin");
        let good = std::fs::read(&path).unwrap();
        let mut bytes = good.clone();
        bytes[12..16].copy_from_slice(&99i32.to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        let e = read_err(&sparse, Form::Binary);
        assert!(
            e.contains("camera 0 (id 3)") && e.contains("model id 99"),
            "{e}"
        );
        let mut bytes = good.clone();
        bytes[16..24].copy_from_slice(&0u64.to_le_bytes());
        std::fs::write(&path, &bytes).unwrap();
        assert!(read_err(&sparse, Form::Binary).contains("width 0"));
        std::fs::write(&path, &good).unwrap();
        // A camera id no camera has.
        let mut s = sample();
        s.images[2].camera_id = 77;
        write(&s, &sparse, Form::Binary).unwrap();
        let e = read_err(&sparse, Form::Binary);
        assert!(
            e.contains("images.bin")
                && e.contains("\"sub/im 2.png\"")
                && e.contains("camera 77 does not exist"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_text_lines_name_the_file_and_line() {
        let dir = scratch("text");
        let sparse = dir.join("sparse/0");
        write(&sample(), &sparse, Form::Text).unwrap();
        let cams = std::fs::read_to_string(sparse.join("cameras.txt")).unwrap();
        let cases = [
            (
                "cameras.txt",
                "3 PINHOLE 32 24 40 41 16\n",
                "takes 4 parameters, got 3",
            ),
            (
                "cameras.txt",
                "3 PINHOLE 32 24 40 41 16 x\n",
                "parameter \"x\"",
            ),
            (
                "cameras.txt",
                "3 WEIRD 32 24 1\n",
                "unknown camera model \"WEIRD\"",
            ),
            (
                "cameras.txt",
                "-3 PINHOLE 32 24 40 41 16 12\n",
                "CAMERA_ID \"-3\"",
            ),
            ("cameras.txt", "3 PINHOLE 32\n", "no HEIGHT"),
            (
                "cameras.txt",
                "3 PINHOLE 32 24 nan 41 16 12\n",
                "not finite",
            ),
            ("images.txt", "1 1 0 0 0 0 0 0 3\n\n", "no NAME"),
            (
                "images.txt",
                "1 0 0 0 0 0 0 0 3 a.png\n\n",
                "quaternion is zero",
            ),
            ("images.txt", "1 1 0 0 0 0 0 inf 3 a.png\n\n", "non-finite"),
            ("images.txt", "1 1 0 0\n", "no QZ"),
            ("points3D.txt", "1 0 0 0 255 0 300 0\n", "B \"300\""),
            ("points3D.txt", "1 0 0\n", "no Z"),
            ("points3D.txt", "1 0 0 1e300 1 2 3 0\n", "not finite"),
        ];
        for (file, line, want) in cases {
            let good = std::fs::read_to_string(sparse.join(file)).unwrap();
            std::fs::write(sparse.join(file), format!("# comment\n\n{line}")).unwrap();
            let e = read_err(&sparse, Form::Text);
            assert!(
                e.contains(file) && e.contains("line 3") && e.contains(want),
                "{file} {line:?}: {e}"
            );
            std::fs::write(sparse.join(file), good).unwrap();
        }
        // Duplicate camera ids; non-UTF-8; an over-long points line is skipped unread.
        std::fs::write(
            sparse.join("cameras.txt"),
            format!("{cams}{}", cams.lines().last().unwrap()),
        )
        .unwrap();
        assert!(read_err(&sparse, Form::Text).contains("same id"));
        std::fs::write(sparse.join("cameras.txt"), b"\xff\xfe\n").unwrap();
        assert!(read_err(&sparse, Form::Text).contains("line 1: not UTF-8"));
        std::fs::write(sparse.join("cameras.txt"), &cams).unwrap();
        let long = "1.5 2.5 -1 ".repeat(MAX_LINE_BYTES / 4);
        let (q, t) = pose_to_colmap(&tilted(0));
        std::fs::write(
            sparse.join("images.txt"),
            format!(
                "7 {} {} {} {} {} {} {} 3 a b.png\n{long}\n8 1 0 0 0 0 0 0 4 c.png\n",
                q.w, q.x, q.y, q.z, t.x, t.y, t.z
            ),
        )
        .unwrap();
        let got = read(&sparse, Form::Text).unwrap();
        assert_eq!(got.images.len(), 2);
        assert_eq!(
            (got.images[0].name.as_str(), got.images[1].name.as_str()),
            ("a b.png", "c.png")
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A COLMAP folder of `n` 8×6 PNGs named `im_NN.png` (colors by index), camera `model`,
    /// and, when `half`, an `images_2/` of 4×3 PNGs of another color.
    fn colmap_folder(name: &str, n: usize, model: Model, params: Vec<f64>, half: bool) -> PathBuf {
        let dir = scratch(name);
        let mut s = sample();
        s.cameras = vec![SparseCamera {
            id: 1,
            model,
            width: 8,
            height: 6,
            params,
        }];
        s.images = (0..n)
            .map(|i| {
                let c2w = Camera::look_at(
                    Vec3::new(4.0 * (i as f32).cos(), 4.0 * (i as f32).sin(), 1.0),
                    Vec3::ZERO,
                    Vec3::Z,
                    0.8,
                    8,
                    8,
                )
                .unwrap()
                .c2w;
                let (q, t) = pose_to_colmap(&c2w);
                SparseImage {
                    id: 100 - i as u32,
                    qvec: [q.w, q.x, q.y, q.z],
                    tvec: t.to_array(),
                    camera_id: 1,
                    name: format!("im_{i:02}.png"),
                }
            })
            .rev()
            .collect();
        write(&s, &dir.join("sparse/0"), Form::Binary).unwrap();
        for i in 0..n {
            let save = |folder: &str, w, h, g: u8| {
                std::fs::create_dir_all(dir.join(folder)).unwrap();
                image::RgbImage::from_pixel(w, h, image::Rgb([i as u8 * 10, g, 0]))
                    .save(dir.join(folder).join(format!("im_{i:02}.png")))
                    .unwrap();
            };
            save("images", 8, 6, 0);
            if half {
                save("images_2", 4, 3, 200);
            }
        }
        dir
    }

    #[test]
    fn colmap_folders_load_with_split_points_and_downscaled_folders() {
        let dir = colmap_folder("load", 10, Model::Pinhole, vec![9.0, 8.0, 4.0, 3.5], true);
        let ds = Dataset::load(&dir, 1).unwrap();
        // Sorted by name, positions 0 and 8 are test views; each split is in id order
        // (ids fall as names rise here).
        let names = |v: &[View]| v.iter().map(|v| v.name.clone()).collect::<Vec<_>>();
        assert_eq!(names(&ds.test), ["im_08.png", "im_00.png"]);
        assert_eq!(names(&ds.train)[..2], ["im_09.png", "im_07.png"]);
        let named = |d: &Dataset, name: &str| d.train.iter().find(|v| v.name == name).cloned();
        assert!(!ds.white_background);
        assert_eq!(
            ds.points.as_ref().unwrap().positions,
            sample().points.positions
        );
        let v = &named(&ds, "im_01.png").unwrap();
        assert_eq!(
            (v.width, v.height, v.rgb[0]),
            (8, 6, [10.0 / 255.0, 0.0, 0.0])
        );
        assert_eq!(
            (v.camera.fx, v.camera.fy, v.camera.cx, v.camera.cy),
            (9.0, 8.0, 4.0, 3.5)
        );
        let want = Vec3::new(4.0 * 1f32.cos(), 4.0 * 1f32.sin(), 1.0);
        assert!((v.camera.position() - want).length() < 1e-5);
        // --test-every.
        let none = Dataset::load_with(
            &dir,
            &Loading {
                test_every: Some(0),
                ..Loading::default()
            },
        )
        .unwrap();
        assert_eq!((none.train.len(), none.test.len()), (10, 0));
        let third = Dataset::load_with(
            &dir,
            &Loading {
                test_every: Some(3),
                ..Loading::default()
            },
        )
        .unwrap();
        assert_eq!(
            names(&third.test),
            ["im_09.png", "im_06.png", "im_03.png", "im_00.png"]
        );
        // A test list: the views it names, in id order (ids fall as names rise here).
        let list = dir.join("held.txt");
        std::fs::write(&list, "# held out\nim_02.png\n\n./im_07.png\n").unwrap();
        let listed = Loading {
            test_list: Some(list.clone()),
            ..Loading::default()
        };
        let held = Dataset::load_with(&dir, &listed).unwrap();
        assert_eq!(names(&held.test), ["im_07.png", "im_02.png"]);
        assert_eq!(held.train.len(), 8);
        assert_eq!(names(&held.train)[..2], ["im_09.png", "im_08.png"]);
        // A name that is no image, a name twice, a list with test_every: one line each.
        for (text, want) in [
            (
                "im_02.png\nim_99.png\n",
                "line 2: \"im_99.png\" is not an image of",
            ),
            (
                "im_02.png\nim_02.png\n",
                "line 2: \"im_02.png\" is listed twice (line 1)",
            ),
        ] {
            std::fs::write(&list, text).unwrap();
            let e = Dataset::load_with(&dir, &listed).unwrap_err().to_string();
            assert!(e.contains("held.txt") && e.contains(want), "{e}");
            assert_eq!(e.lines().count(), 1, "{e}");
        }
        let both = Loading {
            test_every: Some(4),
            ..listed.clone()
        };
        let e = Dataset::load_with(&dir, &both).unwrap_err().to_string();
        assert!(e.contains("test_list") && e.contains("not both"), "{e}");
        std::fs::remove_file(&list).unwrap();
        let e = Dataset::load_with(&dir, &listed).unwrap_err().to_string();
        assert!(e.contains("held.txt"), "{e}");
        // --downscale 2 reads images_2/ with intrinsics scaled by the photo's size.
        let half = Dataset::load(&dir, 2).unwrap();
        let h = &named(&half, "im_01.png").unwrap();
        assert_eq!(
            (h.width, h.height, h.rgb[0]),
            (4, 3, [10.0 / 255.0, 200.0 / 255.0, 0.0])
        );
        assert_eq!(
            (h.camera.fx, h.camera.fy, h.camera.cx, h.camera.cy),
            (4.5, 4.0, 2.0, 1.75)
        );
        // Without images_2/: block-averaged from images/.
        std::fs::remove_dir_all(dir.join("images_2")).unwrap();
        let half = Dataset::load(&dir, 2).unwrap();
        assert_eq!(
            named(&half, "im_01.png").unwrap().rgb[0],
            [10.0 / 255.0, 0.0, 0.0]
        );
        assert_eq!(half.train[0].camera, ds.train[0].camera.downscaled(2));
        // A missing photo: one line naming the file and the entry.
        std::fs::remove_file(dir.join("images/im_04.png")).unwrap();
        let e = Dataset::load(&dir, 1).unwrap_err().to_string();
        assert!(
            e.contains("im_04.png") && e.contains("id 96") && e.contains("images.bin"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn unsupported_models_and_wrong_sizes_are_refused() {
        let dir = colmap_folder(
            "fisheye",
            2,
            Model::OpencvFisheye,
            vec![9.0, 9.0, 4.0, 3.0, 0.1, 0.0, 0.0, 0.0],
            false,
        );
        let e = Dataset::load(&dir, 1).unwrap_err().to_string();
        assert!(
            e.contains("cameras.bin") && e.contains("camera 1") && e.contains("OPENCV_FISHEYE"),
            "{e}"
        );
        assert_eq!(e.lines().count(), 1);
        std::fs::remove_dir_all(&dir).unwrap();
        let dir = colmap_folder("size", 2, Model::SimplePinhole, vec![9.0, 4.0, 3.0], false);
        image::RgbImage::new(9, 6)
            .save(dir.join("images/im_01.png"))
            .unwrap();
        let e = Dataset::load(&dir, 1).unwrap_err().to_string();
        assert!(
            e.contains("im_01.png") && e.contains("9×6") && e.contains("8×6"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Every view of `a` has a view of `b` whose name starts with its own and whose
    /// camera agrees within 1e-5 (relative for intrinsics).
    fn same_cameras(a: &Dataset, b: &Dataset) {
        let all = |d: &Dataset| d.train.iter().chain(&d.test).cloned().collect::<Vec<_>>();
        let (va, vb) = (all(a), all(b));
        assert_eq!(va.len(), vb.len());
        for v in &va {
            let w = vb
                .iter()
                .find(|w| w.name.trim_end_matches(".png") == v.name.trim_end_matches(".png"))
                .unwrap_or_else(|| panic!("{} missing", v.name));
            let (c, d) = (v.camera, w.camera);
            assert_eq!((c.width, c.height), (d.width, d.height));
            for (x, y) in [
                (c.fx, d.fx),
                (c.fy, d.fy),
                (c.cx, d.cx),
                (c.cy, d.cy),
                (c.k1, d.k1),
                (c.k2, d.k2),
                (c.p1, d.p1),
                (c.p2, d.p2),
            ] {
                assert!(
                    (x - y).abs() <= 1e-5 * x.abs().max(1.0),
                    "{}: {x} vs {y}",
                    v.name
                );
            }
            for (x, y) in [
                (c.c2w.matrix3.x_axis, d.c2w.matrix3.x_axis),
                (c.c2w.matrix3.y_axis, d.c2w.matrix3.y_axis),
                (c.c2w.matrix3.z_axis, d.c2w.matrix3.z_axis),
                (c.c2w.translation, d.c2w.translation),
            ] {
                assert!(
                    (x - y).abs().max_element() <= 1e-5,
                    "{}: {x:?} vs {y:?}",
                    v.name
                );
            }
            assert_eq!(v.rgb, w.rgb, "{}", v.name);
        }
    }

    /// `b` has the train and the test views of `a`, in the same order (names compared
    /// without `.png`).
    fn same_split(a: &Dataset, b: &Dataset) {
        let names = |v: &[View]| {
            v.iter()
                .map(|v| v.name.trim_end_matches(".png").to_string())
                .collect::<Vec<_>>()
        };
        assert_eq!(names(&a.train), names(&b.train));
        assert_eq!(names(&a.test), names(&b.test));
    }

    /// `Loading` with the test list `dst/test.txt`.
    fn with_list(dst: &Path) -> Loading {
        Loading {
            test_list: Some(dst.join(TEST_LIST)),
            ..Loading::default()
        }
    }

    #[test]
    fn converted_folders_load_to_the_same_cameras_in_both_forms() {
        // NeRF-synthetic: 12 train + 3 test views of 8×6 RGBA photos (r_10 sorts before
        // r_2, so name order is not the source's).
        let src = scratch("conv-src");
        for (split, n) in [("train", 12), ("test", 3)] {
            let frames: Vec<_> = (0..n)
                .map(|i| {
                    std::fs::create_dir_all(src.join(split)).unwrap();
                    image::RgbaImage::from_fn(8, 6, |x, _| image::Rgba([i * 40, 9, 9, if x < 4 { 255 } else { 0 }]))
                        .save(src.join(format!("{split}/r_{i}.png")))
                        .unwrap();
                    let m = glam::Mat4::from(tilted(i as usize + 12 * (split == "test") as usize));
                    json!({"file_path": format!("./{split}/r_{i}"),
                           "transform_matrix": (0..4).map(|r| m.row(r).to_array()).collect::<Vec<_>>()})
                })
                .collect();
            std::fs::write(
                src.join(format!("transforms_{split}.json")),
                json!({"camera_angle_x": 0.69, "frames": frames}).to_string(),
            )
            .unwrap();
        }
        let original = Dataset::load(&src, 1).unwrap();
        for form in [Form::Binary, Form::Text] {
            let dst = scratch(&format!("conv-{form:?}"));
            let opts = Convert {
                form,
                points: 50,
                seed: 1,
            };
            let out = convert(&src, &dst, &opts).unwrap();
            assert_eq!(
                out,
                Converted {
                    cameras: 1,
                    images: 15,
                    points: 50
                }
            );
            let ds = Dataset::load(&dst, 1).unwrap();
            same_cameras(&original, &ds);
            // By default COLMAP's split (every 8th by name: test/r_0 and train/r_3, in
            // id order); with the list the converter wrote, the source's split in the
            // source's order.
            let held: Vec<&str> = ds.test.iter().map(|v| v.name.as_str()).collect();
            assert_eq!(held, ["train/r_3.png", "test/r_0.png"]);
            let listed = Dataset::load_with(&dst, &with_list(&dst)).unwrap();
            same_split(&original, &listed);
            same_cameras(&original, &listed);
            assert!(ds.white_background, "RGBA photos are composited over white");
            let pts = ds.points.unwrap();
            assert_eq!(pts.positions.len(), 50);
            // Points inside the photos' opaque left half take its red.
            assert!(pts.colors.unwrap().iter().any(|c| c[1] < 0.1));
            // Not over an existing model.
            assert!(
                convert(&src, &dst, &opts)
                    .unwrap_err()
                    .to_string()
                    .contains("already holds")
            );
            std::fs::remove_dir_all(&dst).unwrap();
        }
        std::fs::remove_dir_all(&src).unwrap();

        // instant-ngp with distortion: OPENCV.
        let src = scratch("conv-ngp");
        std::fs::create_dir_all(src.join("images")).unwrap();
        let frames: Vec<_> = (0..12)
            .map(|i| {
                image::RgbImage::from_pixel(10, 6, image::Rgb([i * 20, 100, 0]))
                    .save(src.join(format!("images/{i}.jpg")))
                    .unwrap();
                let m = glam::Mat4::from(tilted(i as usize));
                json!({"file_path": format!("images/{i}.jpg"),
                       "transform_matrix": (0..4).map(|r| m.row(r).to_array()).collect::<Vec<_>>()})
            })
            .collect();
        std::fs::write(
            src.join("transforms.json"),
            json!({"fl_x": 12.0, "fl_y": 11.0, "cx": 4.5, "cy": 3.25, "k1": 0.05, "k2": -0.08,
                   "p1": -0.001, "p2": 0.0002, "frames": frames})
            .to_string(),
        )
        .unwrap();
        let original = Dataset::load(&src, 1).unwrap();
        for form in [Form::Binary, Form::Text] {
            let dst = scratch(&format!("conv-ngp-{form:?}"));
            convert(
                &src,
                &dst,
                &Convert {
                    form,
                    points: 0,
                    seed: 0,
                },
            )
            .unwrap();
            let ds = Dataset::load(&dst, 1).unwrap();
            same_cameras(&original, &ds);
            // images/10.jpg sorts before images/2.jpg: the held-out views by name are
            // others than the source's; the list gives the source's.
            assert_ne!(ds.test[1].name, original.test[1].name);
            let listed = Dataset::load_with(&dst, &with_list(&dst)).unwrap();
            same_split(&original, &listed);
            assert!(!ds.white_background && ds.points.is_none());
            assert_eq!(
                read(&dst.join("sparse/0"), form).unwrap().cameras[0].model,
                Model::Opencv
            );
            std::fs::remove_dir_all(&dst).unwrap();
        }
        std::fs::remove_dir_all(&src).unwrap();
    }

    #[test]
    fn real_lego_and_fox_convert_to_the_same_cameras_when_present() {
        let test = "real_lego_and_fox_convert_to_the_same_cameras_when_present";
        let Some(scenes) = super::super::dataset::tests::scenes(test) else {
            return;
        };
        for (scene, k) in [("nerf_synthetic_lego_400", 2), ("fox", 4)] {
            let src = scenes.join(scene);
            if !src.is_dir() {
                println!("SKIPPED {test} for {scene}: {} not found", src.display());
                continue;
            }
            let original = Dataset::load(&src, k).unwrap();
            for form in [Form::Binary, Form::Text] {
                let dst = scratch(&format!("real-{scene}-{form:?}"));
                let t = std::time::Instant::now();
                convert(
                    &src,
                    &dst,
                    &Convert {
                        form,
                        points: 100,
                        seed: 0,
                    },
                )
                .unwrap();
                let ds = Dataset::load(&dst, k).unwrap();
                println!(
                    "{scene} {form:?}: converted and loaded in {:.1} s",
                    t.elapsed().as_secs_f64()
                );
                same_cameras(&original, &ds);
                assert_eq!(ds.white_background, original.white_background, "{scene}");
                std::fs::remove_dir_all(&dst).unwrap();
            }
        }
    }
}
