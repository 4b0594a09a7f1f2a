"""diffsvg inside JAX: :func:`render` is differentiable with respect to a scene's parameters.

::

    import jax, jax.numpy as jnp, diffsvg, diffsvg.jax
    scene = diffsvg.Scene.load("svg-samples/10-logo.svg")
    target = jnp.asarray(diffsvg.render(scene))
    x = jnp.asarray(scene.params(), jnp.float32)         # the flat vector: the fast path
    def loss(x):
        img = diffsvg.jax.render(scene, x)               # (h, w, 4) premultiplied float32
        return jnp.mean((img - target) ** 2)
    g = jax.jit(jax.grad(loss))(x)                       # same shape as x

The parameters are **one flat vector** in the layout of :meth:`diffsvg.Scene.params`, so a
jitted step has one input and two custom calls, and compiles in the same time for 10 paths
or 10,000. :func:`params` gives the same vector as a :class:`Params`, a pytree with that
one leaf that reads per shape (``p["shapes"][3]["points"]``) by slicing; optimizers
(optax) see one array. A dict in the structure of :meth:`diffsvg.Scene.arrays` is accepted
too, but it is one leaf per array and its compile time grows with the number of shapes.

The forward pass and the exact backward pass run in diffsvg on the CPU as two **XLA FFI
custom calls** (``jax.ffi.ffi_call`` of the handlers in ``python/src/ffi.rs``, registered
when this module is imported): XLA calls diffsvg directly, without Python, the GIL or
numpy in between, so the jitted step costs little more than the numpy calls (see
docs/python.md, "JAX"). The scene gives the topology (paths, segment kinds, paint kinds),
the vector the values: a scene used here is registered in the native module under an id
(the calls' ``scene`` attribute) as a copy that follows the scene's changes
(``set_params``, shapes added, removed, reordered; each then copies the scene once more)
and is dropped with the scene. Under ``jax.vmap`` a batch of vectors (scenes of one
structure) is one call that renders the rows in parallel. ``float32`` vectors keep the
scene's ``float64`` values wherever they equal their ``float32`` rounding (see
:meth:`diffsvg.Scene.set_params`); with ``jax_enable_x64`` and ``float64`` vectors the
values are exact; other float dtypes go through ``float32``. The image and the gradient
are the bits :func:`diffsvg.render` and :func:`diffsvg.render_backward` give.

Errors: everything about the call's structure (the vector's length and dtype, the arrays'
structure, ``background``, ``tolerance``) is checked while tracing, so a bad call raises
the package's one-line :class:`diffsvg.DiffsvgError` at the call, under ``jit`` too. Values
are known only when the step runs: outside ``jit`` a non-finite parameter raises the same
error; inside ``jit`` the image and the gradient of a row with a non-finite value (or
``d_image`` value) come out NaN, as JAX's own functions do, with a one-line
:class:`DiffsvgWarning` naming the slot, which the custom call issues taking the GIL
(``jax.config.update("jax_debug_nans", True)`` then stops at that step). A failure the
custom call cannot turn into NaN (a scene whose structure changed after the step was
compiled) raises ``JaxRuntimeError`` carrying diffsvg's one-line message.
"""

from __future__ import annotations

import ctypes
import functools
import warnings
import weakref
from collections.abc import Mapping
from typing import Any, Optional, Sequence, Tuple

import jax
import jax.numpy as jnp
import numpy as np

from . import DiffsvgError, Scene, _color, _flag, _native, _scene
from ._types import Arrays

__all__ = ["render", "render_flat", "over", "params", "Params", "DiffsvgWarning"]


class DiffsvgWarning(UserWarning):
    """A value diffsvg refused inside ``jax.jit``, where it renders as NaN instead (issued
    by the native custom call, which imports this class by name)."""


