"""Scenes, parameters and rendering through the numpy API."""

import threading
import time

import numpy as np
import pytest

import diffsvg
from conftest import SAMPLES, run_cli

SQUARE = """<svg xmlns="http://www.w3.org/2000/svg" width="20" height="10">
  <rect x="5" y="2" width="10" height="6" fill="red" fill-opacity="0.5"/></svg>"""


def test_render_is_premultiplied_rows_down():
    s = diffsvg.Scene.from_svg(SQUARE)
    img = diffsvg.render(s)
    assert img.shape == (10, 20, 4) and img.dtype == np.float32
    # Inside: red at half opacity, premultiplied; outside: transparent.
    assert img[3, 6].tolist() == [0.5, 0.0, 0.0, 0.5]
    assert img[0, 0].tolist() == [0.0, 0.0, 0.0, 0.0]
    # Rows are y: row 1 is above the square (y from 2), row 2 inside it.
    assert img[1, 10, 3] == 0.0 and img[2, 10, 3] == 0.5
    # Over white, alpha becomes 1 and red stays 1.
    bg = diffsvg.render(s, background=(1, 1, 1))
    assert bg[3, 6].tolist() == [1.0, 0.5, 0.5, 1.0]
    straight = diffsvg.unpremultiply(img)
    assert straight[3, 6].tolist() == [1.0, 0.0, 0.0, 0.5]


def test_render_at_another_size():
    s = diffsvg.Scene.from_svg(SQUARE)
    img = diffsvg.render(s, width=40)
    assert img.shape == (20, 40, 4)
    assert img[6, 12].tolist() == [0.5, 0.0, 0.0, 0.5]


def test_render_matches_the_cli(tmp_path):
    svg = SAMPLES / "11-landscape.svg"
    run_cli("render", svg, "-o", tmp_path / "cli.png")
    ours = diffsvg.render(diffsvg.Scene.load(svg))
    diffsvg.save_png(ours, tmp_path / "py.png")
    # The CLI writes through the 8-bit renderer, which takes a run's coverage within four
    # float steps of 0 or 1 as exact: the same bytes but where a value sits on a rounding
    # boundary, there one level apart.
    a = diffsvg.load_image(tmp_path / "cli.png")
    b = diffsvg.load_image(tmp_path / "py.png")
    diff = np.abs(a - b)
    assert diff.max() <= 1.5 / 255
    assert np.count_nonzero(diff) <= 0.01 * diff.size


def test_params_round_trip_and_arrays_structure(tmp_path):
    s = diffsvg.Scene.load(SAMPLES / "10-logo.svg")
    p = s.params()
    assert p.dtype == np.float64 and p.shape == (len(s.layout()["group"]),)
    a = s.arrays()
    # Every number once: the arrays flatten back to params exactly.
    assert np.array_equal(s.flatten(s.arrays(np.float64)), p)
    assert sum(np.asarray(x).size for x in diffsvg._leaves(a)) == p.size
    for sh, info in zip(a["shapes"], s.structure()["shapes"]):
        if info["primitive"] is not None:  # a circle or rectangle: its own parameters
            assert "points" not in sh and sh[info["primitive"]["fields"][0][0]].shape == (2,)
            continue
        assert sh["points"].shape == (info["points"][1], 2)
        assert sh["points"].dtype == np.float32
    # float32 round trips keep the float64 values.
    s.set_arrays(a)
    assert np.array_equal(s.params(), p)
    s.set_params(p.astype(np.float32))
    assert np.array_equal(s.params(), p)
    # A moved point moves; save and load keep it.
    k = next(i for i, sh in enumerate(a["shapes"]) if "points" in sh)
    a["shapes"][k]["points"][0] += 3.0
    s.set_arrays(a)
    at = s.structure()["shapes"][k]["points"][0]
    assert s.params()[at] == np.float32(p[at] + 3.0)
    s.save(tmp_path / "moved.svg")
    back = diffsvg.Scene.load(tmp_path / "moved.svg")
    assert np.allclose(back.params(), s.params(), atol=1e-3)
    assert diffsvg.Scene.from_svg(s.to_svg()).path_count == s.path_count


def test_gradient_kinds_and_layout():
    s = diffsvg.Scene.load(SAMPLES / "04-radial-gradient.svg")
    kinds = {sh[k]["kind"] for sh in s.structure()["shapes"] for k in ("fill", "stroke")
             if sh[k] is not None}
    assert "radial" in kinds
    a = s.arrays()
    radial = [sh["fill"] for sh, i in zip(a["shapes"], s.structure()["shapes"])
              if i["fill"] and i["fill"]["kind"] == "radial"][0]
    assert radial["geometry"].shape == (6,) and radial["stops"].shape[1] == 5


