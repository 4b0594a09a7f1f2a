"""diffsvg: exact differentiable vector rendering, from Python.

Conventions (the library's):

* **Space.** Device pixels of the scene's canvas, x right, **y down**, origin at the
  top-left corner. Pixel ``(i, j)`` covers ``[i, i+1] x [j, j+1]``; coverage is the exact
  area of that square inside the shape and paints are evaluated at its center.
* **Images** are ``(height, width, 4)`` ``float32`` arrays of **premultiplied** RGBA in
  ``[0, 1]`` (``unpremultiply`` gives straight alpha); targets are the same.
* **Scene colors** (fills, strokes, gradient stops) are straight sRGB in ``[0, 1]``,
  opacities separate, stroke widths in pixels.
* **Parameters.** ``Scene.params()`` is every number an optimizer may move, one ``float64``
  vector; ``Scene.arrays()`` gives the same numbers per shape as DiffVG names them
  (control points ``(n, 2)``, fill/stroke color ``(4,)`` = r, g, b, opacity, stroke width,
  gradient geometry and stops). Gradients come back in the same structures.
* **3D** (``recon_voxel``, ``recon_splat``, ``recon_ngp``, ``recon_nerf``): a posed-photo folder (NeRF-synthetic or
  instant-ngp) in, a model file out, as ``diffsvg recon``; ``diffsvg view`` renders it.
* **Meshes** (``Mesh``, ``Camera``): triangles rendered with the exact visible area of each
  triangle in each pixel and differentiated exactly (``Mesh.render``,
  ``Mesh.render_backward``, ``Mesh.fit``); world units, OpenGL camera axes (see
  ``docs/mesh.md``).
* **Errors.** Bad input raises ``DiffsvgError`` (a ``ValueError``), ``FileNotFoundError``
  or ``OSError`` with one line naming the file or argument; nothing panics.
"""

from __future__ import annotations

import operator
import os
from collections.abc import Mapping
from typing import Any, List, Optional, Sequence, Tuple, Union

import numpy as np

from . import _native
from ._native import Camera, DiffsvgError, Mesh
from ._types import (Arrays, DigitInfo, FitInfo, GlyphInfo, GradientPaint, GradJson, Layout,
                     Progress, ReconInfo, Structure, VectorizeInfo, Views)

__version__: str = _native.__version__
"""The package's version: the Rust crates' (``diffsvg`` and its binding share it)."""

__all__ = [
    "__version__",
    "DiffsvgError",
    "Scene",
    "Mesh",
    "Camera",
    "render",
    "render_backward",
    "background_backward",
    "loss",
    "psnr",
    "unpremultiply",
    "load_image",
    "load_target",
    "save_png",
    "fit",
    "vectorize",
    "random_blobs",
    "random_strokes",
    "digit",
    "digits",
    "glyph",
    "glyphs",
    "recon_voxel",
    "recon_splat",
    "recon_ngp",
    "recon_nerf",
    "view",
]

Color = Optional[Sequence[float]]
#: A fill or stroke for the builder: straight (r, g, b[, a]), a gradient dict, or None.
Paint = Union[Color, GradientPaint]


def _image(x: Any, name: str) -> np.ndarray:
    """A C-contiguous float32 view (or copy, when the dtype or layout differs).

    Integer arrays are refused: an 8-bit picture holds 0-255, not the [0, 1] every image
    here is in, and converting silently would compare 255 with 1."""
    return np.ascontiguousarray(_floats(x, name), dtype=np.float32)


def _floats(x: Any, name: str) -> np.ndarray:
    """``x`` as an array of a float dtype, or the package's error naming ``name``."""
    a = np.asarray(x)
    if a.dtype.kind in "iu":
        raise DiffsvgError(
            f"{name}: integer dtype {a.dtype}; images are float in [0, 1] "
            f"(convert first, e.g. x.astype(np.float32) / 255)")
    if a.dtype.kind != "f":
        raise DiffsvgError(f"{name}: expected a numeric array, got dtype {a.dtype}")
    return a


_U32 = 2**32 - 1
_U64 = 2**64 - 1


def _whole(v: Any, name: str, top: int = _U32) -> int:
    """``v`` as a whole number in ``[0, top]``, or the package's one-line error naming
    ``name`` (instead of the ``OverflowError`` a negative number gives in the extension)."""
    if isinstance(v, bool):
        raise TypeError(f"{name}: expected a whole number, got {v!r}")
    try:
        n = operator.index(v)
    except TypeError:
        raise TypeError(f"{name}: expected a whole number, got {v!r}") from None
    if n < 0:
        raise DiffsvgError(f"{name}: {n} is negative (expected a whole number >= 0)")
    if n > top:
        raise DiffsvgError(f"{name}: {n} is too large (at most {top})")
    return n


def _flag(v: Any, name: str) -> bool:
    """``v`` if it is ``True`` or ``False``, else a one-line ``TypeError`` naming ``name``
    (a truthy string or number would otherwise pass silently)."""
    if not isinstance(v, bool):
        raise TypeError(f"{name} must be True or False, got {v!r}")
    return v


def _path_or_none(v: Any) -> Optional[str]:
    return None if v is None else os.fspath(v)


def _whole_or_none(v: Any, name: str, top: int = _U32) -> Optional[int]:
    return None if v is None else _whole(v, name, top)


def _pair(p: Any, name: str = "perturb_poses",
          what: str = "(degrees, units)") -> Optional[Tuple[float, float]]:
    if p is None:
        return None
    t = tuple(float(v) for v in p)
    if len(t) != 2:
        raise DiffsvgError(f"{name}: expected {what}, got {p!r}")
    return t


def _color(c: Color, name: str):
    if c is None:
        return None
    t = tuple(float(v) for v in c)
    if len(t) == 3:
        t = t + (1.0,)
    if len(t) != 4:
        raise DiffsvgError(f"{name}: expected (r, g, b) or (r, g, b, a), got {c!r}")
    return t


def _paint(p: Paint, name: str):
    """A paint as the native builder takes it: an RGBA tuple, a gradient dict, or None."""
    if p is None or isinstance(p, Mapping):
        return None if p is None else dict(p)
    return _color(p, name)


def _paint_size(entry: dict) -> int:
    return entry["len"]


