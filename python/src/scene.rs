//! `diffsvg.Scene`: an SVG drawing as the library holds it, with its parameters as numpy.

use std::path::PathBuf;
use std::sync::Mutex;
use std::sync::atomic::AtomicU64;

use diffsvg::scene::params::written_point_gradient;
use diffsvg::scene::project;
use diffsvg::scene::structure::PaintSlots;
use diffsvg::scene::{Fonts, ParamGroup, ParamLayout, Structure};
use diffsvg::{Scene, Sizing};
use numpy::{PyArray1, PyArray2, PyReadonlyArray1};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::array::{vec_out, vector_in};
use crate::error::{bad, to_py};

/// A vector scene: paths with fills and strokes (solid or gradient paints) in groups, in
/// device pixels (y down). Load it with `Scene.load` or `Scene.from_svg`.
#[pyclass(name = "Scene", module = "diffsvg._native")]
pub(crate) struct PyScene {
    pub(crate) inner: Scene,
    /// The copies `render_batch` made for its rows, with the rows: its backward pass on
    /// the same rows takes them instead of copying and projecting again (`diffsvg.jax`
    /// calls the two in turn). Not part of the scene: a copy starts without.
    pub(crate) rendered: Mutex<Vec<Rendered>>,
    /// Its id in `ffi`'s registry once `diffsvg.jax` has used it (0: not registered); the
    /// registered snapshot follows every change and is removed when this is dropped.
    pub(crate) ffi_id: AtomicU64,
}

/// A row of parameters and the scene `render_batch` made of it.
pub(crate) type Rendered = (Vec<f64>, Scene);

impl From<Scene> for PyScene {
    fn from(inner: Scene) -> Self {
        PyScene {
            inner,
            rendered: Mutex::new(Vec::new()),
            ffi_id: AtomicU64::new(0),
        }
    }
}

impl Drop for PyScene {
    fn drop(&mut self) {
        crate::ffi::forget(*self.ffi_id.get_mut());
    }
}

impl Clone for PyScene {
    fn clone(&self) -> Self {
        PyScene::from(self.inner.clone())
    }
}

fn sizing(width: Option<u32>, height: Option<u32>, scale: Option<f64>) -> PyResult<Sizing> {
    Sizing::from_options(width, height, scale).map_err(to_py)
}

fn group_code(g: ParamGroup) -> u8 {
    ParamGroup::ALL.iter().position(|x| *x == g).unwrap_or(0) as u8
}

/// `{"kind", "offset", "len", "geometry", "stops"}` of one paint: `len` slots from `offset`
/// hold its paint values then its opacity (solid: `r, g, b, opacity`; gradient: geometry,
/// stops, opacity); the library's [`PaintSlots`] as a dict.
fn paint_entry<'py>(
    py: Python<'py>,
    ps: Option<&PaintSlots>,
) -> PyResult<Option<Bound<'py, PyDict>>> {
    let Some(ps) = ps else { return Ok(None) };
    let d = PyDict::new(py);
    d.set_item("offset", ps.offset)?;
    d.set_item("len", ps.len)?;
    d.set_item("kind", ps.kind)?;
    if ps.kind != "solid" {
        d.set_item("geometry", ps.geometry)?;
        d.set_item("stops", ps.stops)?;
    }
    Ok(Some(d))
}

#[pymethods]
impl PyScene {
    /// An empty scene of `width × height` pixels.
    #[new]
    fn new(width: u32, height: u32) -> Self {
        PyScene::from(Scene::new(width, height))
    }

    /// Appends a circle, ellipse or rectangle (`kind`: "circle", "ellipse", "rect") drawn
    /// on top, its parameters in `values` in slot order (circle `cx, cy, r`; ellipse
    /// `cx, cy, rx, ry, angle`; rectangle `x, y, width, height, [rx, ry,] angle`; device
    /// pixels, radians), with a `fill` and/or `stroke` (straight `r, g, b, opacity` in
    /// `[0, 1]`, or a gradient dict, see `build::paint_in`) of `stroke_width` pixels.
    #[pyo3(signature = (kind, values, fill=None, stroke=None, stroke_width=1.0, id=String::new()))]
    fn add_shape(
        &mut self,
        kind: &str,
        values: Vec<f64>,
        fill: Option<&Bound<'_, PyAny>>,
        stroke: Option<&Bound<'_, PyAny>>,
        stroke_width: f64,
        id: String,
    ) -> PyResult<()> {
        let prim = crate::build::primitive(kind, &values)?;
        let path = diffsvg::scene::Path::from_primitive(id, prim);
        let node = crate::build::paint_path(path, fill, stroke, stroke_width, false)?;
        self.inner.nodes.push(node);
        crate::ffi::changed(self);
        Ok(())
    }