# ----- the per-shape view of the flat vector --------------------------------------------
class _Layout:
    """Where each array of :meth:`diffsvg.Scene.arrays` lies in the flat vector: static
    data of a :class:`Params` (equal layouts compare equal, so ``jit`` reuses a compiled
    step for every vector of a scene's structure)."""

    __slots__ = ("pieces", "size", "shapes", "groups", "transforms", "filters", "_hash",
                 "_by_owner")

    def __init__(self, scene: Scene):
        st = scene.structure()
        self.pieces = tuple((off, size, key, shape) for off, size, key, shape in scene._pieces())
        self.size = sum(p[1] for p in self.pieces)
        self.shapes = len(st["shapes"])
        self.groups = len(st["groups"])
        self.transforms = len(st["transforms"])
        self.filters = len(st["filters"])
        self._hash = hash(self.pieces)
        self._by_owner: dict = {}
        for off, size, key, shape in self.pieces:
            self._by_owner.setdefault(key[:2], []).append((key[2:], off, size, shape))

    def __eq__(self, other) -> bool:
        return self is other or (isinstance(other, _Layout) and self._hash == other._hash
                                 and self.pieces == other.pieces)

    def __hash__(self) -> int:
        return self._hash

    def view(self, flat, kind: str, i: int) -> dict:
        """Shape or group ``i``'s arrays, slices of ``flat``."""
        out: dict = {}
        for key, off, size, shape in self._by_owner.get((kind, i), ()):
            node = out
            for k in key[:-1]:
                node = node.setdefault(k, {})
            node[key[-1]] = jnp.reshape(flat[off:off + size], shape)
        return out

    def find(self, key: Tuple) -> Tuple[int, int, tuple]:
        for off, size, k, shape in self.pieces:
            if k == key:
                return off, size, shape
        raise DiffsvgError(f"params: no array {'/'.join(map(str, key))} in the scene")


_LAYOUTS: "weakref.WeakKeyDictionary[Scene, _Layout]" = weakref.WeakKeyDictionary()


def _layout(scene: Scene) -> _Layout:
    _scene(scene)
    lay = _LAYOUTS.get(scene)
    if lay is None:
        lay = _LAYOUTS[scene] = _Layout(scene)
    return lay


class _Owners(Sequence):
    """``p["shapes"]`` or ``p["groups"]``: one dict of slices per shape or group."""

    def __init__(self, p: "Params", kind: str, n: int) -> None:
        self._p, self._kind, self._n = p, kind, n

    def __len__(self) -> int:
        return self._n

    def __getitem__(self, i):  # noqa: ANN001 - int or slice, as a Sequence's
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(self._n))]
        j = i + self._n if i < 0 else i
        if not 0 <= j < self._n:
            raise IndexError(f"{self._kind}: index {i} out of range ({self._n})")
        return self._p._layout.view(self._p.flat, self._kind, j)


@jax.tree_util.register_pytree_node_class
class Params:
    """A scene's parameters as one flat vector (``flat``, the layout of
    :meth:`diffsvg.Scene.params`) that reads like :meth:`diffsvg.Scene.arrays`:
    ``p["shapes"][i]["points"]`` is an ``(n, 2)`` slice of ``flat``, and so on for
    ``fill``, ``stroke``, ``stroke_width`` and ``p["groups"][j]["opacity"]``.

    A pytree with the one leaf ``flat``: ``jax.grad`` with respect to a ``Params`` gives a
    ``Params`` (read per shape the same way), ``jax.tree.map`` and optax update the one
    vector, and a jitted step compiles in the same time whatever the number of shapes.
    """

    __slots__ = ("flat", "_layout")

    def __init__(self, flat: jax.Array, layout: _Layout) -> None:
        self.flat = flat
        self._layout = layout

    def tree_flatten(self) -> Tuple[Tuple[jax.Array], _Layout]:
        return (self.flat,), self._layout

    @classmethod
    def tree_unflatten(cls, layout: _Layout, children: Sequence[jax.Array]) -> "Params":
        return cls(children[0], layout)

    def __getitem__(self, key: str) -> _Owners:
        if key == "shapes":
            return _Owners(self, "shapes", self._layout.shapes)
        if key == "groups":
            return _Owners(self, "groups", self._layout.groups)
        if key == "transforms" and self._layout.transforms:
            return _Owners(self, "transforms", self._layout.transforms)
        if key == "filters" and self._layout.filters:
            return _Owners(self, "filters", self._layout.filters)
        raise KeyError(key)

    def keys(self) -> Tuple[str, ...]:
        keys = ("shapes", "groups")
        if self._layout.transforms:
            keys += ("transforms",)
        if self._layout.filters:
            keys += ("filters",)
        return keys

    def arrays(self) -> Arrays:
        """Every shape's and group's arrays as a dict (the structure of
        :meth:`diffsvg.Scene.arrays`), slices of ``flat``."""
        return {k: list(self[k]) for k in self.keys()}

    def set(self, key: Tuple, value) -> "Params":
        """A copy with the array at ``key`` (e.g. ``("shapes", 0, "fill")``) replaced."""
        off, size, shape = self._layout.find(tuple(key))
        v = jnp.asarray(value, dtype=self.flat.dtype)
        if v.shape != shape:
            raise DiffsvgError(f"params: {'/'.join(map(str, key))} has shape {shape}, "
                               f"got {v.shape}")
        return Params(self.flat.at[off:off + size].set(jnp.reshape(v, (size,))), self._layout)

    def __repr__(self) -> str:
        return (f"Params({self._layout.size} values, {self._layout.shapes} shapes, "
                f"{self._layout.groups} groups, dtype {getattr(self.flat, 'dtype', '?')})")


