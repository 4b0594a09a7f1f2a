"""`diffsvg bench painterly` driven from Python, alternating with the CLI in one run.

    python -P python/bench_painterly.py [--paths 64,256] [--iters 50] [--rounds 3]
        [--target ../shared/data/images/astronaut.png] [--cli target/release/diffsvg]

Per path count and round: the CLI's run, then the same workload through ``diffsvg.fit``
(same blobs, seed, target, rates, white background), then examples/painterly.py (render,
loss, render_backward and Adam in numpy). Prints milliseconds per step (medians over
rounds) and the final MSE of each, all at 256 x 256.
"""

import argparse
import os
import pathlib
import re
import statistics
import subprocess
import sys
import time

import diffsvg

ROOT = pathlib.Path(__file__).resolve().parents[1]
ap = argparse.ArgumentParser()
ap.add_argument("--paths", default="64,256")
ap.add_argument("--iters", type=int, default=50)
ap.add_argument("--rounds", type=int, default=3)
ap.add_argument("--target", default=str(ROOT.parent / "shared/data/images/astronaut.png"))
ap.add_argument("--cli", default=str(ROOT / "target/release/diffsvg"))
a = ap.parse_args()
white = (1.0, 1.0, 1.0)
target = diffsvg.load_target(a.target, 256, 256)


def cli(n):
    out = subprocess.run([a.cli, "bench", "painterly", "--paths", str(n), "--iters",
                          str(a.iters), "--size", str(256), "--target", a.target],
                         capture_output=True, text=True, check=True).stdout
    row = [l for l in out.splitlines() if l.startswith(f"| {n} |")][0].split("|")
    # | paths | forward | step | step/forward | total (s) | final MSE | ...: the run's
    # seconds (without the forward passes the bench times on the side), its MSE and its
    # median step.
    return float(row[5]), float(row[6]), float(row[3])


def binding(n):
    scene = diffsvg.random_blobs(n, 256, 256, seed=0)
    t0 = time.perf_counter()
    _, info = diffsvg.fit(scene, target, iters=a.iters, lr_points=1.0, lr_color=0.01,
                          lr_opacity=0.01, background=white)
    return time.perf_counter() - t0, info["final_loss"], info["step_ms"]


def numpy_loop(n):
    """examples/painterly.py (Adam in numpy): its seconds per step and final RGB MSE."""
    out = subprocess.run([sys.executable, str(ROOT / "python/examples/painterly.py"), a.target,
                          "--paths", str(n), "--iters", str(a.iters), "-o", os.devnull],
                         capture_output=True, text=True, check=True).stdout
    m = re.search(r"PSNR ([\d.]+) dB, ([\d.]+) ms per step", out)
    return float(m.group(2)) * a.iters / 1e3, 10 ** (-float(m.group(1)) / 10)


print(f"painterly, 256², {a.iters} steps, {a.rounds} rounds alternating")
print("| paths | CLI ms/step | diffsvg.fit ms/step | ratio | CLI median step | fit median step "
      "| ratio | CLI MSE | fit MSE | numpy Adam ms/step | numpy MSE |")
print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
for n in map(int, a.paths.split(",")):
    c, b, p = [], [], []
    for _ in range(a.rounds):
        c.append(cli(n))
        b.append(binding(n))
        p.append(numpy_loop(n))
    ms = lambda runs: 1e3 * statistics.median(r[0] for r in runs) / a.iters
    # The median step as each measures it inside the library (the CLI bench also times a
    # forward pass between steps, which leaves its caches colder than a plain fit's).
    step = lambda runs: statistics.median(r[2] for r in runs)
    print(f"| {n} | {ms(c):.2f} | {ms(b):.2f} | {ms(b) / ms(c):.3f} | {step(c):.2f} | "
          f"{step(b):.2f} | {step(b) / step(c):.3f} | {c[0][1]:.4f} | "
          f"{b[0][1]:.6f} | {ms(p):.2f} | {p[0][1]:.4f} |")
