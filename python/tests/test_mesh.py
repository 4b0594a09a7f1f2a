"""diffsvg.Mesh and diffsvg.Camera: the exact mesh renderer from Python."""

import numpy as np
import pytest

import diffsvg
from conftest import run_cli, shared_data


def colored_sphere(subdivisions=2):
    m = diffsvg.Mesh.icosphere(subdivisions, 1.0)
    p = m.positions
    m.colors = 0.5 + 0.4 * p  # a smooth color per vertex, in [0.1, 0.9]
    return m


def camera(size=48):
    return diffsvg.Camera.look_at((0.4, 0.3, 3.2), (0.0, 0.0, 0.0), size, size, fov_x=0.8)


def test_render_covers_the_sphere_s_projected_area():
    m = colored_sphere(3)
    cam = camera(64)
    img = m.render(cam)
    assert img.shape == (64, 64, 4) and img.dtype == np.float32
    a = img[..., 3]
    assert a.min() >= 0 and a.max() <= 1 + 1e-6
    # The unit sphere at distance d seen with focal f covers about π (f / √(d² − 1))² px.
    fx, fy, cx, cy = cam.intrinsics
    d = float(np.linalg.norm([0.4, 0.3, 3.2]))
    disc = np.pi * (fx / np.sqrt(d * d - 1)) ** 2
    assert 0.93 * disc < a.sum() < disc, (a.sum(), disc)
    # Over a background every pixel is opaque; premultiplied colors never exceed alpha.
    white = m.render(cam, background=(1.0, 1.0, 1.0))
    assert np.allclose(white[..., 3], 1.0)
    assert np.all(img[..., :3] <= img[..., 3:] + 1e-6)


def test_gradients_match_central_differences():
    m = colored_sphere(2)
    cam = camera(32)
    rng = np.random.default_rng(1)
    w = rng.standard_normal((32, 32, 4)).astype(np.float32)
    g = m.render_backward(cam, w)
    assert g["positions"].shape == m.positions.shape
    assert g["colors"].shape == m.colors.shape

    def loss(mesh):
        return float((mesh.render(cam).astype(np.float64) * w).sum())

    # Vertices with the largest gradients: silhouette ones among them. The image is
    # continuous in the positions but has kinks (a vertex crossing a pixel center's ray,
    # a face turning at the silhouette), so a difference quotient may straddle one:
    # two small steps, one of them must agree.
    big = np.argsort(-np.abs(g["positions"]).sum(axis=1))[:6]

    def fd(v, k, h):
        p = m.positions
        p0 = p.copy()
        p[v, k] += h
        m.positions = p
        up = loss(m)
        p[v, k] -= 2 * h
        m.positions = p
        down = loss(m)
        m.positions = p0
        return (up - down) / (2 * h)

    for v in big:
        for k in range(3):
            an = g["positions"][v, k]
            fds = [fd(v, k, h) for h in (1e-5, 3e-6)]
            assert min(abs(f - an) for f in fds) <= 2e-3 * max(1.0, abs(an)), (v, k, an, fds)
    c = m.colors
    for v in big[:3]:
        c2 = c.copy()
        c2[v, 0] += 1e-3
        m.colors = c2
        fd = (loss(m) - loss(colored_sphere(2))) / 1e-3
        m.colors = c
        assert abs(fd - g["colors"][v, 0]) <= 1e-3 * max(1.0, abs(fd))


def test_fit_recovers_colors_and_stops_on_request():
    target_mesh = colored_sphere(2)
    cams = diffsvg.Camera.orbit(target_mesh, 4, 32)
    views = [(c, target_mesh.render(c, background=(1.0, 1.0, 1.0))) for c in cams]
    m = colored_sphere(2)
    m.colors = np.full_like(m.colors, 0.5)
    seen = []
    first = m.fit(views, iters=1, lr_positions=0.0)
    final = m.fit(views, iters=60, lr_positions=0.0, lr_colors=0.05,
                  progress=lambda s: seen.append(s["mse"]))
    assert len(seen) == 60 and final < 0.1 * first, (first, final)
    calls = []
    m.fit(views, iters=50, progress=lambda s: calls.append(s["iter"]) or s["iter"] < 4)
    assert calls == [0, 1, 2, 3, 4]


