//! Viewing a trained 3D model: loading it by its file's header (a voxel grid or Gaussians),
//! its bounds, the dataset it is compared with, and new cameras around it (a circle, or
//! for real photos the arc their cameras span). The command line's `view` and Python's
//! `view` both render through this module, so both give the same pixels.
//!
//! Colors are linear `[r, g, b]` per pixel, row-major, as the renderers return them
//! (unclamped); cameras follow [`Camera`]'s conventions (world units, +Y up in the image
//! for the orbit's `up`).

use std::path::Path;

use glam::Vec3;

use super::camera::{Camera, orbit};
use super::dataset::{Dataset, Loading, View};
use super::field::{self, Ngp};
use super::recon::{background, load_for_splat};
use super::splat::{self, Gaussians};
use super::voxel::{self, Grid};
use crate::error::{Error, Result};

/// Which views of a dataset to render.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Split {
    /// The held-out views.
    #[default]
    Test,
    /// The training views.
    Train,
}

impl Split {
    /// The views of `data` this split names.
    pub fn views(self, data: &Dataset) -> &[View] {
        match self {
            Split::Test => &data.test,
            Split::Train => &data.train,
        }
    }
}

impl crate::choice::Choice for Split {
    const WHAT: &'static str = "split";
    const ALL: &'static [Self] = &[Split::Test, Split::Train];
    fn name(self) -> &'static str {
        match self {
            Split::Test => "test",
            Split::Train => "train",
        }
    }
}

crate::choice::from_str_by_name!(Split);

/// A trained model of either kind, with the settings it renders with.
pub enum Model {
    /// A sparse voxel grid (`.vox`).
    Voxel(Grid, voxel::RenderSettings),
    /// 3D Gaussians (`.ply`).
    Splat(Gaussians, splat::RenderSettings),
    /// A neural field: Instant-NGP (`.ngp`) or NeRF (`.nerf`).
    Ngp(Ngp, field::RenderSettings),
}

impl Model {
    /// Reads a model file, choosing the kind by its first bytes (a `ply` line, ending in
    /// `\n` or `\r\n` as the PLY reader accepts, or a gzip stream, an
    /// [SPZ file](splat::spz), for Gaussians; a voxel model otherwise).
    /// `step` is the voxel ray-marching step in cells (ignored for Gaussians).
    pub fn load(path: &Path, step: f32) -> Result<Model> {
        use std::io::Read as _;
        let mut head = Vec::with_capacity(8);
        std::fs::File::open(path)
            .and_then(|f| f.take(8).read_to_end(&mut head))
            .map_err(|e| Error::io(path, e))?;
        if head.starts_with(b"ply\n") || head.starts_with(b"ply\r\n") {
            Ok(Model::Splat(
                splat::load(path)?,
                splat::RenderSettings::default(),
            ))
        } else if head.starts_with(&field::io::MAGIC) || head.starts_with(&field::io::NERF_MAGIC) {
            Ok(Model::Ngp(
                field::load(path)?,
                field::RenderSettings::default(),
            ))
        } else if crate::image_io::is_gzip(&head) {
            Ok(Model::Splat(
                splat::load_spz(path)?,
                splat::RenderSettings::default(),
            ))
        } else {
            let settings =
                voxel::RenderSettings::with_step(step).map_err(|message| Error::Setting {
                    name: "step".into(),
                    message,
                })?;
            Ok(Model::Voxel(voxel::load(path)?, settings))
        }
    }

    /// Loads the dataset the model is compared with, as its trainer saw it (photos with
    /// lens distortion undistorted for Gaussians), and takes its background for Gaussians.
    /// `loading.downscale` (at least 1) divides the photos' sizes and
    /// `loading.test_every` chooses the test views, as in training.
    /// Also returns, for undistorted photos, the fraction of pixels that fell outside them.
    pub fn load_dataset(
        &mut self,
        dir: &Path,
        loading: &Loading,
    ) -> Result<(Dataset, Option<f64>)> {
        check_downscale(loading.downscale)?;
        let (data, outside) = match self {
            Model::Splat(..) => load_for_splat(dir, loading)?,
            Model::Voxel(..) | Model::Ngp(..) => (Dataset::load_with(dir, loading)?, None),
        };
        match self {
            Model::Splat(_, s) => s.background = background(&data),
            Model::Ngp(_, s) => s.background = background(&data),
            Model::Voxel(..) => {}
        }
        Ok((data, outside))
    }

