//! Layers: compositing a group's layer onto the one below (opacity and blend mode) and
//! multiplying a layer by a clip path's or mask's factor, with the adjoint of each.
//!
//! Colors are premultiplied sRGB in `[0, 1]`, as everywhere in the rasterizer. The blend
//! functions are those of resvg's compositor (tiny-skia's high-precision pipeline), the
//! source being the layer times its opacity; they are written once, generic over
//! [`Scalar`], run on `f64` forward and on [`Jet`]s for the exact local derivative.

use super::jet::{Jet, Scalar};
use super::render::{Area, over};
use crate::scene::{BlendMode, MaskKind};

/// resvg's luminance coefficients (Rec. 709), applied to premultiplied channels: the
/// luminance of the straight color times the alpha.
pub(crate) const LUMA: [f32; 3] = [0.2126, 0.7152, 0.0722];

/// The factor a mask pixel multiplies the masked layer by.
#[inline]
pub(crate) fn mask_factor(px: [f32; 4], kind: MaskKind) -> f32 {
    match kind {
        MaskKind::Alpha => px[3],
        MaskKind::Luminance => {
            (LUMA[0] * px[0] + LUMA[1] * px[1] + LUMA[2] * px[2]).clamp(0.0, 1.0)
        }
    }
}

/// Multiplies `content` (covering `ca`) by the factor of `mask` (covering `ma`, or no
/// pixels at all); pixels of `ca` outside `ma` become transparent.
pub(crate) fn apply_mask(
    content: &mut [[f32; 4]],
    ca: Area,
    mask: Option<(&[[f32; 4]], Area)>,
    kind: MaskKind,
) {
    let scale = |c: &mut [f32; 4], m: f32| {
        for v in c.iter_mut() {
            *v *= m;
        }
    };
    for y in ca.y0..ca.y0 + ca.h {
        let row = &mut content[ca.index(ca.x0, y)..][..ca.w];
        // The columns `lo..hi` (device) of this row inside the mask; outside, factor 0.
        let (lo, hi) = match mask {
            Some((_, ma)) if y >= ma.y0 && y < ma.y0 + ma.h => {
                let lo = ma.x0.clamp(ca.x0, ca.x0 + ca.w);
                (lo, (ma.x0 + ma.w).clamp(lo, ca.x0 + ca.w))
            }
            _ => (ca.x0, ca.x0),
        };
        let (left, rest) = row.split_at_mut(lo - ca.x0);
        let (mid, right) = rest.split_at_mut(hi - lo);
        for c in left.iter_mut().chain(right) {
            scale(c, 0.0);
        }
        if let Some((m, ma)) = mask.filter(|_| lo < hi) {
            for (c, &px) in mid.iter_mut().zip(&m[ma.index(lo, y)..][..hi - lo]) {
                scale(c, mask_factor(px, kind));
            }
        }
    }
}

fn inside(a: Area, x: usize, y: usize) -> bool {
    x >= a.x0 && x < a.x0 + a.w && y >= a.y0 && y < a.y0 + a.h
}

fn factor_at(mask: Option<(&[[f32; 4]], Area)>, x: usize, y: usize, kind: MaskKind) -> f32 {
    match mask {
        Some((m, ma)) if inside(ma, x, y) => mask_factor(m[ma.index(x, y)], kind),
        _ => 0.0,
    }
}

/// The adjoint of [`apply_mask`]: `g` (over `ca`) holds ∂L/∂(masked content) and becomes
/// ∂L/∂(content before masking); returns ∂L/∂(mask layer) over `ma`. `content` is the
/// content before masking.
pub(crate) fn apply_mask_backward(
    g: &mut [[f32; 4]],
    ca: Area,
    content: &[[f32; 4]],
    mask: &[[f32; 4]],
    ma: Area,
    kind: MaskKind,
) -> Vec<[f32; 4]> {
    let mut gm = vec![[0.0f32; 4]; ma.len()];
    for y in ca.y0..ca.y0 + ca.h {
        for x in ca.x0..ca.x0 + ca.w {
            let k = ca.index(x, y);
            let m = factor_at(Some((mask, ma)), x, y, kind);
            let gk = g[k];
            for v in g[k].iter_mut() {
                *v *= m;
            }
            if !inside(ma, x, y) {
                continue;
            }
            let g_m: f32 = (0..4).map(|c| gk[c] * content[k][c]).sum();
            let px = mask[ma.index(x, y)];
            let dst = &mut gm[ma.index(x, y)];
            match kind {
                MaskKind::Alpha => dst[3] += g_m,
                MaskKind::Luminance => {
                    let l = LUMA[0] * px[0] + LUMA[1] * px[1] + LUMA[2] * px[2];
                    // The clamp passes no gradient where it bites.
                    if (0.0..=1.0).contains(&l) {
                        for c in 0..3 {
                            dst[c] += g_m * LUMA[c];
                        }
                    }
                }
            }
        }
    }
    gm
}

