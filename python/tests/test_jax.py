"""diffsvg.jax: gradients inside JAX equal `diffsvg grad --json`, bit for bit."""

import gc
import json

import numpy as np
import pytest

jax = pytest.importorskip("jax")
import jax.extend  # noqa: E402  (the jaxpr types of _custom_calls)
jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402

import diffsvg  # noqa: E402
import diffsvg.jax as djax  # noqa: E402
from conftest import SAMPLES, run_cli  # noqa: E402

# Drawings that together have every parameter kind: points (lines, quadratics, cubics),
# solid colors, opacities, stroke widths, linear and radial gradient geometry and stops,
# group opacity.
DRAWINGS = ["02-strokes.svg", "03-linear-gradient.svg", "04-radial-gradient.svg",
            "05-translucent-overlap.svg", "10-logo.svg"]


def perturbed_target(scene, path):
    """A target PNG: the scene with every parameter nudged, so no gradient is zero."""
    s = scene.copy()
    rng = np.random.default_rng(0)
    p = s.params()
    s.set_params(p + rng.uniform(-0.02, 0.02, p.shape) * np.maximum(1, np.abs(p)))
    diffsvg.save_png(diffsvg.render(s), path)


def assert_same(ours, cli, where="") -> int:
    """Exact equality of every number in two JSON-like trees; returns how many."""
    if isinstance(cli, dict):
        assert set(ours) == set(cli), where
        return sum(assert_same(ours[k], cli[k], f"{where}/{k}") for k in cli)
    if isinstance(cli, list):
        assert len(ours) == len(cli), where
        return sum(assert_same(a, b, f"{where}[{i}]") for i, (a, b) in enumerate(zip(ours, cli)))
    if isinstance(cli, str):
        assert ours == cli, where
        return 0
    assert ours == cli, f"{where}: jax {ours!r} != cli {cli!r}"
    return 1


@pytest.mark.parametrize("name", DRAWINGS)
def test_jax_gradient_equals_cli_grad_json(name, tmp_path):
    svg = SAMPLES / name
    scene = diffsvg.Scene.load(svg)
    png = tmp_path / "target.png"
    perturbed_target(scene, png)
    cli = json.loads(run_cli("grad", svg, png, "--json").stdout)

    target = jnp.asarray(diffsvg.load_image(png), dtype=jnp.float64)
    arrays = jax.tree.map(jnp.asarray, scene.arrays(np.float64))

    def loss(arrays):
        img = djax.render(scene, arrays)
        # The CLI's MSE: the mean over pixels and the four channels, in f64.
        return jnp.mean((img.astype(jnp.float64) - target) ** 2)

    value, grads = jax.value_and_grad(loss)(arrays)
    assert np.isclose(float(value), cli["loss"], rtol=1e-12, atol=0)
    flat = np.asarray(scene.flatten(jax.tree.map(np.asarray, grads)))
    ours = scene.grad_json(flat)
    # The CLI prints shapes and groups; compare both, every number exactly.
    n = assert_same(ours["shapes"], cli["shapes"], name)
    n += assert_same(ours["groups"], cli["groups"], name)
    assert n > 0 and np.count_nonzero(flat) > 0.5 * flat.size


def test_every_parameter_kind_is_covered():
    groups = set()
    for name in DRAWINGS:
        lay = diffsvg.Scene.load(SAMPLES / name).layout()
        groups |= {lay["group_names"][g] for g in np.unique(lay["group"])}
    assert groups <= {"points", "colors", "opacities", "widths", "paint", "stops", "transforms"}
    assert groups >= {"points", "colors", "opacities", "widths", "paint", "stops"}


def test_jit_and_float32_arrays():
    scene = diffsvg.Scene.load(SAMPLES / "03-linear-gradient.svg")
    arrays = jax.tree.map(jnp.asarray, scene.arrays(np.float32))
    img = jax.jit(lambda a: djax.render(scene, a))(arrays)
    assert np.array_equal(np.asarray(img), diffsvg.render(scene))
    g = jax.grad(lambda a: jnp.sum(djax.render(scene, a)[..., 3]))(arrays)
    assert g["shapes"][0]["corner"].dtype == jnp.float32  # a <rect>: its own parameters
    assert np.isfinite(np.asarray(scene.flatten(jax.tree.map(np.asarray, g)))).all()


