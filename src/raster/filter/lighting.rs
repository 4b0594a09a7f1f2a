//! feDiffuseLighting and feSpecularLighting: the input's alpha as a height map lit by a
//! distant, point or spot light, as resvg computes it, and the adjoint to that alpha.
//!
//! Pixel `(x, y)` of the filter region (its top-left pixel is `(0, 0)`; light positions are
//! given in the same pixels) has height `surfaceScale · α(x, y)`. Its normal is the SVG
//! specification's Sobel estimate: `N = (−surfaceScale · fx · Sx, −surfaceScale · fy · Sy,
//! 1)`, where `Sx` sums the horizontal differences of the rows above, at and below the
//! pixel with weights 1, 2, 1 (a missing neighbor replaced by the pixel itself, a missing
//! row dropped) and `fx = 2 / (span · weights)` (1/4 inside, 1/3, 1/2 or 2/3 on the
//! edges); `Sy` likewise. With `L` the unit vector to the light:
//!
//! * diffuse: `k = kd · N·L / |N|`, color `clamp(color · k)`, alpha 1;
//! * specular: `H = L + (0, 0, 1)`, `k = ks · (N·H / (|N| |H|))^exponent`, color
//!   `clamp(color · k)`, alpha the largest color channel.
//!
//! A spot light's color is scaled by `(−L·S)^exponent` (`S` the unit vector from the
//! light to where it points) and is black outside its cone. resvg rounds to 8 bits at each
//! step (the spot light's color, the result); diffsvg keeps `f32`. A region smaller than
//! 3 × 3 pixels is transparent (resvg's choice).
//!
//! The backward pass differentiates each pixel's result with respect to the nine alphas
//! it reads (forward-mode jets) and scatters the gradient onto them; the color channels of
//! the input get none (they are not read).

use crate::raster::jet::{Jet, Scalar};
use crate::scene::filter::{LightSource, Lighting};

/// The light source relative to the region's top-left pixel, in numbers of kind `S`.
#[derive(Clone, Copy)]
enum Local<S> {
    Distant([S; 3]),
    Point([S; 3]),
    Spot {
        pos: [S; 3],
        dir: [S; 3],
        exponent: S,
        cos_cone: Option<f64>,
    },
}

/// A vector divided by its length, or itself when that length is (nearly) zero.
fn normalized<S: Scalar>(v: [S; 3]) -> [S; 3] {
    let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    if len.v().abs() <= 1e-6 {
        v
    } else {
        v.map(|c| c / len)
    }
}

/// `m^e` with a derivative in both (in `e` only where `m > 0`, where `ln m` exists).
fn pow<S: Scalar>(m: S, e: S) -> S {
    let (mv, ev) = (m.v(), e.v());
    let p = m.powf(ev);
    if mv > 0.0 {
        // The first-order term in `e`: its value is 0, its derivative `m^e ln m · de`.
        p + (e - S::c(ev)) * S::c(mv.powf(ev) * mv.ln())
    } else {
        p
    }
}

/// A lighting primitive's numbers, of kind `S` (plain, or seeded to differentiate them):
/// surface scale, constant, color, specular exponent, and the light with the region's
/// top-left pixel at `corner`.
#[derive(Clone, Copy)]
pub(crate) struct Setup<S> {
    surface_scale: S,
    constant: S,
    color: [S; 3],
    exponent: Option<S>,
    light: Local<S>,
}

impl<S: Scalar> Setup<S> {
    /// `fe`'s setup from its numbers `v` in slot order
    /// ([`Lighting::values_mut`](crate::scene::filter::Lighting::values_mut)).
    fn of(fe: &Lighting, corner: [i64; 2], v: &[S]) -> Self {
        let mut at = 5;
        let exponent = fe.specular.map(|_| {
            at += 1;
            v[5]
        });
        let shift = |p: &[S]| {
            [
                p[0] - S::c(corner[0] as f64),
                p[1] - S::c(corner[1] as f64),
                p[2],
            ]
        };
        let l = &v[at..];
        let light = match &fe.light {
            LightSource::Distant { .. } => {
                let rad = S::c(std::f64::consts::PI / 180.0);
                let (a, e) = (l[0] * rad, l[1] * rad);
                Local::Distant([a.cos() * e.cos(), a.sin() * e.cos(), e.sin()])
            }
            LightSource::Point { .. } => Local::Point(shift(&l[..3])),
            LightSource::Spot { cone, .. } => {
                let pos = shift(&l[..3]);
                let to = shift(&l[3..6]);
                Local::Spot {
                    pos,
                    dir: normalized([to[0] - pos[0], to[1] - pos[1], to[2] - pos[2]]),
                    exponent: l[6],
                    cos_cone: cone.map(|c| c.to_radians().cos()),
                }
            }
        };
        Setup {
            surface_scale: v[0],
            constant: v[1],
            color: [v[2], v[3], v[4]],
            exponent,
            light,
        }
    }
}