def test_render_equals_the_cli(tmp_path):
    m = colored_sphere(2)
    path = tmp_path / "sphere.obj"
    m.save(path)
    back = diffsvg.Mesh.load(path)
    # The reader numbers vertices in the order faces use them.
    def rows(a):
        r = np.round(a, 5) + 0.0  # no -0.0
        return r[np.lexsort(r.T[::-1])]
    assert np.allclose(rows(back.positions), rows(m.positions), atol=2e-5)
    assert back.triangles.shape == m.triangles.shape
    out = tmp_path / "cli.png"
    run_cli("mesh", "render", path, "--size", 40, "-o", out)
    cli = diffsvg.load_image(str(out))
    cam = diffsvg.Camera.orbit(back, 1, 40)[0]
    img = back.render(cam, background=(1.0, 1.0, 1.0))
    assert np.abs(np.round(img * 255) - np.round(cli * 255)).max() <= 1


def test_bad_input_is_one_line_naming_it(tmp_path):
    m = colored_sphere(1)
    with pytest.raises(diffsvg.DiffsvgError, match="positions"):
        m.positions = np.zeros((3, 3))
    with pytest.raises(diffsvg.DiffsvgError, match="not finite"):
        p = m.positions
        p[0, 0] = np.nan
        m.positions = p
    with pytest.raises(diffsvg.DiffsvgError, match="colors"):
        m.colors = np.full_like(m.positions, 2.0)
    with pytest.raises(diffsvg.DiffsvgError, match="d_image"):
        m.render_backward(camera(16), np.zeros((8, 8, 4), np.float32))
    with pytest.raises(diffsvg.DiffsvgError, match="limit"):
        m.render(diffsvg.Camera.look_at((0, 0, 3), (0, 0, 0), 100000, 100000))
    with pytest.raises(diffsvg.DiffsvgError, match="coincide"):
        diffsvg.Camera.look_at((0, 0, 0), (0, 0, 0), 8, 8)
    with pytest.raises(FileNotFoundError, match="nothing.obj"):
        diffsvg.Mesh.load(tmp_path / "nothing.obj")
    with pytest.raises(diffsvg.DiffsvgError, match="texture"):
        m.texture = np.zeros((4, 4, 3))


def test_spot_loads_with_its_texture():
    data = shared_data("test_spot_loads_with_its_texture")
    spot = diffsvg.Mesh.load(data / "meshes" / "spot" / "spot.obj")
    assert spot.texture.shape == (1024, 1024, 3) and spot.uvs is not None
    cam = diffsvg.Camera.orbit(spot, 1, 48)[0]
    g = spot.render_backward(cam, np.ones((48, 48, 4), np.float32))
    assert g["texture"].shape == (1024, 1024, 3) and np.isfinite(g["texture"]).all()
    assert np.abs(g["texture"]).sum() > 0


LIGHTS = [((0.4, 0.5, 1.0), (0.9, 0.8, 0.7)), ((-1.0, 0.2, -0.3), (0.3, 0.5, 0.6))]


def test_lit_render_and_gradients_of_lights_uvs_and_pose():
    m = colored_sphere(2)
    cam = camera(32)
    # Unlit by default; a white ambient light alone gives the same image.
    assert np.array_equal(m.render(cam), m.render(cam, ambient=(1.0, 1.0, 1.0)))
    lit = m.render(cam, lights=LIGHTS, ambient=(0.1, 0.1, 0.1))
    assert not np.array_equal(lit, m.render(cam))
    rng = np.random.default_rng(2)
    w = rng.standard_normal((32, 32, 4)).astype(np.float32)
    g = m.render_backward(cam, w, lights=LIGHTS, ambient=(0.1, 0.1, 0.1))
    assert g["pose"].shape == (6,) and g["light_directions"].shape == (2, 3)

    def loss(lights, ambient):
        img = m.render(cam, lights=lights, ambient=ambient).astype(np.float64)
        return float((img * w).sum())

    # The image is float32: steps of 1e-3 on the light.
    h = 1e-3
    for k in range(3):
        up = [list(map(list, l)) for l in LIGHTS]
        down = [list(map(list, l)) for l in LIGHTS]
        up[0][1][k] += h
        down[0][1][k] -= h
        up = [tuple(l) for l in up]  # pairs as tuples, the vectors as lists
        down = [tuple(l) for l in down]
        fd = (loss(up, (0.1,) * 3) - loss(down, (0.1,) * 3)) / (2 * h)
        an = g["light_intensities"][0, k]
        assert abs(fd - an) <= 1e-3 * max(1.0, abs(an)), (k, an, fd)
        a_up = [0.1] * 3
        a_up[k] += h
        fd = (loss(LIGHTS, tuple(a_up)) - loss(LIGHTS, (0.1,) * 3)) / h
        assert abs(fd - g["ambient"][k]) <= 1e-3 * max(1.0, abs(fd)), (k, g["ambient"][k], fd)
    with pytest.raises(ValueError, match="at most 4"):
        m.render(cam, lights=LIGHTS * 3)
    with pytest.raises(ValueError, match="zero"):
        m.render(cam, lights=[((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))])


