//! feTurbulence: the SVG specification's reference Perlin noise, computed as resvg
//! computes it (same lattice, seed handling, stitching and per-channel scaling).
//!
//! Forward only: the result depends on no content, and its parameters are not
//! differentiable in diffsvg. `seed`, `numOctaves`, `stitchTiles` and `type` are discrete;
//! `baseFrequency` enters smoothly except at lattice crossings but is not a parameter of
//! the scene (filters have none yet), so nothing upstream of a turbulence gets a gradient
//! through it.

use crate::scene::filter::Turbulence;

const LATTICE: usize = 0x100;
const MASK: i64 = 0xff;
const OFFSET: f64 = 4096.0;
const RAND_M: i64 = 2_147_483_647;

/// The Park–Miller step of the reference code (Schrage's method, 32-bit safe).
fn next_random(seed: i64) -> i64 {
    let r = 16_807 * (seed % 127_773) - 2_836 * (seed / 127_773);
    if r <= 0 { r + RAND_M } else { r }
}

/// The permutation and per-channel unit gradients, `2·LATTICE + 2` entries each.
struct Lattice {
    perm: Vec<usize>,
    grad: [Vec<[f64; 2]>; 4],
}

impl Lattice {
    fn new(seed: i32) -> Self {
        let mut seed = seed as i64;
        if seed <= 0 {
            seed = -(seed % (RAND_M - 1)) + 1;
        }
        seed = seed.min(RAND_M - 1);
        let n = 2 * LATTICE + 2;
        let mut perm: Vec<usize> = (0..n).map(|i| i % LATTICE).collect();
        let mut grad: [Vec<[f64; 2]>; 4] = std::array::from_fn(|_| vec![[0.0; 2]; n]);
        for g in grad.iter_mut() {
            for v in g.iter_mut().take(LATTICE) {
                for c in v.iter_mut() {
                    seed = next_random(seed);
                    *c = ((seed % (2 * LATTICE as i64)) - LATTICE as i64) as f64 / LATTICE as f64;
                }
                let len = v[0].hypot(v[1]);
                *v = [v[0] / len, v[1] / len];
            }
        }
        for i in (1..LATTICE).rev() {
            seed = next_random(seed);
            perm.swap(i, (seed % LATTICE as i64) as usize);
        }
        for i in 0..LATTICE + 2 {
            perm[LATTICE + i] = perm[i];
            for g in grad.iter_mut() {
                g[LATTICE + i] = g[i];
            }
        }
        Lattice { perm, grad }
    }
}

#[derive(Clone, Copy)]
struct Stitch {
    width: i64,
    height: i64,
    wrap_x: i64,
    wrap_y: i64,
}

fn s_curve(t: f64) -> f64 {
    t * t * (3.0 - 2.0 * t)
}

fn lerp(t: f64, a: f64, b: f64) -> f64 {
    a + t * (b - a)
}

fn noise2(l: &Lattice, ch: usize, x: f64, y: f64, st: Option<Stitch>) -> f64 {
    let tx = x + OFFSET;
    let ty = y + OFFSET;
    // Truncations toward zero, as the reference's integer casts.
    let (mut bx0, mut by0) = (tx as i32 as i64, ty as i32 as i64);
    let (mut bx1, mut by1) = (bx0 + 1, by0 + 1);
    let rx0 = tx - tx as i64 as f64;
    let ry0 = ty - ty as i64 as f64;
    let (rx1, ry1) = (rx0 - 1.0, ry0 - 1.0);
    if let Some(s) = st {
        if bx0 >= s.wrap_x {
            bx0 -= s.width;
        }
        if bx1 >= s.wrap_x {
            bx1 -= s.width;
        }
        if by0 >= s.wrap_y {
            by0 -= s.height;
        }
        if by1 >= s.wrap_y {
            by1 -= s.height;
        }
    }
    let (bx0, bx1, by0, by1) = (
        (bx0 & MASK) as usize,
        (bx1 & MASK) as usize,
        (by0 & MASK) as usize,
        (by1 & MASK) as usize,
    );
    let (i, j) = (l.perm[bx0], l.perm[bx1]);
    let g = &l.grad[ch];
    let dot = |k: usize, rx: f64, ry: f64| rx * g[k][0] + ry * g[k][1];
    let sx = s_curve(rx0);
    let a = lerp(
        sx,
        dot(l.perm[i + by0], rx0, ry0),
        dot(l.perm[j + by0], rx1, ry0),
    );
    let b = lerp(
        sx,
        dot(l.perm[i + by1], rx0, ry1),
        dot(l.perm[j + by1], rx1, ry1),
    );
    lerp(s_curve(ry0), a, b)
}

/// The base frequency moved to a whole number of periods over the tile (`stitchTiles`).
fn stitch_frequency(f: f64, size: f64) -> f64 {
    if f.abs() <= f64::EPSILON {
        return f;
    }
    let lo = (size * f).floor() / size;
    let hi = (size * f).ceil() / size;
    if f / lo < hi / f { lo } else { hi }
}