impl Setup<f64> {
    /// `fe`'s setup with the region's top-left pixel at device pixel `corner`.
    pub(crate) fn new(fe: &Lighting, corner: [i64; 2]) -> Self {
        Setup::of(fe, corner, &fe.values())
    }

    /// The same numbers as constants of another kind.
    fn constants<T: Scalar>(fe: &Lighting, corner: [i64; 2]) -> Setup<T> {
        let v: Vec<T> = fe.values().into_iter().map(T::c).collect();
        Setup::of(fe, corner, &v)
    }
}

/// One pixel's lighting from the alphas `a` of its 3 × 3 neighborhood (row-major,
/// `a[4]` its own; entries outside the image are not read), premultiplied.
#[allow(clippy::too_many_arguments)]
fn pixel<S: Scalar>(p: &Setup<S>, a: &[S; 9], x: usize, y: usize, w: usize, h: usize) -> [S; 4] {
    let at = |dx: i64, dy: i64| a[((dy + 1) * 3 + dx + 1) as usize];
    let (has_l, has_r, has_t, has_b) = (x > 0, x + 1 < w, y > 0, y + 1 < h);
    // The difference across the pixel along x on row dy (or along y on column d).
    let dx_on = |dy: i64| match (has_l, has_r) {
        (true, true) => at(1, dy) - at(-1, dy),
        (false, _) => at(1, dy) - at(0, dy),
        (_, false) => at(0, dy) - at(-1, dy),
    };
    let dy_on = |d: i64| match (has_t, has_b) {
        (true, true) => at(d, 1) - at(d, -1),
        (false, _) => at(d, 1) - at(d, 0),
        (_, false) => at(d, 0) - at(d, -1),
    };
    let two = S::c(2.0);
    let mut sx = two * dx_on(0);
    let mut sy = two * dy_on(0);
    if has_t {
        sx = sx + dx_on(-1);
    }
    if has_b {
        sx = sx + dx_on(1);
    }
    if has_l {
        sy = sy + dy_on(-1);
    }
    if has_r {
        sy = sy + dy_on(1);
    }
    let span_x = if has_l && has_r { 2.0 } else { 1.0 };
    let span_y = if has_t && has_b { 2.0 } else { 1.0 };
    let rows = 2.0 + has_t as u8 as f64 + has_b as u8 as f64;
    let cols = 2.0 + has_l as u8 as f64 + has_r as u8 as f64;
    let ss = p.surface_scale;
    let n = [
        -sx * ss * S::c(2.0 / (span_x * rows)),
        -sy * ss * S::c(2.0 / (span_y * cols)),
        S::c(1.0),
    ];
    let surface = |pos: [S; 3]| {
        let z = a[4] * ss;
        normalized([pos[0] - S::c(x as f64), pos[1] - S::c(y as f64), pos[2] - z])
    };
    let (l, color) = match p.light {
        Local::Distant(v) => (v, p.color),
        Local::Point(pos) => (surface(pos), p.color),
        Local::Spot {
            pos,
            dir,
            exponent,
            cos_cone,
        } => {
            let l = surface(pos);
            let m = -(l[0] * dir[0] + l[1] * dir[1] + l[2] * dir[2]);
            let dark = m.v() <= 0.0 || cos_cone.is_some_and(|c| m.v() < c);
            let color = if dark {
                [S::c(0.0); 3]
            } else {
                let f = pow(m, exponent);
                p.color.map(|c| super::pixel::clamp(c * f, 0.0, 1.0))
            };
            (l, color)
        }
    };
    let n_len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let dot = |u: [S; 3], v: [S; 3]| u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
    let zero = S::c(0.0);
    let (k, specular) = match p.exponent {
        None => (p.constant * dot(n, l) / n_len, false),
        Some(e) => {
            let hv = [l[0], l[1], l[2] + S::c(1.0)];
            let h_len = dot(hv, hv).sqrt();
            if h_len.v().abs() <= 1e-6 {
                return [zero; 4];
            }
            let nh = dot(n, hv) / n_len / h_len;
            let q = if e.v() == 1.0 && nh.v() <= 0.0 {
                nh
            } else {
                pow(nh, e)
            };
            let q = if q.v().is_finite() { q } else { zero };
            (p.constant * q, true)
        }
    };
    let c = color.map(|c| super::pixel::clamp(c * k, 0.0, 1.0));
    let alpha = if specular {
        let mut m = c[0];
        for v in &c[1..] {
            if v.v() > m.v() {
                m = *v;
            }
        }
        m
    } else {
        S::c(1.0)
    };
    [c[0], c[1], c[2], alpha]
}