# ----- issue 30: the flat vector as the default, Params, vmap, errors -------------------------
def _loss_of(scene, target):
    return lambda p: jnp.mean((djax.render(scene, p).astype(jnp.float64) - target) ** 2)


def test_flat_params_and_dict_give_the_same_gradient():
    scene = diffsvg.Scene.load(SAMPLES / "10-logo.svg")
    s = scene.copy()
    s.set_params(scene.params() * 1.01)
    target = jnp.asarray(diffsvg.render(s), jnp.float64)
    loss = _loss_of(scene, target)
    flat = jax.jit(jax.grad(loss))(jnp.asarray(scene.params()))
    p = jax.jit(jax.grad(loss))(djax.params(scene, jnp.float64))
    d = jax.jit(jax.grad(loss))(jax.tree.map(jnp.asarray, scene.arrays(np.float64)))
    assert isinstance(p, djax.Params) and flat.shape == (scene.params().size,)
    assert np.array_equal(np.asarray(p.flat), np.asarray(flat))
    assert np.array_equal(np.asarray(scene.flatten(jax.tree.map(np.asarray, d))),
                          np.asarray(flat))
    # The numpy call gives the same numbers.
    img = diffsvg.render(scene)
    _, dimg = diffsvg.loss(img, np.asarray(target, np.float32), grad=True)
    ref = diffsvg.render_backward(scene, dimg, structured=False)
    assert np.allclose(np.asarray(flat), ref, rtol=1e-5, atol=1e-9)


def test_params_reads_per_shape_and_is_one_leaf():
    scene = diffsvg.Scene.load(SAMPLES / "03-linear-gradient.svg")
    p = djax.params(scene)
    assert len(jax.tree.leaves(p)) == 1 and p.flat.dtype == jnp.float32
    a = scene.arrays()
    assert len(p["shapes"]) == len(a["shapes"]) and len(p["groups"]) == len(a["groups"])
    for mine, theirs in zip(p.arrays()["shapes"], a["shapes"]):
        assert jax.tree.structure(mine) == jax.tree.structure(theirs)
        for x, y in zip(jax.tree.leaves(mine), jax.tree.leaves(theirs)):
            assert np.array_equal(np.asarray(x), y)
    for key in a["shapes"][-1]:
        if not isinstance(a["shapes"][-1][key], dict):
            assert np.array_equal(p["shapes"][-1][key], a["shapes"][-1][key])
    q = p.set(("shapes", 0, "fill", "opacity"), 0.5)
    assert float(q["shapes"][0]["fill"]["opacity"]) == 0.5
    assert float(p["shapes"][0]["fill"]["opacity"]) == 1.0
    with pytest.raises(diffsvg.DiffsvgError, match=r"shapes/0/size has shape \(2,\)"):
        p.set(("shapes", 0, "size"), np.zeros(3))
    # From arrays, and the optimizer's view: one vector.
    assert np.array_equal(djax.params(scene, arrays=a).flat, p.flat)
    g = jax.grad(lambda q: jnp.sum(djax.render(scene, q)[..., 3]))(p)
    assert isinstance(g, djax.Params) and g["shapes"][0]["radii"].shape == (2,)


def _step_jaxpr(n, how):
    scene = diffsvg.random_blobs(n, 32, 32, seed=0)
    target = jnp.zeros((32, 32, 4))
    loss = _loss_of(scene, target)
    x = {"flat": lambda: jnp.asarray(scene.params(), jnp.float32),
         "params": lambda: djax.params(scene)}[how]()
    return jax.make_jaxpr(jax.value_and_grad(loss))(x)


@pytest.mark.parametrize("how", ["flat", "params"])
def test_the_step_does_not_grow_with_the_shapes(how):
    """What JAX compiles is the same program for 4 paths or 400: one custom call forward,
    one backward (the per-shape pytree was one slice and one concatenation operand per
    array, and compiled for 9.9 s at 256 paths)."""
    small, large = _step_jaxpr(4, how), _step_jaxpr(400, how)
    assert len(small.eqns) == len(large.eqns)
    assert _custom_calls(large) == [("diffsvg_render", ()), ("diffsvg_render_backward", ())]


