"""3D reconstruction from Python: recon_voxel and recon_splat give the command line's model
file bit for bit, report progress, stop when asked, and refuse bad input by name."""

import json

import numpy as np
import pytest

import diffsvg
from conftest import run_cli


def write_scene(root, n_train=6, n_test=2, size=8):
    """A tiny NeRF-synthetic folder: cameras on a circle around the origin looking at it,
    photos of a gray ball over white (the ball's disc drawn where the pinhole sees it)."""
    fov = 0.7
    for split, n, phase in [("train", n_train, 0.0), ("test", n_test, 1.3)]:
        (root / split).mkdir(parents=True)
        frames = []
        for i in range(n):
            a = phase + 2 * np.pi * i / n
            pos = 4.0 * np.array([np.cos(a), np.sin(a), 0.5])
            z = pos / np.linalg.norm(pos)
            x = np.cross([0.0, 0.0, 1.0], z)
            x /= np.linalg.norm(x)
            y = np.cross(z, x)
            m = np.eye(4)
            m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, y, z, pos
            # Pixel centers' angle from the axis; the ball (radius 1) subtends asin(1/|p|).
            f = 0.5 * size / np.tan(fov / 2)
            c = (np.arange(size) + 0.5 - size / 2) / f
            r = np.hypot(c[None, :], c[:, None])
            inside = np.arctan(r) < np.arcsin(1.0 / np.linalg.norm(pos))
            img = np.ones((size, size, 4), np.float32)
            img[inside, :3] = 0.3
            diffsvg.save_png(img, root / split / f"r_{i}.png")
            frames.append({"file_path": f"./{split}/r_{i}", "transform_matrix": m.tolist()})
        (root / f"transforms_{split}.json").write_text(
            json.dumps({"camera_angle_x": fov, "frames": frames}))
    return root


def cli_summary(*args):
    out = run_cli(*args, "--json").stdout
    return json.loads(out.strip().splitlines()[-1])


def test_recon_voxel_equals_the_cli(tmp_path):
    scene = write_scene(tmp_path / "ball")
    seen = []
    info = diffsvg.recon_voxel(scene, tmp_path / "py.vox", res=16, iters=60, batch=256,
                               eval_every=20, progress=seen.append)
    cli = cli_summary("recon", "voxel", "--scene", scene, "-o", tmp_path / "cli.vox",
                      "--res", "16", "--iters", "60", "--batch", "256", "--eval-every", "20")
    assert (tmp_path / "py.vox").read_bytes() == (tmp_path / "cli.vox").read_bytes()
    assert info["test_psnr"] == cli["test_psnr"]
    assert info["allocated"] == cli["allocated"] and info["res"] == cli["res"] == 16
    assert info["iterations"] == 60 and not info["stopped"]
    # The ball is learned: clearly better than an empty (all white) model.
    photos = [diffsvg.load_image(p)[..., :3] for p in sorted((scene / "test").glob("*.png"))]
    empty = np.mean([-10 * np.log10(np.mean((1 - p) ** 2)) for p in photos])
    assert info["test_psnr"] > empty + 3, (info["test_psnr"], empty)
    assert [s["iteration"] for s in seen] == list(range(1, 61))
    assert [s["iteration"] for s in seen if s["test_psnr"] is not None] == [20, 40]
    log = info["log"]
    assert log.shape[1] == 6 and log[-1, 0] == 60 and log[-1, 5] == info["test_psnr"]
    # Rows at the evaluations (20, 40), every 50 iterations and at the end.
    assert log[:, 0].tolist() == [20, 40, 50, 60]
    assert np.isnan(log[:, 5]).tolist() == [False, False, True, False]
    # The written file is one `diffsvg view` reads.
    run_cli("view", tmp_path / "py.vox", "--scene", scene, "-o", tmp_path / "views")


def test_perturbed_poses_report_the_frame_as_the_cli_does(tmp_path):
    scene = write_scene(tmp_path / "ball")
    info = diffsvg.recon_voxel(scene, tmp_path / "py.vox", res=16, iters=30, batch=256,
                               perturb_poses=(0.5, 0.02), refine_poses=True)
    cli = cli_summary("recon", "voxel", "--scene", scene, "-o", tmp_path / "cli.vox",
                      "--res", "16", "--iters", "30", "--batch", "256",
                      "--perturb-poses", "0.5,0.02", "--refine-poses")
    assert info["test_psnr_in_frame"] == cli["test_psnr_in_frame"]
    assert np.isfinite(info["test_psnr_in_frame"])
    e = info["pose_error"]
    for key in ("before", "after", "after_in_frame", "frame"):
        assert e[key] == (cli["pose_error"][key]["degrees"], cli["pose_error"][key]["units"])
    assert abs(e["before"][0] - 0.5) < 1e-3 and 0 <= e["frame"][0] < 0.5
    plain = diffsvg.recon_voxel(scene, tmp_path / "plain.vox", res=16, iters=2, batch=256)
    assert plain["test_psnr_in_frame"] is None and plain["pose_error"] is None
    assert plain["test_psnr_aligned"] is None and plain["test_pose_turn"] is None


