"""DiffVG's single_curve app: one closed cubic path (its points and fill) fitted to a
target picture, in JAX with optax's Adam over the flat parameter vector.

    python single_curve.py [--size 256] [--iters 200] [-o single_curve.svg]
"""
import argparse
import jax, jax.numpy as jnp, numpy as np, optax
import diffsvg, diffsvg.jax

ap = argparse.ArgumentParser()
ap.add_argument("--size", type=int, default=256)
ap.add_argument("--iters", type=int, default=200)
ap.add_argument("-o", "--out", default="single_curve.svg")
a = ap.parse_args()

svg = ('<svg xmlns="http://www.w3.org/2000/svg" width="256" height="256"><path d="{}" '
       'fill="{}"/></svg>')
target = diffsvg.render(diffsvg.Scene.from_svg(svg.format(
    "M120 30 C200 40 230 120 180 190 C130 240 60 200 50 140 C40 80 70 30 120 30 Z",
    "#4d7fcc"), a.size, a.size))
scene = diffsvg.Scene.from_svg(svg.format(
    "M100 60 C180 50 190 150 160 180 C110 210 70 170 80 120 C90 90 60 70 100 60 Z",
    "#cc8040"), a.size, a.size)
rate = jnp.where(scene.layout()["group"] == 0, 1.0, 0.01)  # points: 1 px; colors: 0.01
loss = lambda x: jnp.mean((diffsvg.jax.render(scene, x) - target) ** 2)
step = jax.jit(jax.value_and_grad(loss))
x = jnp.asarray(scene.params(), jnp.float32)
opt = optax.chain(optax.scale_by_adam(), optax.scale(-1.0))
state = opt.init(x)
before = diffsvg.psnr(diffsvg.render(scene), target)
for t in range(a.iters):
    _, g = step(x)
    updates, state = opt.update(g, state)
    x = x + rate * updates
scene.set_params(np.asarray(x))  # projected onto valid scenes: the color into [0, 1]
print(f"PSNR {before:.2f} -> {diffsvg.psnr(diffsvg.render(scene), target):.2f} dB")
scene.save(a.out)
