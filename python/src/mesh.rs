//! `diffsvg.Mesh` and `diffsvg.Camera`: triangle meshes rendered with the exact visible
//! area of every triangle in every pixel, and the exact gradient of that image
//! (`diffsvg::mesh`), with cameras from the volume module.
//!
//! Conventions are the library's (`docs/mesh.md`): world units; cameras with OpenGL axes
//! (+X right, +Y up, looking down −Z), camera-to-world poses, pixel `(x, y)` covering
//! `[x, x+1] × [y, y+1]` with y down; triangles counter-clockwise from the front; vertex
//! colors and texels straight RGB in `[0, 1]`; images premultiplied RGBA `float32`.

use std::path::PathBuf;

use diffsvg::Image;
use diffsvg::mesh::fit::{FitOptions, Snapshot, Step, fit, orbit_cameras};
use diffsvg::mesh::refine::{Displacement, refine};
use diffsvg::mesh::simplify::{reproject_texture, simplify};
use diffsvg::mesh::{
    DirLight, Lighting, Mesh, RenderOptions, Texture, View, icosphere, read_mesh, write_mesh,
};
use diffsvg::volume::camera::Camera;
use glam::{Affine3A, Mat3A, Vec3, Vec3A};
use numpy::ndarray::{Array2, Array3};
use numpy::{
    IntoPyArray, PyArray2, PyArray3, PyReadonlyArray2, PyReadonlyArray3, PyReadonlyArrayDyn,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::array::{image_in, image_out};
use crate::error::{bad, to_py};
use crate::jobs::Progress;
use diffsvg::fit::Control;

/// A pinhole camera without distortion: `width × height` pixels, focal lengths and
/// principal point in pixels, a camera-to-world pose (OpenGL axes).
#[pyclass(name = "Camera", module = "diffsvg._native")]
#[derive(Clone)]
pub(crate) struct PyCamera {
    pub(crate) inner: Camera,
}

#[pymethods]
impl PyCamera {
    /// A camera at `eye` looking at `target`, `up` pointing up in the image as far as
    /// possible; horizontal field of view `fov_x` in radians, centered principal point.
    #[staticmethod]
    #[pyo3(signature = (eye, target, width, height, up=(0.0, 1.0, 0.0), fov_x=0.6981317))]
    fn look_at(
        eye: (f32, f32, f32),
        target: (f32, f32, f32),
        width: u32,
        height: u32,
        up: (f32, f32, f32),
        fov_x: f32,
    ) -> PyResult<Self> {
        let v = |t: (f32, f32, f32)| Vec3::new(t.0, t.1, t.2);
        let inner = Camera::look_at(v(eye), v(target), v(up), fov_x, width, height)
            .map_err(|e| bad(format!("Camera.look_at: {e}")))?;
        Ok(PyCamera { inner })
    }

    /// A camera from intrinsics (pixels) and a camera-to-world matrix `c2w` of shape
    /// `(3, 4)` or `(4, 4)` (rotation columns: the camera's +X, +Y, +Z in world axes).
    #[new]
    fn new(
        width: u32,
        height: u32,
        fx: f32,
        fy: f32,
        cx: f32,
        cy: f32,
        c2w: PyReadonlyArray2<'_, f64>,
    ) -> PyResult<Self> {
        let s = c2w.shape();
        if !(s == [3, 4] || s == [4, 4]) {
            return Err(bad(format!(
                "Camera: c2w must have shape (3, 4) or (4, 4), got {s:?}"
            )));
        }
        let a = c2w.as_array();
        if a.iter().any(|v| !v.is_finite()) {
            return Err(bad("Camera: c2w holds a value that is not finite"));
        }
        let col = |j: usize| Vec3A::new(a[[0, j]] as f32, a[[1, j]] as f32, a[[2, j]] as f32);
        let pose = Affine3A::from_mat3_translation(
            Mat3A::from_cols(col(0), col(1), col(2)).into(),
            col(3).into(),
        );
        let inner = Camera::new(width, height, fx, fy, cx, cy, pose)
            .map_err(|e| bad(format!("Camera: {e}")))?;
        Ok(PyCamera { inner })
    }

    /// `n` cameras on a circle around `mesh` (20° above its equator, world +Y up, 40°
    /// field of view), `size × size` pixels; `phase` turns the circle by that fraction of
    /// a step (0.5: views between those of phase 0). The cameras `mesh fit` trains on.
    #[staticmethod]
    #[pyo3(signature = (mesh, n, size, phase=0.0))]
    fn orbit(mesh: PyRef<'_, PyMesh>, n: usize, size: u32, phase: f64) -> PyResult<Vec<Self>> {
        Ok(orbit_cameras(&mesh.inner, n, size, phase)
            .map_err(to_py)?
            .into_iter()
            .map(|inner| PyCamera { inner })
            .collect())
    }

    #[getter]
    fn width(&self) -> u32 {
        self.inner.width
    }
    #[getter]
    fn height(&self) -> u32 {
        self.inner.height
    }
    /// `(fx, fy, cx, cy)`, pixels.
    #[getter]
    fn intrinsics(&self) -> (f32, f32, f32, f32) {
        let c = &self.inner;
        (c.fx, c.fy, c.cx, c.cy)
    }
    /// The camera-to-world matrix, `(4, 4)` `float64`.
    #[getter]
    fn c2w<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let m = glam::Mat4::from(self.inner.c2w);
        let rows: Vec<f64> = (0..4)
            .flat_map(|r| (0..4).map(move |c| m.col(c)[r] as f64))
            .collect();
        Array2::from_shape_vec((4, 4), rows)
            .expect("16 values")
            .into_pyarray(py)
    }

    fn __repr__(&self) -> String {
        let c = &self.inner;
        format!(
            "Camera({}x{}, fx={}, fy={}, position={:?})",
            c.width,
            c.height,
            c.fx,
            c.fy,
            c.position().to_array()
        )
    }
}

