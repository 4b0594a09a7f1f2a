"""diffsvg inside JAX: :func:`render` is differentiable with respect to a scene's arrays.

::

    import jax, jax.numpy as jnp, diffsvg, diffsvg.jax
    scene = diffsvg.Scene.load("drawing.svg")
    arrays = jax.tree.map(jnp.asarray, scene.arrays())
    def loss(arrays):
        img = diffsvg.jax.render(scene, arrays)          # (h, w, 4) premultiplied float32
        return jnp.mean((img - target) ** 2)
    g = jax.grad(loss)(arrays)                           # same structure as arrays

The forward pass and the exact backward pass run in diffsvg (on the CPU, through
``jax.pure_callback``, so it works under ``jax.jit``); the scene gives the topology (paths,
segment kinds, paint kinds), ``arrays`` the values. ``float32`` arrays keep the scene's
``float64`` values wherever they equal their ``float32`` rounding (see
:meth:`diffsvg.Scene.set_params`); with ``jax_enable_x64`` and ``float64`` arrays the
values are exact.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from . import Scene, _color, _native, _scene

__all__ = ["render", "render_flat"]


def _with_params(scene: Scene, flat: np.ndarray) -> Scene:
    s = scene.copy()
    s.set_params(np.asarray(flat))
    return s


@functools.partial(jax.custom_vjp, nondiff_argnums=(0, 1, 2))
def render_flat(scene: Scene, background, tolerance: float, flat):
    """Renders ``scene`` with the parameter vector ``flat`` (layout of
    :meth:`diffsvg.Scene.params`): a ``(height, width, 4)`` ``float32`` premultiplied
    image, differentiable with respect to ``flat``."""
    return _forward(scene, background, tolerance, flat)


def _forward(scene, background, tolerance, flat):
    shape = jax.ShapeDtypeStruct((scene.height, scene.width, 4), jnp.float32)

    def cb(v):
        s = _with_params(scene, v)
        return _native.render(_scene(s), None, None, background, tolerance)

    return jax.pure_callback(cb, shape, flat, vmap_method="sequential")


def _fwd(scene, background, tolerance, flat):
    return _forward(scene, background, tolerance, flat), flat


def _bwd(scene, background, tolerance, flat, d_image):
    out = jax.ShapeDtypeStruct(flat.shape, flat.dtype)

    def cb(v, d):
        s = _with_params(scene, v)
        g = _native.render_backward(_scene(s), np.ascontiguousarray(d, dtype=np.float32),
                                    background, tolerance)
        return g.astype(out.dtype)

    return (jax.pure_callback(cb, out, flat, d_image, vmap_method="sequential"),)


render_flat.defvjp(_fwd, _bwd)


def render(scene: Scene, arrays, background=None, tolerance: float = 0.02):
    """Renders ``scene`` with the values of ``arrays`` (the structure of
    :meth:`diffsvg.Scene.arrays`, numpy or JAX arrays): a ``(height, width, 4)``
    ``float32`` premultiplied image, differentiable with respect to every array.
    ``background`` (straight RGB[A]) is composited under the drawing."""
    flat = scene.flatten(arrays, xp=jnp)
    return render_flat(scene, _color(background, "background"), float(tolerance), flat)