    /// Renders the view of `camera`: `width × height` linear RGB colors, row-major.
    pub fn render(&self, camera: &Camera) -> Result<Vec<[f32; 3]>> {
        match self {
            Model::Voxel(g, s) => Ok(voxel::render_rays(g, &camera.rays(), s)),
            Model::Ngp(m, s) => Ok(field::render_rays(m, &camera.rays(), s)),
            Model::Splat(g, s) => {
                splat::render(g, camera, s)
                    .map(|r| r.rgb)
                    .map_err(|what| Error::InvalidValue {
                        path: "camera".into(),
                        what,
                    })
            }
        }
    }

    /// The depth images of the view of `camera` ([`splat::Depth`]: expected and median
    /// depth along the viewing axis, world units; for voxels,
    /// [`voxel::render_depth`]).
    ///
    /// # Errors
    /// For a neural field (depth images are drawn for Gaussians and voxels), or the
    /// renderer's refusal of the camera.
    pub fn render_depth(&self, camera: &Camera) -> Result<splat::Depth> {
        match self {
            Model::Ngp(..) => Err(Error::Setting {
                name: "depth".into(),
                message: "depth images are drawn for Gaussian and voxel models only".into(),
            }),
            Model::Voxel(g, s) => Ok(voxel::render_depth(g, camera, s)),
            Model::Splat(g, s) => splat::render(g, camera, s)
                .map(|r| r.depth())
                .map_err(|what| Error::InvalidValue {
                    path: "camera".into(),
                    what,
                }),
        }
    }

    /// The center and half-size of the model's box, world units.
    pub fn bounds(&self) -> (Vec3, f32) {
        match self {
            Model::Voxel(g, _) => (
                (g.min() + g.max()) * 0.5,
                (g.max() - g.min()).max_element() * 0.5,
            ),
            Model::Splat(g, _) => splat_bounds(g),
            Model::Ngp(m, _) => (
                (m.min() + m.max()) * 0.5,
                (m.max() - m.min()).max_element() * 0.5,
            ),
        }
    }
}

/// Refuses a `downscale` of 0 (the photos' sizes are divided by it), naming the option.
pub fn check_downscale(downscale: u32) -> Result<()> {
    crate::limits::check_count("downscale", downscale as usize, 1..=usize::MAX)
}

/// The center and half-size of the box of the middle 98% of a Gaussian model's means on
/// each axis (a few far floaters aside); the unit box when there are none.
pub fn splat_bounds(g: &Gaussians) -> (Vec3, f32) {
    if g.is_empty() {
        return (Vec3::ZERO, 1.0);
    }
    let mut lo = Vec3::ZERO;
    let mut hi = Vec3::ZERO;
    for axis in 0..3 {
        let mut v: Vec<f32> = g.means.iter().map(|m| m[axis]).collect();
        v.sort_by(|a, b| a.total_cmp(b));
        lo[axis] = v[v.len() / 100];
        hi[axis] = v[v.len() - 1 - v.len() / 100];
    }
    ((lo + hi) * 0.5, ((hi - lo).max_element() * 0.5).max(1e-3))
}

fn orbit_error(e: impl std::fmt::Display) -> Error {
    Error::Setting {
        name: "orbit".into(),
        message: format!("cameras: {e}"),
    }
}

/// `n` cameras on a circle around the model, level with the dataset's "up" (the mean of
/// its cameras' up vectors, or +Z), at the dataset's camera distance and field of view,
/// raised by `elevation_deg`; for real photos, along the arc their cameras span instead.
/// Without a dataset: 200×200 views at 3 half-sizes from the center, +Z up.
pub fn orbit_cameras(
    (center, half): (Vec3, f32),
    data: Option<&Dataset>,
    n: usize,
    elevation_deg: f32,
) -> Result<Vec<Camera>> {
    let (radius, up, fov, w, h) =
        match data.and_then(|d| d.train.first().or(d.test.first()).map(|v| (d, v))) {
            Some((d, v)) => {
                let views = if d.train.is_empty() {
                    &d.test
                } else {
                    &d.train
                };
                let up: Vec3 = views
                    .iter()
                    .map(|v| v.camera.c2w.matrix3.y_axis.into())
                    .fold(Vec3::ZERO, |a: Vec3, b: Vec3| a + b);
                let (_, dist) = d.focus();
                let up = up.try_normalize().unwrap_or(Vec3::Z);
                let fov = v.camera.fov_x();
                if !d.white_background {
                    return arc_cameras(views, center, dist, up, n, fov, v.width, v.height);
                }
                (dist, up, fov, v.width, v.height)
            }
            None => (3.0 * half, Vec3::Z, 0.69, 200, 200),
        };
    orbit(n, center, radius, elevation_deg.to_radians(), up, fov, w, h).map_err(orbit_error)
}

