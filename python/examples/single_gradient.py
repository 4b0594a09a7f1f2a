"""DiffVG's single_gradient app: a linear gradient's ends and stops fitted to a target
picture, with Adam written in numpy over render / loss / render_backward.

    python single_gradient.py [--size 256] [--iters 300] [-o single_gradient.svg]
"""
import argparse
import numpy as np
import diffsvg

ap = argparse.ArgumentParser()
ap.add_argument("--size", type=int, default=256)
ap.add_argument("--iters", type=int, default=300)
ap.add_argument("-o", "--out", default="single_gradient.svg")
a = ap.parse_args()

svg = ('<svg xmlns="http://www.w3.org/2000/svg" width="256" height="256"><linearGradient '
       'id="g" gradientUnits="userSpaceOnUse" x1="{}" y1="{}" x2="{}" y2="{}"><stop offset="{}" '
       'stop-color="{}"/><stop offset="1" stop-color="{}"/></linearGradient>'
       '<rect x="16" y="16" width="224" height="224" fill="url(#g)"/></svg>')
load = lambda *v: diffsvg.Scene.from_svg(svg.format(*v), a.size, a.size)
target = diffsvg.render(load(40, 30, 220, 200, 0.2, "#e04a3c", "#2a5cd0"))
scene = load(128, 40, 128, 220, 0.0, "#808080", "#40a040")
group = np.array(scene.layout()["group_names"])[scene.layout()["group"]]
rate = np.select([group == "points", group == "paint"], [0.0, 1.0], 0.01)  # the rect stays
x, m, v = scene.params(), 0.0, 0.0
before = diffsvg.psnr(diffsvg.render(scene), target)
for t in range(1, a.iters + 1):
    _, d_img = diffsvg.loss(diffsvg.render(scene), target, grad=True)
    g = diffsvg.render_backward(scene, d_img, structured=False)
    m, v = 0.9 * m + 0.1 * g, 0.999 * v + 0.001 * g * g
    x = x - rate * (m / (1 - 0.9**t)) / (np.sqrt(v / (1 - 0.999**t)) + 1e-8)
    scene.set_params(x)  # projected: colors in [0, 1], stop offsets in order
    x = scene.params()
print(f"PSNR {before:.2f} -> {diffsvg.psnr(diffsvg.render(scene), target):.2f} dB")
print("gradient:", np.round(scene.arrays(np.float64)["shapes"][0]["fill"]["geometry"], 1))
scene.save(a.out)