def _custom_calls(closed) -> list:
    """The diffsvg custom calls of a jaxpr (nested ones too), in order: each its target and
    the batch dimensions of its params operand."""
    out = []

    def walk(jaxpr):
        for eqn in jaxpr.eqns:
            if eqn.primitive.name == "ffi_call":
                out.append((eqn.params["target_name"], tuple(eqn.invars[0].aval.shape[:-1])))
            for v in eqn.params.values():
                for sub in (v if isinstance(v, (tuple, list)) else (v,)):
                    if isinstance(sub, jax.extend.core.ClosedJaxpr):
                        walk(sub.jaxpr)
                    elif isinstance(sub, jax.extend.core.Jaxpr):
                        walk(sub)
    walk(closed.jaxpr)
    return out


def test_vmap_renders_a_batch_in_one_call():
    scene = diffsvg.Scene.load(SAMPLES / "05-translucent-overlap.svg")
    x = scene.params()
    xs = np.stack([x, x + 0.5, x - 0.5])
    render = jax.jit(jax.vmap(lambda v: djax.render(scene, v)))
    assert _custom_calls(jax.make_jaxpr(render)(jnp.asarray(xs))) == [("diffsvg_render", (3,))]
    imgs = render(jnp.asarray(xs))
    for img, v in zip(imgs, xs):
        s = scene.copy()
        s.set_params(v)
        assert np.array_equal(np.asarray(img), diffsvg.render(s))
    target = jnp.asarray(diffsvg.render(scene), jnp.float64)
    step = jax.jit(jax.vmap(jax.grad(_loss_of(scene, target))))
    assert _custom_calls(jax.make_jaxpr(step)(jnp.asarray(xs))) == [
        ("diffsvg_render", (3,)), ("diffsvg_render_backward", (3,))]
    grads = step(jnp.asarray(xs))
    for g, v in zip(grads, xs):
        assert np.array_equal(np.asarray(g), np.asarray(jax.grad(_loss_of(scene, target))(v)))


def test_errors_under_jit_are_the_packages_one_line():
    scene = diffsvg.Scene.load(SAMPLES / "01-curves.svg")
    n = scene.params().size
    render = jax.jit(lambda v: djax.render(scene, v))
    with pytest.raises(diffsvg.DiffsvgError, match=rf"params: shape \({n + 1},\), expected "
                                                   rf"\({n},\)"):
        render(jnp.zeros(n + 1))
    with pytest.raises(diffsvg.DiffsvgError, match=r"params: dtype int32"):
        render(jnp.zeros(n, jnp.int32))
    with pytest.raises(diffsvg.DiffsvgError, match="background"):
        jax.jit(lambda v: djax.render(scene, v, background=(2, 0, 0)))(jnp.zeros(n))
    with pytest.raises(diffsvg.DiffsvgError, match="tolerance"):
        jax.jit(lambda v: djax.render(scene, v, tolerance=0))(jnp.zeros(n))
    a = scene.arrays()
    a["shapes"].append(a["shapes"][0])
    with pytest.raises(diffsvg.DiffsvgError, match="arrays: shapes has"):
        jax.jit(lambda t: djax.render(scene, t))(a)
    other = djax.params(diffsvg.Scene.load(SAMPLES / "10-logo.svg"))
    with pytest.raises(diffsvg.DiffsvgError, match="another scene's structure"):
        render(other)
    # A value known only when the step runs: outside jit the package's error ...
    x = scene.params()
    x[3] = np.nan
    with pytest.raises(diffsvg.DiffsvgError, match="params: value 3 is nan"):
        djax.render(scene, jnp.asarray(x))
    # ... inside jit NaN out, as JAX's own functions, with a one-line warning.
    with pytest.warns(djax.DiffsvgWarning, match=r"params value 3 is nan \(not finite\)"):
        img = render(jnp.asarray(x))
    assert np.isnan(np.asarray(img)).all()
    with pytest.warns(djax.DiffsvgWarning):
        g = jax.jit(jax.grad(lambda v: jnp.sum(djax.render(scene, v))))(jnp.asarray(x))
    assert np.isnan(np.asarray(g)).all()