def test_render_backward_matches_finite_differences():
    s = diffsvg.Scene.from_svg(SQUARE)
    target = np.zeros((10, 20, 4), np.float32)
    img = diffsvg.render(s)
    value, d = diffsvg.loss(img, target, grad=True)
    g = diffsvg.render_backward(s, d, structured=False)
    p = s.params()
    # The square is a <rect>: corner, size, angle. Its width grown widens the red area
    # (the loss, against a transparent target, rises).
    assert s.structure()["shapes"][0]["primitive"]["kind"] == "rect"
    h = 1e-3
    i = 2  # the width
    q = p.copy(); q[i] += h; s.set_params(q)
    up = diffsvg.loss(diffsvg.render(s), target)
    q[i] -= 2 * h; s.set_params(q)
    down = diffsvg.loss(diffsvg.render(s), target)
    s.set_params(p)
    numeric = (up - down) / (2 * h)
    assert g[i] > 0 and abs(g[i] - numeric) < 1e-3 * abs(numeric) + 1e-9
    # Structured gradients mirror the arrays.
    gs = diffsvg.render_backward(s, d)
    assert gs["shapes"][0]["size"].shape == s.arrays()["shapes"][0]["size"].shape == (2,)


# Two coincident rectangles in one path, each covering the left half of a pixel column;
# and two squares of one path overlapping, whose edges share pixels along the top and
# where they cross.
COINCIDENT = """<svg xmlns="http://www.w3.org/2000/svg" width="4" height="4">
  <path d="M 1 1 H 1.5 V 3 H 1 Z M 1 1 H 1.5 V 3 H 1 Z"/></svg>"""
OVERLAPPING = """<svg xmlns="http://www.w3.org/2000/svg" width="12" height="12">
  <path d="M 2.3 2.2 L 7.6 2.2 L 7.6 7.4 L 2.3 7.4 Z M 4.1 2.5 L 9.2 2.5 L 9.2 8.6 L 4.1 8.6 Z"
        fill="#3366cc" fill-opacity="0.8"/></svg>"""


def test_exact_overlaps_render_and_differentiate():
    s = diffsvg.Scene.from_svg(COINCIDENT)
    # The clamped winding integral covers the half-covered pixels fully; exact, half.
    assert diffsvg.render(s)[1, 1, 3] == 1.0
    assert abs(diffsvg.render(s, exact_overlaps=True)[1, 1, 3] - 0.5) < 1e-6
    with pytest.raises(TypeError, match="exact_overlaps must be True or False"):
        diffsvg.render(s, exact_overlaps=1)

    s = diffsvg.Scene.from_svg(OVERLAPPING)
    target = np.zeros((12, 12, 4), np.float32)
    img = diffsvg.render(s, exact_overlaps=True)
    assert not np.array_equal(img, diffsvg.render(s))
    _, d = diffsvg.loss(img, target, grad=True)
    g = diffsvg.render_backward(s, d, structured=False, exact_overlaps=True)
    # The same image gradient through the clamped coverage gives another answer.
    assert not np.allclose(g, diffsvg.render_backward(s, d, structured=False))
    p = s.params()
    h = 1e-3
    numeric = np.zeros_like(g)
    for i in range(len(p)):
        q = p.copy(); q[i] += h; s.set_params(q)
        up = diffsvg.loss(diffsvg.render(s, exact_overlaps=True), target)
        q[i] -= 2 * h; s.set_params(q)
        down = diffsvg.loss(diffsvg.render(s, exact_overlaps=True), target)
        numeric[i] = (up - down) / (2 * h)
    s.set_params(p)
    assert np.abs(g - numeric).max() <= 2e-3 * np.abs(numeric).max() + 1e-7


def test_fit_with_exact_overlaps_differentiates_the_exact_coverage():
    """A fit of a self-overlapping path toward its own exact rendering starts at the
    optimum with the option (loss 0, nothing moves) and away from it without."""
    s = diffsvg.Scene.from_svg(OVERLAPPING)
    target = diffsvg.render(s, exact_overlaps=True)
    _, exact = diffsvg.fit(s, target, iters=5, exact_overlaps=True)
    _, clamped = diffsvg.fit(s, target, iters=5)
    assert exact["history"][0][1] == 0.0
    assert clamped["history"][0][1] > 0.0
    with pytest.raises(TypeError, match="exact_overlaps must be True or False"):
        diffsvg.fit(s, target, iters=1, exact_overlaps=None)


