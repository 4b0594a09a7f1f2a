"""The example scripts (DiffVG's apps) run, stay under 40 lines, and improve their PSNR;
the Python snippets of README.md and docs/python.md run as written."""

import importlib.util
import pathlib
import re
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT, SAMPLES, run_cli, shared_data

EXAMPLES = pathlib.Path(__file__).resolve().parents[1] / "examples"


def run(script, *args, cwd):
    out = subprocess.run([sys.executable, str(EXAMPLES / script), *map(str, args)],
                         capture_output=True, text=True, check=True, cwd=cwd).stdout
    return out


def test_examples_are_short():
    for p in EXAMPLES.glob("*.py"):
        assert len(p.read_text().splitlines()) < 40, p


def test_refine_svg_on_a_bundled_sample(tmp_path):
    run_cli("perturb", SAMPLES / "10-logo.svg", "-o", tmp_path / "p.svg", "--seed", "3")
    out = run("refine_svg.py", tmp_path / "p.svg", SAMPLES / "10-logo.svg", "--iters", "60",
              "-o", tmp_path / "r.svg", cwd=tmp_path)
    before, after = map(float, re.search(r"PSNR ([\d.]+) -> ([\d.]+) dB", out).groups())
    assert after > before + 5, out
    assert (tmp_path / "r.svg").exists()


def test_examples_on_a_photo(tmp_path):
    photo = shared_data("test_examples_on_a_photo") / "images" / "astronaut.png"
    out = run("refine_svg.py", SAMPLES / "11-landscape.svg", photo, "--iters", "30",
              "-o", tmp_path / "r.svg", cwd=tmp_path)
    before, after = map(float, re.search(r"PSNR ([\d.]+) -> ([\d.]+) dB", out).groups())
    assert after > before + 1, out
    out = run("painterly.py", photo, "--paths", "32", "--iters", "30", "-o",
              tmp_path / "p.svg", cwd=tmp_path)
    steps = [float(x) for x in re.findall(r"step \d+: PSNR ([\d.]+)", out)]
    final = float(re.search(r"paths: PSNR ([\d.]+)", out).group(1))
    assert final > steps[0] > 0, out


def psnr_gain(out):
    return tuple(map(float, re.search(r"PSNR ([\d.]+) -> ([\d.]+) dB", out).groups()))


@pytest.mark.skipif(importlib.util.find_spec("optax") is None
                    or importlib.util.find_spec("jax") is None,
                    reason="single_curve.py needs jax and optax")
def test_single_curve(tmp_path):
    out = run("single_curve.py", "--size", 64, "--iters", 100, "-o", tmp_path / "c.svg",
              cwd=tmp_path)
    before, after = psnr_gain(out)
    assert before < 15 and after > 35, out
    assert "<path" in (tmp_path / "c.svg").read_text()


@pytest.mark.skipif(importlib.util.find_spec("optax") is None
                    or importlib.util.find_spec("jax") is None,
                    reason="single_circle.py needs jax and optax")
def test_single_circle_recovers_center_and_radius(tmp_path):
    out = run("single_circle.py", "--size", 64, "--iters", 300, "-o", tmp_path / "c.svg",
              cwd=tmp_path)
    x, y, r = map(float, re.search(r"center \[([-\d.]+) +([-\d.]+)\] radius ([\d.]+)",
                                   out).groups())
    # At 64 px the target is the circle (35, 30) of radius 16.25.
    assert max(abs(x - 35), abs(y - 30), abs(r - 16.25)) <= 1e-3, out
    text = (tmp_path / "c.svg").read_text()
    assert "<circle" in text and "<path" not in text, text