/// A triangle mesh: vertex positions (world units), triangles (counter-clockwise from the
/// front), optional vertex colors, UVs and texture.
#[pyclass(name = "Mesh", module = "diffsvg._native")]
#[derive(Clone)]
pub(crate) struct PyMesh {
    pub(crate) inner: Mesh,
}

/// `rows × k` values as a `(rows, k)` array.
fn rows_out<'py, const K: usize>(py: Python<'py>, v: &[[f64; K]]) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_vec((v.len(), K), v.iter().flatten().copied().collect())
        .expect("rows of K values")
        .into_pyarray(py)
}

/// A `(n, K)` array of finite values, `n` given; `what` names it.
fn rows_in<const K: usize>(
    a: &PyReadonlyArray2<'_, f64>,
    n: usize,
    what: &str,
) -> PyResult<Vec<[f64; K]>> {
    let s = a.shape();
    if s != [n, K] {
        return Err(bad(format!("{what}: expected shape ({n}, {K}), got {s:?}")));
    }
    let a = a.as_array();
    if let Some(v) = a.iter().find(|v| !v.is_finite()) {
        return Err(bad(format!("{what}: holds {v} (not finite)")));
    }
    Ok(a.rows()
        .into_iter()
        .map(|r| std::array::from_fn(|k| r[k]))
        .collect())
}

/// A light as Python gives it: `((dx, dy, dz), (r, g, b))` (tuples or lists).
type PyLight = ([f64; 3], [f64; 3]);

/// The lighting of `lights` and `ambient` (`None` when both are absent: unlit).
fn lighting(
    lights: Option<Vec<PyLight>>,
    ambient: Option<(f64, f64, f64)>,
) -> PyResult<Option<Lighting>> {
    if lights.is_none() && ambient.is_none() {
        return Ok(None);
    }
    let lights: Vec<DirLight> = lights
        .unwrap_or_default()
        .into_iter()
        .map(|(direction, intensity)| DirLight {
            direction,
            intensity,
        })
        .collect();
    let a = ambient.unwrap_or((0.0, 0.0, 0.0));
    Lighting::new([a.0, a.1, a.2], &lights)
        .map(Some)
        .map_err(|e| bad(e.to_string()))
}

