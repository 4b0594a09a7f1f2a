//! What `diffsvg view` renders: a trained volume model (voxels, Gaussians, a neural field)
//! or a triangle mesh (OBJ, glTF), behind one set of calls. The library keeps the two
//! apart (`volume` does not use `mesh`); the command line joins them here.

use std::path::Path;

use diffsvg::Result;
use diffsvg::mesh::{self, Mesh};
use diffsvg::volume::camera::Camera;
use diffsvg::volume::dataset::{Dataset, Loading};
use diffsvg::volume::splat::Depth;
use diffsvg::volume::view::Model;
use glam::Vec3;

/// A model `view` renders.
pub(crate) enum Viewed {
    /// A volume model, as `volume::view::Model` loads it.
    Volume(Model),
    /// A triangle mesh and how it is rendered (its background is the dataset's), and its
    /// mip levels once a view with `mipmaps` built them (shared by every view).
    Mesh(
        Mesh,
        mesh::RenderOptions,
        std::sync::OnceLock<Option<mesh::MipPyramid>>,
    ),
}

/// Whether `path` names a mesh file (by its extension, as `mesh::read_mesh` reads them).
pub(crate) fn is_mesh(path: &Path) -> bool {
    mesh::MeshFormat::of(path).is_some()
}

impl Viewed {
    /// Reads a mesh (by extension) or a volume model (by its header); `step` is the voxel
    /// renderer's sample spacing.
    pub(crate) fn load(path: &Path, step: f32) -> Result<Viewed> {
        if is_mesh(path) {
            let m = mesh::read_mesh(path)?;
            let opts = mesh::RenderOptions {
                background: Some([1.0; 3]),
                ..mesh::RenderOptions::default()
            };
            Ok(Viewed::Mesh(m, opts, std::sync::OnceLock::new()))
        } else {
            Model::load(path, step).map(Viewed::Volume)
        }
    }

    /// Whether depth images can be drawn (Gaussians and voxels).
    pub(crate) fn has_depth(&self) -> bool {
        matches!(self, Viewed::Volume(Model::Voxel(..) | Model::Splat(..)))
    }

    /// Loads the dataset the model is compared with (see `Model::load_dataset`); a mesh
    /// takes the dataset's background: white for objects on white, else black.
    pub(crate) fn load_dataset(
        &mut self,
        dir: &Path,
        loading: &Loading,
    ) -> Result<(Dataset, Option<f64>)> {
        match self {
            Viewed::Volume(m) => m.load_dataset(dir, loading),
            Viewed::Mesh(_, opts, _) => {
                let data = Dataset::load_with(dir, loading)?;
                opts.background = Some(if data.white_background {
                    [1.0; 3]
                } else {
                    [0.0; 3]
                });
                Ok((data, None))
            }
        }
    }

    /// The view of `camera`: `width × height` RGB colors, row-major.
    pub(crate) fn render(&self, camera: &Camera) -> Result<Vec<[f32; 3]>> {
        match self {
            Viewed::Volume(m) => m.render(camera),
            Viewed::Mesh(m, opts, pyramid) => {
                // Over an opaque background every pixel is opaque: premultiplied RGB is RGB.
                let pyramid = pyramid.get_or_init(|| mesh::MipPyramid::for_mesh(m, opts));
                let img = mesh::View::with_pyramid(m, camera, *opts, pyramid.as_ref())?.render();
                Ok(img.data.iter().map(|p| [p[0], p[1], p[2]]).collect())
            }
        }
    }

    /// Depth images of the view of `camera` (Gaussians and voxels only).
    pub(crate) fn render_depth(&self, camera: &Camera) -> Result<Depth> {
        match self {
            Viewed::Volume(m) => m.render_depth(camera),
            Viewed::Mesh(..) => Err(diffsvg::Error::Setting {
                name: "depth".into(),
                message: "depth images are drawn for Gaussian and voxel models only".into(),
            }),
        }
    }

    /// The center and half-size of the model's box, world units.
    pub(crate) fn bounds(&self) -> (Vec3, f32) {
        match self {
            Viewed::Volume(m) => m.bounds(),
            Viewed::Mesh(m, _, _) => {
                let (lo, hi) = m.bounds();
                let (lo, hi) = (
                    Vec3::from(lo.map(|v| v as f32)),
                    Vec3::from(hi.map(|v| v as f32)),
                );
                ((lo + hi) * 0.5, ((hi - lo).max_element() * 0.5).max(1e-3))
            }
        }
    }
}
