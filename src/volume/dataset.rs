//! Posed-photo datasets: NeRF-synthetic (`transforms_{train,test}.json`), instant-ngp
//! (`transforms.json`) and COLMAP (`sparse/0/`, see [`colmap`](super::colmap)) folders,
//! loaded into cameras and RGB images; tried in that order.
//!
//! * **NeRF-synthetic** (detected by `transforms_train.json`): train views from
//!   `transforms_train.json`, test views from `transforms_test.json` when it exists (none
//!   otherwise). `file_path` usually has no extension (`"./train/r_0"`); `.png` is then
//!   appended. Every listed image must exist.
//! * **instant-ngp** (`transforms.json`): frames whose image is missing are skipped with one
//!   warning on stderr naming them all; of the frames present, in file order, those at
//!   positions 0, 8, 16, … are the test views and the rest are train views
//!   ([`Loading::test_every`] chooses another interval, [`Loading::test_list`] names the
//!   test views instead). nerfstudio's `transforms.json`
//!   reads the same way (its `applied_transform` is informational and ignored).
//!
//! Both formats share one reader. Intrinsics come from the top level and may be
//! overridden per frame: `fl_x`, `fl_y` (pixels) or `camera_angle_x`, `camera_angle_y`
//! (radians, full field of view across the image width/height); a missing vertical focal
//! length equals the horizontal one; `cx`, `cy` default to the image center; `w`, `h`, when
//! given, must match the image; `k1 k2 p1 p2` are OpenCV distortion (default 0).
//! `transform_matrix` is a 4×4 (or 3×4) row-major camera-to-world matrix in the
//! OpenGL/Blender convention. Paths are relative to the JSON file's folder.
//!
//! Images (PNG or JPEG, 8 or 16 bit) become RGB in `[0, 1]`; an alpha channel is
//! composited over white (straight alpha, no gamma handling). All images must have the
//! same size. With `downscale` K > 1 each output pixel is the mean of a K×K block
//! (sizes rounded down, the right/bottom remainder dropped) and the cameras are
//! [`Camera::downscaled`], so pixel geometry stays exact.
//!
//! Loading only reads files; on any error nothing is returned (and nothing written).
//!
//! **Limits**, checked before the work they bound: a transforms file is read only up to
//! [`limits::MAX_FILE_BYTES`](crate::limits::MAX_FILE_BYTES) and lists at most
//! [`MAX_FRAMES`] frames; every `file_path` must stay inside the dataset folder (after
//! resolving `..` and symbolic links); each image's size is read from its header and must
//! stay within [`limits::MAX_SIDE`](crate::limits::MAX_SIDE) and
//! [`limits::MAX_IMAGE_PIXELS`](crate::limits::MAX_IMAGE_PIXELS), and all images together,
//! after downscaling, within [`MAX_DATASET_PIXELS`], before any is decoded. Intrinsics must
//! describe a usable camera ([`Camera::validate`]): a field of view within
//! `camera::fov_range`, bounded one-to-one distortion.
//!
//! ```
//! use diffsvg::Image;
//! use diffsvg::volume::dataset::Dataset;
//! // A NeRF-synthetic folder with one training view: a pose and a 4 × 2 photo.
//! let dir = std::env::temp_dir().join(format!("diffsvg-doc-dataset-{}", std::process::id()));
//! std::fs::create_dir_all(dir.join("train"))?;
//! Image::filled(4, 2, [0.0, 0.0, 1.0, 1.0]).save_png(dir.join("train/r_0.png"))?;
//! std::fs::write(dir.join("transforms_train.json"), r#"{"camera_angle_x": 0.69,
//!   "frames": [{"file_path": "./train/r_0", "transform_matrix":
//!     [[1,0,0,0],[0,1,0,0],[0,0,1,4],[0,0,0,1]]}]}"#)?;
//! let ds = Dataset::load(&dir, 1)?;
//! assert_eq!((ds.train.len(), ds.test.len()), (1, 0));
//! let view = &ds.train[0];
//! assert_eq!((view.width, view.height, view.rgb[0]), (4, 2, [0.0, 0.0, 1.0]));
//! assert_eq!(view.camera.position().z, 4.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::path::{Path, PathBuf};

use glam::Affine3A;
use rayon::prelude::*;
use serde_json::{Map, Value};

use super::camera::{
    Camera, MAX_FOCAL_RATIO, MIN_FOCAL_RATIO, focal_from_fov, fov_range, pose_from_rows,
};
use super::splat::PointCloud;
use crate::error::{Error, Result};
use crate::limits::{MAX_FILE_BYTES, MAX_IMAGE_PIXELS, MAX_SIDE};

/// Most frames in one transforms file.
pub const MAX_FRAMES: usize = 10_000;

/// Most pixels of all a dataset's images together, after downscaling: each costs about
/// 50 bytes while fitting (color, ray, batch), so this bounds a fit near 1.6 GiB (lego's
/// 125 views at 400² hold 2·10⁷).
pub const MAX_DATASET_PIXELS: u64 = 1 << 25;

/// One posed photo.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    /// The frame's `file_path` as written in the JSON, without a leading `./`.
    pub name: String,
    /// The camera, for the (possibly downscaled) image.
    pub camera: Camera,
    /// Image width in pixels (equals `camera.width`).
    pub width: u32,
    /// Image height in pixels (equals `camera.height`).
    pub height: u32,
    /// `width × height` RGB pixels in `[0, 1]`, row-major, y down, alpha composited over
    /// white.
    pub rgb: Vec<[f32; 3]>,
}

/// A dataset split into training and held-out test views.
#[derive(Clone, Debug, PartialEq)]
pub struct Dataset {
    /// Views to fit.
    pub train: Vec<View>,
    /// Views to evaluate on (may be empty for a NeRF-synthetic folder without
    /// `transforms_test.json`).
    pub test: Vec<View>,
    /// The dataset folder's name.
    pub name: String,
    /// Whether the photos show an object composited over white (NeRF-synthetic), so that
    /// a ray leaving the scene sees white; false for real photos (instant-ngp), whose
    /// surroundings fill every pixel and must be inside the model.
    pub white_background: bool,
    /// What was read other than the folder says, one line each, for the caller to show
    /// (the library prints nothing): frames skipped because their image is missing.
    pub warnings: Vec<String>,
    /// The capture's sparse points (COLMAP's `points3D`), world units, colors linear in
    /// `[0, 1]`; `None` for formats that carry none (a point-cloud file beside them is
    /// found by [`find_point_cloud`](super::splat::find_point_cloud)).
    pub points: Option<PointCloud>,
}

/// How to load a dataset: [`Dataset::load_with`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Loading {
    /// Divide image sizes by this integer, at least 1 (COLMAP: read `images_K/` when it
    /// exists).
    pub downscale: u32,
    /// Instant-ngp and COLMAP folders: the views at positions 0, N, 2N, … (file order
    /// for instant-ngp, sorted by name for COLMAP) are held out as test views; `Some(0)`:
    /// none; `None`: every 8th. NeRF-synthetic folders have their own test split and
    /// refuse `Some`.
    pub test_every: Option<usize>,
    /// Instant-ngp and COLMAP folders: a text file naming the test views instead, one a
    /// line as [`View::name`] gives them (COLMAP: the image's name in `images`, such as
    /// `test/r_0.png`; instant-ngp: the frame's `file_path` without a leading `./`);
    /// blank lines and lines starting with `#` are skipped, a leading `./` is ignored.
    /// Every name must be one of the folder's photos. Excludes `test_every`;
    /// NeRF-synthetic folders refuse it.
    pub test_list: Option<PathBuf>,
}