/// The neighborhood alphas of `(x, y)` (0 outside the image, never read there).
fn neighborhood(img: &[[f32; 4]], w: usize, h: usize, x: usize, y: usize) -> [f64; 9] {
    std::array::from_fn(|k| {
        let (dx, dy) = ((k % 3) as i64 - 1, (k / 3) as i64 - 1);
        let (sx, sy) = (x as i64 + dx, y as i64 + dy);
        if sx < 0 || sy < 0 || sx >= w as i64 || sy >= h as i64 {
            0.0
        } else {
            img[sy as usize * w + sx as usize][3] as f64
        }
    })
}

/// The lit image (`w × h`) of `img`'s alpha.
pub(crate) fn apply(p: &Setup<f64>, img: &[[f32; 4]], w: usize, h: usize) -> Vec<[f32; 4]> {
    let mut out = vec![[0.0f32; 4]; w * h];
    if w < 3 || h < 3 {
        return out;
    }
    for y in 0..h {
        for x in 0..w {
            let a = neighborhood(img, w, h, x, y);
            out[y * w + x] = pixel(p, &a, x, y, w, h).map(|v| v as f32);
        }
    }
    out
}

/// The most numbers a lighting primitive has
/// ([`Lighting::values_mut`](crate::scene::filter::Lighting::values_mut)).
const MOST_VALUES: usize = 13;

/// `∂L/∂θ` of `fe`'s numbers `θ` (slot order) from `∂L/∂out` at `img`, the region's
/// top-left pixel at device pixel `corner`; added to `grad`.
pub(crate) fn value_gradient(
    fe: &Lighting,
    corner: [i64; 2],
    img: &[[f32; 4]],
    w: usize,
    h: usize,
    g: &[[f32; 4]],
    grad: &mut [f64],
) {
    if w < 3 || h < 3 {
        return;
    }
    let v = fe.values();
    let seeded: Vec<Jet<MOST_VALUES>> =
        v.iter().enumerate().map(|(i, &x)| Jet::var(x, i)).collect();
    let p = Setup::of(fe, corner, &seeded);
    for y in 0..h {
        for x in 0..w {
            let gv = g[y * w + x];
            if gv == [0.0; 4] {
                continue;
            }
            let a = neighborhood(img, w, h, x, y).map(Jet::c);
            let o = pixel(&p, &a, x, y, w, h);
            for (k, d) in grad.iter_mut().enumerate().take(v.len()) {
                *d += (0..4).map(|c| gv[c] as f64 * o[c].d[k]).sum::<f64>();
            }
        }
    }
}