def test_the_gil_is_released_while_rendering():
    s = diffsvg.random_blobs(512, 1024, 1024, seed=1)
    d = np.full((1024, 1024, 4), 1e-6, np.float32)
    ticks = []
    done = threading.Event()

    def work():
        for _ in range(2):
            diffsvg.render(s)
            diffsvg.render_backward(s, d, structured=False)
        done.set()

    t0 = time.perf_counter()
    t = threading.Thread(target=work)
    t.start()
    while not done.is_set():
        ticks.append(time.perf_counter())
        time.sleep(0.001)
    t.join()
    ms = (time.perf_counter() - t0) * 1e3
    # This loop ticks about once a millisecond while the other thread renders; were the
    # GIL held, it would tick only between the four calls.
    assert len(ticks) > max(20, 0.3 * ms), (len(ticks), ms)


TEXT = """<svg xmlns="http://www.w3.org/2000/svg" width="80" height="30">
  <text id="t" x="4" y="22" font-size="20" font-family="{family}">Hi-</text></svg>"""


def test_text_with_font_options(tmp_path):
    svg = tmp_path / "text.svg"
    svg.write_text(TEXT.format(family="DejaVu Sans"))
    s = diffsvg.Scene.load(svg)
    assert s.path_count >= 1
    assert "<!-- text: Hi- -->" in s.to_svg()
    missing = tmp_path / "missing.svg"
    missing.write_text(TEXT.format(family="No Such Family"))
    with pytest.raises(diffsvg.DiffsvgError, match="missing.svg.*No Such Family"):
        diffsvg.Scene.load(missing)
    # Fallback sets it in DejaVu Sans: the same pixels as asking for it.
    fell = diffsvg.Scene.load(missing, font_fallback=True)
    assert np.array_equal(diffsvg.render(fell), diffsvg.render(s))
    # A font folder and a font file are loaded (a folder without fonts is fine).
    (tmp_path / "fonts").mkdir()
    assert diffsvg.Scene.load(svg, font_dirs=[tmp_path / "fonts"]).path_count >= 1
    with pytest.raises(diffsvg.DiffsvgError, match="not a font file"):
        diffsvg.Scene.load(svg, fonts=[svg])

def test_an_image_is_a_rectangle_with_only_an_opacity(tmp_path):
    # A 2 x 1 PNG: red, then half-transparent blue.
    import base64, struct, zlib
    raw = b"\x00" + bytes([255, 0, 0, 255, 0, 0, 255, 128])
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", 2, 1, 8, 6, 0, 0, 0))
           + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))
    url = "data:image/png;base64," + base64.b64encode(png).decode()
    s = diffsvg.Scene.from_svg(
        f'<svg xmlns="http://www.w3.org/2000/svg" width="8" height="4">'
        f'<image width="8" height="4" image-rendering="optimizeSpeed" href="{url}"/></svg>')
    fill = s.structure()["shapes"][0]["fill"]
    assert fill["kind"] == "image" and fill["len"] == 1
    a = s.arrays()
    assert set(a["shapes"][0]["fill"]) == {"opacity"}
    assert np.array_equal(s.flatten(s.arrays(np.float64)), s.params())
    img = diffsvg.render(s)
    assert img[1, 1].tolist() == [1.0, 0.0, 0.0, 1.0]
    assert abs(img[1, 6, 3] - 128 / 255) < 1e-6
    s.save(tmp_path / "image.svg")
    back = diffsvg.Scene.load(tmp_path / "image.svg")
    assert np.array_equal(diffsvg.render(back), img)


def test_version_is_the_crates():
    import importlib.metadata
    import tomllib
    from conftest import ROOT
    root = tomllib.loads((ROOT / "Cargo.toml").read_text())["package"]["version"]
    binding = tomllib.loads((ROOT / "python" / "Cargo.toml").read_text())["package"]["version"]
    assert diffsvg.__version__ == root == binding
    assert importlib.metadata.version("diffsvg") == diffsvg.__version__
    assert "__version__" in diffsvg.__all__


def _pair():
    rng = np.random.default_rng(1)
    a = rng.uniform(0, 1, (6, 5, 4)).astype(np.float32)
    b = rng.uniform(0, 1, (6, 5, 4)).astype(np.float32)
    return a, b