impl Default for Loading {
    fn default() -> Self {
        Loading {
            downscale: 1,
            test_every: None,
            test_list: None,
        }
    }
}

/// The test split of a [`Loading`] for an instant-ngp or COLMAP folder, its list read.
pub(crate) struct Holdout {
    every: usize,
    /// The list's file and its names, each with its line (from 1).
    list: Option<(PathBuf, Vec<(String, usize)>)>,
}

impl Holdout {
    /// Reads `loading.test_list`, if any.
    ///
    /// # Errors
    /// Both a list and `test_every`; an unreadable or oversized list; a name listed twice.
    pub(crate) fn new(loading: &Loading) -> Result<Holdout> {
        let Some(path) = &loading.test_list else {
            return Ok(Holdout {
                every: loading.test_every.unwrap_or(HOLDOUT),
                list: None,
            });
        };
        if let Some(n) = loading.test_every {
            return Err(Error::Setting {
                name: "test_list".into(),
                message: format!(
                    "{}: choose it or test_every ({n}), not both",
                    path.display()
                ),
            });
        }
        let bytes = read_bounded(path)?;
        let text = String::from_utf8(bytes).map_err(|_| Error::InvalidValue {
            path: path.clone(),
            what: "the test list is not UTF-8 text".into(),
        })?;
        let mut names: Vec<(String, usize)> = Vec::new();
        let mut seen = std::collections::HashMap::new();
        for (i, line) in text.lines().enumerate() {
            let name = line.trim();
            if name.is_empty() || name.starts_with('#') {
                continue;
            }
            let name = name.trim_start_matches("./").to_string();
            if let Some(first) = seen.insert(name.clone(), i + 1) {
                return Err(Error::InvalidValue {
                    path: path.clone(),
                    what: format!("line {}: {name:?} is listed twice (line {first})", i + 1),
                });
            }
            names.push((name, i + 1));
        }
        Ok(Holdout {
            every: 0,
            list: Some((path.clone(), names)),
        })
    }

    /// Whether the view named `name` at `position` (in the format's order) is a test view.
    pub(crate) fn is_test(&self, position: usize, name: &str) -> bool {
        match &self.list {
            Some((_, names)) => names.iter().any(|(n, _)| n == name),
            None => self.every != 0 && position.is_multiple_of(self.every),
        }
    }

    /// Checks that every listed name is one of `names` (all the folder's views); the
    /// error names the list, the line and the name. `what` says what the names are.
    pub(crate) fn check_found<'a>(
        &self,
        names: impl Iterator<Item = &'a str>,
        what: &str,
    ) -> Result<()> {
        let Some((path, list)) = &self.list else {
            return Ok(());
        };
        let names: std::collections::HashSet<&str> = names.collect();
        match list.iter().find(|(n, _)| !names.contains(n.as_str())) {
            Some((name, line)) => Err(Error::InvalidValue {
                path: path.clone(),
                what: format!("line {line}: {name:?} is not {what}"),
            }),
            None => Ok(()),
        }
    }
}

impl Dataset {
    /// Loads a dataset folder; see [`load`].
    pub fn load(dir: &Path, downscale: u32) -> Result<Dataset> {
        load(dir, downscale)
    }

    /// Loads a dataset folder with a choice of test split; see [`load_with`].
    pub fn load_with(dir: &Path, loading: &Loading) -> Result<Dataset> {
        load_with(dir, loading)
    }

    /// Where the cameras look: the point closest (in least squares) to every training
    /// camera's optical axis, and the median distance of the cameras from it, world units.
    /// Falls back to the cameras' mean position when the axes are (near) parallel.
    pub fn focus(&self) -> (glam::Vec3, f32) {
        let views = if self.train.is_empty() {
            &self.test
        } else {
            &self.train
        };
        focus(views.iter().map(|v| &v.camera))
    }
}

/// [`Dataset::focus`] of a set of cameras.
pub(crate) fn focus<'a>(cameras: impl Iterator<Item = &'a Camera>) -> (glam::Vec3, f32) {
    let cameras: Vec<&Camera> = cameras.collect();
    // Σ (I − d dᵀ) p = Σ (I − d dᵀ) o over the axes o + t d.
    let mut a = glam::DMat3::ZERO;
    let mut b = glam::DVec3::ZERO;
    let mut mean = glam::DVec3::ZERO;
    for c in &cameras {
        let o = c.position().as_dvec3();
        let d = c.forward().as_dvec3().normalize_or_zero();
        let m = glam::DMat3::IDENTITY - glam::DMat3::from_cols(d * d.x, d * d.y, d * d.z);
        a += m;
        b += m * o;
        mean += o;
    }
    mean /= cameras.len().max(1) as f64;
    let center = if a.determinant().abs() > 1e-9 {
        a.inverse() * b
    } else {
        mean
    };
    let center = center.as_vec3();
    let mut dist: Vec<f32> = cameras
        .iter()
        .map(|c| c.position().distance(center))
        .collect();
    dist.sort_by(|x, y| x.total_cmp(y));
    let median = dist.get(dist.len() / 2).copied().unwrap_or(1.0);
    (center, median)
}

/// Every `HOLDOUT`-th present frame of an instant-ngp dataset is a test view.
pub(crate) const HOLDOUT: usize = 8;

/// Loads a NeRF-synthetic, instant-ngp or COLMAP folder (see the module documentation),
/// with images and cameras downscaled by the integer `downscale ≥ 1` and the default
/// test split: [`load_with`] with `test_every: None`.
pub fn load(dir: &Path, downscale: u32) -> Result<Dataset> {
    load_with(
        dir,
        &Loading {
            downscale,
            ..Loading::default()
        },
    )
}