def test_aligned_test_poses_are_scored_as_the_cli_does(tmp_path):
    scene = write_scene(tmp_path / "ball")
    info = diffsvg.recon_voxel(scene, tmp_path / "py.vox", res=16, iters=30, batch=256,
                               align_test_poses=True)
    cli = cli_summary("recon", "voxel", "--scene", scene, "-o", tmp_path / "cli.vox",
                      "--res", "16", "--iters", "30", "--batch", "256", "--align-test-poses")
    assert info["test_psnr_aligned"] == cli["test_psnr_aligned"]
    assert info["test_pose_turn"] == cli["test_pose_turn"]
    assert info["test_psnr_aligned"] >= info["test_psnr"] - 0.05


def test_recon_splat_equals_the_cli_and_stops(tmp_path):
    scene = write_scene(tmp_path / "ball")
    info = diffsvg.recon_splat(scene, tmp_path / "py.ply", iters=40, initial=200, seed=3)
    cli = cli_summary("recon", "splat", "--scene", scene, "-o", tmp_path / "cli.ply",
                      "--iters", "40", "--initial", "200", "--seed", "3")
    assert (tmp_path / "py.ply").read_bytes() == (tmp_path / "cli.ply").read_bytes()
    assert info["test_psnr"] == cli["test_psnr"] and info["gaussians"] == cli["gaussians"]
    assert info["undistorted"] is None
    stopped = diffsvg.recon_splat(scene, tmp_path / "stop.ply", iters=40, initial=200,
                                  progress=lambda s: s["iteration"] < 5)
    assert stopped["stopped"] and stopped["iterations"] == 5
    assert (tmp_path / "stop.ply").exists()


def ngp_ball(tmp_path):
    """The ball as an instant-ngp folder (one transforms.json), and a file listing two of
    its views as the test views."""
    scene = write_scene(tmp_path / "ball")
    frames = []
    for split in ["train", "test"]:
        path = scene / f"transforms_{split}.json"
        frames += json.loads(path.read_text())["frames"]
        path.unlink()
    (scene / "transforms.json").write_text(json.dumps({"camera_angle_x": 0.7, "frames": frames}))
    held = tmp_path / "held.txt"
    held.write_text("test/r_0\n./test/r_1\n")
    return scene, held


def test_recon_splat_test_list_is_the_cli_s(tmp_path):
    scene, held = ngp_ball(tmp_path)
    info = diffsvg.recon_splat(scene, tmp_path / "py.ply", iters=20, initial=100,
                               test_list=held)
    cli = cli_summary("recon", "splat", "--scene", scene, "-o", tmp_path / "cli.ply",
                      "--iters", "20", "--initial", "100", "--test-list", held)
    assert (tmp_path / "py.ply").read_bytes() == (tmp_path / "cli.ply").read_bytes()
    assert info["test_psnr"] == cli["test_psnr"]
    every = diffsvg.recon_splat(scene, tmp_path / "every.ply", iters=20, initial=100)
    assert every["test_psnr"] != info["test_psnr"]
    held.write_text("test/r_5\n")
    with pytest.raises(diffsvg.DiffsvgError, match=r"held\.txt.*line 1.*test/r_5"):
        diffsvg.recon_splat(scene, tmp_path / "bad.ply", iters=2, test_list=held)
    with pytest.raises(diffsvg.DiffsvgError, match="transforms_test.json"):
        diffsvg.recon_splat(write_scene(tmp_path / "synthetic"), tmp_path / "bad.ply",
                            iters=2, test_list=held)