def test_uv_gradients_of_spot():
    data = shared_data("test_uv_gradients_of_spot")
    spot = diffsvg.Mesh.load(data / "meshes" / "spot" / "spot.obj")
    cam = diffsvg.Camera.orbit(spot, 1, 48)[0]
    w = np.random.default_rng(4).standard_normal((48, 48, 4)).astype(np.float32)
    g = spot.render_backward(cam, w)
    assert g["uvs"].shape == spot.uvs.shape
    uv0 = spot.uvs

    def loss(uv):
        spot.uvs = uv
        return float((spot.render(cam).astype(np.float64) * w).sum())

    # The vertices with the largest UV gradients, against central differences (a float32
    # image: steps of 1e-4; a texel border may lie between, so one of two steps agrees).
    big = np.argsort(-np.abs(g["uvs"]).sum(axis=1))[:4]
    assert np.abs(g["uvs"][big[0]]).max() > 1e-2
    for v in big:
        for k in range(2):
            fds = []
            for h in (1e-4, 3e-5):
                up, down = uv0.copy(), uv0.copy()
                up[v, k] += h
                down[v, k] -= h
                fds.append((loss(up) - loss(down)) / (2 * h))
            an = g["uvs"][v, k]
            assert min(abs(f - an) for f in fds) <= 2e-2 * max(1.0, abs(an)), (v, k, an, fds)


def test_mipmaps_read_a_minified_texture_as_the_cli_does(tmp_path):
    data = shared_data("test_mipmaps_read_a_minified_texture_as_the_cli_does")
    path = data / "meshes" / "spot" / "spot.obj"
    spot = diffsvg.Mesh.load(path)
    # Spot's 1024² texture seen at 24²: each pixel covers many texels.
    cam = diffsvg.Camera.orbit(spot, 1, 24)[0]
    plain = spot.render(cam, background=(1.0, 1.0, 1.0))
    mip = spot.render(cam, background=(1.0, 1.0, 1.0), mipmaps=True)
    assert np.abs(mip - plain).max() > 1e-3
    out = tmp_path / "cli.png"
    run_cli("mesh", "render", path, "--size", 24, "--mipmaps", "-o", out)
    cli = diffsvg.load_image(str(out))
    assert np.abs(np.round(mip * 255) - np.round(cli * 255)).max() <= 1
    w = np.random.default_rng(5).standard_normal((24, 24, 4)).astype(np.float32)
    g = spot.render_backward(cam, w, mipmaps=True)
    assert np.isfinite(g["texture"]).all() and np.abs(g["texture"]).sum() > 0
    # The texture's gradient is that of the mipmapped image: one texel by differences.
    t = spot.texture
    iy, ix = np.unravel_index(np.argmax(np.abs(g["texture"][..., 0])), t.shape[:2])
    h = 0.05
    def loss(v):
        tt = t.copy()
        tt[iy, ix, 0] = v
        spot.texture = tt
        return float((spot.render(cam, mipmaps=True).astype(np.float64) * w).sum())
    # The image is linear in a texel: a difference within [0, 1] is exact up to rounding.
    lo, hi = max(0.0, t[iy, ix, 0] - h), min(1.0, t[iy, ix, 0] + h)
    fd = (loss(hi) - loss(lo)) / (hi - lo)
    spot.texture = t
    an = g["texture"][iy, ix, 0]
    assert abs(fd - an) <= 2e-2 * max(1.0, abs(an)), (an, fd)