/// Composites a layer `top` (covering `ta`) onto `below` (covering `ba`, which contains
/// `ta`) with `opacity` and `blend`. Pixels of `below` outside `ta` are left as they are,
/// which is what compositing a transparent pixel does in every blend mode.
pub(crate) fn composite_layer(
    below: &mut [[f32; 4]],
    ba: Area,
    top: &[[f32; 4]],
    ta: Area,
    opacity: f32,
    blend: BlendMode,
) {
    for r in 0..ta.h {
        let src = &top[r * ta.w..][..ta.w];
        let dst = &mut below[ba.index(ta.x0, ta.y0 + r)..][..ta.w];
        if blend == BlendMode::Normal {
            // Eight transparent pixels of the layer leave the ones below as they are
            // (`over` of a zero source is `0 + d·1`): skipped.
            let mut dd = dst.chunks_exact_mut(8);
            let mut ss = src.chunks_exact(8);
            for (d8, s8) in (&mut dd).zip(&mut ss) {
                if s8.iter().all(|p| super::render::all_zero(p)) {
                    continue;
                }
                for (d, s) in d8.iter_mut().zip(s8) {
                    over(d, *s, opacity);
                }
            }
            for (d, s) in dd.into_remainder().iter_mut().zip(ss.remainder()) {
                over(d, *s, opacity);
            }
            continue;
        }
        for (d, s) in dst.iter_mut().zip(src) {
            if s[3] == 0.0 {
                continue;
            }
            let sv: [f64; 4] = std::array::from_fn(|c| (s[c] * opacity) as f64);
            let dv: [f64; 4] = d.map(|v| v as f64);
            let r = blend_px(blend, sv, dv);
            *d = r.map(|v| v as f32);
        }
    }
}

/// The adjoint of [`composite_layer`] at one pixel: for the output's gradient `go`, the
/// layer pixel `t` and the pixel below `b`, returns `(∂L/∂t, ∂L/∂b, ∂L/∂opacity)`.
#[inline]
pub(crate) fn composite_backward(
    blend: BlendMode,
    opacity: f32,
    go: [f32; 4],
    t: [f32; 4],
    b: [f32; 4],
) -> ([f32; 4], [f32; 4], f32) {
    if blend == BlendMode::Normal || t[3] == 0.0 {
        let gb: f32 = (0..4).map(|c| go[c] * b[c]).sum();
        let gt: f32 = (0..4).map(|c| go[c] * t[c]).sum();
        let mut g_top = go.map(|v| v * opacity);
        g_top[3] -= opacity * gb;
        let g_below = go.map(|v| v * (1.0 - t[3] * opacity));
        return (g_top, g_below, gt - t[3] * gb);
    }
    // Seeds 0..4: the source (layer × opacity); 4..8: the pixel below.
    let s: [Jet<8>; 4] = std::array::from_fn(|c| Jet::var((t[c] * opacity) as f64, c));
    let d: [Jet<8>; 4] = std::array::from_fn(|c| Jet::var(b[c] as f64, 4 + c));
    let r = blend_px(blend, s, d);
    let mut gs = [0.0f64; 4];
    let mut gd = [0.0f64; 4];
    for (o, rv) in r.iter().enumerate() {
        let g = go[o] as f64;
        if g == 0.0 {
            continue;
        }
        for c in 0..4 {
            gs[c] += g * rv.d[c];
            gd[c] += g * rv.d[4 + c];
        }
    }
    let g_top = gs.map(|v| (v * opacity as f64) as f32);
    let g_op: f64 = (0..4).map(|c| gs[c] * t[c] as f64).sum();
    (g_top, gd.map(|v| v as f32), g_op as f32)
}

