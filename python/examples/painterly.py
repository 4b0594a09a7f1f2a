"""DiffVG's painterly app: random blobs fitted to a photo, with Adam written in numpy.

    python painterly.py PHOTO [--paths 256] [--iters 100] [-o painterly.svg]
"""
import argparse, time
import numpy as np
import diffsvg

ap = argparse.ArgumentParser()
ap.add_argument("photo")
ap.add_argument("--paths", type=int, default=256)
ap.add_argument("--iters", type=int, default=100)
ap.add_argument("-o", "--out", default="painterly.svg")
a = ap.parse_args()

white = (1.0, 1.0, 1.0)
photo = diffsvg.load_target(a.photo, 256, 256)
target = photo + (1 - photo[..., 3:]) * np.float32(1)  # the photo over white
scene = diffsvg.random_blobs(a.paths, 256, 256, seed=0)
rate = np.where(scene.layout()["group"] == 0, 1.0, 0.01)  # points: 1 px; colors: 0.01
x, m, v = scene.params(), 0.0, 0.0
start = time.perf_counter()
for t in range(1, a.iters + 1):
    img = diffsvg.render(scene, background=white)
    mse, d_img = diffsvg.loss(img, target, grad=True)
    g = diffsvg.render_backward(scene, d_img, background=white, structured=False)
    m = 0.9 * m + 0.1 * g
    v = 0.999 * v + 0.001 * g * g
    x = x - rate * (m / (1 - 0.9**t)) / (np.sqrt(v / (1 - 0.999**t)) + 1e-8)
    scene.set_params(x)  # projected onto valid scenes: colors stay in [0, 1]
    x = scene.params()
    if t % 25 == 0:
        print(f"step {t}: PSNR {diffsvg.psnr(img, target, channels='rgb'):.2f} dB")
ms = 1e3 * (time.perf_counter() - start) / a.iters
final = diffsvg.render(scene, background=white)
print(f"{a.paths} paths: PSNR {diffsvg.psnr(final, target, channels='rgb'):.2f} dB, "
      f"{ms:.1f} ms per step")
scene.save(a.out)
