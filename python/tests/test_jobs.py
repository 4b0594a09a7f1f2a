"""The long jobs from Python: fit, vectorize, digits, glyphs, progress and stopping."""

import _thread
import re
import signal
import threading

import numpy as np
import pytest

import diffsvg
from conftest import SAMPLES, run_cli


def test_fit_recovers_a_perturbed_drawing(tmp_path):
    run_cli("perturb", SAMPLES / "10-logo.svg", "-o", tmp_path / "p.svg", "--seed", "3")
    start = diffsvg.Scene.load(tmp_path / "p.svg")
    target = diffsvg.load_target(SAMPLES / "10-logo.svg")
    before = diffsvg.psnr(diffsvg.render(start), target)
    seen = []
    best, info = diffsvg.fit(start, target, iters=30, progress=seen.append)
    after = diffsvg.psnr(diffsvg.render(best), target)
    assert after > before + 3, (before, after)
    assert [s["iter"] for s in seen] == list(range(31))
    assert info["steps"] == 30 and info["reason"] == "finished"
    assert info["history"].shape == (31, 4)


def test_fit_background_recovers_the_backdrop():
    svg = ('<svg xmlns="http://www.w3.org/2000/svg" width="64" height="48">'
           '<rect width="64" height="48" fill="rgb(40,120,200)"/>'
           '<circle cx="30" cy="22" r="12" fill="rgb(230,180,20)"/></svg>')
    target = diffsvg.render(diffsvg.Scene.from_svg(svg))
    start = diffsvg.Scene.from_svg(
        '<svg xmlns="http://www.w3.org/2000/svg" width="64" height="48">'
        '<circle cx="33" cy="24" r="10" fill="rgb(200,150,60)"/></svg>')
    _, info = diffsvg.fit(start, target, iters=300, background=(1, 1, 1),
                          fit_background=True)
    assert np.allclose(np.array(info["background"][:3]) * 255, [40, 120, 200], atol=2)
    _, plain = diffsvg.fit(start, target, iters=2)
    assert plain["background"] is None
    with pytest.raises(diffsvg.DiffsvgError, match="opaque background"):
        diffsvg.fit(start, target, iters=2, fit_background=True, background=(1, 1, 1, 0.5))


def test_progress_false_or_exception_stops():
    scene = diffsvg.random_blobs(4, 32, 32, seed=2)
    target = np.ones((32, 32, 4), np.float32)
    _, info = diffsvg.fit(scene, target, iters=50, progress=lambda s: s["iter"] < 3)
    assert info["reason"] == "stopped" and info["steps"] == 3

    class Boom(Exception):
        pass

    def cb(step):
        if step["iter"] == 2:
            raise Boom("stop here")

    with pytest.raises(Boom, match="stop here"):
        diffsvg.fit(scene, target, iters=50, progress=cb)


def test_painterly_matches_the_cli_benchmark():
    """`bench painterly`'s workload driven from Python gives the same final MSE."""
    target = diffsvg.load_target(SAMPLES / "11-landscape.svg", 64, 64)
    out = run_cli("bench", "painterly", "--paths", "16", "--size", "64", "--iters", "10",
                  "--target", SAMPLES / "11-landscape.svg").stdout
    row = [l for l in out.splitlines() if l.startswith("| 16 |")][0]
    # | paths | forward | step | step/forward | total (s) | final MSE | …
    cli_mse = float(row.split("|")[6])
    scene = diffsvg.random_blobs(16, 64, 64, seed=0)
    _, info = diffsvg.fit(scene, target, iters=10, lr_points=1.0, lr_color=0.01,
                          lr_opacity=0.01, background=(1, 1, 1))
    assert f"{info['final_loss']:.4f}" == f"{cli_mse:.4f}"


def test_vectorize_and_glyph_and_digit():
    target = diffsvg.load_target(SAMPLES / "10-logo.svg", 64, 64)
    scene, info = diffsvg.vectorize(target, paths=4, iters=40)
    assert 1 <= scene.path_count <= 4 and info["psnr"] > 10
    # A glyph: a black disc on white.
    yy, xx = np.mgrid[0:32, 0:32]
    ink = ((xx - 15.5) ** 2 + (yy - 15.5) ** 2 < 100).astype(np.float32)
    img = np.ones((32, 32, 4), np.float32)
    img[..., :3] -= ink[..., None]
    g, ginfo = diffsvg.glyph(img, iou=0.9, iters=60)
    assert g.path_count == 1 and ginfo["iou"] > 0.9
    # A digit "1": a bright vertical bar.
    d = np.zeros((28, 28), np.float32)
    d[5:23, 13:15] = 1.0
    s, dinfo = diffsvg.digit(d)
    assert s.path_count >= 1 and dinfo["iou"] > 0.5
    seen = []
    out = diffsvg.digits(np.stack([d, d.T]), progress=lambda i: seen.append(i["index"]))
    assert len(out) == 2 and seen == [0, 1]
    assert diffsvg.digits(np.stack([d, d]), progress=lambda i: False)[0][1]["iou"] > 0.5


def test_ctrl_c_stops_a_fit():
    """KeyboardInterrupt reaches the running job (which has released the GIL) and stops it."""
    scene = diffsvg.random_blobs(8, 64, 64, seed=1)
    target = np.ones((64, 64, 4), np.float32)
    # Python's own SIGINT handler, whatever an earlier test left (interrupt_main does
    # nothing under SIG_IGN or SIG_DFL: with the data present, the suite lost it).
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    timer = threading.Timer(0.3, _thread.interrupt_main)
    timer.start()
    # Bounded (about 30 s at 1.4 ms a step): a lost interrupt fails the test rather than
    # running for hours. One CI run (2026-11-27) hung here with 10**7 steps, once in
    # many runs; the cause is not known.
    with pytest.raises(KeyboardInterrupt):
        diffsvg.fit(scene, target, iters=20_000)
    timer.join()
    signal.signal(signal.SIGINT, previous)
