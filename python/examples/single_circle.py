"""DiffVG's single_circle app: a circle built in code, its center and radius (3 numbers)
fitted to a picture of another circle with optax's Adam; the SVG written holds a
``<circle>``.

    python single_circle.py [--size 256] [--iters 300] [-o single_circle.svg]
"""
import argparse
import jax, jax.numpy as jnp, numpy as np, optax
import diffsvg, diffsvg.jax

ap = argparse.ArgumentParser()
ap.add_argument("--size", type=int, default=256)
ap.add_argument("--iters", type=int, default=300)
ap.add_argument("-o", "--out", default="single_circle.svg")
a = ap.parse_args()

s = a.size / 256
goal = diffsvg.Scene(a.size, a.size)
goal.add_circle((140 * s, 120 * s), 65 * s, fill=(0.3, 0.6, 0.8))
target = diffsvg.render(goal)
scene = diffsvg.Scene(a.size, a.size)
scene.add_circle((100 * s, 150 * s), 40 * s, fill=(0.3, 0.6, 0.8))
layout = scene.layout()
points = np.array(layout["group_names"])[layout["group"]] == "points"
loss = lambda x: jnp.mean((diffsvg.jax.render(scene, x) - target) ** 2)
step = jax.jit(jax.value_and_grad(loss))
x = jnp.asarray(scene.params(), jnp.float32)
opt = optax.adam(optax.cosine_decay_schedule(2.0 * s, a.iters))
state = opt.init(x)
for t in range(a.iters):
    _, g = step(x)
    updates, state = opt.update(jnp.where(points, g, 0.0), state)  # center, radius only
    x = x + updates
scene.set_params(np.asarray(x, np.float64))
c = scene.arrays(np.float64)["shapes"][0]
print(f"center {c['center'].round(3)} radius {float(c['radius']):.3f} "
      f"(target {[140 * s, 120 * s]} {65 * s})")
scene.save(a.out)