# ----- a background that is a parameter ----------------------------------------------
def test_background_color_and_image_are_parameters():
    scene = diffsvg.Scene(24, 16)
    scene.add_circle((10, 8), 6, fill=(0.9, 0.2, 0.1, 0.7))
    x = jnp.asarray(scene.params())
    target = jnp.asarray(np.random.default_rng(1).uniform(0, 1, (16, 24, 4)), jnp.float32)
    for bg in (jnp.asarray([0.2, 0.5, 0.7]), jnp.asarray([0.2, 0.5, 0.7, 0.6]),
               jnp.asarray(np.random.default_rng(2).uniform(0, 1, (16, 24, 4)),
                           jnp.float32)):
        # A fixed color renders the same as the parameter.
        if bg.shape == (3,):
            fixed = djax.render(scene, x, tuple(float(c) for c in bg))
            assert np.allclose(djax.render(scene, x, bg), fixed, atol=1e-6)
        loss = lambda b, x: jnp.sum((djax.render(scene, x, b) - target) ** 2)
        gb, gx = jax.grad(loss, argnums=(0, 1))(bg, x)
        # The numpy gradient, and central differences in float64.
        img = diffsvg.render(scene)
        d = 2 * (np.asarray(djax.over(jnp.asarray(img), bg)) - np.asarray(target))
        assert np.allclose(diffsvg.background_backward(img, d, np.asarray(bg)), gb,
                           rtol=1e-4, atol=1e-4)
        flat = np.asarray(bg, np.float64).ravel()
        for k in (0, 1, flat.size - 1):
            e = np.zeros_like(flat); e[k] = 1e-3
            f = lambda v: float(np.sum((np.asarray(djax.over(
                jnp.asarray(img, jnp.float64), jnp.asarray(v.reshape(bg.shape))),
                np.float64) - np.asarray(target, np.float64)) ** 2))
            num = (f(flat + e) - f(flat - e)) / 2e-3
            assert abs(num - float(np.asarray(gb).ravel()[k])) < 1e-3 * (1 + abs(num))
        assert np.isfinite(np.asarray(gx)).all()
    with pytest.raises(diffsvg.DiffsvgError, match="background: shape"):
        djax.render(scene, x, jnp.zeros((5, 5, 3)))


def test_a_background_color_is_recovered():
    scene = diffsvg.Scene(32, 32)
    scene.add_rect((8, 8), (16, 12), fill=(0.1, 0.3, 0.8))
    x = jnp.asarray(scene.params(), jnp.float32)
    target = djax.render(scene, x, jnp.asarray([0.9, 0.6, 0.2]))
    step = jax.jit(jax.grad(lambda b: jnp.mean((djax.render(scene, x, b) - target) ** 2)))
    b = jnp.asarray([0.5, 0.5, 0.5])
    for _ in range(200):
        b = b - 2.0 * step(b)
    assert np.allclose(np.asarray(b), [0.9, 0.6, 0.2], atol=1e-3), b


# ----- the XLA custom calls (python/src/ffi.rs) -----------------------------------------
@pytest.mark.parametrize("name", ["02-strokes.svg", "04-radial-gradient.svg", "10-logo.svg"])
@pytest.mark.parametrize("background", [None, (0.2, 0.4, 0.6, 0.5)])
@pytest.mark.parametrize("ffi", [True, False])
def test_custom_calls_give_the_bits_of_render_and_render_backward(name, background, ffi,
                                                                 monkeypatch):
    """The custom calls, and the pure_callback fallback (a JAX without the FFI, or a
    default backend other than the CPU), give diffsvg.render's and render_backward's bits."""
    monkeypatch.setattr(djax, "_FFI", ffi and djax._FFI)
    scene = diffsvg.Scene.load(SAMPLES / name)
    d = np.random.default_rng(3).normal(0, 1e-3, (scene.height, scene.width, 4)).astype(
        np.float32)
    img = diffsvg.render(scene, background=background)
    g = diffsvg.render_backward(scene, d, background=background, structured=False)
    for dtype in (jnp.float64, jnp.float32):
        x = jnp.asarray(scene.params(), dtype)
        f = jax.jit(lambda v: djax.render(scene, v, background))
        assert np.array_equal(np.asarray(f(x)), img)
        out, vjp = jax.vjp(f, x)
        assert np.array_equal(np.asarray(out), img)
        (gx,) = jax.jit(vjp)(jnp.asarray(d))
        assert gx.dtype == dtype
        assert np.array_equal(np.asarray(gx), g.astype(dtype)), (name, dtype)
    step = jax.make_jaxpr(jax.grad(lambda v: jnp.sum(djax.render(scene, v))))(x)
    assert _custom_calls(step) == ([("diffsvg_render", ()), ("diffsvg_render_backward", ())]
                                   if ffi else [])