    /// Appends a path of cubic segments drawn on top: `points` (start, then three per
    /// segment, per subpath), `segments` per subpath and `closed` per subpath, with paints
    /// as in `add_shape`; `evenodd` picks the fill rule.
    #[pyo3(signature = (points, segments, closed, fill=None, stroke=None, stroke_width=1.0, evenodd=false, id=String::new()))]
    #[allow(clippy::too_many_arguments)]
    fn add_path(
        &mut self,
        points: Vec<[f64; 2]>,
        segments: Vec<usize>,
        closed: Vec<bool>,
        fill: Option<&Bound<'_, PyAny>>,
        stroke: Option<&Bound<'_, PyAny>>,
        stroke_width: f64,
        evenodd: bool,
        id: String,
    ) -> PyResult<()> {
        let path = crate::build::cubic_path(&points, &segments, &closed, id)?;
        let node = crate::build::paint_path(path, fill, stroke, stroke_width, evenodd)?;
        self.inner.nodes.push(node);
        crate::ffi::changed(self);
        Ok(())
    }

    /// Number of top-level nodes (shapes and groups), the ones `remove` and `reorder`
    /// index.
    #[getter]
    fn node_count(&self) -> usize {
        self.inner.nodes.len()
    }

    /// Removes top-level node `index` (paint order, 0 first drawn).
    fn remove(&mut self, index: usize) -> PyResult<()> {
        if index >= self.inner.nodes.len() {
            return Err(bad(format!(
                "remove: index {index} out of range (the scene has {} top-level nodes)",
                self.inner.nodes.len()
            )));
        }
        self.inner.nodes.remove(index);
        crate::ffi::changed(self);
        Ok(())
    }

    /// Puts the top-level nodes in the order `order` (a permutation of their indices):
    /// `order[0]` is drawn first.
    fn reorder(&mut self, order: Vec<usize>) -> PyResult<()> {
        let n = self.inner.nodes.len();
        let mut seen = vec![false; n];
        if order.len() != n
            || order
                .iter()
                .any(|&i| i >= n || std::mem::replace(&mut seen[i], true))
        {
            return Err(bad(format!(
                "reorder: {order:?} is not a permutation of 0..{n}"
            )));
        }
        let old = std::mem::take(&mut self.inner.nodes);
        let mut slots: Vec<Option<diffsvg::scene::Node>> = old.into_iter().map(Some).collect();
        self.inner.nodes = order
            .iter()
            .map(|&i| slots[i].take().expect("a permutation"))
            .collect();
        crate::ffi::changed(self);
        Ok(())
    }

    /// Turns every circle, ellipse and rectangle into a plain path of its outline (its
    /// control points become its parameters).
    fn outline_primitives(&mut self) {
        self.inner.outline_primitives();
        crate::ffi::changed(self);
    }

    /// Loads an SVG or SVGZ file. `width` (with `height`: exactly that size) or `scale`
    /// resize the canvas; by default the SVG's own size. `<text>` is set in the bundled
    /// DejaVu fonts plus the font files `fonts` and the fonts under the folders
    /// `font_dirs`; a missing family is an error unless `font_fallback`. Errors name the
    /// file.
    #[staticmethod]
    #[pyo3(signature = (path, width=None, height=None, scale=None, fonts=Vec::new(), font_dirs=Vec::new(), font_fallback=false))]
    #[allow(clippy::too_many_arguments)]
    fn load(
        py: Python<'_>,
        path: PathBuf,
        width: Option<u32>,
        height: Option<u32>,
        scale: Option<f64>,
        fonts: Vec<PathBuf>,
        font_dirs: Vec<PathBuf>,
        font_fallback: bool,
    ) -> PyResult<Self> {
        let s = sizing(width, height, scale)?;
        let mut f = Fonts::new().with_fallback(font_fallback);
        for file in fonts {
            f = f.with_file(file);
        }
        for dir in font_dirs {
            f = f.with_dir(dir);
        }
        let inner = py
            .detach(|| Scene::load_with(&path, s, &f))
            .map_err(to_py)?;
        Ok(PyScene::from(inner))
    }