fn options(
    background: Option<(f64, f64, f64)>,
    cull: bool,
    near: f64,
    lighting: Option<Lighting>,
    mipmaps: bool,
) -> PyResult<RenderOptions> {
    if let Some(b) = background {
        let b = [b.0, b.1, b.2];
        if !b.iter().all(|v| (0.0..=1.0).contains(v)) {
            return Err(bad(format!(
                "background: {b:?} is not an RGB color with values in [0, 1]"
            )));
        }
    }
    if !(near > 0.0 && near.is_finite()) {
        return Err(bad(format!("near: {near} must be finite and above 0")));
    }
    Ok(RenderOptions {
        background: background.map(|b| [b.0, b.1, b.2]),
        cull_back_faces: cull,
        near,
        lighting,
        mipmaps,
    })
}

#[pymethods]
impl PyMesh {
    /// Reads an OBJ (with its MTL and texture) or glTF 2.0 (`.gltf`, `.glb`) file.
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        Ok(PyMesh {
            inner: read_mesh(&path).map_err(to_py)?,
        })
    }

    /// An icosphere of `radius` around the origin, `subdivisions` times refined (20·4ⁿ
    /// triangles, at most 7), without colors.
    #[staticmethod]
    #[pyo3(signature = (subdivisions, radius=1.0))]
    fn icosphere(subdivisions: u32, radius: f64) -> PyResult<Self> {
        if subdivisions > 7 || !(radius > 0.0 && radius.is_finite()) {
            return Err(bad(format!(
                "icosphere: subdivisions {subdivisions} must be at most 7 and radius \
                 {radius} finite and above 0"
            )));
        }
        Ok(PyMesh {
            inner: icosphere(subdivisions, radius),
        })
    }

    /// Writes glTF 2.0 (`.glb`, `.gltf`: one file, the texture inside) or else OBJ with
    /// its MTL (and the texture as PNG beside it, when it has one).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let m = &self.inner;
        py.detach(|| write_mesh(m, &path)).map_err(to_py)
    }

    /// Vertex positions, `(n, 3)` `float64` (a copy; assign to change them).
    #[getter]
    fn positions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        rows_out(py, &self.inner.positions)
    }
    #[setter]
    fn set_positions(&mut self, a: PyReadonlyArray2<'_, f64>) -> PyResult<()> {
        self.inner.positions = rows_in(&a, self.inner.positions.len(), "positions")?;
        Ok(())
    }

    /// Triangles as vertex indices, `(m, 3)` `uint32`.
    #[getter]
    fn triangles<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<u32>> {
        let t = &self.inner.triangles;
        Array2::from_shape_vec((t.len(), 3), t.iter().flatten().copied().collect())
            .expect("rows of 3")
            .into_pyarray(py)
    }

    /// Vertex colors, `(n, 3)` straight RGB in `[0, 1]`, or `None`.
    #[getter]
    fn colors<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        self.inner.colors.as_ref().map(|c| rows_out(py, c))
    }
    #[setter]
    fn set_colors(&mut self, a: Option<PyReadonlyArray2<'_, f64>>) -> PyResult<()> {
        self.inner.colors = match a {
            None => None,
            Some(a) => {
                let c: Vec<[f64; 3]> = rows_in(&a, self.inner.positions.len(), "colors")?;
                if c.iter().flatten().any(|v| !(0.0..=1.0).contains(v)) {
                    return Err(bad("colors: values must lie in [0, 1]"));
                }
                Some(c)
            }
        };
        Ok(())
    }

    /// Texture coordinates per vertex, `(n, 2)` (v up), or `None`.
    #[getter]
    fn uvs<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<f64>>> {
        self.inner.uvs.as_ref().map(|c| rows_out(py, c))
    }
    #[setter]
    fn set_uvs(&mut self, a: Option<PyReadonlyArray2<'_, f64>>) -> PyResult<()> {
        self.inner.uvs = match a {
            None if self.inner.texture.is_some() => {
                return Err(bad("uvs: a textured mesh needs them"));
            }
            None => None,
            Some(a) => Some(rows_in(&a, self.inner.positions.len(), "uvs")?),
        };
        Ok(())
    }

    /// The texture, `(height, width, 3)` straight RGB `float64` (row 0 at the top), or
    /// `None`.
    #[getter]
    fn texture<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray3<f64>>> {
        self.inner.texture.as_ref().map(|t| {
            Array3::from_shape_vec(
                (t.height as usize, t.width as usize, 3),
                t.data.iter().flatten().copied().collect(),
            )
            .expect("width × height texels")
            .into_pyarray(py)
        })
    }
    #[setter]
    fn set_texture(&mut self, a: PyReadonlyArray3<'_, f64>) -> PyResult<()> {
        let Some(t) = &self.inner.texture else {
            return Err(bad(
                "texture: the mesh has none (its size and UVs come from the file)",
            ));
        };
        let s = a.shape();
        if s != [t.height as usize, t.width as usize, 3] {
            return Err(bad(format!(
                "texture: expected shape ({}, {}, 3), got {s:?}",
                t.height, t.width
            )));
        }
        let v: Vec<f64> = a.as_array().iter().copied().collect();
        if v.iter().any(|x| !(0.0..=1.0).contains(x)) {
            return Err(bad("texture: values must lie in [0, 1]"));
        }
        let data = v.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
        self.inner.texture = Some(Texture {
            width: t.width,
            height: t.height,
            data,
        });
        Ok(())
    }

    /// `(lo, hi)`: the corners of the bounding box, world units.
    fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        self.inner.bounds()
    }

    /// The image seen by `camera`: premultiplied RGBA `float32`, `(height, width, 4)`;
    /// uncovered area transparent, or `background` (straight RGB) behind everything.
    /// Unlit unless `lights` (a list of `((dx, dy, dz), (r, g, b))`: world direction
    /// towards the light and RGB intensity, at most 4) or `ambient` (RGB) is given; then
    /// Lambert shading with smooth normals: albedo × (ambient + Σ max(0, n·l)·intensity).
    /// `mipmaps`: a minified texture is read from the mip level of each pixel's footprint
    /// (2×2 box averages) rather than bilinearly from the full texture.
    #[pyo3(signature = (camera, background=None, cull=true, near=1e-3, lights=None, ambient=None,
        mipmaps=false))]
    #[allow(clippy::too_many_arguments)]
    fn render<'py>(
        &self,
        py: Python<'py>,
        camera: PyRef<'py, PyCamera>,
        background: Option<(f64, f64, f64)>,
        cull: bool,
        near: f64,
        lights: Option<Vec<PyLight>>,
        ambient: Option<(f64, f64, f64)>,
        mipmaps: bool,
    ) -> PyResult<Bound<'py, PyArray3<f32>>> {
        let opts = options(background, cull, near, lighting(lights, ambient)?, mipmaps)?;
        let (m, c) = (&self.inner, &camera.inner);
        let img = py
            .detach(|| crate::on_pool(|| View::new(m, c, opts).map(|v| v.render())))
            .map_err(to_py)?;
        Ok(image_out(py, img))
    }

    /// The gradient of a loss with respect to the mesh, given `d_image = ∂loss/∂image`
    /// (`float32`, the shape `render` gives) for the same camera and options: a dict with
    /// `positions` `(n, 3)`, `pose` `(6,)` (a camera pose correction `[ωx, ωy, ωz, vx,
    /// vy, vz]` applied on top of `camera`: rotation about its center in world axes,
    /// radians, then translation, world units; at zero), and `colors` `(n, 3)`, `texture`
    /// `(h, w, 3)` and `uvs` `(n, 2)` when the mesh has them; lit, also `ambient` `(3,)`,
    /// `light_directions` and `light_intensities` `(k, 3)`. Exact (the derivative of the
    /// rendered box-filtered image).
    #[pyo3(signature = (camera, d_image, background=None, cull=true, near=1e-3, lights=None,
        ambient=None, mipmaps=false))]
    #[allow(clippy::too_many_arguments)]
    fn render_backward<'py>(
        &self,
        py: Python<'py>,
        camera: PyRef<'py, PyCamera>,
        d_image: PyReadonlyArrayDyn<'py, f32>,
        background: Option<(f64, f64, f64)>,
        cull: bool,
        near: f64,
        lights: Option<Vec<PyLight>>,
        ambient: Option<(f64, f64, f64)>,
        mipmaps: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let opts = options(background, cull, near, lighting(lights, ambient)?, mipmaps)?;
        let d: Image = image_in(&d_image, "d_image")?;
        let c = &camera.inner;
        if (d.width, d.height) != (c.width, c.height) {
            return Err(bad(format!(
                "d_image: {}x{} (width x height) but the camera is {}x{}",
                d.width, d.height, c.width, c.height
            )));
        }
        let m = &self.inner;
        let g = py
            .detach(|| crate::on_pool(|| View::new(m, c, opts).and_then(|v| v.backward(&d, true))))
            .map_err(to_py)?;
        let out = PyDict::new(py);
        out.set_item("positions", rows_out(py, &g.positions))?;
        out.set_item("pose", g.pose.to_vec().into_pyarray(py))?;
        if let Some(ug) = &g.uvs {
            out.set_item("uvs", rows_out(py, ug))?;
        }
        if let Some(lg) = &g.lighting {
            out.set_item("ambient", lg.ambient.to_vec().into_pyarray(py))?;
            out.set_item("light_directions", rows_out(py, &lg.directions))?;
            out.set_item("light_intensities", rows_out(py, &lg.intensities))?;
        }
        if let Some(cg) = &g.colors {
            out.set_item("colors", rows_out(py, cg))?;
        }
        if let (Some(tg), Some(t)) = (&g.texture, &m.texture) {
            let a = Array3::from_shape_vec(
                (t.height as usize, t.width as usize, 3),
                tg.iter().flatten().copied().collect(),
            )
            .expect("width × height texels");
            out.set_item("texture", a.into_pyarray(py))?;
        }
        Ok(out)
    }

    /// Fits the positions and colors (vertex colors, or texels when the mesh has a
    /// texture) to `views`, a list of `(camera, target)` with targets premultiplied RGBA
    /// `float32` of each camera's size, in place, as `diffsvg mesh fit` does (Adam,
    /// smoothness `½ w Σ_edges |p_i − p_j|²`, every view rendered each step). `lights`,
    /// `ambient` and `mipmaps` render every view as `render` does (the lights fixed, the
    /// fitted colors albedo; `mipmaps` shares one pyramid between the views of a step).
    /// `progress` gets `{"iter", "mse"}` each step and stops the fit by returning
    /// `False`. Returns the final training mean squared error.
    #[pyo3(signature = (views, iters=200, lr_positions=2e-3, lr_colors=1e-2,
        smoothness=1e-3, background=Some((1.0, 1.0, 1.0)), cull=true, progress=None,
        lights=None, ambient=None, mipmaps=false))]
    #[allow(clippy::too_many_arguments)]
    fn fit(
        &mut self,
        py: Python<'_>,
        views: Vec<(PyRef<'_, PyCamera>, PyReadonlyArrayDyn<'_, f32>)>,
        iters: usize,
        lr_positions: f64,
        lr_colors: f64,
        smoothness: f64,
        background: Option<(f64, f64, f64)>,
        cull: bool,
        progress: Option<Py<PyAny>>,
        lights: Option<Vec<PyLight>>,
        ambient: Option<(f64, f64, f64)>,
        mipmaps: bool,
    ) -> PyResult<f64> {
        let mut vs = Vec::with_capacity(views.len());
        for (k, (c, t)) in views.iter().enumerate() {
            let img = image_in(t, &format!("views[{k}] target"))?;
            let c = c.inner;
            if (img.width, img.height) != (c.width, c.height) {
                return Err(bad(format!(
                    "views[{k}]: the target is {}x{} but the camera {}x{}",
                    img.width, img.height, c.width, c.height
                )));
            }
            vs.push((c, img));
        }
        let opts = FitOptions {
            iters,
            lr_positions,
            lr_colors,
            smoothness,
            render: options(background, cull, 1e-3, lighting(lights, ambient)?, mipmaps)?,
            ..FitOptions::default()
        };
        let mut prog = Progress::new(progress);
        let mut mesh = self.inner.clone();
        let out = py.detach(|| {
            fit(&mut mesh, &vs, &opts, |s: Step, _: &Snapshot| {
                prog.call(|d| {
                    d.set_item("iter", s.iter)?;
                    d.set_item("mse", s.mse)
                }) == Control::Continue
            })
        });
        prog.finish()?;
        let mse = out.map_err(to_py)?.mse;
        self.inner = mesh;
        Ok(mse)
    }

    /// The library function behind `diffsvg mesh refine`: every triangle split in four
    /// `levels` times (UVs and colors interpolated at edge midpoints), then every vertex
    /// moved along its normal by `displace` times the bounding radius times smooth value
    /// noise in `[−1, 1]` (`octaves` octaves, the first `frequency` cycles per bounding
    /// radius, lattice from `seed`); seam copies move together. A new mesh. Counts are
    /// checked before allocating; `levels` at most 8.
    #[pyo3(signature = (levels=4, displace=0.03, frequency=16.0, octaves=3, seed=1))]
    fn refine(
        &self,
        py: Python<'_>,
        levels: u32,
        displace: f64,
        frequency: f64,
        octaves: u32,
        seed: u64,
    ) -> PyResult<Self> {
        if levels > 8 {
            return Err(bad(format!("levels: {levels} must be at most 8")));
        }
        let d = Displacement {
            amplitude: displace,
            frequency,
            octaves,
            seed,
        };
        let m = &self.inner;
        let out = py.detach(|| refine(m, levels, &d)).map_err(to_py)?;
        Ok(PyMesh { inner: out })
    }

    /// The classic simplification behind `diffsvg mesh simplify`: quadric-error edge
    /// collapses (meshoptimizer) to at most `triangles`, surviving vertices keeping their
    /// attributes (UV seams collapse only along themselves). With `reference` (a mesh
    /// with the surface to copy colors from, such as the one simplified) and
    /// `texture_size`, the result gets a `texture_size`² texture reprojected from it in
    /// its own UV chart (needs UVs) and loses its vertex colors, as `mesh simplify`'s
    /// baseline. A new mesh; optimize it further with `fit`.
    #[pyo3(signature = (triangles, reference=None, texture_size=512))]
    fn simplify(
        &self,
        py: Python<'_>,
        triangles: usize,
        reference: Option<PyRef<'_, PyMesh>>,
        texture_size: u32,
    ) -> PyResult<Self> {
        let m = &self.inner;
        let r = reference.as_ref().map(|r| &r.inner);
        let out = py
            .detach(|| -> diffsvg::Result<Mesh> {
                let mut low = simplify(m, triangles)?;
                if let Some(r) = r {
                    low.texture = Some(reproject_texture(&low, r, texture_size)?);
                    low.colors = None;
                }
                Ok(low)
            })
            .map_err(to_py)?;
        Ok(PyMesh { inner: out })
    }

    fn __repr__(&self) -> String {
        let m = &self.inner;
        format!(
            "Mesh({} vertices, {} triangles{}{})",
            m.positions.len(),
            m.triangles.len(),
            if m.colors.is_some() { ", colors" } else { "" },
            m.texture
                .as_ref()
                .map(|t| format!(", texture {}x{}", t.width, t.height))
                .unwrap_or_default()
        )
    }
}
