"""diffsvg.jax against the numpy calls: compile time and step time per path count.

    python -P python/bench_jax.py [--paths 256,1096] [--steps 30] [--dict] [--profile]

Scenes are DiffVG's painterly blobs (``random_blobs``, 256x256, seed 0) fitted toward
another set of blobs (seed 1). One step is the MSE and its gradient with respect to every
parameter:

* numpy: ``set_params(x)``, ``render``, ``loss(grad=True)``, ``render_backward``;
* jax: ``jax.jit(jax.value_and_grad(loss))`` over the flat vector, over a
  ``diffsvg.jax.Params``, and (``--dict``) over the dict of ``Scene.arrays()``, one leaf
  per array (the old default; its compile time grows with the paths).

Compile time is ``lower`` plus ``compile`` of the jitted step; step times are medians over
``--steps`` steps after one warm-up, ``block_until_ready`` included, the numpy and the jax
step alternating; "eager" is the same step without ``jit``. ``vmap`` renders a batch of 4
vectors in one call against 4 jitted calls one after the other.

``--profile`` prints where the steps' time goes instead (medians over ``--steps``, the
steps alternating): per step of numpy, ``render``, ``loss`` and ``render_backward``; per
jitted jax step, its time, the time of the native batch calls that do the work of its two
custom calls (``render_batch``, ``render_backward_batch``: the same code, timed on their
own since the handlers run inside XLA), and the rest (JAX: dispatch, the fused loss, the
custom calls' entry and exit).
"""
import argparse
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np

import diffsvg
import diffsvg.jax as djax


def median_ms(fn, steps):
    fn()
    ts = []
    for _ in range(steps):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return 1e3 * statistics.median(ts)


def alternating(f, g, steps):
    f(), g()
    tf, tg = [], []
    for _ in range(steps):
        for fn, ts in ((f, tf), (g, tg)):
            t = time.perf_counter()
            fn()
            ts.append(time.perf_counter() - t)
    return 1e3 * statistics.median(tf), 1e3 * statistics.median(tg)


def jitted(loss, x):
    """The compiled value-and-gradient step and the seconds lowering and compiling took."""
    f = jax.jit(jax.value_and_grad(loss))
    t = time.perf_counter()
    c = f.lower(x).compile()
    return time.perf_counter() - t, c


def profile(n, steps):
    """The breakdown of one numpy and one jitted jax step at ``n`` paths (``--profile``)."""
    from diffsvg import _native
    times = {}

    def timed(name, f):
        def g(*a, **k):
            t = time.perf_counter()
            try:
                return f(*a, **k)
            finally:
                times.setdefault(name, []).append(time.perf_counter() - t)
        return g

    scene = diffsvg.random_blobs(n, 256, 256, seed=0)
    np_scene = scene.copy()
    target = diffsvg.render(diffsvg.random_blobs(n, 256, 256, seed=1))
    x64 = scene.params()
    jt = jnp.asarray(target)
    render, loss_np = timed("render", diffsvg.render), timed("loss", diffsvg.loss)
    backward = timed("render_backward", diffsvg.render_backward)

    def numpy_step():
        np_scene.set_params(x64)
        _, d = loss_np(render(np_scene), target, grad=True)
        return backward(np_scene, d, structured=False)

    # The work of the jitted step's two custom calls, as the batch calls that share their
    # code (the handlers run inside XLA, out of Python's reach).
    rows = x64[None, :]
    d_rows = np.zeros((1, 256, 256, 4), np.float32)
    native_fwd = timed("native forward", lambda: _native.render_batch(scene._s, rows))
    native_bwd = timed("native backward",
                       lambda: _native.render_backward_batch(scene._s, rows, d_rows))

    def native():
        native_fwd()
        native_bwd()

    x = jnp.asarray(x64, jnp.float32)
    step = jax.jit(jax.value_and_grad(lambda v: jnp.mean((djax.render(scene, v) - jt) ** 2)))
    jax_step = timed("jax step", lambda: jax.block_until_ready(step(x)))
    numpy_step = timed("numpy step", numpy_step)
    jax_step(), numpy_step(), native()
    times.clear()
    for _ in range(steps):
        numpy_step()
        jax_step()
        native()
    ms = {k: 1e3 * statistics.median(v) for k, v in times.items()}
    ms["jax rest"] = ms["jax step"] - ms["native forward"] - ms["native backward"]
    print(f"{n} paths: " + ", ".join(f"{k} {v:.2f} ms" for k, v in ms.items()), flush=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--paths", default="256,1096")
    ap.add_argument("--steps", type=int, default=30)
    ap.add_argument("--dict", action="store_true")
    ap.add_argument("--profile", action="store_true")
    a = ap.parse_args()
    if a.profile:
        for n in map(int, a.paths.split(",")):
            profile(n, a.steps)
        return
    print("| paths | params | compile flat s | compile Params s"
          + (" | compile dict s" if a.dict else "")
          + " | numpy step ms | jax step ms | ratio | eager ms | vmap 4 ms | 4 calls ms |")
    for n in map(int, a.paths.split(",")):
        scene = diffsvg.random_blobs(n, 256, 256, seed=0)
        # Its own copy: set_params on a scene diffsvg.jax uses also updates the copy the
        # custom calls read, a cost of mixing the two that neither step has alone.
        np_scene = scene.copy()
        target = diffsvg.render(diffsvg.random_blobs(n, 256, 256, seed=1))
        x64 = scene.params()
        jt = jnp.asarray(target)

        def numpy_step():
            np_scene.set_params(x64)
            img = diffsvg.render(np_scene)
            _, d = diffsvg.loss(img, target, grad=True)
            return diffsvg.render_backward(np_scene, d, structured=False)

        x = jnp.asarray(x64, jnp.float32)
        loss = lambda v: jnp.mean((djax.render(scene, v) - jt) ** 2)  # noqa: E731
        c_flat, step = jitted(loss, x)
        eager = jax.value_and_grad(loss)
        eager_ms = median_ms(lambda: jax.block_until_ready(eager(x)), max(5, a.steps // 4))
        # The two steps alternate, so that a change of the machine's load hits both.
        numpy_ms, jax_ms = alternating(numpy_step, lambda: jax.block_until_ready(step(x)),
                                       a.steps)
        p = djax.params(scene)
        c_params, _ = jitted(lambda q: jnp.mean((djax.render(scene, q) - jt) ** 2), p)
        row = [n, x.size, f"{c_flat:.2f}", f"{c_params:.2f}"]
        if a.dict:
            arrays = jax.tree.map(jnp.asarray, scene.arrays())
            c_dict, _ = jitted(lambda d: jnp.mean((djax.render(scene, d) - jt) ** 2), arrays)
            row.append(f"{c_dict:.2f}")
        xs = jnp.stack([x + 0.5 * k for k in range(4)])
        batch = jax.jit(jax.vmap(lambda v: djax.render(scene, v)))
        one = jax.jit(lambda v: djax.render(scene, v))
        vmap_ms, calls_ms = alternating(lambda: jax.block_until_ready(batch(xs)),
                                        lambda: [jax.block_until_ready(one(v)) for v in xs],
                                        a.steps)
        row += [f"{numpy_ms:.2f}", f"{jax_ms:.2f}", f"{jax_ms / numpy_ms:.2f}",
                f"{eager_ms:.1f}", f"{vmap_ms:.2f}", f"{calls_ms:.2f}"]
        print("| " + " | ".join(map(str, row)) + " |", flush=True)


if __name__ == "__main__":
    main()
