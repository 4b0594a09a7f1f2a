//! feConvolveMatrix, as resvg computes it, and its exact adjoint.
//!
//! For output pixel `(x, y)` the tap `(i, j)` of the kernel (SVG's row-major order) reads
//! input pixel `(x − targetX + (cols − 1 − i), y − targetY + (rows − 1 − j))`: the kernel
//! is rotated half a turn, a true convolution. `edgeMode` decides what a tap outside the
//! image reads: nothing (`none`), the nearest edge pixel (`duplicate`) or the opposite
//! side (`wrap`). The sums `S` are of premultiplied channels, or of straight colors with
//! `preserveAlpha` (alpha then kept). resvg's output, per pixel with `d` the divisor and
//! `b` the bias:
//!
//! * alpha: `a = S_a/d + b` (or the input's alpha), clamped to `[0, 1]`;
//! * colors: `S_c/d + b·a` with the unclamped `a`, clamped to `[0, a]`; with
//!   `preserveAlpha` clamped to `[0, 1]` and multiplied by `a`.
//!
//! The backward pass runs the per-pixel part on jets and scatters the sums' gradients back
//! along the taps (the transpose of the linear part); a clamp's derivative is one side's.
//! With `preserveAlpha` the straight colors are read, so the result jumps where a pixel
//! turns from transparent (straight color 0, as resvg divides) to barely covered: the
//! gradient is that of each side, not of the jump.

use super::pixel;
use crate::raster::jet::{Jet, Scalar};
use crate::scene::filter::Convolve;

/// The input pixel each tap of output pixel `(x, y)` reads, with the tap's weight.
fn taps(m: &Convolve, w: usize, h: usize, x: usize, y: usize, mut f: impl FnMut(usize, f64)) {
    let [cols, rows] = m.order;
    for oy in 0..rows {
        for ox in 0..cols {
            let tx = x as i64 - m.target[0] as i64 + ox as i64;
            let ty = y as i64 - m.target[1] as i64 + oy as i64;
            let (wi, hi) = (w as i64, h as i64);
            let (tx, ty) = match m.edge {
                0 => {
                    if tx < 0 || ty < 0 || tx >= wi || ty >= hi {
                        continue;
                    }
                    (tx, ty)
                }
                1 => (tx.clamp(0, wi - 1), ty.clamp(0, hi - 1)),
                _ => (tx.rem_euclid(wi), ty.rem_euclid(hi)),
            };
            let k = m.kernel[(rows - 1 - oy) * cols + (cols - 1 - ox)];
            f(ty as usize * w + tx as usize, k);
        }
    }
}

/// The per-pixel output from the sums `s` and the pixel's own alpha `own_a`.
fn finish<S: Scalar>(m: &Convolve, s: [S; 4], own_a: S) -> [S; 4] {
    let d = S::c(m.divisor);
    let b = S::c(m.bias);
    let a = if m.preserve_alpha {
        own_a
    } else {
        s[3] / d + b
    };
    let ba = pixel::clamp(a, 0.0, 1.0);
    let c = |v: S| {
        let v = v / d + b * a;
        if m.preserve_alpha {
            pixel::clamp(v, 0.0, 1.0) * ba
        } else if v.v() < 0.0 {
            S::c(0.0)
        } else if v.v() > ba.v() {
            ba
        } else {
            v
        }
    };
    [c(s[0]), c(s[1]), c(s[2]), ba]
}

/// The values the taps read: premultiplied, or straight with `preserveAlpha`.
fn read(m: &Convolve, img: &[[f32; 4]]) -> Vec<[f32; 4]> {
    if m.preserve_alpha {
        img.iter()
            .map(|&p| pixel::eval1(&|v| pixel::straight(v), p))
            .collect()
    } else {
        img.to_vec()
    }
}

fn sums(m: &Convolve, u: &[[f32; 4]], w: usize, h: usize, x: usize, y: usize) -> [f64; 4] {
    let mut s = [0.0f64; 4];
    taps(m, w, h, x, y, |i, k| {
        for c in 0..4 {
            s[c] += k * u[i][c] as f64;
        }
    });
    s
}

/// The convolved image (`w × h`, premultiplied in and out).
pub(crate) fn apply(m: &Convolve, img: &[[f32; 4]], w: usize, h: usize) -> Vec<[f32; 4]> {
    let u = read(m, img);
    let mut out = Vec::with_capacity(img.len());
    for y in 0..h {
        for x in 0..w {
            let s = sums(m, &u, w, h, x, y);
            out.push(finish(m, s, u[y * w + x][3] as f64).map(|v| v as f32));
        }
    }
    out
}

