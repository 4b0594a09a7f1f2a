"""The example scripts (DiffVG's apps) run, stay under 40 lines, and improve their PSNR;
the Python snippets of README.md and docs/python.md run as written."""

import importlib.util
import pathlib
import re
import subprocess
import sys

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