class Scene:
    """A vector scene: paths with fills and strokes (solid or gradient paints; an
    ``<image>`` is its rectangle filled with the image's fixed pixels) in groups.

    Build one with :meth:`load` or :meth:`from_svg`, or start from ``Scene(width, height)``
    (empty) and add shapes with :meth:`add_circle`, :meth:`add_ellipse`, :meth:`add_rect`.
    """

    __slots__ = ("_s", "_structure", "_params", "__weakref__")

    def __init__(self, width: int = 0, height: int = 0, *, _native_scene=None) -> None:
        if _native_scene is None:
            _native_scene = _native.Scene(_whole(width, "width"), _whole(height, "height"))
        self._s = _native_scene
        self._structure = None
        self._params = None

    # ----- input and output ---------------------------------------------------------
    @classmethod
    def load(cls, path, width: Optional[int] = None, height: Optional[int] = None,
             scale: Optional[float] = None, *, fonts=(), font_dirs=(),
             font_fallback: bool = False) -> "Scene":
        """Loads an SVG or SVGZ file; ``width`` (with ``height``: exactly that size) or
        ``scale`` resize the canvas, by default the SVG's own size. ``<text>`` is set in
        the bundled DejaVu fonts plus the font files ``fonts`` and every font under the
        folders ``font_dirs``; a font family none of them has is an error unless
        ``font_fallback`` (then DejaVu Sans is used)."""
        return cls(_native_scene=_native.Scene.load(
            os.fspath(path), _whole_or_none(width, "width"), _whole_or_none(height, "height"),
            scale, [os.fspath(f) for f in fonts],
            [os.fspath(d) for d in font_dirs], font_fallback))

    @classmethod
    def from_svg(cls, text: str, width: Optional[int] = None, height: Optional[int] = None,
                 scale: Optional[float] = None, name: str = "<string>") -> "Scene":
        """Parses SVG text; ``name`` is what error messages call it."""
        return cls(_native_scene=_native.Scene.from_svg(
            text, _whole_or_none(width, "width"), _whole_or_none(height, "height"), scale,
            name))

    # ----- building in code ---------------------------------------------------------
    def _changed(self) -> None:
        self._structure = None
        self._params = None

    def _add(self, kind: str, values, fill: Paint, stroke: Paint, stroke_width: float,
             id: str) -> None:
        vals = [float(v) for v in np.asarray(values, dtype=np.float64).ravel()]
        self._s.add_shape(kind, vals, _paint(fill, "fill"), _paint(stroke, "stroke"),
                          float(stroke_width), str(id))
        self._changed()

    def add_path(self, points, segments=None, closed=True, *, fill: Paint = (0, 0, 0, 1),
                 stroke: Paint = None, stroke_width: float = 1.0, evenodd: bool = False,
                 id: str = "") -> None:
        """Draws a path of cubic segments on top (DiffVG's ``Path``): ``points`` ``(n, 2)``,
        each subpath its start then three points per segment; ``segments``: cubics per
        subpath (default: one subpath of ``(n − 1) / 3``); ``closed``: one flag, or one
        per subpath. Paints: straight (r, g, b[, a]), or a gradient
        ``{"kind": "linear"|"radial", "geometry": [...], "stops": [[offset, r, g, b, a],
        ...]}`` in pixels (the layout of ``arrays()``), or None."""
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise DiffsvgError(f"add_path: points must be (n, 2), got shape {pts.shape}")
        if segments is None:
            segments = [(len(pts) - 1) // 3]
        segments = [_whole(n, "segments") for n in np.atleast_1d(segments)]
        flags = [bool(closed)] * len(segments) if np.ndim(closed) == 0 else \
            [bool(c) for c in closed]
        self._s.add_path([tuple(p) for p in pts.tolist()], segments, flags,
                         _paint(fill, "fill"), _paint(stroke, "stroke"), float(stroke_width),
                         bool(evenodd), str(id))
        self._changed()

    @property
    def node_count(self) -> int:
        """Top-level nodes (shapes and groups), as :meth:`remove` and :meth:`reorder`
        index them."""
        return self._s.node_count

    def remove(self, index: int) -> None:
        """Removes top-level node ``index`` (0 is drawn first)."""
        self._s.remove(_whole(index, "index"))
        self._changed()

    def reorder(self, order) -> None:
        """Redraws the top-level nodes in ``order`` (a permutation; ``order[0]`` first)."""
        self._s.reorder([_whole(i, "order") for i in order])
        self._changed()

    def add_circle(self, center, radius: float, *, fill: Paint = (0, 0, 0, 1),
                   stroke: Paint = None, stroke_width: float = 1.0, id: str = "") -> None:
        """Draws a circle on top: ``center`` (x, y) and ``radius`` in pixels are its
        parameters (``arrays()`` names them so), and SVG out writes a ``<circle>``.
        ``fill``/``stroke``: straight (r, g, b[, a]) in [0, 1], or None."""
        self._add("circle", [*center, radius], fill, stroke, stroke_width, id)

    def add_ellipse(self, center, radius, angle: float = 0.0, *, fill: Paint = (0, 0, 0, 1),
                    stroke: Paint = None, stroke_width: float = 1.0, id: str = "") -> None:
        """Draws an ellipse on top: ``center``, ``radius`` (rx, ry) and ``angle`` (radians,
        its rotation about the center, clockwise on screen) are its parameters."""
        self._add("ellipse", [*center, *radius, angle], fill, stroke, stroke_width, id)

    def add_rect(self, corner, size, radii=None, angle: float = 0.0, *,
                 fill: Paint = (0, 0, 0, 1), stroke: Paint = None, stroke_width: float = 1.0,
                 id: str = "") -> None:
        """Draws a rectangle on top: ``corner`` (x, y), ``size`` (width, height), the
        corner ``radii`` (rx, ry) of a rounded one and ``angle`` (radians, about its
        center) are its parameters."""
        r = [] if radii is None else list(radii)
        self._add("rect", [*corner, *size, *r, angle], fill, stroke, stroke_width, id)

    def outline_primitives(self) -> None:
        """Turns every circle, ellipse and rectangle into a plain path of its outline:
        its control points become its parameters (``arrays()`` then has ``points``), and
        the SVG written holds ``<path>``s (``diffsvg fit --free-shapes``)."""
        self._s.outline_primitives()
        self._changed()

    def save(self, path) -> None:
        """Writes the scene as SVG (to a temporary file, then renamed)."""
        self._s.save(os.fspath(path))

    def to_svg(self) -> str:
        """The scene as SVG text."""
        return self._s.to_svg()

    def copy(self) -> "Scene":
        """An independent copy."""
        return Scene(_native_scene=self._s.copy())

    __copy__ = copy

    def __deepcopy__(self, memo) -> "Scene":
        return self.copy()

    @property
    def width(self) -> int:
        """Canvas width, pixels."""
        return self._s.width

    @property
    def height(self) -> int:
        """Canvas height, pixels."""
        return self._s.height

    @property
    def path_count(self) -> int:
        """Number of paths."""
        return self._s.path_count

    def __repr__(self) -> str:
        return repr(self._s)

    # ----- the flat parameter vector ------------------------------------------------
    def params(self) -> np.ndarray:
        """Every parameter, one ``float64`` vector in the library's order (see
        :meth:`layout`)."""
        return self._current().copy()

    def _current(self) -> np.ndarray:
        """:meth:`params`, read once after each change (not to be written to)."""
        if self._params is None:
            self._params = self._s.params()
        return self._params

    def set_params(self, values) -> None:
        """Writes a parameter vector of ``len(params())`` finite values, then projects it
        onto valid scenes (colors and opacities into [0, 1], widths >= 0, stop offsets
        ordered).

        A ``float32`` value equal to the ``float32`` rounding of the current value leaves
        the current (``float64``) value as it is, so a round trip through ``float32``
        arrays changes nothing.
        """
        v = np.asarray(values)
        if v.ndim != 1:
            raise DiffsvgError(f"set_params: expected a 1-D array, got shape {v.shape}")
        if v.dtype.kind not in "fiu":
            raise DiffsvgError(f"set_params: expected a numeric array, got dtype {v.dtype}")
        if v.dtype == np.float32:
            cur = self._current()
            if cur.shape == v.shape:
                v = np.where(cur.astype(np.float32) == v, cur, v.astype(np.float64))
        self._params = None
        self._s.set_params(np.ascontiguousarray(v, dtype=np.float64))

    def layout(self) -> Layout:
        """Per slot of :meth:`params`: ``group`` (index into ``group_names``: points,
        colors, opacities, widths, paint, stops, transforms) and ``owner`` (index into ``owners``,
        dicts with ``id`` and ``kind``)."""
        return self._s.layout()

    def structure(self) -> Structure:
        """Where each shape's arrays lie in :meth:`params` (offsets and sizes), with the
        path data's segment kinds ("L", "Q", "C") and closed flags per subpath."""
        if self._structure is None:
            self._structure = self._s.structure()
        return self._structure

    # ----- per-shape arrays ---------------------------------------------------------
    def _pieces(self):
        """(offset, size, key path) of every leaf of :meth:`arrays`, in params order."""
        st = self.structure()
        out = []
        for i, sh in enumerate(st["shapes"]):
            prim = sh["primitive"]
            if prim is None:
                off, n = sh["points"]
                out.append((off, 2 * n, ("shapes", i, "points"), (n, 2)))
            else:
                at = prim["offset"]
                for name, size in prim["fields"]:
                    out.append((at, size, ("shapes", i, name), () if size == 1 else (size,)))
                    at += size
            for key in ("fill", "stroke"):
                e = sh[key]
                if e is None:
                    continue
                if e["kind"] == "solid":
                    out.append((e["offset"], 4, ("shapes", i, key), (4,)))
                elif e["kind"] == "image":
                    # Fixed pixels: only the opacity is a parameter.
                    out.append((e["offset"], 1, ("shapes", i, key, "opacity"), ()))
                else:
                    g, k = e["geometry"], e["stops"]
                    out.append((e["offset"], g, ("shapes", i, key, "geometry"), (g,)))
                    out.append((e["offset"] + g, 5 * k, ("shapes", i, key, "stops"), (k, 5)))
                    out.append((e["offset"] + g + 5 * k, 1, ("shapes", i, key, "opacity"), ()))
            if sh["stroke_width"] is not None:
                out.append((sh["stroke_width"], 1, ("shapes", i, "stroke_width"), ()))
        for j, g in enumerate(st["groups"]):
            out.append((g["offset"], 1, ("groups", j, "opacity"), ()))
        for j, t in enumerate(st["transforms"]):
            at = t["offset"]
            out.append((at, 2, ("transforms", j, "translate"), (2,)))
            if t["len"] == 6:  # a general affine map: its linear part [a, b, c, d]
                out.append((at + 2, 4, ("transforms", j, "linear"), (4,)))
            else:
                out.append((at + 2, 1, ("transforms", j, "angle"), ()))
                out.append((at + 3, 1, ("transforms", j, "scale"), ()))
        for j, f in enumerate(st["filters"]):
            out.append((f["offset"], f["len"], ("filters", j, "values"), (f["len"],)))
        out.sort(key=lambda p: p[0])
        return out

    def _skeleton(self):
        st = self.structure()
        shapes = []
        for sh in st["shapes"]:
            d = {}
            for key in ("fill", "stroke"):
                e = sh[key]
                if e is not None and e["kind"] != "solid":
                    d[key] = {}
            shapes.append(d)
        tree = {"shapes": shapes, "groups": [{} for _ in st["groups"]]}
        if st["transforms"]:
            tree["transforms"] = [{} for _ in st["transforms"]]
        if st["filters"]:
            tree["filters"] = [{} for _ in st["filters"]]
        return tree

    def unflatten(self, flat, dtype=np.float32) -> Arrays:
        """A vector in :meth:`params` layout as the per-shape structure of
        :meth:`arrays` (views of one array of ``dtype``)."""
        v = np.asarray(flat, dtype=dtype)
        tree = self._skeleton()
        for off, size, key, shape in self._pieces():
            node = tree
            for k in key[:-1]:
                node = node[k]
            node[key[-1]] = v[off:off + size].reshape(shape)
        return tree

    def arrays(self, dtype=np.float32) -> Arrays:
        """The parameters per shape, as DiffVG names them::

            {"shapes": [{"points": (n, 2),           # a path: every control point
                         # or a circle: "center": (2,), "radius": ()
                         # an ellipse: "center": (2,), "radius": (2,), "angle": ()
                         # a rect: "corner": (2,), "size": (2,), ["radii": (2,),] "angle": ()
                         "fill": (4,)                # solid: r, g, b, opacity
                              | {"geometry": (4,)    # linear: x1, y1, x2, y2
                                             (6,),   # radial: cx, cy, r, fx, fy, fr
                                 "stops": (k, 5),    # offset, r, g, b, opacity
                                 "opacity": ()}
                              | {"opacity": ()},     # image: its pixels are fixed
                         "stroke": ...,              # as fill
                         "stroke_width": ()}, ...],
             "groups": [{"opacity": ()}, ...],
             "transforms": [{"translate": (2,), "angle": (), "scale": ()}, ...],
             "filters": [{"values": (n,)}, ...]}

        ``transforms`` is present when groups' transforms are parameters (a similarity
        over two or more shapes: translation in pixels, angle in radians, scale, about
        the content's center; the shapes in such a group are in its own frame);
        ``filters`` when filtered groups' filters have parameters (per group, its
        primitives' numbers in order: offsets, blur deviations, drop shadows, flood
        colors, color matrices, arithmetic k; docs/filters.md).
        A key is absent when the shape has no such paint. A circle, ellipse or
        rectangle has its own parameters in place of ``points`` (device pixels; ``angle``
        in radians, its rotation about its center). In a path every segment is a cubic:
        point ``3k`` starts segment ``k`` of a subpath and ``3k+1``, ``3k+2`` are its
        control points (a line's at 1/3 and 2/3). The structure is a pytree for JAX.
        """
        return self.unflatten(self._current(), dtype)

    def _expected(self):
        """The structure of :meth:`arrays` with each leaf's shape in place of its array."""
        tree = self._skeleton()
        for _, _, key, shape in self._pieces():
            node = tree
            for k in key[:-1]:
                node = node[k]
            node[key[-1]] = shape
        return tree

    def check_arrays(self, arrays) -> None:
        """Refuses ``arrays`` unless it has exactly the structure of :meth:`arrays`: the
        same shapes and groups, the same keys, the same array shapes. An appended shape or
        a key the scene has no parameter for (a ``stroke_width`` on a shape without a
        stroke) is an error, not ignored: arrays carry values, the scene its structure."""
        _match(arrays, self._expected(), "")

    def flatten(self, arrays, xp=np) -> Any:
        """The inverse of :meth:`arrays`: one vector in :meth:`params` layout; ``xp`` is
        the array module (``numpy`` or ``jax.numpy``, which keeps it differentiable).
        ``arrays`` must match the scene's structure (:meth:`check_arrays`)."""
        self.check_arrays(arrays)
        parts = []
        total = 0
        for off, size, key, shape in self._pieces():
            node = arrays
            try:
                for k in key:
                    node = node[k]
            except (KeyError, IndexError, TypeError):
                raise DiffsvgError(f"arrays: missing {'/'.join(map(str, key))}") from None
            if tuple(getattr(node, "shape", np.shape(node))) != shape:
                raise DiffsvgError(
                    f"arrays: {'/'.join(map(str, key))} has shape "
                    f"{tuple(np.shape(node))}, expected {shape}")
            if off != total:
                raise DiffsvgError("arrays: the scene's layout has a gap (internal error)")
            parts.append(xp.reshape(node, (size,)))
            total += size
        if not parts:
            return xp.zeros((0,))
        return xp.concatenate(parts)

    def set_arrays(self, arrays) -> None:
        """Writes per-shape arrays (the structure of :meth:`arrays`) back, as
        :meth:`set_params` does."""
        leaves = [np.asarray(node) for node in _leaves(arrays)]
        dtype = np.float32 if leaves and all(a.dtype == np.float32 for a in leaves) else np.float64
        flat = np.asarray(self.flatten(arrays), dtype=dtype)
        self.set_params(flat)

    def grad_json(self, grad) -> GradJson:
        """A gradient (flat vector in :meth:`params` layout) in the layout of
        ``diffsvg grad --json``: per shape its id, ``points`` chained to the points as
        written in the path data, ``fill``/``stroke`` ([r, g, b, opacity] or
        {kind, geometry, stops, opacity}) and ``stroke_width``; per group its opacity."""
        g = np.ascontiguousarray(grad, dtype=np.float64)
        written = self._s.written_points_gradient(g)
        st = self.structure()
        shapes = []
        for sh, pts in zip(st["shapes"], written):
            d = {"id": sh["id"], "points": pts.tolist()}
            prim = sh["primitive"]
            if prim is not None:
                shape, at = {"kind": prim["kind"]}, prim["offset"]
                for name, size in prim["fields"]:
                    v = g[at:at + size]
                    shape[name] = float(v[0]) if size == 1 else v.tolist()
                    at += size
                d["shape"] = shape
            for key in ("fill", "stroke"):
                e = sh[key]
                if e is None:
                    continue
                o = e["offset"]
                if e["kind"] == "solid":
                    d[key] = g[o:o + 4].tolist()
                else:
                    n, k = e["geometry"], e["stops"]
                    d[key] = {
                        "kind": e["kind"],
                        "geometry": g[o:o + n].tolist(),
                        "stops": g[o + n:o + n + 5 * k].reshape(k, 5).tolist(),
                        "opacity": float(g[o + n + 5 * k]),
                    }
            if sh["stroke_width"] is not None:
                d["stroke_width"] = float(g[sh["stroke_width"]])
            shapes.append(d)
        groups = [{"id": gr["id"], "opacity": float(g[gr["offset"]])} for gr in st["groups"]]
        out = {"shapes": shapes, "groups": groups}
        if st["transforms"]:
            out["transforms"] = [
                {"id": t["id"], "translate": g[t["offset"]:t["offset"] + 2].tolist(),
                 "linear": g[t["offset"] + 2:t["offset"] + 6].tolist()}
                if t["len"] == 6 else
                {"id": t["id"], "translate": g[t["offset"]:t["offset"] + 2].tolist(),
                 "angle": float(g[t["offset"] + 2]), "scale": float(g[t["offset"] + 3])}
                for t in st["transforms"]]
        if st["filters"]:
            out["filters"] = [
                {"id": f["id"], "values": g[f["offset"]:f["offset"] + f["len"]].tolist()}
                for f in st["filters"]]
        return out


_VALUES_NOT_STRUCTURE = "arrays carry values; the scene's structure is fixed"


def _match(given, expected, where: str) -> None:
    """Raises the package's error at the first place ``given`` differs in structure from
    ``expected`` (a tree of dicts and lists whose leaves are shapes)."""
    name = where or "arrays"
    if isinstance(expected, dict):
        if not isinstance(given, Mapping):
            raise DiffsvgError(f"arrays: {name} is a {type(given).__name__}, expected a dict "
                               f"with keys {sorted(expected)}")
        for k in given:
            if k not in expected:
                raise DiffsvgError(
                    f"arrays: {where + '/' if where else ''}{k} is not in the scene's "
                    f"structure (expected keys {sorted(expected)}; {_VALUES_NOT_STRUCTURE})")
        for k in expected:
            if k not in given:
                raise DiffsvgError(f"arrays: missing {where + '/' if where else ''}{k}")
            _match(given[k], expected[k], f"{where}/{k}" if where else str(k))
    elif isinstance(expected, list):
        if not isinstance(given, (list, tuple)):
            raise DiffsvgError(f"arrays: {name} is a {type(given).__name__}, expected a list "
                               f"of {len(expected)}")
        if len(given) != len(expected):
            raise DiffsvgError(
                f"arrays: {name} has {len(given)} entries but the scene has {len(expected)} "
                f"({_VALUES_NOT_STRUCTURE})")
        for i, (g, e) in enumerate(zip(given, expected)):
            _match(g, e, f"{where}/{i}")
    else:
        if isinstance(given, Mapping):
            raise DiffsvgError(f"arrays: {name} is a dict, expected an array of shape "
                               f"{expected}")
        shape = tuple(getattr(given, "shape", np.shape(given)))
        if shape != expected:
            raise DiffsvgError(f"arrays: {name} has shape {shape}, expected {expected}")


def _leaves(tree):
    if isinstance(tree, dict):
        for k in tree:
            yield from _leaves(tree[k])
    elif isinstance(tree, (list, tuple)):
        for v in tree:
            yield from _leaves(v)
    else:
        yield tree


def _scene(scene) -> "_native.Scene":
    if not isinstance(scene, Scene):
        raise DiffsvgError(f"expected a diffsvg.Scene, got {type(scene).__name__}")
    return scene._s


# ----- rendering ------------------------------------------------------------------------
def render(scene: Scene, width: Optional[int] = None, height: Optional[int] = None,
           background: Color = None, tolerance: float = 0.02,
           exact_overlaps: bool = False) -> np.ndarray:
    """Renders ``scene`` into a ``(height, width, 4)`` ``float32`` array of
    **premultiplied** RGBA in ``[0, 1]``, y down.

    ``width`` (and ``height``) render at another size: the scene is scaled uniformly by
    ``width / scene.width``. ``background`` (straight (r, g, b[, a])) is composited under
    the drawing. ``tolerance`` is the largest curve-to-chord distance in pixels.
    ``exact_overlaps`` integrates exactly the pixels where a path overlaps itself (two
    coincident half-pixel rectangles in one path cover half the pixel, not all of it),
    as ``diffsvg render --exact-overlaps`` does; off by default, as it costs about a
    fifth more time on text. The GIL is released while rendering; the pixels are moved
    into numpy, not copied.
    """
    return _native.render(_scene(scene), _whole_or_none(width, "width"),
                          _whole_or_none(height, "height"), _color(background, "background"),
                          tolerance, _flag(exact_overlaps, "exact_overlaps"))


def render_backward(scene: Scene, d_image, background: Color = None,
                    tolerance: float = 0.02, structured: bool = True,
                    dtype=np.float32, exact_overlaps: bool = False) -> Union[Arrays, np.ndarray]:
    """The exact gradient of a loss with respect to every parameter of ``scene``, given
    ``d_image = dL/d(image)`` (``(height, width, 4)``, the scene's size).

    With ``background``, ``d_image`` is the gradient with respect to the image composited
    over it (as :func:`render` returns it). With ``exact_overlaps``, the gradient of the
    exact coverage where a path overlaps itself (as :func:`render` draws it with the same
    flag). Returns the structure of :meth:`Scene.arrays` (of ``dtype``), or with
    ``structured=False`` a ``float64`` vector in :meth:`Scene.params` layout. The GIL is
    released while it runs.
    """
    g = _native.render_backward(_scene(scene), _image(d_image, "d_image"),
                                _color(background, "background"), tolerance,
                                _flag(exact_overlaps, "exact_overlaps"))
    return scene.unflatten(g, dtype) if structured else g


def background_backward(image, d_image, background) -> np.ndarray:
    """The gradient with respect to a background of a loss of ``image`` composited over
    it (as :func:`render`'s ``background`` composites: ``image + (1 − alpha) ·
    premultiplied background``), given ``d_image = dL/d(composited)``: an array of the
    background's shape, a straight color ``(3,)``/``(4,)`` or a straight image
    ``(h, w, 3|4)``. With :func:`render_backward` for the scene's parameters, a background
    is a parameter like any other (``diffsvg.jax.render`` does both inside JAX)."""
    img = _image(image, "image")
    d = _image(d_image, "d_image")
    bg = np.asarray(background, dtype=np.float64)
    h, w = img.shape[:2]
    if d.shape != img.shape:
        raise DiffsvgError(f"d_image: shape {d.shape}, expected {img.shape}")
    if not (bg.shape in ((3,), (4,)) or bg.shape in ((h, w, 3), (h, w, 4))):
        raise DiffsvgError(f"background: shape {bg.shape}; expected (3,), (4,), "
                           f"({h}, {w}, 3) or ({h}, {w}, 4)")
    if not np.isfinite(bg).all():
        raise DiffsvgError("background: values must be finite")
    d_pm = (1.0 - img[..., 3:].astype(np.float64)) * d.astype(np.float64)
    alpha = bg[..., 3:] if bg.shape[-1] == 4 else np.ones(bg.shape[:-1] + (1,))
    d_color = d_pm[..., :3] * alpha
    out = d_color
    if bg.shape[-1] == 4:
        d_alpha = (d_pm[..., :3] * bg[..., :3]).sum(-1, keepdims=True) + d_pm[..., 3:]
        out = np.concatenate([d_color, d_alpha], axis=-1)
    if bg.ndim == 1:
        out = out.reshape(-1, out.shape[-1]).sum(0)
    return out


_CHANNELS = {"rgba": 4, "rgb": 3}


def _channels(channels: str) -> int:
    k = _CHANNELS.get(channels) if isinstance(channels, str) else None
    if k is None:
        raise DiffsvgError(f"channels: {channels!r} (expected 'rgba' or 'rgb')")
    return k


def loss(image, target, kind: str = "mse", grad: bool = False,
         channels: str = "rgba") -> Union[float, Tuple[float, np.ndarray]]:
    """The mean of the squared (``kind="mse"``) or absolute (``"l1"``) difference of two
    premultiplied ``(h, w, 4)`` float images, as ``float``; with ``grad``,
    ``(loss, dL/d(image))``.

    ``channels``: ``"rgba"`` (the default, as ``diffsvg fit`` and ``diffsvg grad``
    compare) averages over every pixel and all four premultiplied channels, alpha
    included; ``"rgb"`` over the three color channels only (the gradient's alpha is then
    0). Integer images (0-255) are refused: convert to float in [0, 1] first."""
    k = _channels(channels)
    v, d = _native.loss(_image(image, "image"), _image(target, "target"), kind, grad, k)
    return (v, d) if grad else v


def psnr(image, target, channels: str = "rgba") -> float:
    """Peak signal-to-noise ratio in dB (values in [0, 1], peak 1) of two float images
    of the same shape, from the mean squared difference in ``float64``.

    ``channels``: ``"rgba"`` (the default) over all four channels of ``(..., 4)`` arrays;
    ``"rgb"`` over the first three (of ``(..., 4)`` or ``(..., 3)`` arrays)."""
    k = _channels(channels)
    a, b = _float_array(image, "image"), _float_array(target, "target")
    if a.shape != b.shape:
        raise DiffsvgError(f"psnr: target has shape {b.shape} but the image {a.shape}")
    last = a.shape[-1] if a.ndim else 0
    if last != 4 and not (k == 3 and last == 3):
        hint = " (pass channels='rgb')" if last == 3 else ""
        shapes = "(..., 4) or (..., 3)" if k == 3 else "(..., 4)"
        raise DiffsvgError(
            f"psnr: channels={channels!r} needs arrays of shape {shapes}, got {a.shape}{hint}")
    mse = float(np.mean((a[..., :k] - b[..., :k]) ** 2))
    return float("inf") if mse == 0 else -10.0 * np.log10(mse)


def _float_array(x: Any, name: str) -> np.ndarray:
    """``x`` as ``float64``, refusing integer (0-255) and non-numeric arrays."""
    return _floats(x, name).astype(np.float64)


def unpremultiply(image) -> np.ndarray:
    """Premultiplied RGBA to straight RGBA (transparent pixels stay 0)."""
    a = np.asarray(image, dtype=np.float32)
    out = a.copy()
    alpha = a[..., 3:4]
    np.divide(a[..., :3], alpha, out=out[..., :3], where=alpha > 0)
    return out


def load_image(path) -> np.ndarray:
    """Reads a PNG or JPEG as premultiplied RGBA ``float32``, ``(height, width, 4)``."""
    return _native.load_image(os.fspath(path))


def load_target(path, width: Optional[int] = None, height: Optional[int] = None) -> np.ndarray:
    """A picture to fit: PNG or JPEG, or an SVG rendered at its size; resampled to
    ``width x height`` when both are given."""
    return _native.load_target(os.fspath(path), _whole_or_none(width, "width"),
                               _whole_or_none(height, "height"))


def save_png(image, path) -> None:
    """Writes a premultiplied RGBA image as an 8-bit PNG (temporary file, renamed)."""
    _native.save_png(_image(image, "image"), os.fspath(path))


# ----- long jobs ------------------------------------------------------------------------


def _target_for(target, width: int, height: int) -> np.ndarray:
    if isinstance(target, (str, os.PathLike)):
        return load_target(target, width, height)
    return _image(target, "target")


def fit(scene: Scene, target, iters: int = 500, *, lr_points: float = 1.0,
        lr_color: float = 0.01, lr_opacity: float = 0.01, lr_width: float = 0.1,
        lr_paint: float = 0.5, lr_stops: float = 0.005, lr_transform: float = 0.5,
        lr_filter: float = 0.1, exact_filters: bool = False, schedule: str = "constant", loss: str = "mse", background: Color = None,
        pyramid: int = 1, until_psnr: Optional[float] = None, tolerance: float = 0.02,
        fit_background: bool = False, progress: Progress = None,
        exact_overlaps: bool = False) -> Tuple["Scene", FitInfo]:
    """Refines every parameter of ``scene`` toward ``target`` with exact gradients and
    Adam (as ``diffsvg fit``); returns ``(best scene, info)``.

    ``target``: a premultiplied ``(h, w, 4)`` array of the scene's size, or a file (PNG,
    JPEG or SVG), resampled to the scene's size. Learning rates are per step in each
    group's units (pixels for points and gradient geometry; ``lr_transform``, the
    rotation of circles, ellipses and rectangles, in pixels of motion at the shape's
    edge; ``lr_filter``, filter offsets and blur deviations in pixels, color-matrix values
    and feComposite's k a tenth of it). ``exact_filters`` evaluates filters as the SVG
    specification defines them (true Gaussian blurs, fractional offsets), so that blur
    deviations and offsets get a gradient (as ``diffsvg fit --exact-filters``).
    ``exact_overlaps`` renders and differentiates the exact coverage where a path overlaps
    itself (as :func:`render` with ``exact_overlaps``, and ``diffsvg fit --exact-overlaps``).
    ``background`` (straight RGB[A]) is composited under render and target before
    comparing (opaque: over RGB only); with ``fit_background`` an opaque background's
    color is fitted too (as ``diffsvg fit --fit-background``) and returned as
    ``info["background"]`` (straight RGBA; ``None`` otherwise). ``progress(step)`` is called after every evaluation with ``iter``, ``loss``,
    ``psnr``, ``seconds``; returning ``False`` or raising stops the run (an exception is
    re-raised once the GIL is back; Ctrl-C raises KeyboardInterrupt the same way).
    ``info`` has ``loss``, ``psnr``, ``steps``, ``reason``, the median ``step_ms`` (render,
    loss and gradient of one step), ``final_loss``, ``seconds`` and ``history`` (rows of
    iter, loss, psnr, seconds).
    """
    t = _target_for(target, scene.width, scene.height)
    options = dict(lr_points=lr_points, lr_color=lr_color, lr_opacity=lr_opacity,
                   lr_width=lr_width, lr_paint=lr_paint, lr_stops=lr_stops,
                   lr_transform=lr_transform, lr_filter=lr_filter,
                   exact_filters=bool(exact_filters),
                   exact_overlaps=_flag(exact_overlaps, "exact_overlaps"),
                   schedule=schedule, loss=loss,
                   background=_color(background, "background"),
                   pyramid=_whole(pyramid, "pyramid", _U64), tolerance=tolerance,
                   fit_background=bool(fit_background))
    s, info = _native.fit(_scene(scene), t, _whole(iters, "iters", _U64), until_psnr, options,
                          progress)
    return Scene(_native_scene=s), info


def vectorize(target, paths: int = 64, mode: str = "adaptive", iters: int = 1000, *,
              seed: int = 0, target_psnr: Optional[float] = None, segments: int = 4,
              width: Optional[int] = None, background: Color = None,
              progress: Progress = None, **rates) -> Tuple["Scene", VectorizeInfo]:
    """An SVG scene from a picture (as ``diffsvg vectorize``); returns ``(scene, info)``.

    ``mode``: "adaptive" (paths added in rounds where the error is largest, pruned),
    "fixed" (DiffVG's random blobs), "painterly" (random strokes) or "trace" (vtracer).
    ``target``: a premultiplied array or a file; ``width`` resamples a file to that width.
    ``rates``: ``lr_points`` … ``lr_stops``, ``lr_transform``, ``schedule``, ``loss``,
    ``pyramid``, ``tolerance`` as in :func:`fit`. ``progress`` sees rounds (``round``, ``paths``) and
    evaluations (``iter``, ``loss``, ``psnr``, ``seconds``, ``paths``).
    """
    width = _whole_or_none(width, "width")
    if isinstance(target, (str, os.PathLike)):
        t = load_target(target)
        if width is not None:
            h = max(1, round(t.shape[0] * width / t.shape[1]))
            t = load_target(target, width, h)
    else:
        t = _image(target, "target")
    options = dict(rates, background=_color(background, "background"))
    if options.get("pyramid") is not None:
        options["pyramid"] = _whole(options["pyramid"], "pyramid", _U64)
    s, info = _native.vectorize(t, _whole(paths, "paths", _U64), mode,
                                _whole(iters, "iters", _U64), _whole(seed, "seed", _U64),
                                target_psnr, _whole(segments, "segments", _U64), options,
                                progress)
    return Scene(_native_scene=s), info


def _blob_args(n, width, height, seed):
    return (_whole(n, "n", _U64), _whole(width, "width"), _whole(height, "height"),
            _whole(seed, "seed", _U64))


def random_blobs(n: int, width: int, height: int, seed: int = 0) -> Scene:
    """DiffVG's painterly blobs: ``n`` closed random-walk paths of 3-5 cubics with random
    RGBA fills (the scene of ``diffsvg bench painterly`` for the same seed)."""
    return Scene(_native_scene=_native.random_blobs(*_blob_args(n, width, height, seed)))


def random_strokes(n: int, width: int, height: int, seed: int = 0) -> Scene:
    """DiffVG's painterly strokes: ``n`` open random-walk paths, 1 px wide."""
    return Scene(_native_scene=_native.random_strokes(*_blob_args(n, width, height, seed)))


def digit(pixels, target_iou: float = 0.85, max_strokes: int = 2, max_segments: int = 3,
          scale: int = 2) -> Tuple["Scene", DigitInfo]:
    """White strokes fitted to one grayscale digit (``(h, w)`` in [0, 1], ink bright, e.g.
    an MNIST image / 255), the fewest curves reaching ``target_iou``; ``(scene, info)``."""
    s, info = _native.digit(_image(pixels, "pixels"), target_iou,
                            _whole(max_strokes, "max_strokes", _U64),
                            _whole(max_segments, "max_segments", _U64), _whole(scale, "scale"))
    return Scene(_native_scene=s), info


def glyph(target, iou: float = 0.99, max_segments: int = 64,
          iters: int = 150) -> Tuple["Scene", GlyphInfo]:
    """A closed outline fitted to a rendered glyph (premultiplied RGBA, dark ink), the
    fewest cubic segments reaching ``iou``; ``(scene, info)``."""
    s, info = _native.glyph(_image(target, "target"), iou,
                            _whole(max_segments, "max_segments", _U64),
                            _whole(iters, "iters", _U64))
    return Scene(_native_scene=s), info


def _each(fn, items, progress: Progress, kwargs):
    out = []
    for i, item in enumerate(items):
        scene, info = fn(item, **kwargs)
        out.append((scene, info))
        if progress is not None and progress({"index": i, **info}) is False:
            break
    return out


def digits(images, progress: Progress = None, **kwargs) -> List[Tuple["Scene", DigitInfo]]:
    """:func:`digit` over a stack of digits (``(n, h, w)`` in [0, 1]); a list of
    ``(scene, info)``. ``progress`` sees each digit's info with its ``index``; returning
    ``False`` stops after that digit."""
    return _each(digit, images, progress, kwargs)


def glyphs(images, progress: Progress = None, **kwargs) -> List[Tuple["Scene", GlyphInfo]]:
    """:func:`glyph` over several glyph images; a list of ``(scene, info)``, ``progress``
    as in :func:`digits`."""
    return _each(glyph, images, progress, kwargs)


def recon_voxel(scene, output, *, res: int = 128, iters: int = 3000, batch: int = 8192,
                downscale: int = 1, degree: int = 2, bound: Optional[float] = None,
                step: float = 0.5, tv_density: Optional[float] = None,
                tv_sh: Optional[float] = None, sparsity: Optional[float] = None,
                seed: int = 0, eval_every: int = 0, test_every: Optional[int] = None,
                test_list=None, refine_poses: bool = False,
                perturb_poses: Optional[Tuple[float, float]] = None,
                align_test_poses: bool = False,
                progress: Progress = None) -> ReconInfo:
    """Fits a sparse voxel grid of density and spherical-harmonic color (Plenoxels) to
    the posed photos in the folder ``scene`` and writes it to ``output`` (``.vox``),
    exactly as ``diffsvg recon voxel`` with the same options (same file, bit for bit).

    ``res``: final cells per axis (training starts at 64³ or coarser and doubles);
    ``batch``: rays per iteration; ``bound``: half the box's side in world units (default
    from the cameras); ``step``: sample spacing in voxels; ``tv_density``, ``tv_sh``,
    ``sparsity``: regularization weights (default by kind of dataset). ``progress(step)``
    runs after every iteration with ``iteration``, ``loss``, ``psnr`` (batch, dB),
    ``rays_per_second``, ``res``, ``allocated``, ``seconds`` and ``test_psnr`` (``None``
    unless this iteration evaluated the test views, every ``eval_every``); returning
    ``False`` stops, and the model so far is written. ``test_every`` and ``test_list``
    choose the test views of instant-ngp and COLMAP folders, as for :func:`recon_splat`.

    Returns a dict: ``output``, ``iterations``, ``stopped``, ``seconds`` (training),
    ``load_seconds``, ``test_psnr`` (mean over the test views, dB; ``None`` without any),
    ``res``, ``allocated`` (voxel slots), ``batch`` (rays per iteration used) and ``log``:
    rows of iteration, seconds, res, allocated, batch PSNR, test PSNR (NaN where not
    evaluated), one per 50 iterations and per evaluation, the last the end of the run.

    ``refine_poses``: learn a small correction of each training view's camera pose (a turn
    about its center and a move); test views keep theirs. ``perturb_poses=(degrees,
    units)``: a testing aid that first moves every training camera by a random turn and
    move of those sizes; the dict's ``pose_error`` is then ``{"before": (degrees, units),
    "after": (degrees, units), "after_in_frame": …, "frame": …}``, the mean distance of the
    training poses from the loaded ones before and after training, after it once the
    whole scene's rigid motion that photos cannot tell is removed, and that motion's size
    (else ``None``); ``test_psnr_in_frame`` is the test PSNR with the test cameras carried
    by that motion into the model's frame (else ``None``).

    ``align_test_poses``: after training, also score the test views with each camera
    aligned to the model held fixed (test-time pose alignment, the protocol of
    pose-refining reconstructions; score the runs you compare alike):
    ``test_psnr_aligned`` (dB) and ``test_pose_turn`` (the mean turn it took, degrees),
    else ``None``.
    """
    return _native.recon_voxel(
        os.fspath(scene), os.fspath(output), _whole(res, "res"), _whole(iters, "iters", _U64),
        _whole(batch, "batch", _U64), _whole(downscale, "downscale"), _whole(degree, "degree"),
        bound, step, tv_density, tv_sh, sparsity, _whole(seed, "seed", _U64),
        _whole(eval_every, "eval_every", _U64),
        _whole_or_none(test_every, "test_every", _U64), _path_or_none(test_list),
        bool(refine_poses), _pair(perturb_poses), bool(align_test_poses), progress)


def recon_splat(scene, output, *, iters: int = 5000, downscale: int = 1,
                max_gaussians: int = 300_000, initial: int = 50_000, degree: int = 3,
                bound: Optional[float] = None, seed: int = 0, eval_every: int = 0,
                test_every: Optional[int] = None, test_list=None, antialias: bool = False,
                exposure: bool = False, mcmc: bool = False, refine_poses: bool = False,
                perturb_poses: Optional[Tuple[float, float]] = None,
                progress: Progress = None) -> ReconInfo:
    """Fits 3D Gaussians (splatting) to the posed photos in ``scene`` and writes them to
    ``output`` (``.ply``, the layout Gaussian-splatting viewers read), as ``diffsvg recon
    splat``. Photos with lens distortion are undistorted first. The model starts from the
    folder's point cloud or from ``initial`` random Gaussians in the box ``bound``.

    ``progress(step)`` runs after every iteration with ``iteration``, ``loss``, ``psnr``
    (this view, dB), ``gaussians``, ``sh_degree``, ``seconds`` and ``test_psnr``
    (as in :func:`recon_voxel`). Returns a dict: ``output``, ``iterations``, ``stopped``,
    ``seconds``, ``load_seconds``, ``test_psnr``, ``gaussians``, ``undistorted`` (the
    fraction of pixels that fell outside the photos when they were undistorted, else
    ``None``) and ``log``: rows of iteration, seconds, gaussians, SH degree, view PSNR,
    test PSNR (NaN where not evaluated).

    ``test_every``: hold out every N-th view of instant-ngp and COLMAP folders (0: none;
    default every 8th); or ``test_list``: a file naming the test views, one a line (as
    ``--test-list``; the ``to_colmap`` example writes the source's as ``test.txt``).
    ``antialias``: anti-aliased splats, saved with the model. ``exposure``: learn a
    per-image color transform of each training photo. ``mcmc``: a fixed budget of
    ``max_gaussians`` by relocation. ``refine_poses``, ``perturb_poses``
    and ``pose_error``: as in :func:`recon_voxel`. As the CLI's flags of the same names.
    """
    return _native.recon_splat(
        os.fspath(scene), os.fspath(output), _whole(iters, "iters", _U64),
        _whole(downscale, "downscale"), _whole(max_gaussians, "max_gaussians", _U64),
        _whole(initial, "initial", _U64), _whole(degree, "degree"), bound,
        _whole(seed, "seed", _U64), _whole(eval_every, "eval_every", _U64),
        _whole_or_none(test_every, "test_every", _U64), _path_or_none(test_list),
        bool(antialias), bool(exposure), bool(mcmc), bool(refine_poses), _pair(perturb_poses),
        progress)


def recon_ngp(scene, output, *, iters: int = 2000, seconds: float = 0.0, batch: int = 8192,
              samples: int = 65536, downscale: int = 1, bound: Optional[float] = None,
              steps: int = 512, levels: int = 16, log2_table: int = 16, min_res: int = 16,
              max_res: int = 1024, width: int = 64, lr: Tuple[float, float] = (1e-2, 1e-3),
              seed: int = 0, eval_every: int = 0, test_every: Optional[int] = None,
              test_list=None, progress: Progress = None) -> ReconInfo:
    """Fits an Instant-NGP neural field (a multiresolution hash grid and tiny MLPs) to the
    posed photos in ``scene`` and writes it to ``output`` (``.ngp``), exactly as ``diffsvg
    recon ngp`` with the same options (same file, bit for bit, for a fixed ``iters`` and
    ``seconds=0``).

    ``seconds``: a training time budget (0: none; the learning rate ``lr = (start, end)``
    then decays over it). ``samples``: network evaluations aimed at per iteration (at most
    ``batch`` rays); ``steps``: samples along the box's diagonal; ``levels``,
    ``log2_table``, ``min_res``, ``max_res``: the hash grid; ``width``: neurons per hidden
    layer. ``progress(step)`` runs after every iteration with ``iteration``, ``loss``,
    ``psnr``, ``samples_per_second``, ``occupied``, ``seconds`` and ``test_psnr`` (as in
    :func:`recon_voxel`).

    Returns a dict: ``output``, ``iterations``, ``stopped``, ``seconds``,
    ``load_seconds``, ``test_psnr``, ``samples``, ``samples_per_second``, ``parameters``,
    ``occupied`` (fraction of occupancy cells kept), ``pose_error`` (``None``) and
    ``log``: rows of iteration, seconds, samples, samples per second, batch PSNR, test PSNR.
    """
    return _native.recon_ngp(
        os.fspath(scene), os.fspath(output), _whole(iters, "iters", _U64), seconds,
        _whole(batch, "batch", _U64), _whole(samples, "samples", _U64),
        _whole(downscale, "downscale"), bound, _whole(steps, "steps"),
        _whole(levels, "levels"), _whole(log2_table, "log2_table"),
        _whole(min_res, "min_res"), _whole(max_res, "max_res"), _whole(width, "width"),
        _pair(lr, "lr", "(start, end)"), _whole(seed, "seed", _U64), _whole(eval_every, "eval_every", _U64),
        _whole_or_none(test_every, "test_every", _U64), _path_or_none(test_list), progress)


def recon_nerf(scene, output, *, iters: int = 2000, seconds: float = 0.0, batch: int = 8192,
               samples: int = 16384, downscale: int = 1, bound: Optional[float] = None,
               steps: int = 256, frequencies: int = 10, width: int = 64,
               density_layers: int = 4, color_layers: int = 1,
               lr: Tuple[float, float] = (2e-3, 2e-4), seed: int = 0, eval_every: int = 0,
               test_every: Optional[int] = None, test_list=None,
               progress: Progress = None) -> ReconInfo:
    """Fits a NeRF field (NeRF's positional encoding of ``frequencies`` octaves and an MLP
    of ``density_layers`` and ``color_layers`` hidden layers of ``width``) to the posed
    photos in ``scene`` and writes it to ``output`` (``.nerf``), exactly as ``diffsvg
    recon nerf``. Slow: the ladder's first rung. Options, progress and the returned dict
    as :func:`recon_ngp`'s.
    """
    return _native.recon_nerf(
        os.fspath(scene), os.fspath(output), _whole(iters, "iters", _U64), seconds,
        _whole(batch, "batch", _U64), _whole(samples, "samples", _U64),
        _whole(downscale, "downscale"), bound, _whole(steps, "steps"),
        _whole(frequencies, "frequencies"), _whole(width, "width"),
        _whole(density_layers, "density_layers"), _whole(color_layers, "color_layers"),
        _pair(lr, "lr", "(start, end)"), _whole(seed, "seed", _U64), _whole(eval_every, "eval_every", _U64),
        _whole_or_none(test_every, "test_every", _U64), _path_or_none(test_list), progress)


def view(model, scene=None, *, split: str = "test", orbit: int = 0, elevation: float = 30.0,
         downscale: int = 1, step: float = 0.5, depth: bool = False,
         test_every: Optional[int] = None, test_list=None) -> Views:
    """Renders a trained model (``.vox`` or Gaussian ``.ply``, told apart by its header)
    as ``diffsvg view`` does, into arrays: from the cameras of the dataset ``scene``'s
    ``split`` views ("test" or "train"), and from ``orbit`` new cameras around the model
    (a circle raised by ``elevation`` degrees; for real photos, the arc their cameras
    span). ``step``: sample spacing in voxels (voxel models). ``test_every`` and
    ``test_list`` choose the test views of instant-ngp and COLMAP folders as the training
    run did (as for :func:`recon_splat`).

    Returns a dict: ``views``, a list of ``(name, rendering, photo)``, and ``orbit``, a
    list of renderings; each an ``(h, w, 3)`` ``float32`` array of linear RGB, unclamped.
    With ``depth=True`` (Gaussian and voxel models), also ``depth`` and ``orbit_depth``:
    per view and per orbit camera, in the same order, a dict of ``expected`` and ``median``
    ``(h, w)`` ``float32`` depth images in world units along the viewing axis (0 where
    nothing was hit), the values ``diffsvg view --depth`` writes as ``.npy``.
    """
    _flag(depth, "depth")
    return _native.view(os.fspath(model), None if scene is None else os.fspath(scene),
                        split, _whole(orbit, "orbit", _U64), elevation,
                        _whole(downscale, "downscale"), step, depth,
                        _whole_or_none(test_every, "test_every", _U64),
                        _path_or_none(test_list))