/// Loads a NeRF-synthetic, instant-ngp or COLMAP folder (see the module documentation).
///
/// Errors name the file and the problem: a missing folder or transforms file, malformed
/// JSON or fields (`"frame 3 (./train/r_3): transform_matrix must be 4×4 (or 3×4)
/// numbers"`, frames counted from 0), degenerate poses, missing or unreadable images, an
/// image whose size differs from the first one, no frames with images, `test_every`
/// given for a NeRF-synthetic folder.
pub fn load_with(dir: &Path, loading: &Loading) -> Result<Dataset> {
    let downscale = loading.downscale;
    if downscale == 0 {
        return Err(Error::InvalidValue {
            path: dir.to_path_buf(),
            what: "downscale must be at least 1".into(),
        });
    }
    match std::fs::metadata(dir) {
        Ok(m) if m.is_dir() => {}
        Ok(_) => return Err(not_found(dir, "not a folder")),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(not_found(dir, "dataset folder does not exist"));
        }
        Err(e) => return Err(Error::io(dir, e)),
    }
    let name = dir
        .canonicalize()
        .ok()
        .as_deref()
        .and_then(Path::file_name)
        .or_else(|| dir.file_name())
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();

    let synthetic = dir.join("transforms_train.json");
    let ngp = dir.join("transforms.json");
    // Frames to load, each with its split (true = test).
    let mut frames: Vec<(Frame, bool)> = Vec::new();
    let mut warnings = Vec::new();
    if synthetic.is_file() {
        if let Some(list) = &loading.test_list {
            return Err(Error::Setting {
                name: "test_list".into(),
                message: format!(
                    "{}: {} is a NeRF-synthetic folder, whose test views are those of \
                     transforms_test.json",
                    list.display(),
                    dir.display()
                ),
            });
        }
        if let Some(n) = loading.test_every {
            return Err(Error::Setting {
                name: "test_every".into(),
                message: format!(
                    "{n}: {} is a NeRF-synthetic folder, whose test views are those of \
                     transforms_test.json",
                    dir.display()
                ),
            });
        }
        let train = parse_transforms(&synthetic)?;
        require_images(&synthetic, &train)?;
        frames.extend(train.into_iter().map(|f| (f, false)));
        let test_json = dir.join("transforms_test.json");
        if test_json.is_file() {
            let test = parse_transforms(&test_json)?;
            require_images(&test_json, &test)?;
            frames.extend(test.into_iter().map(|f| (f, true)));
        }
    } else if ngp.is_file() {
        let all = parse_transforms(&ngp)?;
        let total = all.len();
        let (present, missing): (Vec<Frame>, Vec<Frame>) =
            all.into_iter().partition(|f| f.image.is_some());
        if present.is_empty() {
            return Err(Error::io(
                &ngp,
                std::io::Error::new(
                    std::io::ErrorKind::NotFound,
                    format!(
                        "none of the {total} frames has its image (first looked for: {})",
                        missing
                            .first()
                            .map(|f| f.tried.display().to_string())
                            .unwrap_or_default()
                    ),
                ),
            ));
        }
        if !missing.is_empty() {
            let names: Vec<&str> = missing.iter().map(|f| f.file_path.as_str()).collect();
            warnings.push(format!(
                "{}: skipping {} of {total} frames whose image is missing: {}",
                ngp.display(),
                missing.len(),
                names.join(", ")
            ));
        }
        let holdout = Holdout::new(loading)?;
        let trimmed = |f: &Frame| f.file_path.trim_start_matches("./").to_string();
        holdout.check_found(
            present.iter().map(|f| f.file_path.trim_start_matches("./")),
            &format!(
                "the file_path of a frame with its image in {}",
                ngp.display()
            ),
        )?;
        frames.extend(present.into_iter().enumerate().map(|(i, f)| {
            let test = holdout.is_test(i, &trimmed(&f));
            (f, test)
        }));
    } else if let Some((sparse, form)) = super::colmap::find(dir) {
        let holdout = Holdout::new(loading)?;
        return super::colmap::load(dir, &sparse, form, loading.downscale, &holdout, name);
    } else {
        return Err(not_found(
            dir,
            "no transforms_train.json (NeRF-synthetic), transforms.json (instant-ngp) or \
             sparse/0/cameras.bin or .txt (COLMAP) here",
        ));
    }
    if frames.is_empty() {
        return Err(not_found(dir, "no frames"));
    }

    let paths: Vec<&Path> = frames
        .iter()
        .map(|(f, _)| f.image.as_deref().expect("present"))
        .collect();
    let sizes = paths
        .iter()
        .map(|p| header_size(p))
        .collect::<Result<Vec<_>>>()?;
    let images = decode_all(dir, &paths, &sizes, downscale)?;

    let (rw, rh) = (images[0].width, images[0].height);
    let first = frames[0].0.image.clone().expect("present");
    if rw < downscale || rh < downscale {
        return Err(Error::InvalidValue {
            path: first,
            what: format!("downscale {downscale} leaves no pixels of a {rw}×{rh} image"),
        });
    }
    let mut train = Vec::new();
    let mut test = Vec::new();
    for ((frame, is_test), img) in frames.into_iter().zip(images) {
        let path = frame.image.as_deref().expect("present");
        if (img.width, img.height) != (rw, rh) {
            return Err(Error::Image {
                path: path.to_path_buf(),
                message: format!(
                    "image is {}×{} but {} is {rw}×{rh}: all images must have the same size",
                    img.width,
                    img.height,
                    first.display()
                ),
            });
        }
        let camera = frame.camera(rw, rh)?.downscaled(downscale);
        debug_assert_eq!(img.rgb.len(), (camera.width * camera.height) as usize);
        let view = View {
            name: frame.file_path.trim_start_matches("./").to_string(),
            width: camera.width,
            height: camera.height,
            camera,
            rgb: img.rgb,
        };
        if is_test {
            test.push(view);
        } else {
            train.push(view);
        }
    }
    Ok(Dataset {
        train,
        test,
        name,
        white_background: synthetic.is_file(),
        warnings,
        points: None,
    })
}

/// One photo of a NeRF-synthetic or instant-ngp folder, for the COLMAP converter: its
/// path relative to the folder (with its extension), its file, its full-size camera and
/// whether [`load`] makes it a test view by default.
pub(super) struct SourceFrame {
    pub name: String,
    pub image: PathBuf,
    pub camera: Camera,
    pub test: bool,
}

/// The photos of a NeRF-synthetic (train, then test) or instant-ngp folder (those
/// present, in file order), read as [`load`] reads them but not decoded; and whether the
/// folder is NeRF-synthetic.
pub(super) fn source_frames(dir: &Path) -> Result<(Vec<SourceFrame>, bool)> {
    let synthetic = dir.join("transforms_train.json");
    let mut frames = Vec::new();
    if synthetic.is_file() {
        for json in [synthetic.clone(), dir.join("transforms_test.json")] {
            if json == synthetic || json.is_file() {
                let f = parse_transforms(&json)?;
                require_images(&json, &f)?;
                frames.extend(f.into_iter().map(|f| (f, json != synthetic)));
            }
        }
    } else {
        let ngp = dir.join("transforms.json");
        if !ngp.is_file() {
            return Err(not_found(
                dir,
                "no transforms_train.json (NeRF-synthetic) or transforms.json (instant-ngp) here",
            ));
        }
        frames.extend(
            parse_transforms(&ngp)?
                .into_iter()
                .filter(|f| f.image.is_some())
                .enumerate()
                .map(|(i, f)| (f, i.is_multiple_of(HOLDOUT))),
        );
    }
    let out = frames
        .iter()
        .map(|(f, test)| {
            let image = f.image.clone().expect("present");
            let (w, h) = header_size(&image)?;
            let name = image
                .strip_prefix(dir)
                .unwrap_or(&image)
                .to_string_lossy()
                .replace('\\', "/");
            let name = name.trim_start_matches("./").to_string();
            Ok(SourceFrame {
                name,
                camera: f.camera(w, h)?,
                image,
                test: *test,
            })
        })
        .collect::<Result<Vec<_>>>()?;
    Ok((out, synthetic.is_file()))
}

/// Decodes `paths` (whose header sizes are `sizes`) downscaled by `k`, in parallel,
/// after checking that all of them together stay within [`MAX_DATASET_PIXELS`]; the
/// first failure in order is reported.
pub(super) fn decode_all(
    dir: &Path,
    paths: &[&Path],
    sizes: &[(u32, u32)],
    k: u32,
) -> Result<Vec<Decoded>> {
    let total: u64 = sizes
        .iter()
        .map(|&(w, h)| (w / k) as u64 * (h / k) as u64)
        .sum();
    if total > MAX_DATASET_PIXELS {
        return Err(Error::InvalidValue {
            path: dir.to_path_buf(),
            what: format!(
                "the {} images hold {total} pixels at downscale {k}, more than the \
                 limit of {MAX_DATASET_PIXELS}: give a larger --downscale",
                paths.len()
            ),
        });
    }
    let images: Vec<Result<Decoded>> = paths.par_iter().map(|p| decode(p, k)).collect();
    images.into_iter().collect()
}

