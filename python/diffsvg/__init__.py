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
* **3D** (``recon_voxel``, ``recon_splat``): a posed-photo folder (NeRF-synthetic or
  instant-ngp) in, a model file out, as ``diffsvg recon``; ``diffsvg view`` renders it.
* **Errors.** Bad input raises ``DiffsvgError`` (a ``ValueError``), ``FileNotFoundError``
  or ``OSError`` with one line naming the file or argument; nothing panics.
"""

from __future__ import annotations

import os
from typing import Any, Callable, Optional, Sequence

import numpy as np

from . import _native
from ._native import DiffsvgError

__all__ = [
    "DiffsvgError",
    "Scene",
    "render",
    "render_backward",
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
    "view",
]

Color = Optional[Sequence[float]]


def _image(x: Any, name: str) -> np.ndarray:
    """A C-contiguous float32 view (or copy, when the dtype or layout differs)."""
    a = np.asarray(x)
    if a.dtype.kind not in "fiu":
        raise DiffsvgError(f"{name}: expected a numeric array, got dtype {a.dtype}")
    return np.ascontiguousarray(a, dtype=np.float32)


def _color(c: Color, name: str):
    if c is None:
        return None
    t = tuple(float(v) for v in c)
    if len(t) == 3:
        t = t + (1.0,)
    if len(t) != 4:
        raise DiffsvgError(f"{name}: expected (r, g, b) or (r, g, b, a), got {c!r}")
    return t


def _paint_size(entry: dict) -> int:
    return entry["len"]


class Scene:
    """A vector scene: paths with fills and strokes (solid or gradient paints; an
    ``<image>`` is its rectangle filled with the image's fixed pixels) in groups.

    Build one with :meth:`load` or :meth:`from_svg`; ``Scene(width, height)`` is empty.
    """

    __slots__ = ("_s", "_structure")

    def __init__(self, width: int = 0, height: int = 0, *, _native_scene=None):
        self._s = _native_scene if _native_scene is not None else _native.Scene(width, height)
        self._structure = None

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
            os.fspath(path), width, height, scale, [os.fspath(f) for f in fonts],
            [os.fspath(d) for d in font_dirs], font_fallback))

    @classmethod
    def from_svg(cls, text: str, width: Optional[int] = None, height: Optional[int] = None,
                 scale: Optional[float] = None, name: str = "<string>") -> "Scene":
        """Parses SVG text; ``name`` is what error messages call it."""
        return cls(_native_scene=_native.Scene.from_svg(text, width, height, scale, name))

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
        return self._s.params()

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
            cur = self._s.params()
            if cur.shape == v.shape:
                v = np.where(cur.astype(np.float32) == v, cur, v.astype(np.float64))
        self._s.set_params(np.ascontiguousarray(v, dtype=np.float64))

    def layout(self) -> dict:
        """Per slot of :meth:`params`: ``group`` (index into ``group_names``: points,
        colors, opacities, widths, paint, stops) and ``owner`` (index into ``owners``,
        dicts with ``id`` and ``kind``)."""
        return self._s.layout()

    def structure(self) -> dict:
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
            off, n = sh["points"]
            out.append((off, 2 * n, ("shapes", i, "points"), (n, 2)))
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
        return {"shapes": shapes, "groups": [{} for _ in st["groups"]]}

    def unflatten(self, flat, dtype=np.float32) -> dict:
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

    def arrays(self, dtype=np.float32) -> dict:
        """The parameters per shape, as DiffVG names them::

            {"shapes": [{"points": (n, 2),           # every control point, cubic segments
                         "fill": (4,)                # solid: r, g, b, opacity
                              | {"geometry": (4,)    # linear: x1, y1, x2, y2
                                             (6,),   # radial: cx, cy, r, fx, fy, fr
                                 "stops": (k, 5),    # offset, r, g, b, opacity
                                 "opacity": ()}
                              | {"opacity": ()},     # image: its pixels are fixed
                         "stroke": ...,              # as fill
                         "stroke_width": ()}, ...],
             "groups": [{"opacity": ()}, ...]}

        A key is absent when the shape has no such paint. Every segment is a cubic:
        point ``3k`` starts segment ``k`` of a subpath and ``3k+1``, ``3k+2`` are its
        control points (a line's at 1/3 and 2/3). The structure is a pytree for JAX.
        """
        return self.unflatten(self._s.params(), dtype)

    def flatten(self, arrays, xp=np):
        """The inverse of :meth:`arrays`: one vector in :meth:`params` layout; ``xp`` is
        the array module (``numpy`` or ``jax.numpy``, which keeps it differentiable)."""
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

    def grad_json(self, grad) -> dict:
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
        return {"shapes": shapes, "groups": groups}


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
           background: Color = None, tolerance: float = 0.02) -> np.ndarray:
    """Renders ``scene`` into a ``(height, width, 4)`` ``float32`` array of
    **premultiplied** RGBA in ``[0, 1]``, y down.

    ``width`` (and ``height``) render at another size: the scene is scaled uniformly by
    ``width / scene.width``. ``background`` (straight (r, g, b[, a])) is composited under
    the drawing. ``tolerance`` is the largest curve-to-chord distance in pixels. The GIL
    is released while rendering; the pixels are moved into numpy, not copied.
    """
    return _native.render(_scene(scene), width, height, _color(background, "background"),
                          tolerance)


def render_backward(scene: Scene, d_image, background: Color = None,
                    tolerance: float = 0.02, structured: bool = True, dtype=np.float32):
    """The exact gradient of a loss with respect to every parameter of ``scene``, given
    ``d_image = dL/d(image)`` (``(height, width, 4)``, the scene's size).

    With ``background``, ``d_image`` is the gradient with respect to the image composited
    over it (as :func:`render` returns it). Returns the structure of
    :meth:`Scene.arrays` (of ``dtype``), or with ``structured=False`` a ``float64`` vector
    in :meth:`Scene.params` layout. The GIL is released while it runs.
    """
    g = _native.render_backward(_scene(scene), _image(d_image, "d_image"),
                                _color(background, "background"), tolerance)
    return scene.unflatten(g, dtype) if structured else g


def loss(image, target, kind: str = "mse", grad: bool = False):
    """The mean over pixels and the four premultiplied channels of the squared
    (``kind="mse"``) or absolute (``"l1"``) difference, as ``float``; with ``grad``,
    ``(loss, dL/d(image))``."""
    v, d = _native.loss(_image(image, "image"), _image(target, "target"), kind, grad)
    return (v, d) if grad else v


def psnr(image, target) -> float:
    """Peak signal-to-noise ratio in dB over all four channels (values in [0, 1])."""
    mse = float(np.mean((np.asarray(image, np.float64) - np.asarray(target, np.float64)) ** 2))
    return float("inf") if mse == 0 else -10.0 * np.log10(mse)


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
    return _native.load_target(os.fspath(path), width, height)


def save_png(image, path) -> None:
    """Writes a premultiplied RGBA image as an 8-bit PNG (temporary file, renamed)."""
    _native.save_png(_image(image, "image"), os.fspath(path))


# ----- long jobs ------------------------------------------------------------------------
Progress = Optional[Callable[[dict], Any]]


def _target_for(target, width: int, height: int) -> np.ndarray:
    if isinstance(target, (str, os.PathLike)):
        return load_target(target, width, height)
    return _image(target, "target")


def fit(scene: Scene, target, iters: int = 500, *, lr_points: float = 1.0,
        lr_color: float = 0.01, lr_opacity: float = 0.01, lr_width: float = 0.1,
        lr_paint: float = 0.5, lr_stops: float = 0.005, schedule: str = "constant",
        loss: str = "mse", background: Color = None, pyramid: int = 1,
        until_psnr: Optional[float] = None, tolerance: float = 0.02,
        progress: Progress = None):
    """Refines every parameter of ``scene`` toward ``target`` with exact gradients and
    Adam (as ``diffsvg fit``); returns ``(best scene, info)``.

    ``target``: a premultiplied ``(h, w, 4)`` array of the scene's size, or a file (PNG,
    JPEG or SVG), resampled to the scene's size. Learning rates are per step in each
    group's units (pixels for points and gradient geometry). ``background`` (straight
    RGB[A]) is composited under render and target before comparing (opaque: over RGB
    only). ``progress(step)`` is called after every evaluation with ``iter``, ``loss``,
    ``psnr``, ``seconds``; returning ``False`` or raising stops the run (an exception is
    re-raised once the GIL is back; Ctrl-C raises KeyboardInterrupt the same way).
    ``info`` has ``loss``, ``psnr``, ``steps``, ``reason``, the median ``step_ms`` (render,
    loss and gradient of one step), ``final_loss``, ``seconds`` and ``history`` (rows of
    iter, loss, psnr, seconds).
    """
    t = _target_for(target, scene.width, scene.height)
    options = dict(lr_points=lr_points, lr_color=lr_color, lr_opacity=lr_opacity,
                   lr_width=lr_width, lr_paint=lr_paint, lr_stops=lr_stops,
                   schedule=schedule, loss=loss, background=_color(background, "background"),
                   pyramid=pyramid, tolerance=tolerance)
    s, info = _native.fit(_scene(scene), t, iters, until_psnr, options, progress)
    return Scene(_native_scene=s), info


def vectorize(target, paths: int = 64, mode: str = "adaptive", iters: int = 1000, *,
              seed: int = 0, target_psnr: Optional[float] = None, segments: int = 4,
              width: Optional[int] = None, background: Color = None,
              progress: Progress = None, **rates):
    """An SVG scene from a picture (as ``diffsvg vectorize``); returns ``(scene, info)``.

    ``mode``: "adaptive" (paths added in rounds where the error is largest, pruned),
    "fixed" (DiffVG's random blobs), "painterly" (random strokes) or "trace" (vtracer).
    ``target``: a premultiplied array or a file; ``width`` resamples a file to that width.
    ``rates``: ``lr_points`` … ``lr_stops``, ``schedule``, ``loss``, ``pyramid``,
    ``tolerance`` as in :func:`fit`. ``progress`` sees rounds (``round``, ``paths``) and
    evaluations (``iter``, ``loss``, ``psnr``, ``seconds``, ``paths``).
    """
    if isinstance(target, (str, os.PathLike)):
        t = load_target(target)
        if width is not None:
            h = max(1, round(t.shape[0] * width / t.shape[1]))
            t = load_target(target, width, h)
    else:
        t = _image(target, "target")
    options = dict(rates, background=_color(background, "background"))
    s, info = _native.vectorize(t, paths, mode, iters, seed, target_psnr, segments, options,
                                progress)
    return Scene(_native_scene=s), info


def random_blobs(n: int, width: int, height: int, seed: int = 0) -> Scene:
    """DiffVG's painterly blobs: ``n`` closed random-walk paths of 3-5 cubics with random
    RGBA fills (the scene of ``diffsvg bench painterly`` for the same seed)."""
    return Scene(_native_scene=_native.random_blobs(n, width, height, seed))


def random_strokes(n: int, width: int, height: int, seed: int = 0) -> Scene:
    """DiffVG's painterly strokes: ``n`` open random-walk paths, 1 px wide."""
    return Scene(_native_scene=_native.random_strokes(n, width, height, seed))


def digit(pixels, target_iou: float = 0.85, max_strokes: int = 2, max_segments: int = 3,
          scale: int = 2):
    """White strokes fitted to one grayscale digit (``(h, w)`` in [0, 1], ink bright, e.g.
    an MNIST image / 255), the fewest curves reaching ``target_iou``; ``(scene, info)``."""
    s, info = _native.digit(_image(pixels, "pixels"), target_iou, max_strokes, max_segments,
                            scale)
    return Scene(_native_scene=s), info


def glyph(target, iou: float = 0.99, max_segments: int = 64, iters: int = 150):
    """A closed outline fitted to a rendered glyph (premultiplied RGBA, dark ink), the
    fewest cubic segments reaching ``iou``; ``(scene, info)``."""
    s, info = _native.glyph(_image(target, "target"), iou, max_segments, iters)
    return Scene(_native_scene=s), info


def _each(fn, items, progress: Progress, kwargs):
    out = []
    for i, item in enumerate(items):
        scene, info = fn(item, **kwargs)
        out.append((scene, info))
        if progress is not None and progress({"index": i, **info}) is False:
            break
    return out


def digits(images, progress: Progress = None, **kwargs):
    """:func:`digit` over a stack of digits (``(n, h, w)`` in [0, 1]); a list of
    ``(scene, info)``. ``progress`` sees each digit's info with its ``index``; returning
    ``False`` stops after that digit."""
    return _each(digit, images, progress, kwargs)


def glyphs(images, progress: Progress = None, **kwargs):
    """:func:`glyph` over several glyph images; a list of ``(scene, info)``, ``progress``
    as in :func:`digits`."""
    return _each(glyph, images, progress, kwargs)


def recon_voxel(scene, output, *, res: int = 128, iters: int = 3000, batch: int = 8192,
                downscale: int = 1, degree: int = 2, bound: Optional[float] = None,
                step: float = 0.5, tv_density: Optional[float] = None,
                tv_sh: Optional[float] = None, sparsity: Optional[float] = None,
                seed: int = 0, eval_every: int = 0, progress: Progress = None) -> dict:
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
    ``False`` stops, and the model so far is written.

    Returns a dict: ``output``, ``iterations``, ``stopped``, ``seconds`` (training),
    ``load_seconds``, ``test_psnr`` (mean over the test views, dB; ``None`` without any),
    ``res``, ``allocated`` (voxel slots), ``batch`` (rays per iteration used) and ``log``:
    rows of iteration, seconds, res, allocated, batch PSNR, test PSNR (NaN where not
    evaluated), one per 50 iterations and per evaluation, the last the end of the run.
    """
    return _native.recon_voxel(
        os.fspath(scene), os.fspath(output), res, iters, batch, downscale, degree, bound,
        step, tv_density, tv_sh, sparsity, seed, eval_every, progress)


def recon_splat(scene, output, *, iters: int = 5000, downscale: int = 1,
                max_gaussians: int = 300_000, initial: int = 50_000, degree: int = 3,
                bound: Optional[float] = None, seed: int = 0, eval_every: int = 0,
                progress: Progress = None) -> dict:
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
    """
    return _native.recon_splat(
        os.fspath(scene), os.fspath(output), iters, downscale, max_gaussians, initial,
        degree, bound, seed, eval_every, progress)


def view(model, scene=None, *, split: str = "test", orbit: int = 0, elevation: float = 30.0,
         downscale: int = 1, step: float = 0.5) -> dict:
    """Renders a trained model (``.vox`` or Gaussian ``.ply``, told apart by its header)
    as ``diffsvg view`` does, into arrays: from the cameras of the dataset ``scene``'s
    ``split`` views ("test" or "train"), and from ``orbit`` new cameras around the model
    (a circle raised by ``elevation`` degrees; for real photos, the arc their cameras
    span). ``step``: sample spacing in voxels (voxel models).

    Returns a dict: ``views``, a list of ``(name, rendering, photo)``, and ``orbit``, a
    list of renderings; each an ``(h, w, 3)`` ``float32`` array of linear RGB, unclamped.
    """
    return _native.view(os.fspath(model), None if scene is None else os.fspath(scene),
                        split, orbit, elevation, downscale, step)
