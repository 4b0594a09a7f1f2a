//! feMorphology: each premultiplied channel's minimum (erode) or maximum (dilate) over a
//! window, and its subgradient.
//!
//! resvg 0.49's window: the pixels within `t = min(round(r), size − 1)` of the pixel along
//! each axis (`2t + 1` per axis); pixels outside the image are skipped (not read as
//! transparent). A rectangle's
//! extremum is separable (rows, then columns), and each 1-D pass is a sliding window with
//! a monotonic queue, so the cost is independent of the radius. The backward pass sends
//! each output's gradient to the one pixel that attains the extremum (the first one in
//! scan order at a tie): a subgradient of the piecewise-linear max/min.

use std::collections::VecDeque;

/// The window length and its start before the pixel, for a radius `r` (device pixels) on
/// an axis of `n` pixels (`n ≥ 1`).
fn window(r: f64, n: usize) -> (usize, usize) {
    // Rounded in f32, half away from zero, as resvg rounds it.
    let t = ((r as f32).round().max(0.0) as f64).min(n.saturating_sub(1) as f64) as usize;
    (2 * t + 1, t)
}

/// For each `i < n`, the index in `[i − t, i − t + c)` ∩ `[0, n)` whose value is the
/// largest (`dilate`) or smallest.
fn arg_line(v: impl Fn(usize) -> f32, n: usize, c: usize, t: usize, dilate: bool) -> Vec<usize> {
    let better = |a: f32, b: f32| if dilate { a > b } else { a < b };
    let mut out = Vec::with_capacity(n);
    let mut q: VecDeque<usize> = VecDeque::new();
    let mut next = 0usize;
    for i in 0..n {
        let lo = i.saturating_sub(t);
        let hi = (i + c).saturating_sub(t).min(n); // exclusive
        while next < hi {
            let x = v(next);
            // Keep the earlier index at a tie: pop only strictly worse ones.
            while q.back().is_some_and(|&b| better(x, v(b))) {
                q.pop_back();
            }
            q.push_back(next);
            next += 1;
        }
        while q.front().is_some_and(|&f| f < lo) {
            q.pop_front();
        }
        out.push(*q.front().expect("the window holds its own pixel"));
    }
    out
}

/// For each output pixel and channel, the index of the input pixel it copies.
pub(crate) fn sources(
    img: &[[f32; 4]],
    w: usize,
    h: usize,
    dilate: bool,
    radius: [f64; 2],
) -> Vec<[usize; 4]> {
    let (cx, tx) = window(radius[0], w);
    let (cy, ty) = window(radius[1], h);
    let mut rows = vec![[0usize; 4]; w * h];
    for y in 0..h {
        for c in 0..4 {
            let arg = arg_line(|x| img[y * w + x][c], w, cx, tx, dilate);
            for (x, a) in arg.into_iter().enumerate() {
                rows[y * w + x][c] = y * w + a;
            }
        }
    }
    let mut out = vec![[0usize; 4]; w * h];
    for x in 0..w {
        for c in 0..4 {
            let arg = arg_line(|y| img[rows[y * w + x][c]][c], h, cy, ty, dilate);
            for (y, a) in arg.into_iter().enumerate() {
                out[y * w + x][c] = rows[a * w + x][c];
            }
        }
    }
    out
}

/// Whether the radii make the result transparent (resvg: either not positive).
pub(crate) fn empty(radius: [f64; 2]) -> bool {
    !(radius[0] > 0.0 && radius[1] > 0.0)
}

/// The eroded or dilated image (`w × h`, premultiplied).
pub(crate) fn apply(
    img: &[[f32; 4]],
    w: usize,
    h: usize,
    dilate: bool,
    radius: [f64; 2],
) -> Vec<[f32; 4]> {
    if empty(radius) {
        return vec![[0.0; 4]; img.len()];
    }
    sources(img, w, h, dilate, radius)
        .iter()
        .map(|s| std::array::from_fn(|c| img[s[c]][c]))
        .collect()
}