def test_scene_built_in_code_round_trips(tmp_path):
    import diffsvg
    s = diffsvg.Scene(40, 30)
    s.add_circle((10, 12), 5.5, fill=(1, 0, 0), id="c")
    s.add_ellipse((25, 12), (8, 4), 0.3, fill=None, stroke=(0, 0, 1, 0.5), stroke_width=2)
    s.add_rect((4, 20), (30, 6), radii=(2, 1.5), fill=(0, 0.4, 0))
    a = s.arrays(np.float64)["shapes"]
    assert a[0]["center"].tolist() == [10, 12] and float(a[0]["radius"]) == 5.5
    assert a[1]["radius"].tolist() == [8, 4] and abs(float(a[1]["angle"]) - 0.3) < 1e-12
    assert a[2]["radii"].tolist() == [2, 1.5]
    text = s.to_svg()
    assert text.count("<circle") == 1 and text.count("<ellipse") == 1 and text.count("<rect") == 1
    back = diffsvg.Scene.from_svg(text)
    assert np.allclose(back.params(), s.params(), atol=1e-4)
    free = s.copy()
    free.outline_primitives()
    assert "points" in free.arrays()["shapes"][0] and "<circle" not in free.to_svg()
    assert np.array_equal(diffsvg.render(free), diffsvg.render(s))
    with pytest.raises(diffsvg.DiffsvgError, match="takes 3 values"):
        s._s.add_shape("circle", [1.0, 2.0])
    with pytest.raises(diffsvg.DiffsvgError, match="sizes must be"):
        s.add_circle((1, 2), -1)
    with pytest.raises(diffsvg.DiffsvgError, match="unknown kind"):
        s._s.add_shape("star", [1.0])


def test_paths_gradients_and_order_built_in_code():
    import diffsvg
    s = diffsvg.Scene(32, 24)
    # DiffVG's single_curve shape: one closed subpath of three cubics.
    pts = [(4, 4), (12, 2), (20, 6), (24, 12), (20, 18), (10, 22), (6, 16), (3, 10), (2, 6),
           (4, 4)]
    grad = {"kind": "linear", "geometry": [0, 0, 32, 0],
            "stops": [[0, 1, 0, 0, 1], [1, 0, 0, 1, 1]]}
    s.add_path(pts, fill=grad, id="curve")
    s.add_rect((10, 8), (16, 10), fill=(0, 0.4, 0, 0.8), id="box")
    a = s.arrays(np.float64)["shapes"]
    assert a[0]["points"].shape == (10, 2) and a[0]["fill"]["stops"].shape == (2, 5)
    assert s.node_count == 2
    text = s.to_svg()
    assert 'id="curve"' in text and "<linearGradient" in text and "<rect" in text
    back = diffsvg.Scene.from_svg(text)
    assert np.allclose(back.params(), s.params(), atol=1e-4)
    # The rectangle drawn first instead: the picture changes where they overlap.
    before = diffsvg.render(s)
    s.reorder([1, 0])
    assert s.structure()["shapes"][0]["id"] == "box"
    assert not np.array_equal(diffsvg.render(s), before)
    s.remove(0)
    assert s.node_count == 1 and s.structure()["shapes"][0]["id"] == "curve"
    for bad, match in [(lambda: s.reorder([0, 0]), "not a permutation"),
                       (lambda: s.remove(3), "out of range"),
                       (lambda: s.add_path(pts[:-1], segments=[3]), "expected 10"),
                       (lambda: s.add_path(pts, fill={"kind": "conic", "geometry": [0],
                                                      "stops": [[0, 0, 0, 0, 1]]}), "conic"),
                       (lambda: s.add_path(pts, fill=(2, 0, 0)), r"in \[0, 1\]"),
                       (lambda: s.add_path(pts, fill=None), "fill, a stroke")]:
        with pytest.raises(diffsvg.DiffsvgError, match=match):
            bad()


def test_single_gradient(tmp_path):
    out = run("single_gradient.py", "--size", 64, "--iters", 150, "-o", tmp_path / "g.svg",
              cwd=tmp_path)
    before, after = psnr_gain(out)
    assert before < 20 and after > 35, out
    assert "<linearGradient" in (tmp_path / "g.svg").read_text()


def python_block(doc, after):
    """The first ```python block after the line ``after`` in ``doc``."""
    text = (ROOT / doc).read_text()
    start = text.index(after)
    return re.search(r"```python\n(.*?)```", text[start:], re.S).group(1)


def run_snippet(code, tmp_path):
    script = tmp_path / "snippet.py"
    script.write_text(code)
    return subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          check=True, cwd=ROOT).stdout


def test_readme_python_snippet_runs_as_written(tmp_path):
    out = run_snippet(python_block("README.md", "## Python"), tmp_path)
    assert float(re.search(r"([\d.]+) dB", out).group(1)) > 40, out


@pytest.mark.skipif(importlib.util.find_spec("jax") is None
                    or importlib.util.find_spec("optax") is None, reason="needs jax and optax")
def test_docs_jax_snippet_runs_as_written(tmp_path):
    out = run_snippet(python_block("docs/python.md", "## JAX"), tmp_path)
    assert "PSNR" in out, out