/// `∂L/∂img` from `∂L/∂out` at `img` (alpha channel only), the region's top-left pixel
/// at device pixel `corner`.
pub(crate) fn adjoint(
    fe: &Lighting,
    corner: [i64; 2],
    img: &[[f32; 4]],
    w: usize,
    h: usize,
    g: &[[f32; 4]],
) -> Vec<[f32; 4]> {
    let mut out = vec![[0.0f32; 4]; w * h];
    if w < 3 || h < 3 {
        return out;
    }
    let p = Setup::constants::<Jet<9>>(fe, corner);
    for y in 0..h {
        for x in 0..w {
            let gv = g[y * w + x];
            if gv == [0.0; 4] {
                continue;
            }
            let a = neighborhood(img, w, h, x, y);
            let aj: [Jet<9>; 9] = std::array::from_fn(|k| Jet::var(a[k], k));
            let o = pixel(&p, &aj, x, y, w, h);
            for k in 0..9 {
                let (sx, sy) = (x as i64 + (k % 3) as i64 - 1, y as i64 + (k / 3) as i64 - 1);
                if sx < 0 || sy < 0 || sx >= w as i64 || sy >= h as i64 {
                    continue;
                }
                let d: f64 = (0..4).map(|c| gv[c] as f64 * o[c].d[k]).sum();
                out[sy as usize * w + sx as usize][3] += d as f32;
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::filter::FilterInput;

    fn fe(specular: Option<f64>, light: LightSource) -> Lighting {
        Lighting {
            input: FilterInput::SourceGraphic,
            specular,
            surface_scale: 3.0,
            constant: 1.2,
            color: [1.0, 0.6, 0.3],
            light,
        }
    }

    fn flat(w: usize, h: usize, a: f32) -> Vec<[f32; 4]> {
        vec![[0.0, 0.0, 0.0, a]; w * h]
    }

    #[test]
    fn flat_and_sloped_surfaces_are_exact() {
        // A flat surface lit from straight above: k = constant, color · k clamped.
        let up = LightSource::Distant {
            azimuth: 30.0,
            elevation: 90.0,
        };
        let d = fe(None, up.clone());
        let out = apply(&Setup::new(&d, [0, 0]), &flat(4, 3, 0.5), 4, 3);
        for p in &out {
            let want = [1.0, 0.72, 0.36, 1.0];
            for c in 0..4 {
                assert!((p[c] - want[c]).abs() < 1e-6, "{p:?}");
            }
        }
        // Specular from above: N·H/|H| = 1, alpha the largest channel.
        let mut s = fe(Some(4.0), up);
        s.constant = 0.5;
        let out = apply(&Setup::new(&s, [0, 0]), &flat(4, 3, 0.5), 4, 3);
        assert!((out[5][0] - 0.5).abs() < 1e-6 && (out[5][3] - 0.5).abs() < 1e-6);
        assert!((out[5][1] - 0.3).abs() < 1e-6, "{:?}", out[5]);
        // A ramp α = 0.1·x lit from +x at elevation 0: inside, Sx = 4 · 0.2, fx = 1/4,
        // N = (−ss · 0.2, 0, 1), so N·L/|N| = −0.6/√1.36 < 0: black; from −x, positive.
        let ramp: Vec<[f32; 4]> = (0..15)
            .map(|i| [0.0, 0.0, 0.0, 0.1 * (i % 5) as f32])
            .collect();
        let mut d = fe(
            None,
            LightSource::Distant {
                azimuth: 180.0,
                elevation: 0.0,
            },
        );
        d.constant = 1.0;
        d.color = [1.0; 3];
        let out = apply(&Setup::new(&d, [0, 0]), &ramp, 5, 3);
        let want = 0.6 / 1.36f64.sqrt();
        assert!((out[7][0] as f64 - want).abs() < 1e-5, "{:?}", out[7]);
        // Too small a region: transparent.
        assert!(
            apply(&Setup::new(&d, [0, 0]), &flat(2, 5, 1.0), 2, 5)
                .iter()
                .all(|p| *p == [0.0; 4])
        );
    }

    #[test]
    fn adjoint_agrees_with_finite_differences() {
        let (w, h) = (6, 5);
        // A smooth bump, alphas away from 0 and 1.
        let img: Vec<[f32; 4]> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let a = 0.5 + 0.3 * (0.7 * x).sin() * (0.5 * y + 0.3).cos();
                [0.0, 0.0, 0.0, a]
            })
            .collect();
        let mut r = crate::rng::Rng::new(11);
        let g: Vec<[f32; 4]> = (0..w * h)
            .map(|_| std::array::from_fn(|_| r.uniform() - 0.5))
            .collect();
        let v: Vec<[f32; 4]> = (0..w * h)
            .map(|_| [0.0, 0.0, 0.0, r.uniform() - 0.5])
            .collect();
        let dot = super::super::blur::dot;
        let lights = [
            LightSource::Distant {
                azimuth: 40.0,
                elevation: 30.0,
            },
            LightSource::Point {
                pos: [12.0, 4.0, 8.0],
            },
            LightSource::Spot {
                pos: [13.0, 5.0, 9.0],
                points_at: [10.0, 7.0, 0.0],
                exponent: 2.0,
                cone: Some(80.0),
            },
        ];
        for light in lights {
            for specular in [None, Some(1.0), Some(3.5)] {
                let mut f = fe(specular, light.clone());
                f.constant = 0.4;
                f.surface_scale = 2.0;
                let loc = Setup::new(&f, [10, 3]);
                let back = adjoint(&f, [10, 3], &img, w, h, &g);
                let e = 1e-3f32;
                let at = |t: f32| {
                    let p: Vec<[f32; 4]> = img
                        .iter()
                        .zip(&v)
                        .map(|(a, b)| std::array::from_fn(|c| a[c] + t * b[c]))
                        .collect();
                    dot(&g, &apply(&loc, &p, w, h))
                };
                let fd = (at(e) - at(-e)) / (2.0 * e as f64);
                let an = dot(&back, &v);
                assert!(
                    (fd - an).abs() < 2e-2 * fd.abs().max(0.1),
                    "{light:?} {specular:?}: {fd} {an}"
                );
                // The primitive's own numbers.
                let mut grad = vec![0.0; f.value_count()];
                value_gradient(&f, [10, 3], &img, w, h, &g, &mut grad);
                for (k, an) in grad.iter().enumerate() {
                    let with = |d: f64| {
                        let mut q = f.clone();
                        *q.values_mut()[k].1 += d;
                        dot(&g, &apply(&Setup::new(&q, [10, 3]), &img, w, h))
                    };
                    let e = 1e-4;
                    let fd = (with(e) - with(-e)) / (2.0 * e);
                    assert!(
                        (fd - an).abs() < 2e-2 * fd.abs().max(0.1),
                        "{light:?} {specular:?} value {k}: {fd} {an}"
                    );
                }
            }
        }
    }
}