/// The noise sum of one channel at lattice point `(x, y)`; `(px, py)` is the pixel in the
/// `size` tile (for stitching).
fn turbulence(
    l: &Lattice,
    t: &Turbulence,
    ch: usize,
    p: [f64; 2],
    px: [f64; 2],
    size: [f64; 2],
) -> f64 {
    let mut f = t.base_frequency;
    let mut st = None;
    if t.stitch {
        f = [
            stitch_frequency(f[0], size[0]),
            stitch_frequency(f[1], size[1]),
        ];
        let width = (size[0] * f[0] + 0.5) as i32 as i64;
        let height = (size[1] * f[1] + 0.5) as i32 as i64;
        st = Some(Stitch {
            width,
            height,
            wrap_x: (px[0] * f[0] + OFFSET + width as f64) as i32 as i64,
            wrap_y: (px[1] * f[1] + OFFSET + height as f64) as i32 as i64,
        });
    }
    let (mut x, mut y) = (p[0] * f[0], p[1] * f[1]);
    let (mut sum, mut ratio) = (0.0, 1.0);
    for _ in 0..t.octaves {
        let n = noise2(l, ch, x, y, st);
        sum += if t.fractal { n } else { n.abs() } / ratio;
        x *= 2.0;
        y *= 2.0;
        ratio *= 2.0;
        if let Some(s) = st.as_mut() {
            s.width *= 2;
            s.wrap_x = 2 * s.wrap_x - OFFSET as i64;
            s.height *= 2;
            s.wrap_y = 2 * s.wrap_y - OFFSET as i64;
        }
    }
    sum
}

/// The noise over a `w × h` region whose top-left pixel is device pixel `corner`,
/// premultiplied (each channel clamped to `[0, 1]`, then multiplied by alpha).
pub(crate) fn render(t: &Turbulence, w: usize, h: usize, corner: [i64; 2]) -> Vec<[f32; 4]> {
    let mut out = vec![[0.0f32; 4]; w * h];
    if t.scale[0].abs() <= 1e-12 || t.scale[1].abs() <= 1e-12 {
        return out;
    }
    let l = Lattice::new(t.seed);
    let size = [w as f64, h as f64];
    for y in 0..h {
        for x in 0..w {
            let p = [
                (x as f64 + corner[0] as f64 - t.origin[0]) / t.scale[0],
                (y as f64 + corner[1] as f64 - t.origin[1]) / t.scale[1],
            ];
            let px = [x as f64, y as f64];
            let v: [f64; 4] = std::array::from_fn(|ch| {
                let n = turbulence(&l, t, ch, p, px, size);
                let n = if t.fractal { (n + 1.0) / 2.0 } else { n };
                n.clamp(0.0, 1.0)
            });
            // resvg stores 8-bit values before premultiplying; keep that rounding so
            // that the noise matches it.
            let q = v.map(|c| (c * 255.0 + 0.5).floor() / 255.0);
            out[y * w + x] = [q[0] * q[3], q[1] * q[3], q[2] * q[3], q[3]].map(|c| c as f32);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn turb(fractal: bool, stitch: bool) -> Turbulence {
        Turbulence {
            base_frequency: [0.05, 0.08],
            octaves: 3,
            seed: 7,
            stitch,
            fractal,
            origin: [0.0, 0.0],
            scale: [1.0, 1.0],
        }
    }

    #[test]
    fn noise_is_deterministic_bounded_and_varied() {
        for fractal in [false, true] {
            for stitch in [false, true] {
                let t = turb(fractal, stitch);
                let a = render(&t, 16, 12, [3, 4]);
                assert_eq!(a, render(&t, 16, 12, [3, 4]));
                assert!(
                    a.iter()
                        .all(|p| p.iter().all(|v| (0.0..=1.0).contains(v)) && p[0] <= p[3] + 1e-6)
                );
                let distinct: std::collections::BTreeSet<u32> =
                    a.iter().map(|p| p[3].to_bits()).collect();
                assert!(
                    distinct.len() > 20,
                    "{fractal} {stitch}: {}",
                    distinct.len()
                );
                // Another seed, another pattern.
                let mut t2 = t.clone();
                t2.seed = 8;
                assert_ne!(a, render(&t2, 16, 12, [3, 4]));
            }
        }
    }

    #[test]
    fn lattice_points_are_zero_noise() {
        // Perlin noise vanishes on the lattice: at integer lattice coordinates every
        // octave's noise is 0, so fractal noise is ½ and turbulence 0.
        let mut t = turb(true, false);
        t.base_frequency = [1.0, 1.0];
        t.octaves = 1;
        let a = render(&t, 3, 3, [0, 0]);
        for p in &a {
            assert!((p[3] - 128.0 / 255.0).abs() < 1e-6, "{p:?}");
        }
        t.fractal = false;
        assert!(render(&t, 3, 3, [0, 0]).iter().all(|p| p[3] == 0.0));
    }
}