/// `∂L/∂img` from `∂L/∂out` at `img`.
pub(crate) fn adjoint(
    m: &Convolve,
    img: &[[f32; 4]],
    w: usize,
    h: usize,
    g: &[[f32; 4]],
) -> Vec<[f32; 4]> {
    let u = read(m, img);
    let mut gu = vec![[0.0f64; 4]; img.len()];
    for y in 0..h {
        for x in 0..w {
            let gv = g[y * w + x];
            if gv == [0.0; 4] {
                continue;
            }
            let s = sums(m, &u, w, h, x, y);
            let sj: [Jet<5>; 4] = std::array::from_fn(|c| Jet::var(s[c], c));
            let own = Jet::var(u[y * w + x][3] as f64, 4);
            let o = finish(m, sj, own);
            let d = |i: usize| (0..4).map(|c| gv[c] as f64 * o[c].d[i]).sum::<f64>();
            let gs = [d(0), d(1), d(2), d(3)];
            gu[y * w + x][3] += d(4);
            taps(m, w, h, x, y, |i, k| {
                for c in 0..4 {
                    gu[i][c] += k * gs[c];
                }
            });
        }
    }
    let gu: Vec<[f32; 4]> = gu.iter().map(|v| v.map(|x| x as f32)).collect();
    if m.preserve_alpha {
        img.iter()
            .zip(&gu)
            .map(|(&p, &gv)| pixel::adjoint1(&|v| pixel::straight(v), p, gv))
            .collect()
    } else {
        gu
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::filter::FilterInput;

    fn conv(kernel: Vec<f64>, order: [usize; 2], target: [usize; 2], edge: u8) -> Convolve {
        Convolve {
            input: FilterInput::SourceGraphic,
            order,
            kernel,
            target,
            divisor: 1.0,
            bias: 0.0,
            edge,
            preserve_alpha: false,
        }
    }

    #[test]
    fn small_cases_are_exact() {
        // A 3 × 1 image; the kernel [1, 2] with target 0 reads pixel x + 1 with weight 1
        // and pixel x with weight 2 (the kernel rotated).
        let a = [0.1f32, 0.2, 0.3];
        let img: Vec<[f32; 4]> = a.iter().map(|&v| [v, v, v, v]).collect();
        let m = conv(vec![1.0, 2.0], [2, 1], [0, 0], 0);
        let out = apply(&m, &img, 3, 1);
        let want = [0.1 * 2.0 + 0.2, 0.2 * 2.0 + 0.3, 0.3 * 2.0];
        for (o, w) in out.iter().zip(want) {
            assert!((o[3] - w).abs() < 1e-6, "{o:?} {w}");
        }
        // Duplicate: the last pixel reads itself past the edge; wrap: the first pixel.
        let dup = apply(&conv(vec![1.0, 2.0], [2, 1], [0, 0], 1), &img, 3, 1);
        assert!((dup[2][3] - 0.9).abs() < 1e-6);
        let wrap = apply(&conv(vec![1.0, 2.0], [2, 1], [0, 0], 2), &img, 3, 1);
        assert!((wrap[2][3] - 0.7).abs() < 1e-6);
        // Bias lifts alpha, and colors by bias times alpha, clamped to alpha.
        let mut m = conv(vec![0.5], [1, 1], [0, 0], 0);
        m.bias = 0.25;
        let out = apply(&m, &[[0.2, 0.4, 0.0, 0.4]], 1, 1);
        let a = 0.2 + 0.25;
        let want = [0.1 + 0.25 * a, 0.2 + 0.25 * a, 0.25 * a, a];
        for c in 0..4 {
            assert!((out[0][c] as f64 - want[c]).abs() < 1e-6, "{out:?}");
        }
    }

    #[test]
    fn adjoint_agrees_with_finite_differences() {
        let mut r = crate::rng::Rng::new(9);
        let (w, h) = (5, 4);
        let img: Vec<[f32; 4]> = (0..w * h)
            .map(|_| {
                let a = 0.4 + 0.5 * r.uniform();
                [0.2, 0.5, 0.8, 1.0].map(|c| c * a * (0.5 + 0.5 * r.uniform()))
            })
            .map(|mut p: [f32; 4]| {
                p[3] = p[3].max(p[0]).max(p[1]).max(p[2]) + 0.05;
                p
            })
            .collect();
        let g: Vec<[f32; 4]> = (0..w * h)
            .map(|_| std::array::from_fn(|_| r.uniform() - 0.5))
            .collect();
        let dot = super::super::blur::dot;
        let kernel = vec![0.1, -0.05, 0.2, 0.15, 0.3, 0.05];
        for (edge, preserve) in [(0, false), (1, true), (2, false), (2, true)] {
            let mut m = conv(kernel.clone(), [3, 2], [1, 1], edge);
            m.preserve_alpha = preserve;
            m.divisor = 0.9;
            m.bias = 0.02;
            let back = adjoint(&m, &img, w, h, &g);
            let v: Vec<[f32; 4]> = (0..w * h)
                .map(|_| std::array::from_fn(|_| r.uniform() - 0.5))
                .collect();
            let e = 1e-3f32;
            let at = |t: f32| {
                let p: Vec<[f32; 4]> = img
                    .iter()
                    .zip(&v)
                    .map(|(a, b)| std::array::from_fn(|c| a[c] + t * b[c]))
                    .collect();
                dot(&g, &apply(&m, &p, w, h))
            };
            let fd = (at(e) - at(-e)) / (2.0 * e as f64);
            let an = dot(&back, &v);
            assert!(
                (fd - an).abs() < 1e-2 * fd.abs().max(0.1),
                "{edge} {preserve}: {fd} {an}"
            );
        }
    }
}
