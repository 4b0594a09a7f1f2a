"""DiffVG's refine_svg app: an SVG's points, colors, widths and gradients refined toward
a photo (or another drawing).

    python refine_svg.py IN.svg TARGET [--iters 200] [-o refined.svg]
"""
import argparse, time
import diffsvg

ap = argparse.ArgumentParser()
ap.add_argument("svg")
ap.add_argument("target", help="PNG, JPEG or SVG; resampled to the drawing's size")
ap.add_argument("--iters", type=int, default=200)
ap.add_argument("-o", "--out", default="refined.svg")
a = ap.parse_args()

scene = diffsvg.Scene.load(a.svg)
target = diffsvg.load_target(a.target, scene.width, scene.height)
white = (1.0, 1.0, 1.0)
over_white = target + (1 - target[..., 3:])  # compared over white, as the fit does
over = lambda s: diffsvg.render(s, background=white)
before = diffsvg.psnr(over(scene), over_white, channels="rgb")  # over RGB, as fit


def progress(step):
    if step["iter"] % 50 == 0:
        print(f"step {step['iter']}: PSNR {step['psnr']:.2f} dB")


start = time.perf_counter()
best, info = diffsvg.fit(scene, target, iters=a.iters, background=white,
                         schedule="cosine", progress=progress)
secs = time.perf_counter() - start
after = diffsvg.psnr(over(best), over_white, channels="rgb")
print(f"PSNR {before:.2f} -> {after:.2f} dB in {secs:.2f} s ({a.iters} steps)")
best.save(a.out)