pub(super) fn not_found(path: &Path, message: &str) -> Error {
    Error::io(
        path,
        std::io::Error::new(std::io::ErrorKind::NotFound, message.to_string()),
    )
}

/// Intrinsics as given at one level (top or frame) of a transforms file.
#[derive(Clone, Copy, Debug, Default)]
struct Intrinsics {
    fl_x: Option<f64>,
    fl_y: Option<f64>,
    angle_x: Option<f64>,
    angle_y: Option<f64>,
    cx: Option<f64>,
    cy: Option<f64>,
    w: Option<f64>,
    h: Option<f64>,
    k1: Option<f64>,
    k2: Option<f64>,
    p1: Option<f64>,
    p2: Option<f64>,
}

/// One frame of a transforms file, parsed and checked, image not yet read.
#[derive(Clone, Debug)]
struct Frame {
    /// The transforms file (for errors).
    json: PathBuf,
    /// Position in its `frames` array.
    index: usize,
    file_path: String,
    /// The image file, when it exists.
    image: Option<PathBuf>,
    /// Where the image was looked for (for errors).
    tried: PathBuf,
    c2w: Affine3A,
    top: Intrinsics,
    own: Intrinsics,
}

impl Frame {
    fn err(&self, what: impl std::fmt::Display) -> Error {
        Error::InvalidValue {
            path: self.json.clone(),
            what: format!("frame {} ({}): {what}", self.index, self.file_path),
        }
    }

    /// The camera for an image of `iw × ih` pixels (before downscaling).
    fn camera(&self, iw: u32, ih: u32) -> Result<Camera> {
        let (own, top) = (&self.own, &self.top);
        for (key, given, actual) in [("w", own.w.or(top.w), iw), ("h", own.h.or(top.h), ih)] {
            if let Some(g) = given.filter(|&g| g != actual as f64) {
                return Err(Error::Image {
                    path: self.image.clone().unwrap_or_default(),
                    message: format!(
                        "image is {iw}×{ih} but {} gives {key} = {g}",
                        self.json.display()
                    ),
                });
            }
        }
        let (lo, hi) = fov_range();
        let angle = |a: Option<f64>, key: &str, size: u32| -> Result<Option<f64>> {
            match a {
                None => Ok(None),
                Some(a) if a >= lo && a <= hi => {
                    Ok(Some(focal_from_fov(size as f32, a as f32) as f64))
                }
                Some(a) => Err(self.err(format!(
                    "{key} = {a:?} must be between {lo:.1e} and {hi:.4} radians"
                ))),
            }
        };
        let focal = |f: Option<f64>, key: &str, size: u32, what: &str| -> Result<Option<f64>> {
            match f {
                Some(f) if !(MIN_FOCAL_RATIO * size as f64..=MAX_FOCAL_RATIO * size as f64)
                    .contains(&f) =>
                {
                    Err(self.err(format!(
                        "{key} = {f:?} px must be between {} and {} px \
                         ({MIN_FOCAL_RATIO:e} to {MAX_FOCAL_RATIO:e} times the image {what}, {size} px)",
                        MIN_FOCAL_RATIO * size as f64,
                        MAX_FOCAL_RATIO * size as f64
                    )))
                }
                f => Ok(f),
            }
        };
        let fx = match focal(own.fl_x, "fl_x", iw, "width")? {
            Some(f) => Some(f),
            None => match angle(own.angle_x, "camera_angle_x", iw)? {
                Some(f) => Some(f),
                None => match focal(top.fl_x, "fl_x", iw, "width")? {
                    Some(f) => Some(f),
                    None => angle(top.angle_x, "camera_angle_x", iw)?,
                },
            },
        };
        let fy = match focal(own.fl_y, "fl_y", ih, "height")? {
            Some(f) => Some(f),
            None => match angle(own.angle_y, "camera_angle_y", ih)? {
                Some(f) => Some(f),
                None => match focal(top.fl_y, "fl_y", ih, "height")? {
                    Some(f) => Some(f),
                    None => angle(top.angle_y, "camera_angle_y", ih)?,
                },
            },
        };
        let (fx, fy) = match (fx, fy) {
            (Some(x), Some(y)) => (x, y),
            (Some(x), None) => (x, x),
            (None, Some(y)) => (y, y),
            (None, None) => {
                return Err(self.err("no focal length: give fl_x (and fl_y) or camera_angle_x"));
            }
        };
        let get = |a: Option<f64>, b: Option<f64>, default: f64| a.or(b).unwrap_or(default);
        let cam = Camera {
            width: iw,
            height: ih,
            fx: fx as f32,
            fy: fy as f32,
            cx: get(own.cx, top.cx, iw as f64 / 2.0) as f32,
            cy: get(own.cy, top.cy, ih as f64 / 2.0) as f32,
            k1: get(own.k1, top.k1, 0.0) as f32,
            k2: get(own.k2, top.k2, 0.0) as f32,
            p1: get(own.p1, top.p1, 0.0) as f32,
            p2: get(own.p2, top.p2, 0.0) as f32,
            c2w: self.c2w,
        };
        cam.validate().map_err(|e| self.err(e))?;
        Ok(cam)
    }
}

/// Errors unless every frame's image exists (NeRF-synthetic).
fn require_images(json: &Path, frames: &[Frame]) -> Result<()> {
    if let Some(f) = frames.iter().find(|f| f.image.is_none()) {
        return Err(not_found(
            &f.tried,
            &format!(
                "image of frame {} ({}) in {} does not exist",
                f.index,
                f.file_path,
                json.display()
            ),
        ));
    }
    Ok(())
}