#[inline]
fn inv<S: Scalar>(v: S) -> S {
    S::c(1.0) - v
}

#[inline]
fn two<S: Scalar>(v: S) -> S {
    v + v
}

#[inline]
fn min<S: Scalar>(a: S, b: S) -> S {
    if b.v() < a.v() { b } else { a }
}

#[inline]
fn max<S: Scalar>(a: S, b: S) -> S {
    if b.v() > a.v() { b } else { a }
}

/// `blend(s, d)` for one pixel, premultiplied, as tiny-skia's high-precision stages.
pub(crate) fn blend_px<S: Scalar>(mode: BlendMode, s: [S; 4], d: [S; 4]) -> [S; 4] {
    let (sa, da) = (s[3], d[3]);
    // A function of the color channels; alpha is source-over.
    let sep = |f: &dyn Fn(S, S) -> S| -> [S; 4] {
        [
            f(s[0], d[0]),
            f(s[1], d[1]),
            f(s[2], d[2]),
            d[3] * inv(sa) + sa,
        ]
    };
    match mode {
        BlendMode::Normal => std::array::from_fn(|c| d[c] * inv(sa) + s[c]),
        // Multiply and screen apply the same function to alpha.
        BlendMode::Multiply => {
            std::array::from_fn(|c| s[c] * inv(da) + d[c] * inv(sa) + s[c] * d[c])
        }
        BlendMode::Screen => std::array::from_fn(|c| s[c] + d[c] - s[c] * d[c]),
        BlendMode::PlusLighter => std::array::from_fn(|c| min(s[c] + d[c], S::c(1.0))),
        BlendMode::Darken => sep(&|s, d| s + d - max(s * da, d * sa)),
        BlendMode::Lighten => sep(&|s, d| s + d - min(s * da, d * sa)),
        BlendMode::Difference => sep(&|s, d| s + d - two(min(s * da, d * sa))),
        BlendMode::Exclusion => sep(&|s, d| s + d - two(s * d)),
        BlendMode::ColorBurn => sep(&|s, d| {
            if d.v() == da.v() {
                d + s * inv(da)
            } else if s.v() == 0.0 {
                d * inv(sa)
            } else {
                sa * (da - min(da, (da - d) * sa / s)) + s * inv(da) + d * inv(sa)
            }
        }),
        BlendMode::ColorDodge => sep(&|s, d| {
            if d.v() == 0.0 {
                s * inv(da)
            } else if s.v() == sa.v() {
                s + d * inv(sa)
            } else {
                sa * min(da, (d * sa) / (sa - s)) + s * inv(da) + d * inv(sa)
            }
        }),
        // Multiply or screen, chosen by the source (hard light) or the backdrop (overlay).
        BlendMode::HardLight | BlendMode::Overlay => sep(&|s, d| {
            let multiply = match mode {
                BlendMode::HardLight => two(s).v() <= sa.v(),
                _ => two(d).v() <= da.v(),
            };
            let k = if multiply {
                two(s * d)
            } else {
                sa * da - two((da - d) * (sa - s))
            };
            s * inv(da) + d * inv(sa) + k
        }),
        BlendMode::SoftLight => sep(&|s, d| {
            let one = S::c(1.0);
            let m = if da.v() > 0.0 { d / da } else { S::c(0.0) };
            let s2 = two(s);
            let m4 = two(two(m));
            let dark_src = d * (sa + (s2 - sa) * (one - m));
            let dark_dst = (m4 * m4 + m4) * (m - one) + S::c(7.0) * m;
            let lite_dst = m.sqrt() - m;
            let k = if two(two(d)).v() <= da.v() {
                dark_dst
            } else {
                lite_dst
            };
            let lite_src = d * sa + da * (s2 - sa) * k;
            s * inv(da) + d * inv(sa) + if s2.v() <= sa.v() { dark_src } else { lite_src }
        }),
        BlendMode::Hue | BlendMode::Saturation | BlendMode::Color | BlendMode::Luminosity => {
            non_separable(mode, s, d)
        }
    }
}