@pytest.mark.parametrize("kind", ["mse", "l1"])
def test_loss_channels_rgba_and_rgb(kind):
    a, b = _pair()
    d64 = a.astype(np.float64) - b
    term = d64 ** 2 if kind == "mse" else np.abs(d64)
    # The default averages alpha in with the color, as `diffsvg fit` and `grad` do.
    assert diffsvg.loss(a, b, kind) == pytest.approx(term.mean(), rel=1e-12)
    assert diffsvg.loss(a, b, kind, channels="rgba") == diffsvg.loss(a, b, kind)
    assert diffsvg.loss(a, b, kind, channels="rgb") == pytest.approx(term[..., :3].mean(),
                                                                    rel=1e-12)
    v, g = diffsvg.loss(a, b, kind, grad=True, channels="rgb")
    assert v == diffsvg.loss(a, b, kind, channels="rgb")
    assert np.all(g[..., 3] == 0)
    expected = (2 * d64 if kind == "mse" else np.sign(d64))[..., :3] / (a.size // 4 * 3)
    assert np.allclose(g[..., :3], expected, rtol=1e-6)
    v4, g4 = diffsvg.loss(a, b, kind, grad=True)
    assert np.allclose(g4, (2 * d64 if kind == "mse" else np.sign(d64)) / a.size, rtol=1e-6)
    with pytest.raises(diffsvg.DiffsvgError, match="channels: 'bgr'"):
        diffsvg.loss(a, b, channels="bgr")


def test_psnr_channels_rgba_and_rgb():
    a, b = _pair()
    d = a.astype(np.float64) - b
    assert diffsvg.psnr(a, b) == pytest.approx(-10 * np.log10(np.mean(d ** 2)))
    rgb = -10 * np.log10(np.mean(d[..., :3] ** 2))
    assert diffsvg.psnr(a, b, channels="rgb") == pytest.approx(rgb)
    assert diffsvg.psnr(a[..., :3], b[..., :3], channels="rgb") == pytest.approx(rgb)
    with pytest.raises(diffsvg.DiffsvgError, match=r"needs arrays of shape \(\.\.\., 4\), got "
                                                   r"\(6, 5, 3\) \(pass channels='rgb'\)"):
        diffsvg.psnr(a[..., :3], b[..., :3])
    assert diffsvg.psnr(a, a) == float("inf")


TURNED = """<svg xmlns="http://www.w3.org/2000/svg" width="64" height="48">
  <g id="turned" transform="translate(6 4) rotate(12 30 20)">
    <rect x="10" y="10" width="20" height="12" fill="#cc4422"/>
    <path d="M34 8 L50 12 L40 30 Z" fill="#2255aa"/>
  </g>
</svg>"""


def test_group_transforms_are_arrays(tmp_path):
    s = diffsvg.Scene.from_svg(TURNED)
    st = s.structure()
    assert [t["id"] for t in st["transforms"]] == ["turned"] and st["groups"] == []
    a = s.arrays(np.float64)
    t = a["transforms"][0]
    assert t["translate"].shape == (2,)
    assert abs(float(t["angle"]) - np.radians(12)) < 1e-6 and abs(float(t["scale"]) - 1) < 1e-6
    assert np.array_equal(s.flatten(a), s.params())
    # The rectangle's own parameters are in the group's frame: as written.
    assert np.allclose(a["shapes"][0]["corner"], [10, 10], atol=1e-6)
    # Turning the group is one number; it survives a save and a load.
    t["angle"] = t["angle"] + 0.2
    s.set_arrays(a)
    s.save(tmp_path / "turned.svg")
    back = diffsvg.Scene.load(tmp_path / "turned.svg").arrays(np.float64)
    assert abs(float(back["transforms"][0]["angle"]) - (np.radians(12) + 0.2)) < 1e-5
    assert np.allclose(back["shapes"][0]["corner"], [10, 10], atol=1e-3)
    # Gradients come per transform too.
    target = diffsvg.render(diffsvg.Scene.from_svg(TURNED))
    _, d = diffsvg.loss(diffsvg.render(s), target, grad=True)
    g = diffsvg.render_backward(s, d)
    assert float(g["transforms"][0]["angle"]) > 0  # turning back lowers the loss


SKEWED_SHAPES = """<svg xmlns="http://www.w3.org/2000/svg" width="64" height="48">
  <g id="leaning" transform="matrix(1.1 0.15 0.4 0.75 -3 5)">
    <circle id="dot" cx="12" cy="14" r="6" fill="#27ae60"/>
    <rect id="card" x="14" y="26" width="20" height="12" rx="3" fill="#c0392b"/>
  </g>
</svg>"""


def test_skewed_groups_keep_circles_as_circles(tmp_path):
    # Issue 30: a circle under a skewed group keeps its center and radius (in the
    # group's frame, as written), and the group its six slots.
    s = diffsvg.Scene.from_svg(SKEWED_SHAPES)
    st = s.structure()
    assert [(t["id"], t["len"]) for t in st["transforms"]] == [("leaning", 6)]
    assert [sh["primitive"]["kind"] for sh in st["shapes"]] == ["circle", "rect"]
    a = s.arrays(np.float64)
    dot = a["shapes"][0]
    assert set(dot) >= {"center", "radius"} and "points" not in dot
    assert np.allclose(dot["center"], [12, 14], atol=1e-5)
    assert abs(float(dot["radius"]) - 6) < 1e-5
    t = a["transforms"][0]
    assert t["translate"].shape == (2,) and t["linear"].shape == (4,)
    assert np.allclose(t["linear"], [1.1, 0.15, 0.4, 0.75], atol=1e-6)
    # The radius grows in the group's frame; saved, it stays a <circle> in the group.
    dot["radius"] = dot["radius"] + 1
    s.set_arrays(a)
    s.save(tmp_path / "skewed.svg")
    text = (tmp_path / "skewed.svg").read_text()
    assert '<g id="leaning" transform="matrix(' in text and '<circle id="dot"' in text
    back = diffsvg.Scene.load(tmp_path / "skewed.svg").arrays(np.float64)
    assert abs(float(back["shapes"][0]["radius"]) - 7) < 1e-4
    assert np.allclose(back["transforms"][0]["linear"], t["linear"], atol=1e-5)
    # Gradients reach the radius and the six slots.
    target = diffsvg.render(diffsvg.Scene.from_svg(SKEWED_SHAPES))
    _, d = diffsvg.loss(diffsvg.render(s), target, grad=True)
    g = diffsvg.render_backward(s, d)
    assert float(g["shapes"][0]["radius"]) > 0  # shrinking back lowers the loss
    assert np.all(np.isfinite(g["transforms"][0]["linear"]))
    assert np.any(g["transforms"][0]["linear"] != 0)


def test_colors_survive_to_svg_exactly():
    s = diffsvg.Scene.load(SAMPLES / "10-logo.svg")
    p = s.params()
    lay = s.layout()
    colors = np.flatnonzero(lay["group"] == lay["group_names"].index("colors"))
    assert colors.size > 0
    p[colors] = np.linspace(0.013, 0.987, colors.size)
    s.set_params(p)
    back = diffsvg.Scene.from_svg(s.to_svg())
    assert np.array_equal(back.params()[colors], s.params()[colors])


SHADOW = """<svg xmlns="http://www.w3.org/2000/svg" width="48" height="40">
  <filter id="s" x="-50%" y="-50%" width="200%" height="200%">
    <feDropShadow dx="{dx}" dy="2" stdDeviation="1.5"/></filter>
  <g id="g" filter="url(#s)">
    <rect x="10" y="8" width="20" height="16" fill="rgb(40,110,220)"/>
    <circle cx="30" cy="24" r="7" fill="rgb(230,80,40)"/></g></svg>"""


def test_filter_parameters_are_arrays_and_fit():
    s = diffsvg.Scene.from_svg(SHADOW.format(dx=1.5))
    st = s.structure()
    assert [(f["id"], f["len"]) for f in st["filters"]] == [("g", 8)]
    a = s.arrays(np.float64)
    v = a["filters"][0]["values"]  # dx, dy, σx, σy, r, g, b, opacity
    assert v.shape == (8,) and abs(v[0] - 1.5) < 1e-9 and abs(v[2] - 1.5) < 1e-9
    assert np.array_equal(s.flatten(a), s.params())
    # With exact filters the shadow's offset has a gradient: a fit moves it to the
    # target's (rendered by resvg's rule, whole pixels: dx 4).
    target = diffsvg.render(diffsvg.Scene.from_svg(SHADOW.format(dx=4)))
    fitted, _ = diffsvg.fit(s, target, 150, exact_filters=True, lr_points=0.0, lr_color=0.0,
                            lr_opacity=0.0, lr_filter=0.1)
    assert abs(fitted.arrays(np.float64)["filters"][0]["values"][0] - 4) < 0.3
    # Without, it stays where it was.
    still, _ = diffsvg.fit(s, target, 20, lr_points=0.0, lr_color=0.0, lr_opacity=0.0)
    assert still.arrays(np.float64)["filters"][0]["values"][0] == 1.5