/// `∂L/∂img` from `∂L/∂out` at `img`.
pub(crate) fn adjoint(
    img: &[[f32; 4]],
    w: usize,
    h: usize,
    dilate: bool,
    radius: [f64; 2],
    g: &[[f32; 4]],
) -> Vec<[f32; 4]> {
    let mut out = vec![[0.0f32; 4]; img.len()];
    if empty(radius) {
        return out;
    }
    for (s, gv) in sources(img, w, h, dilate, radius).iter().zip(g) {
        for c in 0..4 {
            out[s[c]][c] += gv[c];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute force over resvg's window.
    fn naive(img: &[[f32; 4]], w: usize, h: usize, dilate: bool, r: [f64; 2]) -> Vec<[f32; 4]> {
        let (cx, tx) = window(r[0], w);
        let (cy, ty) = window(r[1], h);
        let mut out = Vec::new();
        for y in 0..h as i64 {
            for x in 0..w as i64 {
                let mut p = [if dilate { f32::MIN } else { f32::MAX }; 4];
                for oy in 0..cy as i64 {
                    for ox in 0..cx as i64 {
                        let (sx, sy) = (x - tx as i64 + ox, y - ty as i64 + oy);
                        if sx < 0 || sy < 0 || sx >= w as i64 || sy >= h as i64 {
                            continue;
                        }
                        let q = img[(sy * w as i64 + sx) as usize];
                        for c in 0..4 {
                            p[c] = if dilate {
                                p[c].max(q[c])
                            } else {
                                p[c].min(q[c])
                            };
                        }
                    }
                }
                out.push(p);
            }
        }
        out
    }

    #[test]
    fn matches_the_brute_force_window() {
        let mut r = crate::rng::Rng::new(5);
        let (w, h) = (9, 7);
        let img: Vec<[f32; 4]> = (0..w * h)
            .map(|_| std::array::from_fn(|_| r.uniform()))
            .collect();
        for dilate in [false, true] {
            for rad in [[0.5, 0.5], [1.0, 2.0], [2.3, 0.7], [40.0, 3.0]] {
                let got = apply(&img, w, h, dilate, rad);
                assert_eq!(got, naive(&img, w, h, dilate, rad), "{dilate} {rad:?}");
            }
        }
        assert!(
            apply(&img, w, h, true, [0.0, 1.0])
                .iter()
                .all(|p| *p == [0.0; 4])
        );
    }

    #[test]
    fn adjoint_sends_each_gradient_to_the_extremum() {
        // Distinct values: the derivative exists and finite differences agree.
        let (w, h) = (6, 5);
        let img: Vec<[f32; 4]> = (0..w * h)
            .map(|i| std::array::from_fn(|c| ((i * 7 + c * 13) % 31) as f32 / 31.0))
            .collect();
        let g: Vec<[f32; 4]> = (0..w * h)
            .map(|i| std::array::from_fn(|c| ((i * 5 + c * 3) % 11) as f32 - 5.0))
            .collect();
        let dot = super::super::blur::dot;
        for dilate in [false, true] {
            let rad = [1.5, 1.0];
            let back = adjoint(&img, w, h, dilate, rad, &g);
            for k in 0..w * h {
                for c in 0..4 {
                    let mut p = img.clone();
                    let e = 1e-3f32;
                    p[k][c] += e;
                    let up = dot(&g, &apply(&p, w, h, dilate, rad));
                    p[k][c] -= 2.0 * e;
                    let down = dot(&g, &apply(&p, w, h, dilate, rad));
                    let fd = (up - down) / (2.0 * e as f64);
                    assert!(
                        (fd - back[k][c] as f64).abs() < 1e-2,
                        "{k} {c}: {fd} {}",
                        back[k][c]
                    );
                }
            }
        }
    }
}