fn lum<S: Scalar>(c: [S; 3]) -> S {
    c[0] * S::c(0.30) + c[1] * S::c(0.59) + c[2] * S::c(0.11)
}

fn sat<S: Scalar>(c: [S; 3]) -> S {
    max(c[0], max(c[1], c[2])) - min(c[0], min(c[1], c[2]))
}

fn set_sat<S: Scalar>(c: &mut [S; 3], s: S) {
    let mn = min(c[0], min(c[1], c[2]));
    let mx = max(c[0], max(c[1], c[2]));
    let sat = mx - mn;
    for v in c.iter_mut() {
        *v = if sat.v() == 0.0 {
            S::c(0.0)
        } else {
            (*v - mn) * s / sat
        };
    }
}

fn set_lum<S: Scalar>(c: &mut [S; 3], l: S) {
    let diff = l - lum(*c);
    for v in c.iter_mut() {
        *v = *v + diff;
    }
}

fn clip_color<S: Scalar>(c: &mut [S; 3], a: S) {
    let mn = min(c[0], min(c[1], c[2]));
    let mx = max(c[0], max(c[1], c[2]));
    let l = lum(*c);
    for v in c.iter_mut() {
        let mut x = *v;
        if mx.v() < 0.0 {
            x = l + (x - l) * l / (l - mn);
        }
        if mx.v() > a.v() {
            x = l + (x - l) * (a - l) / (mx - l);
        }
        *v = max(x, S::c(0.0));
    }
}