def params(scene: Scene, dtype=jnp.float32, arrays: Any = None) -> Params:
    """The parameters of ``scene`` (or of ``arrays``, the structure of
    :meth:`diffsvg.Scene.arrays`) as a :class:`Params` of ``dtype``."""
    lay = _layout(scene)
    if arrays is None:
        flat = jnp.asarray(scene.params(), dtype=dtype)
    else:
        flat = jnp.asarray(scene.flatten(arrays, xp=jnp), dtype=dtype)
    return Params(flat, lay)


# ----- the custom calls -------------------------------------------------------------------
def _register_targets() -> bool:
    """Registers diffsvg's two XLA FFI handlers (``_native``'s ``diffsvg_ffi_render`` and
    ``diffsvg_ffi_render_backward``, see ``python/src/ffi.rs``) as CPU custom-call targets;
    False where this JAX cannot (no ``jax.ffi.ffi_call``: older than the FFI API)."""
    ffi = getattr(jax, "ffi", None)
    if ffi is None or not hasattr(ffi, "ffi_call"):
        return False
    lib = ctypes.CDLL(_native.__file__)
    for name in ("render", "render_backward"):
        ffi.register_ffi_target(f"diffsvg_{name}",
                                ffi.pycapsule(getattr(lib, f"diffsvg_ffi_{name}")),
                                platform="cpu")
    return True


#: Whether the custom calls are registered; where they are not, or JAX's default backend
#: is not the CPU (the handlers are CPU targets), the passes are ``jax.pure_callback``s
#: into the same native code instead (slower by the Python in between; same bits).
_FFI = _register_targets()


def _use_ffi() -> bool:
    return _FFI and jax.default_backend() == "cpu"


def _attributes(scene: Scene, background: Optional[tuple], tolerance: float,
                exact: bool) -> dict:
    """The custom calls' attributes: the scene's id in the native registry (its entry
    follows the scene's changes and goes when the scene is dropped), ``tolerance``,
    ``background`` (straight RGBA, when given) and ``exact_overlaps`` (1, when on)."""
    attrs = {"scene": np.uint64(_native.ffi_scene(_scene(scene))),
             "tolerance": np.float64(tolerance)}
    if background is not None:
        attrs["background"] = np.asarray(background, np.float32)
    if exact:
        attrs["exact_overlaps"] = np.int64(1)
    return attrs


def _native_dtype(flat):
    """``flat`` as the handlers take it: ``float32`` or ``float64`` (others as ``float32``)."""
    return flat if flat.dtype in (jnp.float32, jnp.float64) else flat.astype(jnp.float32)


def render_flat(scene: Scene, background: Optional[tuple], tolerance: float,
                flat: jax.Array) -> jax.Array:
    """:func:`render` of a flat vector with ``background`` (``None`` or straight
    ``(r, g, b, a)``) and ``tolerance`` given as they are, unchecked: the primitive under
    :func:`render`, kept for code written against it."""
    return _render_flat(scene, background, tolerance, False, flat)


@functools.partial(jax.custom_vjp, nondiff_argnums=(0, 1, 2, 3))
def _render_flat(scene: Scene, background: Optional[tuple], tolerance: float, exact: bool,
                 flat: jax.Array) -> jax.Array:
    """:func:`render_flat` with ``exact`` (``exact_overlaps``)."""
    return _forward(scene, background, tolerance, exact, flat)


def _forward(scene, background, tolerance, exact, flat):
    shape = jax.ShapeDtypeStruct((scene.height, scene.width, 4), jnp.float32)
    if not _use_ffi():
        cb = _callbacks(scene, background, tolerance, exact)[0]
        return jax.pure_callback(cb, shape, flat, vmap_method="broadcast_all")
    call = jax.ffi.ffi_call("diffsvg_render", shape, vmap_method="broadcast_all")
    return call(_native_dtype(jnp.asarray(flat)),
                **_attributes(scene, background, tolerance, exact))


def _fwd(scene, background, tolerance, exact, flat):
    return _forward(scene, background, tolerance, exact, flat), flat


