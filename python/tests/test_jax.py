"""diffsvg.jax: gradients inside JAX equal `diffsvg grad --json`, bit for bit."""

import json

import numpy as np
import pytest

jax = pytest.importorskip("jax")
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
    assert groups == {"points", "colors", "opacities", "widths", "paint", "stops"}


def test_jit_and_float32_arrays():
    scene = diffsvg.Scene.load(SAMPLES / "03-linear-gradient.svg")
    arrays = jax.tree.map(jnp.asarray, scene.arrays(np.float32))
    img = jax.jit(lambda a: djax.render(scene, a))(arrays)
    assert np.array_equal(np.asarray(img), diffsvg.render(scene))
    g = jax.grad(lambda a: jnp.sum(djax.render(scene, a)[..., 3]))(arrays)
    assert g["shapes"][0]["points"].dtype == jnp.float32
    assert np.isfinite(np.asarray(scene.flatten(jax.tree.map(np.asarray, g)))).all()
