"""Bad input raises one clear Python exception; nothing panics."""

import re

import numpy as np
import pytest

import diffsvg
from conftest import SAMPLES


@pytest.fixture
def scene():
    return diffsvg.Scene.load(SAMPLES / "01-curves.svg")


def test_missing_file_names_it():
    with pytest.raises(FileNotFoundError, match="nope/missing.svg"):
        diffsvg.Scene.load("nope/missing.svg")
    with pytest.raises(FileNotFoundError, match="missing.png"):
        diffsvg.load_image("missing.png")


def test_malformed_svg_names_it():
    with pytest.raises(diffsvg.DiffsvgError, match="bad.svg: malformed SVG"):
        diffsvg.Scene.from_svg("<svg", name="bad.svg")
    assert issubclass(diffsvg.DiffsvgError, ValueError)


def test_nan_parameters_are_refused(scene):
    p = scene.params()
    p[3] = np.nan
    with pytest.raises(diffsvg.DiffsvgError, match="value 3 is NaN"):
        scene.set_params(p)
    # Unchanged after the refusal.
    assert np.isfinite(scene.params()).all()
    a = scene.arrays()
    k = next(i for i, sh in enumerate(a["shapes"]) if "points" in sh)
    a["shapes"][k]["points"][0, 0] = np.inf
    with pytest.raises(diffsvg.DiffsvgError, match="not finite"):
        scene.set_arrays(a)


def test_wrong_shapes_are_refused(scene):
    with pytest.raises(diffsvg.DiffsvgError, match="expected .* values"):
        scene.set_params(np.zeros(3))
    with pytest.raises(diffsvg.DiffsvgError, match="1-D"):
        scene.set_params(np.zeros((2, 2)))
    a = scene.arrays()
    k = next(i for i, sh in enumerate(a["shapes"]) if "points" in sh)
    a["shapes"][k]["points"] = a["shapes"][k]["points"][:-1]
    with pytest.raises(diffsvg.DiffsvgError, match="points has shape"):
        scene.set_arrays(a)
    with pytest.raises(diffsvg.DiffsvgError, match=r"shape \(height, width, 4\)"):
        diffsvg.render_backward(scene, np.zeros((scene.height, scene.width, 3)))
    with pytest.raises(diffsvg.DiffsvgError, match="numeric"):
        diffsvg.render_backward(scene, np.array([["a"]]))


def test_size_mismatch_in_backward_and_loss(scene):
    d = np.zeros((scene.height + 1, scene.width, 4), np.float32)
    with pytest.raises(diffsvg.DiffsvgError, match="d_image: .* but the scene is"):
        diffsvg.render_backward(scene, d)
    img = diffsvg.render(scene)
    with pytest.raises(diffsvg.DiffsvgError, match="target: .* but the image is"):
        diffsvg.loss(img, d)
    with pytest.raises(diffsvg.DiffsvgError, match="target: .* but the scene is"):
        diffsvg.fit(scene, d, iters=1)


def test_nan_images_and_bad_options(scene):
    d = np.zeros((scene.height, scene.width, 4), np.float32)
    d[1, 2, 0] = np.nan
    with pytest.raises(diffsvg.DiffsvgError, match="d_image: pixel .* non-finite"):
        diffsvg.render_backward(scene, d)
    with pytest.raises(diffsvg.DiffsvgError, match="background"):
        diffsvg.render(scene, background=(2, 0, 0))
    with pytest.raises(diffsvg.DiffsvgError, match="tolerance"):
        diffsvg.render(scene, tolerance=0)
    with pytest.raises(diffsvg.DiffsvgError, match="lr_points"):
        diffsvg.fit(scene, diffsvg.render(scene), iters=1, lr_points=float("nan"))
    with pytest.raises(diffsvg.DiffsvgError, match="mode"):
        diffsvg.vectorize(diffsvg.render(scene), mode="magic")
    with pytest.raises(diffsvg.DiffsvgError, match="schedule"):
        diffsvg.fit(scene, diffsvg.render(scene), iters=1, schedule="sometimes")
    with pytest.raises(diffsvg.DiffsvgError, match="expected a diffsvg.Scene"):
        diffsvg.render("scene.svg")


def test_fit_target_file_errors_name_it(scene, tmp_path):
    with pytest.raises(FileNotFoundError, match="absent.png"):
        diffsvg.fit(scene, tmp_path / "absent.png", iters=1)
    (tmp_path / "junk.png").write_bytes(b"not a png")
    with pytest.raises(diffsvg.DiffsvgError, match="junk.png"):
        diffsvg.fit(scene, tmp_path / "junk.png", iters=1)