def _bwd(scene, background, tolerance, exact, flat, d_image):
    if not _use_ffi():
        out = jax.ShapeDtypeStruct(flat.shape, flat.dtype)
        cb = _callbacks(scene, background, tolerance, exact)[1]
        return (jax.pure_callback(cb, out, flat, d_image, vmap_method="broadcast_all"),)
    x = _native_dtype(jnp.asarray(flat))
    out = jax.ShapeDtypeStruct(x.shape, x.dtype)
    call = jax.ffi.ffi_call("diffsvg_render_backward", out, vmap_method="broadcast_all")
    d = jnp.asarray(d_image, jnp.float32)
    g = call(x, d, **_attributes(scene, background, tolerance, exact))
    return (g.astype(flat.dtype),)


_render_flat.defvjp(_fwd, _bwd)


# ----- the fallback: pure_callbacks into the batch calls ---------------------------------
def _rows(scene: Scene, v: np.ndarray) -> np.ndarray:
    """Batched vectors as ``(batch, n)`` ``float64``, keeping each ``float64`` value of the
    scene whose ``float32`` rounding a ``float32`` vector holds."""
    v = np.asarray(v)
    rows = v.reshape(-1, v.shape[-1])
    if rows.dtype == np.float32:
        cur = scene._current()
        return np.where(cur.astype(np.float32) == rows, cur, rows.astype(np.float64))
    return np.ascontiguousarray(rows, dtype=np.float64)


def _warn_non_finite(bad: np.ndarray, rows: np.ndarray, what: str) -> None:
    """One warning naming the first non-finite value of the first bad row."""
    b = int(np.argmax(bad))
    where = f"row {b}, " if rows.shape[0] > 1 else ""
    r = rows[b].reshape(-1)
    i = int(np.argmax(~np.isfinite(r)))
    warnings.warn(DiffsvgWarning(
        f"diffsvg.jax.render: {what} {where}value {i} is {r[i]} (not finite); the result "
        "is NaN"), stacklevel=3)


def _forward_cb(scene, background, tolerance, exact, v):
    batch = v.shape[:-1]
    rows = _rows(scene, v)
    try:
        img = _native.render_batch(_scene(scene), rows, background, tolerance, exact)
    except DiffsvgError:
        # Inside jit a callback must not raise: rows with a non-finite value render NaN.
        bad = ~np.isfinite(rows).all(axis=1)
        if not bad.any():
            raise
        _warn_non_finite(bad, rows, "params")
        rows = rows.copy()
        rows[bad] = scene._current()
        img = _native.render_batch(_scene(scene), rows, background, tolerance, exact)
        img[bad] = np.nan
    return img.reshape(*batch, scene.height, scene.width, 4)


def _backward_cb(scene, background, tolerance, exact, v, d):
    batch = v.shape[:-1]
    rows = _rows(scene, v)
    d = np.ascontiguousarray(np.broadcast_to(d, (*batch, scene.height, scene.width, 4)),
                             dtype=np.float32).reshape(-1, scene.height, scene.width, 4)
    try:
        g = _native.render_backward_batch(_scene(scene), rows, d, background, tolerance,
                                          exact)
    except DiffsvgError:
        bad_p = ~np.isfinite(rows).all(axis=1)
        bad_d = ~np.isfinite(d).all(axis=(1, 2, 3))
        if not (bad_p | bad_d).any():
            raise
        if bad_p.any():
            _warn_non_finite(bad_p, rows, "params")
        else:
            _warn_non_finite(bad_d, d, "d_image")
        bad = bad_p | bad_d
        rows, d = rows.copy(), d.copy()
        rows[bad] = scene._current()
        d[bad] = 0
        g = _native.render_backward_batch(_scene(scene), rows, d, background, tolerance,
                                          exact)
        g[bad] = np.nan
    return g.reshape(*batch, rows.shape[1]).astype(v.dtype)


_CALLBACKS: "weakref.WeakKeyDictionary[Scene, dict]" = weakref.WeakKeyDictionary()


def _callbacks(scene, background, tolerance, exact):
    """The forward and backward callbacks of one scene and options, the same objects on
    every call: JAX caches what it compiles for a callback by the callable, so outside
    ``jit`` a new one per call would compile each step anew."""
    per_scene = _CALLBACKS.setdefault(scene, {})
    key = (background, tolerance, exact)
    if key not in per_scene:
        ref = weakref.ref(scene)  # not the scene itself: the cache must not keep it alive
        per_scene[key] = (
            lambda v: _forward_cb(ref(), background, tolerance, exact, v),
            lambda v, d: _backward_cb(ref(), background, tolerance, exact, v, d))
    return per_scene[key]