/// Reads and checks a transforms file (both formats), resolving image paths.
fn parse_transforms(path: &Path) -> Result<Vec<Frame>> {
    let bytes = read_bounded(path)?;
    let bad = |what: String| Error::InvalidValue {
        path: path.to_path_buf(),
        what,
    };
    let root: Value = serde_json::from_slice(&bytes).map_err(|e| {
        bad(format!(
            "malformed JSON: {e}{}",
            non_json_number(&bytes, &e)
        ))
    })?;
    let top = root
        .as_object()
        .ok_or_else(|| bad("the top level must be a JSON object".into()))?;
    check_supported(path, top, "")?;
    let top_intr = intrinsics(top).map_err(bad)?;
    let frames = match top.get("frames") {
        None => return Err(bad("no \"frames\" array".into())),
        Some(Value::Array(a)) => a,
        Some(_) => return Err(bad("\"frames\" must be an array".into())),
    };
    if frames.is_empty() {
        return Err(bad("\"frames\" is empty".into()));
    }
    if frames.len() > MAX_FRAMES {
        return Err(bad(format!(
            "{} frames, more than the limit of {MAX_FRAMES}",
            frames.len()
        )));
    }
    let base = path.parent().unwrap_or(Path::new("."));
    let base = if base.as_os_str().is_empty() {
        Path::new(".")
    } else {
        base
    };
    let canonical_base = base.canonicalize().map_err(|e| Error::io(base, e))?;
    let mut out = Vec::with_capacity(frames.len());
    for (index, fv) in frames.iter().enumerate() {
        let fobj = fv
            .as_object()
            .ok_or_else(|| bad(format!("frame {index}: must be a JSON object")))?;
        let file_path = match fobj.get("file_path") {
            Some(Value::String(s)) => s.clone(),
            Some(_) => return Err(bad(format!("frame {index}: file_path must be a string"))),
            None => return Err(bad(format!("frame {index}: no file_path"))),
        };
        let at = |what: String| bad(format!("frame {index} ({file_path}): {what}"));
        check_supported(path, fobj, &format!("frame {index} ({file_path}): "))?;
        let own = intrinsics(fobj).map_err(at)?;
        let rows = matrix_rows(fobj.get("transform_matrix")).map_err(|w| at(w.into()))?;
        let c2w = pose_from_rows(&rows).map_err(|e| at(e.to_string()))?;
        if escapes(&file_path) {
            return Err(at(
                "file_path leads outside the dataset folder (paths must be relative and stay inside it)"
                    .into(),
            ));
        }
        let tried = base.join(file_path.trim_start_matches("./"));
        let image = if tried.is_file() {
            Some(tried.clone())
        } else {
            let mut png = tried.clone().into_os_string();
            png.push(".png");
            let png = PathBuf::from(png);
            png.is_file().then_some(png)
        };
        if let Some(img) = &image {
            // Symbolic links may not lead out either.
            let real = img.canonicalize().map_err(|e| Error::io(img, e))?;
            if !real.starts_with(&canonical_base) {
                return Err(at(format!(
                    "file_path resolves to {}, outside the dataset folder",
                    real.display()
                )));
            }
        }
        out.push(Frame {
            json: path.to_path_buf(),
            index,
            file_path,
            image,
            tried,
            c2w,
            top: top_intr,
            own,
        });
    }
    Ok(out)
}

/// A note when a JSON syntax error sits on `NaN` or `Infinity` (which Python's `json`
/// module writes for non-finite floats, but JSON has no such numbers); empty otherwise.
fn non_json_number(bytes: &[u8], e: &serde_json::Error) -> &'static str {
    let Some(line) = bytes.split(|&b| b == b'\n').nth(e.line().saturating_sub(1)) else {
        return "";
    };
    let at = e.column().saturating_sub(1).min(line.len());
    let rest = line[at..].strip_prefix(b"-").unwrap_or(&line[at..]);
    if rest.starts_with(b"NaN") || rest.starts_with(b"Infinity") {
        " (NaN and Infinity are not JSON numbers: every value must be finite)"
    } else {
        ""
    }
}

/// Whether a `file_path` is absolute or climbs above its folder with `..`.
pub(super) fn escapes(file_path: &str) -> bool {
    use std::path::Component;
    let mut depth = 0i64;
    for c in Path::new(file_path).components() {
        match c {
            Component::Prefix(_) | Component::RootDir => return true,
            Component::ParentDir => {
                depth -= 1;
                if depth < 0 {
                    return true;
                }
            }
            Component::Normal(_) => depth += 1,
            Component::CurDir => {}
        }
    }
    false
}

/// Reads a whole regular file of at most [`MAX_FILE_BYTES`] bytes; never more than that
/// (a device or a growing file cannot make it read forever).
fn read_bounded(path: &Path) -> Result<Vec<u8>> {
    use std::io::Read;
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let too_big = |n: String| Error::InvalidValue {
        path: path.to_path_buf(),
        what: format!("{n} bytes, more than the limit of {MAX_FILE_BYTES}"),
    };
    let meta = file.metadata().map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(Error::InvalidValue {
            path: path.to_path_buf(),
            what: "not a regular file".into(),
        });
    }
    if meta.len() > MAX_FILE_BYTES {
        return Err(too_big(meta.len().to_string()));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(MAX_FILE_BYTES + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| Error::io(path, e))?;
    if bytes.len() as u64 > MAX_FILE_BYTES {
        return Err(too_big("over".into()));
    }
    Ok(bytes)
}

/// An image's size from its header, checked against the limits, before decoding.
pub(super) fn header_size(path: &Path) -> Result<(u32, u32)> {
    let bad = |message: String| Error::Image {
        path: path.to_path_buf(),
        message,
    };
    let (w, h) = image::ImageReader::open(path)
        .map_err(|e| Error::io(path, e))?
        .with_guessed_format()
        .map_err(|e| Error::io(path, e))?
        .into_dimensions()
        .map_err(|e| bad(format!("not a readable PNG or JPEG image: {e}")))?;
    if w > MAX_SIDE || h > MAX_SIDE || w as u64 * h as u64 > MAX_IMAGE_PIXELS {
        return Err(bad(format!(
            "image is {w}×{h}, over the limit of {MAX_SIDE} px a side and \
             {MAX_IMAGE_PIXELS} pixels"
        )));
    }
    Ok((w, h))
}

/// `transform_matrix` as 3 or 4 rows of 4 numbers.
fn matrix_rows(v: Option<&Value>) -> std::result::Result<Vec<[f64; 4]>, &'static str> {
    const SHAPE: &str = "transform_matrix must be 4×4 (or 3×4) numbers";
    let rows = match v {
        None => return Err("no transform_matrix"),
        Some(Value::Array(rows)) => rows,
        Some(_) => return Err(SHAPE),
    };
    if rows.len() != 3 && rows.len() != 4 {
        return Err(SHAPE);
    }
    rows.iter()
        .map(|r| {
            let r = r.as_array().filter(|r| r.len() == 4).ok_or(SHAPE)?;
            let mut out = [0.0; 4];
            for (o, x) in out.iter_mut().zip(r) {
                *o = x.as_f64().ok_or(SHAPE)?;
            }
            Ok(out)
        })
        .collect()
}

/// The intrinsics keys of one JSON object.
fn intrinsics(obj: &Map<String, Value>) -> std::result::Result<Intrinsics, String> {
    let num = |key: &str| -> std::result::Result<Option<f64>, String> {
        match obj.get(key) {
            None | Some(Value::Null) => Ok(None),
            Some(v) => v
                .as_f64()
                .filter(|x| x.is_finite())
                .map(Some)
                .ok_or_else(|| format!("{key} must be a number, got {v}")),
        }
    };
    let size = |key: &str| -> std::result::Result<Option<f64>, String> {
        match num(key)? {
            Some(v) if v < 1.0 || v.fract() != 0.0 => Err(format!(
                "{key} = {v} must be a positive whole number of pixels"
            )),
            v => Ok(v),
        }
    };
    Ok(Intrinsics {
        fl_x: num("fl_x")?,
        fl_y: num("fl_y")?,
        angle_x: num("camera_angle_x")?,
        angle_y: num("camera_angle_y")?,
        cx: num("cx")?,
        cy: num("cy")?,
        w: size("w")?,
        h: size("h")?,
        k1: num("k1")?,
        k2: num("k2")?,
        p1: num("p1")?,
        p2: num("p2")?,
    })
}

