"""The two example scripts run, stay under 40 lines, and improve their PSNR."""

import pathlib
import re
import subprocess
import sys

from conftest import SAMPLES, run_cli, shared_data

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