    /// Parses SVG text; `name` is what error messages call it.
    #[staticmethod]
    #[pyo3(signature = (text, width=None, height=None, scale=None, name="<string>"))]
    fn from_svg(
        text: &str,
        width: Option<u32>,
        height: Option<u32>,
        scale: Option<f64>,
        name: &str,
    ) -> PyResult<Self> {
        let s = sizing(width, height, scale)?;
        let inner = Scene::from_svg_str(text, name, s).map_err(to_py)?;
        Ok(PyScene::from(inner))
    }

    /// Writes the scene as SVG (to a temporary file, then renamed) into a folder that
    /// exists.
    fn save(&self, path: PathBuf) -> PyResult<()> {
        crate::output::check_folder(&path)?;
        self.inner.save_svg(&path).map_err(to_py)
    }

    /// The scene as SVG text.
    fn to_svg(&self) -> String {
        self.inner.to_svg_string()
    }

    /// Canvas width, pixels.
    #[getter]
    fn width(&self) -> u32 {
        self.inner.width
    }

    /// Canvas height, pixels.
    #[getter]
    fn height(&self) -> u32 {
        self.inner.height
    }

    /// Number of paths.
    #[getter]
    fn path_count(&self) -> usize {
        self.inner.path_count()
    }

    /// A copy.
    fn copy(&self) -> Self {
        self.clone()
    }

    fn __copy__(&self) -> Self {
        self.clone()
    }

    fn __deepcopy__(&self, _memo: &Bound<'_, PyAny>) -> Self {
        self.clone()
    }

    fn __repr__(&self) -> String {
        format!(
            "Scene({}x{}, {} paths, {} parameters)",
            self.inner.width,
            self.inner.height,
            self.inner.path_count(),
            ParamLayout::new(&self.inner).len()
        )
    }