/// Rejects camera models this loader would silently get wrong.
fn check_supported(path: &Path, obj: &Map<String, Value>, prefix: &str) -> Result<()> {
    let unsupported = |what: String| Error::Unsupported {
        path: path.to_path_buf(),
        what: format!("{prefix}{what}"),
    };
    for key in ["k3", "k4", "k5", "k6", "p3", "p4"] {
        if let Some(v) = obj.get(key).and_then(Value::as_f64).filter(|v| *v != 0.0) {
            return Err(unsupported(format!(
                "{key} = {v} (only OpenCV k1 k2 p1 p2 distortion is supported)"
            )));
        }
    }
    if obj.get("is_fisheye").and_then(Value::as_bool) == Some(true) {
        return Err(unsupported("fisheye cameras".into()));
    }
    if let Some(model) = obj.get("camera_model").and_then(Value::as_str) {
        const OK: [&str; 5] = [
            "OPENCV",
            "PINHOLE",
            "SIMPLE_PINHOLE",
            "SIMPLE_RADIAL",
            "RADIAL",
        ];
        if !OK.contains(&model) {
            return Err(unsupported(format!("camera_model {model}")));
        }
    }
    Ok(())
}

/// A decoded image: its size before downscaling and its downscaled RGB pixels.
pub(super) struct Decoded {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<[f32; 3]>,
    /// Whether the file has an alpha channel (composited over white).
    pub alpha: bool,
}

/// Reads an image, composites alpha over white and averages `k × k` blocks.
pub(super) fn decode(path: &Path, k: u32) -> Result<Decoded> {
    let bytes = read_bounded(path)?;
    let img = image::load_from_memory(&bytes).map_err(|e| Error::Image {
        path: path.to_path_buf(),
        message: format!("not a readable PNG or JPEG image: {e}"),
    })?;
    let (w, h) = (img.width(), img.height());
    let lut: [f32; 256] = std::array::from_fn(|i| i as f32 / 255.0);
    let over_white = |c: f32, a: f32| c * a + (1.0 - a);
    let color = img.color();
    let alpha = color.has_alpha();
    let full: Vec<[f32; 3]> = match img {
        image::DynamicImage::ImageRgb8(b) => b
            .as_raw()
            .chunks_exact(3)
            .map(|p| [lut[p[0] as usize], lut[p[1] as usize], lut[p[2] as usize]])
            .collect(),
        other if color.bytes_per_pixel() == color.channel_count() => other
            .to_rgba8()
            .as_raw()
            .chunks_exact(4)
            .map(|p| {
                let a = lut[p[3] as usize];
                [0, 1, 2].map(|c| over_white(lut[p[c] as usize], a))
            })
            .collect(),
        other => other
            .to_rgba32f()
            .as_raw()
            .chunks_exact(4)
            .map(|p| [0, 1, 2].map(|c| over_white(p[c], p[3])))
            .collect(),
    };
    let rgb = if k == 1 {
        full
    } else {
        box_downscale(&full, w as usize, h as usize, k as usize)
    };
    Ok(Decoded {
        width: w,
        height: h,
        rgb,
        alpha,
    })
}