/// Hue, saturation, color and luminosity, on premultiplied inputs as tiny-skia computes
/// them (the compositing spec's formulas, simplified as in OpenGL ES 3.2).
fn non_separable<S: Scalar>(mode: BlendMode, s: [S; 4], d: [S; 4]) -> [S; 4] {
    let (a, da) = (s[3], d[3]);
    let sc = [s[0], s[1], s[2]];
    let dc = [d[0], d[1], d[2]];
    let mut k = match mode {
        BlendMode::Hue => {
            let mut k = sc.map(|v| v * a);
            set_sat(&mut k, sat(dc) * a);
            set_lum(&mut k, lum(dc) * a);
            k
        }
        BlendMode::Saturation => {
            let mut k = dc.map(|v| v * a);
            set_sat(&mut k, sat(sc) * da);
            set_lum(&mut k, lum(dc) * a);
            k
        }
        BlendMode::Color => {
            let mut k = sc.map(|v| v * da);
            set_lum(&mut k, lum(dc) * a);
            k
        }
        _ => {
            let mut k = dc.map(|v| v * a);
            set_lum(&mut k, lum(sc) * da);
            k
        }
    };
    clip_color(&mut k, a * da);
    [
        sc[0] * inv(da) + dc[0] * inv(a) + k[0],
        sc[1] * inv(da) + dc[1] * inv(a) + k[1],
        sc[2] * inv(da) + dc[2] * inv(a) + k[2],
        a + da - a * da,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn px(seed: u64) -> [f64; 4] {
        let mut r = crate::rng::Rng::new(seed);
        let a = r.range(0.05, 1.0);
        [
            r.range(0.0, 1.0) * a,
            r.range(0.0, 1.0) * a,
            r.range(0.0, 1.0) * a,
            a,
        ]
    }

    /// Every mode's Jacobian (the one the backward pass uses) matches central
    /// differences of the forward function, away from its branch points.
    #[test]
    fn blend_derivatives_match_differences() {
        for mode in BlendMode::ALL {
            let mut checked = 0;
            for seed in 0..40u64 {
                let (s0, d0) = (px(2 * seed + 1), px(2 * seed + 2));
                let f = |s: [f64; 4], d: [f64; 4]| blend_px(mode, s, d);
                let s: [Jet<8>; 4] = std::array::from_fn(|c| Jet::var(s0[c], c));
                let d: [Jet<8>; 4] = std::array::from_fn(|c| Jet::var(d0[c], 4 + c));
                let r = blend_px(mode, s, d);
                let e = 1e-6;
                let mut ok = true;
                let mut worst: f64 = 0.0;
                for k in 0..8 {
                    let (mut sp, mut sm, mut dp, mut dm) = (s0, s0, d0, d0);
                    if k < 4 {
                        sp[k] += e;
                        sm[k] -= e;
                    } else {
                        dp[k - 4] += e;
                        dm[k - 4] -= e;
                    }
                    let (a, b) = (f(sp, dp), f(sm, dm));
                    for o in 0..4 {
                        let fd = (a[o] - b[o]) / (2.0 * e);
                        let err = (fd - r[o].d[k]).abs();
                        // A branch point between the two samples: skip this sample.
                        if err > 1e-3 * (1.0 + fd.abs()) {
                            ok = false;
                        }
                        worst = worst.max(err);
                    }
                }
                for o in 0..4 {
                    assert!(r[o].v.is_finite(), "{mode:?}");
                    assert!((r[o].v - f(s0, d0)[o]).abs() < 1e-12);
                }
                checked += ok as usize;
            }
            // Branches are few: most random pixels lie away from them.
            assert!(checked >= 30, "{mode:?}: only {checked} of 40 pixels agree");
        }
    }

    #[test]
    fn normal_blend_is_source_over() {
        let (s, d) = (px(3), px(4));
        let r = blend_px(BlendMode::Normal, s, d);
        for c in 0..4 {
            assert!((r[c] - (s[c] + d[c] * (1.0 - s[3]))).abs() < 1e-15);
        }
    }

    #[test]
    fn multiply_of_opaque_colors_is_their_product() {
        let (s, d) = ([0.5, 0.2, 1.0, 1.0], [0.4, 1.0, 0.3, 1.0]);
        let r = blend_px(BlendMode::Multiply, s, d);
        for c in 0..3 {
            assert!((r[c] - s[c] * d[c]).abs() < 1e-15);
        }
        assert_eq!(r[3], 1.0);
    }

    #[test]
    fn mask_backward_is_the_transpose() {
        let ca = Area {
            x0: 0,
            y0: 0,
            w: 3,
            h: 2,
        };
        let ma = Area {
            x0: 1,
            y0: 0,
            w: 2,
            h: 2,
        };
        let content: Vec<[f32; 4]> = (0..6).map(|k| px(k + 10).map(|v| v as f32)).collect();
        let mask: Vec<[f32; 4]> = (0..4).map(|k| px(k + 20).map(|v| v as f32)).collect();
        let gout: Vec<[f32; 4]> = (0..6).map(|k| px(k + 30).map(|v| v as f32 - 0.5)).collect();
        for kind in [MaskKind::Alpha, MaskKind::Luminance] {
            let loss = |c: &[[f32; 4]], m: &[[f32; 4]]| -> f64 {
                let mut out = c.to_vec();
                apply_mask(&mut out, ca, Some((m, ma)), kind);
                out.iter()
                    .zip(&gout)
                    .map(|(o, g)| (0..4).map(|i| (o[i] * g[i]) as f64).sum::<f64>())
                    .sum()
            };
            let mut g = gout.clone();
            let gm = apply_mask_backward(&mut g, ca, &content, &mask, ma, kind);
            let e = 1e-3f32;
            for k in 0..4 {
                for c in 0..4 {
                    let (mut p, mut m) = (mask.clone(), mask.clone());
                    p[k][c] += e;
                    m[k][c] -= e;
                    let fd = (loss(&content, &p) - loss(&content, &m)) / (2.0 * e as f64);
                    assert!((fd - gm[k][c] as f64).abs() < 1e-3, "{kind:?} mask {k} {c}");
                }
            }
            for k in 0..6 {
                for c in 0..4 {
                    let (mut p, mut m) = (content.clone(), content.clone());
                    p[k][c] += e;
                    m[k][c] -= e;
                    let fd = (loss(&p, &mask) - loss(&m, &mask)) / (2.0 * e as f64);
                    assert!(
                        (fd - g[k][c] as f64).abs() < 1e-3,
                        "{kind:?} content {k} {c}"
                    );
                }
            }
        }
    }
}