def _drifted_options():
    """`(command, option, value, message)` rows of tests/drifted-options.tsv, which the
    command line's test reads too (issue 28: each bound is the library's)."""
    from conftest import ROOT
    rows = []
    for line in (ROOT / "tests" / "drifted-options.tsv").read_text().splitlines():
        if line.strip() and not line.startswith("#"):
            rows.append(line.split("\t"))
    return rows


@pytest.mark.parametrize("command,option,value,message", _drifted_options())
def test_drifted_options_are_refused_with_the_librarys_message(command, option, value,
                                                               message):
    img = np.zeros((16, 16, 4), np.float32)
    img[..., 3] = 1
    v = float(value) if "." in value or option == "iou" else int(value)
    expected = f"{option} {value} {message}"
    with pytest.raises(diffsvg.DiffsvgError) as e:
        if command == "vectorize":
            diffsvg.vectorize(img, iters=1, **{option: v})
        elif command == "digits":
            diffsvg.digit(np.zeros((28, 28), np.float32), **{option: v})
        elif command == "glyphs":
            diffsvg.glyph(img, **{option: v})
        else:
            raise AssertionError(command)
    assert str(e.value) == expected


# ----- issue 30: input that was silently accepted is refused, one line each ------------------
def test_set_arrays_refuses_an_appended_shape(scene):
    a = scene.arrays()
    a["shapes"].append(a["shapes"][0])
    n = len(scene.structure()["shapes"])
    with pytest.raises(diffsvg.DiffsvgError,
                       match=rf"arrays: shapes has {n + 1} entries but the scene has {n} "):
        scene.set_arrays(a)
    a = scene.arrays()
    a["groups"] = a["groups"] + [{"opacity": np.float32(1)}]
    with pytest.raises(diffsvg.DiffsvgError, match=r"arrays: groups has .* entries"):
        scene.set_arrays(a)


def test_set_arrays_refuses_a_stroke_width_the_shape_has_not():
    s = diffsvg.Scene.load(SAMPLES / "10-logo.svg")
    i = next(i for i, sh in enumerate(s.structure()["shapes"]) if sh["stroke_width"] is None)
    a = s.arrays()
    a["shapes"][i]["stroke_width"] = np.float32(3)
    with pytest.raises(diffsvg.DiffsvgError) as e:
        s.set_arrays(a)
    msg = str(e.value)
    assert msg.startswith(f"arrays: shapes/{i}/stroke_width is not in the scene's structure")
    assert "\n" not in msg
    # A typo in a key is refused the same way, and a missing key is named.
    a = s.arrays()
    a["shapes"][0]["colour"] = a["shapes"][0].pop("fill")
    with pytest.raises(diffsvg.DiffsvgError, match="shapes/0/colour is not in the scene"):
        s.set_arrays(a)
    with pytest.raises(diffsvg.DiffsvgError, match="arrays: shapes is a dict, expected a list"):
        s.set_arrays({"shapes": {}, "groups": []})


@pytest.mark.parametrize("dtype", [np.uint8, np.int32, np.uint16])
def test_integer_targets_are_refused(scene, dtype):
    img = diffsvg.render(scene)
    t = (img * 255).astype(dtype)
    expected = re.escape(f"target: integer dtype {np.dtype(dtype)}; images are float in [0, 1] "
                         "(convert first, e.g. x.astype(np.float32) / 255)")
    with pytest.raises(diffsvg.DiffsvgError, match=expected):
        diffsvg.loss(img, t)
    with pytest.raises(diffsvg.DiffsvgError, match=expected):
        diffsvg.psnr(img, t)
    with pytest.raises(diffsvg.DiffsvgError, match=expected):
        diffsvg.fit(scene, t, iters=1)
    # Converted as the message says, it is accepted.
    assert diffsvg.loss(img, t.astype(np.float32) / 255) < 1e-4


def test_save_refuses_a_missing_folder_and_creates_none(scene, tmp_path):
    img = diffsvg.render(scene)
    for write, name in ((scene.save, "x.svg"), (lambda p: diffsvg.save_png(img, p), "x.png")):
        path = tmp_path / "no" / "such" / name
        with pytest.raises(FileNotFoundError) as e:
            write(path)
        assert str(e.value) == (f"{path}: the folder {path.parent} does not exist "
                                "(create it first; diffsvg does not create folders)")
        assert not (tmp_path / "no").exists()
    (tmp_path / "file").write_text("")
    with pytest.raises(NotADirectoryError, match="is not a folder"):
        scene.save(tmp_path / "file" / "x.svg")


def test_save_replaces_a_file_whole(scene, tmp_path):
    """Atomic writes: a temporary file renamed over the old one (a new inode; a reader
    never sees half a file) and no temporary file left behind."""
    img = diffsvg.render(scene)
    for write, name in ((scene.save, "x.svg"), (lambda p: diffsvg.save_png(img, p), "x.png")):
        path = tmp_path / name
        path.write_text("old")
        before = path.stat().st_ino
        write(path)
        assert path.stat().st_ino != before
        assert path.read_bytes() != b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.png", "x.svg"]