def test_recon_voxel_and_view_take_the_test_list_as_the_cli(tmp_path):
    scene, held = ngp_ball(tmp_path)
    info = diffsvg.recon_voxel(scene, tmp_path / "py.vox", res=16, iters=30, batch=256,
                               test_list=held)
    cli = cli_summary("recon", "voxel", "--scene", scene, "-o", tmp_path / "cli.vox",
                      "--res", "16", "--iters", "30", "--batch", "256", "--test-list", held)
    assert (tmp_path / "py.vox").read_bytes() == (tmp_path / "cli.vox").read_bytes()
    assert info["test_psnr"] == cli["test_psnr"]
    every = diffsvg.recon_voxel(scene, tmp_path / "every.vox", res=16, iters=30, batch=256)
    assert every["test_psnr"] != info["test_psnr"]
    listed = diffsvg.view(tmp_path / "py.vox", scene, test_list=held)["views"]
    assert sorted(name for name, _, _ in listed) == ["test/r_0", "test/r_1"]
    halves = diffsvg.view(tmp_path / "py.vox", scene, test_every=2)["views"]
    assert len(halves) != len(listed) and len(halves) > 0
    with pytest.raises(diffsvg.DiffsvgError, match="test_every|test-every|test_list|test-list"):
        diffsvg.view(tmp_path / "py.vox", scene, test_every=2, test_list=held)


@pytest.mark.parametrize("kind", ["ngp", "nerf"])
def test_recon_fields_equal_the_cli_and_stop(tmp_path, kind):
    scene = write_scene(tmp_path / "ball")
    fit = diffsvg.recon_ngp if kind == "ngp" else diffsvg.recon_nerf
    small = dict(iters=30, steps=64, samples=2048, width=16)
    flags = ["--iters", "30", "--steps", "64", "--samples", "2048", "--width", "16"]
    if kind == "ngp":
        small.update(levels=4, log2_table=10, max_res=32)
        flags += ["--levels", "4", "--log2-table", "10", "--max-res", "32"]
    else:
        small.update(frequencies=4, density_layers=2)
        flags += ["--frequencies", "4", "--density-layers", "2"]
    seen = []
    info = fit(scene, tmp_path / f"py.{kind}", progress=seen.append, **small)
    cli = cli_summary("recon", kind, "--scene", scene, "-o", tmp_path / f"cli.{kind}", *flags)
    assert (tmp_path / f"py.{kind}").read_bytes() == (tmp_path / f"cli.{kind}").read_bytes()
    assert info["test_psnr"] == cli["test_psnr"] and info["samples"] == cli["samples"]
    assert info["iterations"] == 30 and len(seen) == 30 and info["pose_error"] is None
    assert info["log"].shape[1] == 6 and info["log"][-1, 0] == 30
    stopped = fit(scene, tmp_path / f"stop.{kind}", progress=lambda s: s["iteration"] < 5,
                  **small)
    assert stopped["stopped"] and stopped["iterations"] == 5
    views = diffsvg.view(tmp_path / f"py.{kind}", scene)
    assert len(views["views"]) == 2
    with pytest.raises(diffsvg.DiffsvgError, match="frequencies 0"):
        diffsvg.recon_nerf(scene, tmp_path / "m.nerf", frequencies=0)
    with pytest.raises(diffsvg.DiffsvgError, match=rf"m\.png: output must be a \.{kind}"):
        fit(scene, tmp_path / "m.png")
    with pytest.raises(diffsvg.DiffsvgError, match="lr: expected"):
        fit(scene, tmp_path / f"m.{kind}", lr=(1.0,))


def test_recon_refuses_bad_input_by_name(tmp_path):
    scene = write_scene(tmp_path / "ball")
    cases = [
        (dict(res=4), "res 4 must be between 8"),
        (dict(degree=7), "degree 7 must be 0 to 3"),
        (dict(bound=-1.0), "bound -1"),
        (dict(bound=1e30), "bound 1e30 must be between"),
        (dict(step=0.0), "step 0"),
    ]
    for kwargs, message in cases:
        with pytest.raises(diffsvg.DiffsvgError, match=message):
            diffsvg.recon_voxel(scene, tmp_path / "m.vox", iters=2, **kwargs)
    with pytest.raises(diffsvg.DiffsvgError, match="max_gaussians 0"):
        diffsvg.recon_splat(scene, tmp_path / "m.ply", max_gaussians=0)
    with pytest.raises(diffsvg.DiffsvgError, match=r"m\.png: output must be a \.vox"):
        diffsvg.recon_voxel(scene, tmp_path / "m.png")
    with pytest.raises((FileNotFoundError, diffsvg.DiffsvgError), match="no-such-scene"):
        diffsvg.recon_splat(tmp_path / "no-such-scene", tmp_path / "m.ply")
    (scene / "transforms_train.json").write_text("{ not json")
    with pytest.raises(diffsvg.DiffsvgError, match="transforms_train.json"):
        diffsvg.recon_voxel(scene, tmp_path / "m.vox", iters=2)
    # Nothing was written by any refused run.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ball"]