OVERLAPPING = """<svg xmlns="http://www.w3.org/2000/svg" width="12" height="12">
  <path d="M 2.3 2.2 L 7.6 2.2 L 7.6 7.4 L 2.3 7.4 Z M 4.1 2.5 L 9.2 2.5 L 9.2 8.6 L 4.1 8.6 Z"
        fill="#3366cc" fill-opacity="0.8"/></svg>"""


@pytest.mark.parametrize("ffi", [True, False])
def test_exact_overlaps_reach_the_custom_calls(ffi, monkeypatch):
    """With exact_overlaps the custom calls (and the fallback, through render_batch and
    render_backward_batch) give the bits of render and render_backward with it, which
    differ from the clamped coverage's where the two squares of one path overlap."""
    monkeypatch.setattr(djax, "_FFI", ffi and djax._FFI)
    scene = diffsvg.Scene.from_svg(OVERLAPPING)
    d = np.random.default_rng(5).normal(0, 1e-2, (12, 12, 4)).astype(np.float32)
    img = diffsvg.render(scene, exact_overlaps=True)
    g = diffsvg.render_backward(scene, d, structured=False, exact_overlaps=True)
    assert not np.array_equal(img, diffsvg.render(scene))
    x = jnp.asarray(scene.params(), jnp.float64)
    f = jax.jit(lambda v: djax.render(scene, v, exact_overlaps=True))
    out, vjp = jax.vjp(f, x)
    assert np.array_equal(np.asarray(out), img)
    (gx,) = jax.jit(vjp)(jnp.asarray(d))
    assert np.array_equal(np.asarray(gx), g)
    # Off, the clamped coverage's bits, as before.
    plain = jax.jit(lambda v: djax.render(scene, v))(x)
    assert np.array_equal(np.asarray(plain), diffsvg.render(scene))
    # A batch renders each row with the option.
    rows = np.stack([scene.params(), scene.params()])
    batch = diffsvg._native.render_batch(diffsvg._scene(scene), rows, None, 0.02, True)
    assert np.array_equal(batch[1], img)
    with pytest.raises(TypeError, match="exact_overlaps must be True or False"):
        djax.render(scene, x, exact_overlaps="yes")


def test_the_fallback_warns_too(monkeypatch):
    monkeypatch.setattr(djax, "_FFI", False)
    scene = diffsvg.Scene.load(SAMPLES / "01-curves.svg")
    x = scene.params()
    x[3] = np.nan
    with pytest.warns(djax.DiffsvgWarning, match=r"params value 3 is nan \(not finite\)"):
        img = jax.jit(lambda v: djax.render(scene, v))(jnp.asarray(x))
    assert np.isnan(np.asarray(img)).all()


def test_a_dropped_scene_leaves_the_registry():
    scene = diffsvg.Scene.load(SAMPLES / "01-curves.svg")
    x = jnp.asarray(scene.params(), jnp.float32)
    f = jax.jit(jax.value_and_grad(lambda v: jnp.sum(djax.render(scene, v))))
    jax.block_until_ready(f(x))
    sid = djax._native.ffi_scene(scene._s)
    assert djax._native.ffi_registered(sid)
    del scene, f
    gc.collect()
    assert not djax._native.ffi_registered(sid)


def test_the_custom_calls_follow_the_scenes_changes():
    scene = diffsvg.Scene.load(SAMPLES / "05-translucent-overlap.svg")
    f = jax.jit(lambda v: djax.render(scene, v))
    x = scene.params() * 1.01
    scene.set_params(x)  # float32 vectors keep the new float64 values
    assert np.array_equal(np.asarray(f(jnp.asarray(x, jnp.float32))), diffsvg.render(scene))
    n = x.size
    scene.remove(0)  # another structure: the compiled step refuses, with diffsvg's message
    with pytest.raises(Exception, match=rf"diffsvg.jax: params: shape \[{n}\] but the scene "
                                        rf"has {scene.params().size} parameters"):
        jax.block_until_ready(f(jnp.asarray(x, jnp.float32)))