    /// Every parameter as one `float64` vector, in the library's order.
    fn params<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        vec_out(py, self.inner.params())
    }

    /// Writes a parameter vector (`float64`, finite, the length of `params()`), then
    /// projects onto valid scenes (colors and opacities into `[0, 1]`, widths ≥ 0, stop
    /// offsets ordered, coordinates within the readable range).
    fn set_params(&mut self, values: PyReadonlyArray1<'_, f64>) -> PyResult<()> {
        let n = ParamLayout::new(&self.inner).len();
        let v = vector_in(&values, n, "set_params")?;
        self.inner.set_params(&v);
        project(&mut self.inner);
        crate::ffi::changed(self);
        Ok(())
    }

    /// The layout of `params()`: per slot its group (an index into `group_names`) and its
    /// owner (an index into `owners`, dicts with `id` and `kind` "path" or "group").
    fn layout<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let l = ParamLayout::new(&self.inner);
        let d = PyDict::new(py);
        let groups: Vec<u8> = l.slots.iter().map(|s| group_code(s.group)).collect();
        let owners: Vec<u32> = l.slots.iter().map(|s| s.owner as u32).collect();
        d.set_item("group", PyArray1::from_vec(py, groups))?;
        d.set_item("owner", PyArray1::from_vec(py, owners))?;
        let names: Vec<&str> = ParamGroup::ALL.iter().map(|g| g.name()).collect();
        d.set_item("group_names", names)?;
        let owners = PyList::empty(py);
        for o in &l.owners {
            let e = PyDict::new(py);
            e.set_item("id", &o.id)?;
            e.set_item("kind", if o.is_group { "group" } else { "path" })?;
            owners.append(e)?;
        }
        d.set_item("owners", owners)?;
        Ok(d)
    }

    /// Where each shape's and group's arrays lie in `params()`: a dict with `shapes` (per
    /// path: `id`, `points` = (offset, count), `primitive` (a circle's, ellipse's or
    /// rectangle's `kind`, `offset` and `fields`, [(name, length)], or None), `segments`
    /// per subpath, `closed` per subpath, `kinds` of the written segments ("L", "Q", "C"), `fill` and `stroke` paint
    /// entries or None, `stroke_width` offset or None), `groups` (`id`, `offset` of the
    /// opacity), `transforms` (`id`, `offset` and `len` of a group transform's `tx, ty,
    /// angle, scale`, or `tx, ty, a, b, c, d` for a general affine one) and `filters` (`id`, `offset` and `len` of a filtered group's filter
    /// parameters, docs/filters.md).
    fn structure<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let st = Structure::of(&self.inner);
        let shapes = PyList::empty(py);
        for sh in &st.shapes {
            let d = PyDict::new(py);
            d.set_item("id", &sh.id)?;
            d.set_item("points", sh.points)?;
            match &sh.primitive {
                Some(ps) => {
                    let e = PyDict::new(py);
                    e.set_item("kind", ps.kind)?;
                    e.set_item("offset", ps.offset)?;
                    e.set_item("fields", &ps.fields)?;
                    d.set_item("primitive", e)?;
                }
                None => d.set_item("primitive", py.None())?,
            }
            d.set_item("segments", &sh.segments)?;
            d.set_item("closed", &sh.closed)?;
            d.set_item("kinds", &sh.kinds)?;
            d.set_item("fill", paint_entry(py, sh.fill.as_ref())?)?;
            d.set_item("stroke", paint_entry(py, sh.stroke.as_ref())?)?;
            d.set_item("stroke_width", sh.stroke_width)?;
            shapes.append(d)?;
        }
        let entries = |slots: &[diffsvg::scene::structure::GroupSlots]| -> PyResult<_> {
            let list = PyList::empty(py);
            for g in slots {
                let e = PyDict::new(py);
                e.set_item("id", &g.id)?;
                e.set_item("offset", g.offset)?;
                e.set_item("len", g.len)?;
                list.append(e)?;
            }
            Ok(list)
        };
        let d = PyDict::new(py);
        d.set_item("shapes", shapes)?;
        d.set_item("groups", entries(&st.groups)?)?;
        d.set_item("transforms", entries(&st.transforms)?)?;
        let filters = PyList::empty(py);
        for f in &st.filters {
            let e = PyDict::new(py);
            e.set_item("id", &f.id)?;
            e.set_item("offset", f.offset)?;
            e.set_item("len", f.len)?;
            filters.append(e)?;
        }
        d.set_item("filters", filters)?;
        Ok(d)
    }

    /// The control-point part of a gradient (a vector in `params()` layout) chained to
    /// the points as written in each path's data (a line's derived control points passed
    /// to its ends, a quadratic's to its control point), one `(k, 2)` `float64` array per
    /// path: the `points` of `diffsvg grad --json`.
    fn written_points_gradient<'py>(
        &self,
        py: Python<'py>,
        grad: PyReadonlyArray1<'_, f64>,
    ) -> PyResult<Vec<Bound<'py, PyArray2<f64>>>> {
        let l = ParamLayout::new(&self.inner);
        let g = vector_in(&grad, l.len(), "written_points_gradient")?;
        let mut out = Vec::new();
        let mut i = 0;
        self.inner.for_each_path(|p| {
            let off = l.paths[i].points;
            // A primitive's outline points are no parameters (its own are in `shape`).
            let w = match p.primitive {
                Some(_) => Vec::new(),
                None => written_point_gradient(p, &g[off..off + 2 * p.points.len()]),
            };
            out.push(w);
            i += 1;
        });
        out.into_iter()
            .map(|w| {
                let rows: Vec<Vec<f64>> = w.iter().map(|p| p.to_vec()).collect();
                if rows.is_empty() {
                    return Ok(PyArray2::zeros(py, [0, 2], false));
                }
                PyArray2::from_vec2(py, &rows).map_err(|e| bad(e.to_string()))
            })
            .collect()
    }
}