/// Means of `k × k` blocks; output `(w / k) × (h / k)`, remainder dropped.
fn box_downscale(src: &[[f32; 3]], w: usize, h: usize, k: usize) -> Vec<[f32; 3]> {
    let (ow, oh) = (w / k, h / k);
    let mut out = vec![[0.0f32; 3]; ow * oh];
    let inv = 1.0 / (k * k) as f32;
    for (oy, orow) in out.chunks_mut(ow.max(1)).enumerate().take(oh) {
        for dy in 0..k {
            let srow = &src[(oy * k + dy) * w..][..ow * k];
            for (o, block) in orow.iter_mut().zip(srow.chunks_exact(k)) {
                for p in block {
                    for c in 0..3 {
                        o[c] += p[c];
                    }
                }
            }
        }
        for o in orow.iter_mut() {
            *o = o.map(|v| v * inv);
        }
    }
    out
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use glam::Vec3;
    use serde_json::json;

    /// A fresh empty folder under the system temp folder.
    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("diffsvg-dataset-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// Row-major 4×4 JSON for a pose.
    fn rows(c2w: &Affine3A) -> Value {
        let m = glam::Mat4::from(*c2w);
        json!((0..4).map(|r| m.row(r).to_array()).collect::<Vec<_>>())
    }

    fn pose(i: usize) -> Affine3A {
        let a = i as f32 * 0.7;
        Camera::look_at(
            Vec3::new(4.0 * a.cos(), 4.0 * a.sin(), 1.0),
            Vec3::ZERO,
            Vec3::Z,
            0.8,
            8,
            8,
        )
        .unwrap()
        .c2w
    }

    /// An `w × h` RGBA PNG: left half opaque (r, g, b) from `seed`, right half transparent.
    fn write_png(path: &Path, w: u32, h: u32, seed: u8) {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        image::RgbaImage::from_fn(w, h, |x, y| {
            if x < w / 2 {
                image::Rgba([seed, (x * 20) as u8, (y * 20) as u8, 255])
            } else {
                image::Rgba([0, 0, 0, 0])
            }
        })
        .save(path)
        .unwrap();
    }

    fn write_json(path: &Path, v: &Value) {
        std::fs::write(path, serde_json::to_vec_pretty(v).unwrap()).unwrap();
    }

    /// A NeRF-synthetic folder: 2 train + 1 test views of 8×6.
    fn synthetic(name: &str) -> PathBuf {
        let dir = scratch(name);
        for (split, n) in [("train", 2), ("test", 1)] {
            let frames: Vec<Value> = (0..n)
                .map(|i| {
                    write_png(&dir.join(format!("{split}/r_{i}.png")), 8, 6, 10 * i as u8);
                    json!({"file_path": format!("./{split}/r_{i}"), "rotation": 0.01,
                           "transform_matrix": rows(&pose(i + 3 * (split == "test") as usize))})
                })
                .collect();
            write_json(
                &dir.join(format!("transforms_{split}.json")),
                &json!({"camera_angle_x": 0.6911112070083618, "frames": frames}),
            );
        }
        dir
    }

    fn err(dir: &Path, k: u32) -> String {
        load(dir, k).unwrap_err().to_string()
    }

    #[test]
    fn nerf_synthetic_loads_composites_on_white_and_downscales() {
        let dir = synthetic("synthetic");
        let ds = load(&dir, 1).unwrap();
        assert_eq!((ds.train.len(), ds.test.len()), (2, 1));
        assert!(ds.name.starts_with("diffsvg-dataset-synthetic"));
        assert!(ds.white_background);
        let v = &ds.train[1];
        assert_eq!(v.name, "train/r_1");
        assert_eq!((v.width, v.height), (8, 6));
        assert_eq!(v.rgb.len(), 48);
        // Pixel (1, 2): opaque (10, 20, 40); pixel (6, 0): transparent → white.
        let p = v.rgb[2 * 8 + 1];
        assert_eq!(p, [10.0 / 255.0, 20.0 / 255.0, 40.0 / 255.0]);
        assert_eq!(v.rgb[6], [1.0; 3]);
        let f = 4.0 / (0.5f32 * 0.691_111_2).tan();
        assert!((v.camera.fx - f).abs() < 1e-4 && (v.camera.fy - f).abs() < 1e-4);
        assert_eq!((v.camera.cx, v.camera.cy), (4.0, 3.0));
        assert!(!v.camera.has_distortion());
        assert_eq!(v.camera.c2w, pose(1));
        assert_eq!(ds.test[0].camera.c2w, pose(3));

        let half = load(&dir, 2).unwrap();
        let h = &half.train[1];
        assert_eq!((h.width, h.height, h.rgb.len()), (4, 3, 12));
        assert_eq!(h.camera, v.camera.downscaled(2));
        // Block (0, 1) = pixels x 0..2, y 2..4: mean of the four opaque pixels.
        let want: [f32; 3] = [0, 1, 2].map(|c| {
            [(0, 2), (1, 2), (0, 3), (1, 3)]
                .iter()
                .map(|&(x, y)| v.rgb[y * 8 + x][c])
                .sum::<f32>()
                / 4.0
        });
        for (got, want) in h.rgb[4].iter().zip(want) {
            assert!((got - want).abs() < 1e-6);
        }
        assert_eq!(h.rgb[3], [1.0; 3]);
        // 3× leaves 2×2 (remainder dropped).
        let third = load(&dir, 3).unwrap();
        assert_eq!((third.train[0].width, third.train[0].height), (2, 2));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn instant_ngp_skips_missing_images_and_holds_out_every_8th() {
        let dir = scratch("ngp");
        let mut frames = Vec::new();
        for i in 0..11 {
            let file = format!("images/{i:04}.jpg");
            if i != 3 {
                std::fs::create_dir_all(dir.join("images")).unwrap();
                image::RgbImage::from_pixel(10, 6, image::Rgb([200, 100, i as u8 * 10]))
                    .save(dir.join(&file))
                    .unwrap();
            }
            let mut f = json!({"file_path": file, "sharpness": 30.0,
                               "transform_matrix": rows(&pose(i))});
            if i == 5 {
                f["fl_x"] = json!(9.0);
            }
            frames.push(f);
        }
        write_json(
            &dir.join("transforms.json"),
            &json!({"fl_x": 12.0, "fl_y": 11.0, "cx": 4.5, "cy": 3.25, "w": 10.0, "h": 6.0,
                    "k1": 0.05, "k2": -0.08, "p1": -0.001, "p2": 0.0002, "aabb_scale": 4,
                    "frames": frames}),
        );
        let ds = load(&dir, 1).unwrap();
        assert!(!ds.white_background, "real photos fill every pixel");
        // Present: 0 1 2 4 5 6 7 8 9 10 → positions 0 and 8 (files 0 and 9) are test.
        let names = |v: &[View]| v.iter().map(|v| v.name.clone()).collect::<Vec<_>>();
        assert_eq!(names(&ds.test), ["images/0000.jpg", "images/0009.jpg"]);
        assert_eq!(ds.train.len(), 8);
        assert!(!names(&ds.train).contains(&"images/0003.jpg".to_string()));
        let c = ds.train[0].camera;
        assert_eq!((c.fx, c.fy, c.cx, c.cy), (12.0, 11.0, 4.5, 3.25));
        assert_eq!((c.k1, c.k2, c.p1, c.p2), (0.05, -0.08, -0.001, 0.0002));
        let five = ds
            .train
            .iter()
            .find(|v| v.name == "images/0005.jpg")
            .unwrap();
        assert_eq!(five.camera.fx, 9.0);
        // JPEG: close to the written color.
        let p = ds.train[0].rgb[7];
        assert!((p[0] - 200.0 / 255.0).abs() < 0.03 && (p[1] - 100.0 / 255.0).abs() < 0.03);
        // w/h that disagree with the images are an error naming both.
        let mut j: Value =
            serde_json::from_slice(&std::fs::read(dir.join("transforms.json")).unwrap()).unwrap();
        j["w"] = json!(20);
        write_json(&dir.join("transforms.json"), &j);
        let e = err(&dir, 1);
        assert!(e.contains("10×6") && e.contains("w = 20"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn nerfstudio_transforms_load_as_instant_ngp() {
        let dir = scratch("nerfstudio");
        let frames: Vec<Value> = (0..3)
            .map(|i| {
                write_png(&dir.join(format!("images/frame_{i:05}.png")), 8, 6, 5);
                json!({"file_path": format!("images/frame_{i:05}.png"), "fl_x": 9.0 + i as f64,
                       "fl_y": 9.5, "cx": 4.0, "cy": 3.0, "w": 8, "h": 6, "k1": 0.01,
                       "k2": 0.0, "p1": 0.0, "p2": 0.0, "colmap_im_id": i + 1,
                       "transform_matrix": rows(&pose(i))})
            })
            .collect();
        write_json(
            &dir.join("transforms.json"),
            &json!({"camera_model": "OPENCV", "ply_file_path": "sparse_pc.ply",
                    "applied_transform": [[0, 1, 0, 0], [1, 0, 0, 0], [0, 0, -1, 0]],
                    "frames": frames}),
        );
        let ds = load_with(
            &dir,
            &Loading {
                test_every: Some(2),
                ..Loading::default()
            },
        )
        .unwrap();
        assert_eq!((ds.train.len(), ds.test.len()), (1, 2));
        assert_eq!(ds.train[0].camera.fx, 10.0);
        assert_eq!(ds.train[0].camera.k1, 0.01);
        assert_eq!(ds.train[0].camera.c2w, pose(1));
        // A test list names frames by file_path (a leading ./ ignored).
        let list = dir.join("held.txt");
        std::fs::write(&list, "./images/frame_00001.png\n").unwrap();
        let listed = Loading {
            test_list: Some(list.clone()),
            ..Loading::default()
        };
        let ds = load_with(&dir, &listed).unwrap();
        let names = |v: &[View]| v.iter().map(|v| v.name.clone()).collect::<Vec<_>>();
        assert_eq!(names(&ds.test), ["images/frame_00001.png"]);
        assert_eq!(
            names(&ds.train),
            ["images/frame_00000.png", "images/frame_00002.png"]
        );
        std::fs::write(&list, "images/frame_00003.png\n").unwrap();
        let e = load_with(&dir, &listed).unwrap_err().to_string();
        assert!(
            e.contains("held.txt") && e.contains("line 1") && e.contains("frame_00003"),
            "{e}"
        );
        // Fisheye is refused in one line; NeRF-synthetic refuses test_every.
        let mut j: Value =
            serde_json::from_slice(&std::fs::read(dir.join("transforms.json")).unwrap()).unwrap();
        j["camera_model"] = json!("OPENCV_FISHEYE");
        write_json(&dir.join("transforms.json"), &j);
        assert!(err(&dir, 1).contains("camera_model OPENCV_FISHEYE"));
        std::fs::remove_dir_all(&dir).unwrap();
        let dir = synthetic("synthetic-test-every");
        let e = load_with(
            &dir,
            &Loading {
                test_every: Some(4),
                ..Loading::default()
            },
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("test_every") && e.contains("transforms_test.json"),
            "{e}"
        );
        let e = load_with(&dir, &listed).unwrap_err().to_string();
        assert!(
            e.contains("test_list") && e.contains("transforms_test.json"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bad_inputs_give_errors_naming_the_file_and_problem() {
        // Missing folder.
        let e = err(Path::new("/nonexistent/diffsvg-scene"), 1);
        assert!(
            e.contains("diffsvg-scene") && e.contains("does not exist"),
            "{e}"
        );

        // Folder without transforms.
        let dir = scratch("bad");
        let e = err(&dir, 1);
        assert!(e.contains("transforms.json"), "{e}");

        // Malformed JSON.
        std::fs::write(dir.join("transforms.json"), "{\"frames\": [").unwrap();
        let e = err(&dir, 1);
        assert!(
            e.contains("transforms.json") && e.contains("malformed JSON"),
            "{e}"
        );
        write_json(&dir.join("transforms.json"), &json!({"fl_x": 10}));
        assert!(err(&dir, 1).contains("no \"frames\""));

        // A 3×3 transform_matrix.
        std::fs::create_dir_all(dir.join("images")).unwrap();
        for i in 0..2 {
            write_png(&dir.join(format!("images/{i}.png")), 4, 4, 0);
        }
        let good = rows(&pose(0));
        let frames = json!([
            {"file_path": "images/0.png", "transform_matrix": good},
            {"file_path": "images/1.png", "transform_matrix": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]},
        ]);
        write_json(
            &dir.join("transforms.json"),
            &json!({"fl_x": 10, "frames": frames}),
        );
        let e = err(&dir, 1);
        assert!(
            e.contains("transforms.json")
                && e.contains("frame 1 (images/1.png)")
                && e.contains("4×4"),
            "{e}"
        );

        // A degenerate (scaled) pose.
        let scaled = json!([[2, 0, 0, 0], [0, 2, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]]);
        let frames = json!([
            {"file_path": "images/0.png", "transform_matrix": good},
            {"file_path": "images/1.png", "transform_matrix": scaled},
        ]);
        write_json(
            &dir.join("transforms.json"),
            &json!({"fl_x": 10, "frames": frames}),
        );
        let e = err(&dir, 1);
        assert!(
            e.contains("frame 1 (images/1.png)") && e.contains("degenerate pose"),
            "{e}"
        );

        // No focal length.
        let frames = json!([{"file_path": "images/0.png", "transform_matrix": good}]);
        write_json(&dir.join("transforms.json"), &json!({"frames": frames}));
        assert!(err(&dir, 1).contains("no focal length"));

        // No frame has its image.
        let frames = json!([{"file_path": "images/9.png", "transform_matrix": good}]);
        write_json(
            &dir.join("transforms.json"),
            &json!({"fl_x": 10, "frames": frames}),
        );
        let e = err(&dir, 1);
        assert!(
            e.contains("none of the 1 frames") && e.contains("9.png"),
            "{e}"
        );

        // Mixed sizes.
        write_png(&dir.join("images/1.png"), 6, 4, 0);
        let frames = json!([
            {"file_path": "images/0.png", "transform_matrix": good},
            {"file_path": "images/1.png", "transform_matrix": good},
        ]);
        write_json(
            &dir.join("transforms.json"),
            &json!({"fl_x": 10, "frames": frames}),
        );
        let e = err(&dir, 1);
        assert!(
            e.contains("1.png") && e.contains("6×4") && e.contains("4×4") && e.contains("0.png"),
            "{e}"
        );

        // Unreadable image.
        std::fs::write(dir.join("images/1.png"), b"not a png").unwrap();
        let e = err(&dir, 1);
        assert!(e.contains("1.png") && e.contains("not a readable"), "{e}");

        // Downscale 0, or larger than the images.
        assert!(err(&dir, 0).contains("downscale"));
        write_png(&dir.join("images/1.png"), 4, 4, 0);
        assert!(load(&dir, 4).is_ok());
        assert!(err(&dir, 5).contains("leaves no pixels"));

        // Unsupported camera model.
        write_json(
            &dir.join("transforms.json"),
            &json!({"fl_x": 10, "k3": 0.1, "frames": frames}),
        );
        assert!(err(&dir, 1).contains("k3"));
        std::fs::remove_dir_all(&dir).unwrap();

        // NeRF-synthetic: a missing image is an error, not a skip.
        let dir = synthetic("synthetic-missing");
        std::fs::remove_file(dir.join("test/r_0.png")).unwrap();
        let e = err(&dir, 1);
        assert!(
            e.contains("test/r_0") && e.contains("transforms_test.json"),
            "{e}"
        );
        // A malformed test split is reported with its file.
        std::fs::write(dir.join("transforms_test.json"), "[]").unwrap();
        let e = err(&dir, 1);
        assert!(
            e.contains("transforms_test.json") && e.contains("object"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Prints why a test is skipped, or panics when `DIFFSVG_REQUIRE_DATA=1` (CI has the
    /// data, so a skip there would hide a missing check).
    fn skip(test: &str, reason: &str) {
        if std::env::var_os("DIFFSVG_REQUIRE_DATA").is_some_and(|v| v == "1") {
            panic!("{test}: {reason}, and DIFFSVG_REQUIRE_DATA=1 forbids skipping");
        }
        println!("SKIPPED {test}: {reason} (set DIFFSVG_DATA)");
    }

    /// `scenes/` under `$DIFFSVG_DATA`, or under `../shared/data` beside the checkout, when
    /// present (see [`skip`]).
    pub(crate) fn scenes(test: &str) -> Option<PathBuf> {
        let data = std::env::var_os("DIFFSVG_DATA")
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
        let dir = data.join("scenes");
        if dir.is_dir() {
            Some(dir)
        } else {
            skip(test, &format!("{} not found", dir.display()));
            None
        }
    }

    #[test]
    fn real_lego_and_fox_load_when_present() {
        let Some(scenes) = scenes("real_lego_and_fox_load_when_present") else {
            return;
        };
        let lego = scenes.join("nerf_synthetic_lego_400");
        if lego.is_dir() {
            let t = std::time::Instant::now();
            let ds = load(&lego, 2).unwrap();
            println!("lego --downscale 2: {:.2} s", t.elapsed().as_secs_f64());
            assert_eq!((ds.train.len(), ds.test.len()), (100, 25));
            assert_eq!(ds.name, "nerf_synthetic_lego_400");
            let v = &ds.train[0];
            assert_eq!(v.name, "train/r_0");
            assert_eq!((v.width, v.height), (200, 200));
            let f = 100.0 / (0.5f32 * 0.6911112).tan();
            assert!((v.camera.fx - f).abs() < 1e-2);
            // Corners are background (white); cameras look at the object at the origin.
            assert!(v.rgb[0].iter().all(|&c| c > 0.99));
            for v in ds.train.iter().chain(&ds.test) {
                let r = v.camera.ray(100.0, 100.0);
                let t = -r.origin.dot(r.dir);
                assert!(r.at(t).length() < 0.5, "{}: misses the origin", v.name);
            }
        } else {
            skip("lego", &format!("{} not found", lego.display()));
        }
        let fox = scenes.join("fox");
        if fox.is_dir() {
            let t = std::time::Instant::now();
            let ds = load(&fox, 4).unwrap();
            println!("fox --downscale 4: {:.2} s", t.elapsed().as_secs_f64());
            assert_eq!(ds.train.len() + ds.test.len(), 50);
            assert_eq!(ds.test.len(), 7);
            let c = ds.train[0].camera;
            assert_eq!((c.width, c.height), (270, 480));
            assert!((c.fx - 1375.52 / 4.0).abs() < 1e-3);
            assert!((c.cx - 554.558 / 4.0).abs() < 1e-3);
            assert!(c.has_distortion());
        } else {
            skip("fox", &format!("{} not found", fox.display()));
        }
    }
}