def test_recon_refuses_a_missing_output_folder(tmp_path):
    with pytest.raises(FileNotFoundError, match="the folder .*missing does not exist"):
        diffsvg.recon_voxel(tmp_path, tmp_path / "missing" / "m.vox", iters=1)
    assert not (tmp_path / "missing").exists()


@pytest.mark.parametrize("call,name", [
    (lambda: diffsvg.Scene(-1, 8), "width"),
    (lambda: diffsvg.Scene(8, -1), "height"),
    (lambda: diffsvg.Scene.load(SAMPLES / "01-curves.svg", -64, 64), "width"),
    (lambda: diffsvg.Scene.from_svg("<svg/>", 64, -64), "height"),
    (lambda: diffsvg.render(diffsvg.Scene(8, 8), width=-5), "width"),
    (lambda: diffsvg.load_target(SAMPLES / "01-curves.svg", -1, 4), "width"),
    (lambda: diffsvg.random_blobs(-3, 8, 8), "n"),
    (lambda: diffsvg.random_blobs(3, 8, 8, seed=-1), "seed"),
    (lambda: diffsvg.random_strokes(3, 8, -8), "height"),
    (lambda: diffsvg.fit(diffsvg.Scene(8, 8), np.zeros((8, 8, 4)), iters=-1), "iters"),
    (lambda: diffsvg.fit(diffsvg.Scene(8, 8), np.zeros((8, 8, 4)), pyramid=-2), "pyramid"),
    (lambda: diffsvg.vectorize(np.zeros((8, 8, 4)), paths=-1), "paths"),
    (lambda: diffsvg.vectorize(np.zeros((8, 8, 4)), seed=-1), "seed"),
    (lambda: diffsvg.vectorize(np.zeros((8, 8, 4)), pyramid=-1), "pyramid"),
    (lambda: diffsvg.digit(np.zeros((8, 8)), max_strokes=-1), "max_strokes"),
    (lambda: diffsvg.glyph(np.zeros((8, 8, 4)), iters=-1), "iters"),
    (lambda: diffsvg.recon_voxel(".", "m.vox", res=-1), "res"),
    (lambda: diffsvg.recon_splat(".", "m.ply", seed=-7), "seed"),
    (lambda: diffsvg.view("m.vox", orbit=-1), "orbit"),
])
def test_negative_integers_are_the_packages_error(call, name):
    with pytest.raises(diffsvg.DiffsvgError) as e:
        call()
    assert str(e.value).startswith(f"{name}: -") and "is negative" in str(e.value)


def test_too_large_and_non_integer_counts_name_the_argument():
    with pytest.raises(diffsvg.DiffsvgError, match=r"width: 4294967296 is too large"):
        diffsvg.Scene(2**32, 1)
    with pytest.raises(TypeError, match=r"iters: expected a whole number, got 2.5"):
        diffsvg.vectorize(np.zeros((8, 8, 4)), iters=2.5)


def test_load_target_width_without_height_is_refused():
    with pytest.raises(diffsvg.DiffsvgError, match=r"width and height: give both \(or neither\)"):
        diffsvg.load_target(SAMPLES / "01-curves.svg", 64)
    with pytest.raises(diffsvg.DiffsvgError, match=r"give both"):
        diffsvg.load_target(SAMPLES / "01-curves.svg", height=64)


IMAGE_SVG = ('<svg xmlns="http://www.w3.org/2000/svg" width="32" height="32">'
             '<image x="0" y="0" width="32" height="32" href="{}"/></svg>')


@pytest.mark.parametrize("href,named", [
    ("missing-picture.png", "missing-picture.png"),
    ("data:image/png;base64,bm90IGEgcG5n", "image"),
])
def test_an_image_that_cannot_be_loaded_is_an_error(tmp_path, href, named):
    """As ``<text>`` with a missing font: the package's one-line error, not a silently
    missing element."""
    path = tmp_path / "pic.svg"
    path.write_text(IMAGE_SVG.format(href))
    with pytest.raises(diffsvg.DiffsvgError) as e:
        diffsvg.Scene.load(path)
    assert "pic.svg" in str(e.value) and named in str(e.value)
    assert "\n" not in str(e.value)
    with pytest.raises(diffsvg.DiffsvgError):
        diffsvg.Scene.from_svg(IMAGE_SVG.format(href), name="inline.svg")


def test_text_with_a_missing_font_is_the_same_kind_of_error(tmp_path):
    svg = ('<svg xmlns="http://www.w3.org/2000/svg" width="32" height="32">'
           '<text x="2" y="20" font-family="No Such Font">A</text></svg>')
    with pytest.raises(diffsvg.DiffsvgError, match="No Such Font"):
        diffsvg.Scene.from_svg(svg)