/// For real photos, which show one side of the scene: `n` cameras looking at `center`
/// along the arc the training cameras span around `up` (the circle less its largest
/// empty gap), at their mean elevation and at distance `radius`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn arc_cameras(
    views: &[View],
    center: Vec3,
    radius: f32,
    up: Vec3,
    n: usize,
    fov: f32,
    w: u32,
    h: u32,
) -> Result<Vec<Camera>> {
    use std::f32::consts::TAU;
    let e1 = up.any_orthonormal_vector();
    let e2 = up.cross(e1);
    let mut az = Vec::new();
    let mut elev = 0.0;
    for v in views {
        let p = (v.camera.position() - center).normalize_or_zero();
        az.push(p.dot(e2).atan2(p.dot(e1)).rem_euclid(TAU));
        elev += p.dot(up).clamp(-1.0, 1.0).asin();
    }
    elev /= views.len().max(1) as f32;
    az.sort_by(|a, b| a.total_cmp(b));
    // The largest gap between neighbouring azimuths (the last one wraps around).
    let (mut start, mut gap) = (az[0], az[0] + TAU - az[az.len() - 1]);
    for pair in az.windows(2) {
        if pair[1] - pair[0] > gap {
            (start, gap) = (pair[1], pair[1] - pair[0]);
        }
    }
    let span = TAU - gap;
    (0..n)
        .map(|i| {
            let t = if n > 1 {
                i as f32 / (n - 1) as f32
            } else {
                0.5
            };
            let a = start + span * t;
            let dir = (e1 * a.cos() + e2 * a.sin()) * elev.cos() + up * elev.sin();
            Camera::look_at(center + dir * radius, center, up, fov, w, h).map_err(orbit_error)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn real_photo_orbits_follow_the_cameras_arc() {
        // Cameras from azimuth 300° through 0° to 60° (wrapping), 20° above the plane.
        let (center, up) = (Vec3::new(1.0, 2.0, 0.5), Vec3::Z);
        let at = |deg: f32, elev: f32| {
            let (a, e) = (deg.to_radians(), elev.to_radians());
            center + 4.0 * Vec3::new(a.cos() * e.cos(), a.sin() * e.cos(), e.sin())
        };
        let views: Vec<View> = [300.0f32, 330.0, 0.0, 20.0, 60.0]
            .iter()
            .map(|&d| View {
                name: format!("{d}"),
                camera: Camera::look_at(at(d, 20.0), center, up, 0.7, 4, 4).unwrap(),
                width: 4,
                height: 4,
                rgb: vec![[1.0; 3]; 16],
            })
            .collect();
        let cams = arc_cameras(&views, center, 4.0, up, 5, 0.7, 4, 4).unwrap();
        assert_eq!(cams.len(), 5);
        for c in &cams {
            let p = c.position() - center;
            assert!((p.length() - 4.0).abs() < 1e-4);
            let elev = (p.z / p.length()).asin().to_degrees();
            assert!((elev - 20.0).abs() < 1e-2, "elevation {elev}");
            // Looking at the center.
            assert!(c.forward().dot(-p.normalize()) > 0.9999);
        }
        // Along the arc, from one end to the other, never behind (azimuth 60°..300°).
        let az: Vec<f32> = cams
            .iter()
            .map(|c| {
                let p = c.position() - center;
                p.y.atan2(p.x).to_degrees().rem_euclid(360.0)
            })
            .collect();
        let ends = [az[0], az[4]];
        assert!(ends.iter().any(|a| (a - 300.0).abs() < 0.1), "{az:?}");
        assert!(ends.iter().any(|a| (a - 60.0).abs() < 0.1), "{az:?}");
        assert!(
            (az[2] - 0.0).abs() < 0.1 || (az[2] - 360.0).abs() < 0.1,
            "{az:?}"
        );
        assert!(az.iter().all(|&a| !(60.5..299.5).contains(&a)), "{az:?}");
    }

    #[test]
    fn split_names_round_trip() {
        crate::choice::tests::round_trip::<Split>();
    }
}