def test_fit_with_lights_and_mipmaps_as_the_cli():
    # A lit sphere's colors fitted with the lights fixed: the fitted colors are the
    # albedo, so the views are matched and the colors come back where the views see them.
    truth = colored_sphere(2)
    lights = [((0.3, 0.8, 0.5), (0.9, 0.9, 0.9))]
    lit = dict(lights=lights, ambient=(0.2, 0.2, 0.2))
    cams = diffsvg.Camera.orbit(truth, 6, 32)
    views = [(c, truth.render(c, background=(1.0, 1.0, 1.0), **lit)) for c in cams]
    m = colored_sphere(2)
    m.colors = np.full_like(m.colors, 0.5)
    first = m.fit(views, iters=1, lr_positions=0.0, **lit)
    final = m.fit(views, iters=80, lr_positions=0.0, lr_colors=0.05, mipmaps=True, **lit)
    assert final < 0.1 * first, (first, final)
    # Vertices near the equator (the orbit sees them) facing the light: albedo recovered.
    p = truth.positions
    eq = (np.abs(p[:, 1]) < 0.4) & (p @ np.array([0.3, 0.8, 0.5]) / np.sqrt(0.98) > 0.3)
    assert eq.sum() > 5
    err = np.abs(m.colors[eq] - truth.colors[eq]).mean()
    assert err < 0.05, err
    with pytest.raises(ValueError, match="light"):
        m.fit(views, iters=1, lights=[((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))])


def textured_octahedron(tmp_path):
    """An octahedron with a UV per vertex and an 8x8 texture (a horizontal ramp)."""
    tex = np.zeros((8, 8, 4), np.float32)
    tex[..., :3] = np.linspace(0.0, 1.0, 8, dtype=np.float32)[None, :, None]
    tex[..., 3] = 1.0
    diffsvg.save_png(tex, str(tmp_path / "octa.png"))
    (tmp_path / "octa.mtl").write_text("newmtl t\nKd 1 1 1\nmap_Kd octa.png\n")
    v = [(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)]
    lines = ["mtllib octa.mtl"] + [f"v {x} {y} {z}" for x, y, z in v]
    lines += [f"vt {0.5 + 0.4 * x} {0.5 + 0.4 * y + 0.05 * z}" for x, y, z in v]
    lines.append("usemtl t")
    for f in [(1, 3, 5), (3, 2, 5), (2, 4, 5), (4, 1, 5), (3, 1, 6), (2, 3, 6), (4, 2, 6),
              (1, 4, 6)]:
        lines.append("f " + " ".join(f"{i}/{i}" for i in f))
    path = tmp_path / "octa.obj"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_refine_and_simplify_as_the_cli(tmp_path):
    path = textured_octahedron(tmp_path)
    m = diffsvg.Mesh.load(path)
    assert m.texture.shape == (8, 8, 3)
    ref = m.refine(levels=3, displace=0.02, seed=3)
    assert ref.triangles.shape == (8 * 64, 3)
    assert ref.texture.shape == (8, 8, 3) and ref.uvs is not None
    # The same mesh as `mesh refine` writes.
    out = tmp_path / "ref.obj"
    run_cli("mesh", "refine", path, "--levels", 3, "--displace", 0.02, "--seed", 3, "-o", out)
    cli = diffsvg.Mesh.load(out)
    def rows(a):
        r = np.round(a, 4) + 0.0
        return np.unique(r, axis=0)
    assert np.allclose(rows(cli.positions), rows(ref.positions), atol=2e-4)
    # Another seed moves the surface elsewhere.
    other = m.refine(levels=3, displace=0.02, seed=4)
    assert np.abs(other.positions - ref.positions).max() > 1e-3
    low = ref.simplify(100)
    assert 50 <= low.triangles.shape[0] <= 100, low
    textured = ref.simplify(100, reference=ref, texture_size=16)
    assert textured.texture.shape == (16, 16, 3) and textured.colors is None
    # The reprojected ramp still runs from dark (u small) to light.
    t = textured.texture
    assert t[:, :4].mean() < t[:, -4:].mean()
    with pytest.raises(ValueError, match="levels"):
        m.refine(levels=9)
    with pytest.raises(ValueError, match="triangles"):
        m.simplify(0)