def test_recon_progress_exception_is_raised(tmp_path):
    scene = write_scene(tmp_path / "ball")

    class Boom(Exception):
        pass

    def cb(step):
        if step["iteration"] == 3:
            raise Boom("stop at 3")

    with pytest.raises(Boom, match="stop at 3"):
        diffsvg.recon_voxel(scene, tmp_path / "m.vox", res=8, iters=10, batch=16, progress=cb)
    assert not (tmp_path / "m.vox").exists()


def trained(tmp_path, kind):
    """A small scene written under tmp_path and a voxel grid ("vox") or Gaussians ("ply")
    briefly trained on it: (scene folder, model file)."""
    scene = write_scene(tmp_path / "scene")
    model = tmp_path / f"m.{kind}"
    if kind == "vox":
        diffsvg.recon_voxel(scene, model, res=16, iters=30, batch=256)
    else:
        diffsvg.recon_splat(scene, model, iters=20, initial=200, seed=3)
    return scene, model


@pytest.mark.parametrize("kind", ["vox", "ply"])
def test_view_renders_the_pixels_of_the_cli(tmp_path, kind):
    """diffsvg.view renders a trained voxel grid and Gaussians from the dataset's cameras
    and from orbit cameras: the pixels `diffsvg view` writes (its PNGs are 8-bit)."""
    scene, model = trained(tmp_path, kind)
    out = diffsvg.view(model, scene, orbit=4, elevation=20.0)
    run_cli("view", model, "--scene", scene, "--orbit", 4, "--elevation", 20, "-o",
            tmp_path / "cli")
    assert len(out["orbit"]) == 4 and len(out["views"]) == 2

    def eight_bit(rgb):
        return np.round(np.clip(rgb, 0, 1) * 255)

    for i, rgb in enumerate(out["orbit"]):
        png = diffsvg.load_image(tmp_path / "cli" / f"orbit-{i:03}.png")
        assert png.shape[:2] == rgb.shape[:2]
        assert np.abs(eight_bit(rgb) - np.round(png[..., :3] * 255)).max() <= 1
    for name, rgb, photo in out["views"]:
        pair = diffsvg.load_image(tmp_path / "cli" / f"{name.split('/')[-1]}.png")
        w = rgb.shape[1]
        assert np.abs(eight_bit(rgb) - np.round(pair[:, :w, :3] * 255)).max() <= 1
        assert np.abs(eight_bit(photo) - np.round(pair[:, -w:, :3] * 255)).max() <= 1
    # Rendering alone (no dataset), and bad input by name.
    assert len(diffsvg.view(model, orbit=2)["orbit"]) == 2
    with pytest.raises(diffsvg.DiffsvgError, match="split"):
        diffsvg.view(model, scene, split="val")


@pytest.mark.parametrize("kind", ["vox", "ply"])
def test_view_depth_is_the_cli_s(tmp_path, kind):
    """diffsvg.view(depth=True) gives each view's and orbit camera's expected and median
    depth, the float32 values `diffsvg view --depth` writes as .npy."""
    scene, model = trained(tmp_path, kind)
    out = diffsvg.view(model, scene, orbit=2, elevation=20.0, depth=True)
    run_cli("view", model, "--scene", scene, "--orbit", 2, "--elevation", 20, "--depth",
            "-o", tmp_path / "cli")
    assert len(out["depth"]) == len(out["views"]) == 2
    assert len(out["orbit_depth"]) == len(out["orbit"]) == 2
    stems = [name.split("/")[-1] for name, _, _ in out["views"]]
    stems += [f"orbit-{i:03}" for i in range(2)]
    hit = 0
    for stem, d, (_, rgb, _) in zip(stems, out["depth"] + out["orbit_depth"],
                                    out["views"] + [(None, o, None) for o in out["orbit"]]):
        for key in ("expected", "median"):
            got = d[key]
            assert got.dtype == np.float32 and got.shape == rgb.shape[:2]
            want = np.load(tmp_path / "cli" / f"{stem}.depth-{key}.npy")
            assert np.array_equal(got, want), (stem, key)
            assert np.isfinite(got).all() and (got >= 0).all()
            hit += int((got > 0).sum())
    assert hit > 0, "every depth is 0: nothing was seen"
    assert "depth" not in diffsvg.view(model, scene)
    with pytest.raises(TypeError, match="depth"):
        diffsvg.view(model, scene, depth=1)