# ----- the entry point ---------------------------------------------------------------------
def _flat_of(scene: Scene, p) -> Any:
    lay = _layout(scene)
    if isinstance(p, Params):
        if p._layout != lay:
            raise DiffsvgError("params: a Params of another scene's structure "
                               f"({p._layout.size} values; this scene has {lay.size})")
        flat = p.flat
    elif isinstance(p, Mapping):
        flat = scene.flatten(p, xp=jnp)
    else:
        flat = p
    shape = tuple(np.shape(flat))
    if shape != (lay.size,):
        raise DiffsvgError(f"params: shape {shape}, expected ({lay.size},) (the scene's "
                           "parameters; vmap for a batch)")
    if not hasattr(flat, "dtype"):
        flat = np.asarray(flat)
    dtype = np.dtype(flat.dtype)
    if dtype.kind != "f":
        raise DiffsvgError(f"params: dtype {dtype}, expected float32 or float64")
    if not isinstance(flat, jax.core.Tracer):
        v = np.asarray(flat)
        if not np.isfinite(v).all():
            i = int(np.argmax(~np.isfinite(v)))
            raise DiffsvgError(f"params: value {i} is {v[i]} (not finite)")
    return jnp.asarray(flat)


def _options(background, tolerance) -> Tuple[Optional[tuple], float]:
    bg = _color(background, "background")
    if bg is not None and not all(0.0 <= c <= 1.0 for c in bg):
        raise DiffsvgError(f"background: {bg} is not a straight RGBA color with values in "
                           "[0, 1]")
    t = float(tolerance)
    if not 0.0 < t <= 10.0:
        raise DiffsvgError(f"tolerance {t} must be in (0, 10] pixels")
    return bg, t


def render(scene: Scene, params: Any, background: Any = None,
           tolerance: float = 0.02, exact_overlaps: bool = False) -> jax.Array:
    """Renders ``scene`` with the values of ``params``: a ``(height, width, 4)``
    ``float32`` premultiplied image, differentiable with respect to ``params``.

    ``params``: the flat vector (layout of :meth:`diffsvg.Scene.params`, ``float32`` or
    ``float64``; the fast path), a :class:`Params`, or a dict in the structure of
    :meth:`diffsvg.Scene.arrays` (numpy or JAX arrays; one leaf per array, so its compile
    time grows with the number of shapes). ``background`` is composited under the
    drawing: a tuple (straight RGB[A]) is a fixed color; a JAX array is a parameter, with
    gradients — a straight color ``(3,)``/``(4,)`` or a straight image
    ``(height, width, 3 or 4)`` (see :func:`over`). Under ``jax.vmap`` a batch of vectors
    is one call, rendered in parallel. ``exact_overlaps`` renders and differentiates the
    exact coverage where a path overlaps itself, as :func:`diffsvg.render` does with it."""
    exact = _flag(exact_overlaps, "exact_overlaps")
    if isinstance(background, jax.Array):
        _, t = _options(None, tolerance)
        img = _render_flat(scene, None, t, exact, _flat_of(scene, params))
        return over(img, background)
    bg, t = _options(background, tolerance)
    return _render_flat(scene, bg, t, exact, _flat_of(scene, params))


def over(image: jax.Array, background: Any) -> jax.Array:
    """``image`` (premultiplied ``(h, w, 4)``) composited over ``background``, in JAX so
    that gradients reach both: a straight color ``(3,)`` or ``(4,)`` (RGB opaque), or a
    straight image ``(h, w, 3)`` or ``(h, w, 4)`` of the same size. The formula of
    :func:`diffsvg.render`'s ``background``: ``image + (1 − alpha) · premultiplied
    background``."""
    bg = jnp.asarray(background)
    h, w = image.shape[-3], image.shape[-2]
    if not (bg.shape in ((3,), (4,)) or bg.shape in ((h, w, 3), (h, w, 4))):
        raise DiffsvgError(f"background: shape {tuple(bg.shape)}; expected (3,), (4,), "
                           f"({h}, {w}, 3) or ({h}, {w}, 4)")
    if not jnp.issubdtype(bg.dtype, jnp.floating):
        raise DiffsvgError(f"background: dtype {bg.dtype}; colors are float in [0, 1]")
    bg = bg.astype(image.dtype)
    if bg.shape[-1] == 3:
        bg = jnp.concatenate([bg, jnp.ones(bg.shape[:-1] + (1,), bg.dtype)], axis=-1)
    pm = jnp.concatenate([bg[..., :3] * bg[..., 3:], bg[..., 3:]], axis=-1)
    return image + (1.0 - image[..., 3:]) * pm
