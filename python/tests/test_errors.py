"""Bad input raises one clear Python exception; nothing panics."""

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
    a["shapes"][0]["points"][0, 0] = np.inf
    with pytest.raises(diffsvg.DiffsvgError, match="not finite"):
        scene.set_arrays(a)


def test_wrong_shapes_are_refused(scene):
    with pytest.raises(diffsvg.DiffsvgError, match="expected .* values"):
        scene.set_params(np.zeros(3))
    with pytest.raises(diffsvg.DiffsvgError, match="1-D"):
        scene.set_params(np.zeros((2, 2)))
    a = scene.arrays()
    a["shapes"][0]["points"] = a["shapes"][0]["points"][:-1]
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
