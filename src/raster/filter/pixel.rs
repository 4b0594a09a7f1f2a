//! The per-pixel filter operators: color-space conversion, feColorMatrix,
//! feComponentTransfer, feComposite and feBlend.
//!
//! Pixels are premultiplied. Each operator is written once, generic over [`Scalar`]: the
//! forward pass runs it on `f64`, the backward pass on [`Jet`]s seeded on its inputs for
//! the exact local derivative (piecewise: at a clamp or a table's knot it is one side's).
//! The formulas are resvg's (`crates/resvg/src/filter/`), on `f32` values instead of
//! bytes.

use crate::raster::jet::{Jet, Scalar};
use crate::raster::layer::blend_px;
use crate::scene::BlendMode;
use crate::scene::filter::{CompositeOp, TransferFunction};

/// `x` clamped to `[lo, hi]` (a constant outside).
#[inline]
pub(crate) fn clamp<S: Scalar>(x: S, lo: f64, hi: f64) -> S {
    if x.v() < lo {
        S::c(lo)
    } else if x.v() > hi {
        S::c(hi)
    } else {
        x
    }
}

/// The straight color of a premultiplied pixel (0 where it is transparent, as resvg's
/// byte division gives).
#[inline]
pub(crate) fn straight<S: Scalar>(px: [S; 4]) -> [S; 4] {
    let a = px[3];
    if a.v() <= 0.0 {
        return [S::c(0.0); 4];
    }
    [
        clamp(px[0] / a, 0.0, 1.0),
        clamp(px[1] / a, 0.0, 1.0),
        clamp(px[2] / a, 0.0, 1.0),
        a,
    ]
}

/// A straight color with its channels clamped to `[0, 1]`, premultiplied.
#[inline]
fn premultiplied<S: Scalar>(c: [S; 4]) -> [S; 4] {
    let a = clamp(c[3], 0.0, 1.0);
    [
        clamp(c[0], 0.0, 1.0) * a,
        clamp(c[1], 0.0, 1.0) * a,
        clamp(c[2], 0.0, 1.0) * a,
        a,
    ]
}

/// Knots of the tables of the sRGB curves' power segments, uniform in `√u` over `[0, 1]`.
///
/// A power per channel per pixel was a quarter of a large blur's time. Interpolated
/// linearly in `√u`, the tables are within 1e-7 of the curves (`sqrt(u)` spreads the knots
/// where `u^(1/2.4)` bends most; tested against `powf`), and the derivative used backward
/// is that of the interpolation, so forward and backward agree exactly.
const CURVE_KNOTS: usize = 4096;

fn exact_to_linear(u: f64) -> f64 {
    ((u + 0.055) / 1.055).powf(2.4)
}

fn exact_to_srgb(u: f64) -> f64 {
    u.powf(1.0 / 2.4) * 1.055 - 0.055
}

/// `f` at `(k / CURVE_KNOTS)²`, `k = 0 ..= CURVE_KNOTS`.
fn curve_table(f: fn(f64) -> f64) -> Vec<f64> {
    (0..=CURVE_KNOTS)
        .map(|k| {
            let t = k as f64 / CURVE_KNOTS as f64;
            f(t * t)
        })
        .collect()
}

static TO_LINEAR: std::sync::LazyLock<Vec<f64>> =
    std::sync::LazyLock::new(|| curve_table(exact_to_linear));
static TO_SRGB: std::sync::LazyLock<Vec<f64>> =
    std::sync::LazyLock::new(|| curve_table(exact_to_srgb));

/// `u` (in `[0, 1]`, where the derivative is taken; clamped) through a curve's table.
#[inline]
fn on_curve<S: Scalar>(u: S, table: &[f64]) -> S {
    let x = u.v().clamp(0.0, 1.0);
    let r = x.sqrt();
    let t = r * CURVE_KNOTS as f64;
    let k = (t as usize).min(CURVE_KNOTS - 1);
    let (a, b) = (table[k], table[k + 1]);
    let v = a + (b - a) * (t - k as f64);
    let inside = r > 0.0 && u.v() <= 1.0;
    let dv = if inside {
        (b - a) * CURVE_KNOTS as f64 / (2.0 * r)
    } else {
        0.0
    };
    u.then(v, dv)
}

/// One sRGB-encoded channel value to linear light.
#[inline]
fn to_linear<S: Scalar>(u: S) -> S {
    if u.v() <= 0.04045 {
        u / S::c(12.92)
    } else {
        on_curve(u, &TO_LINEAR)
    }
}

/// One linear channel value to its sRGB encoding.
#[inline]
fn to_srgb<S: Scalar>(u: S) -> S {
    if u.v() <= 0.0031308 {
        u * S::c(12.92)
    } else {
        on_curve(u, &TO_SRGB)
    }
}

/// A premultiplied pixel from sRGB to linearRGB (`linear`) or back.
pub(crate) fn convert<S: Scalar>(px: [S; 4], linear: bool) -> [S; 4] {
    let s = straight(px);
    let f = |u: S| if linear { to_linear(u) } else { to_srgb(u) };
    let a = s[3];
    [f(s[0]) * a, f(s[1]) * a, f(s[2]) * a, a]
}

/// feColorMatrix: the 4 × 5 matrix applied to the straight color, each channel clamped.
pub(crate) fn color_matrix<S: Scalar>(px: [S; 4], m: &[f64; 20]) -> [S; 4] {
    color_matrix_with(px, &m.map(S::c))
}

/// [`color_matrix`] with the matrix's values as numbers of the same kind as the pixel's
/// (so that the matrix can be differentiated).
pub(crate) fn color_matrix_with<S: Scalar>(px: [S; 4], m: &[S; 20]) -> [S; 4] {
    let s = straight(px);
    premultiplied(std::array::from_fn(|r| {
        let row = &m[r * 5..r * 5 + 5];
        s[0] * row[0] + s[1] * row[1] + s[2] * row[2] + s[3] * row[3] + row[4]
    }))
}

/// feComposite's arithmetic operator `k1·i1·i2 + k2·i1 + k3·i2 + k4` per premultiplied
/// channel, alpha clamped to `[0, 1]` and colors to `[0, alpha]` (transparent where alpha
/// is below `f32::EPSILON`, as resvg).
pub(crate) fn arithmetic<S: Scalar>(k: [S; 4], s: [S; 4], d: [S; 4]) -> [S; 4] {
    let f = |i1: S, i2: S| k[0] * i1 * i2 + k[1] * i1 + k[2] * i2 + k[3];
    let a = clamp(f(s[3], d[3]), 0.0, 1.0);
    if a.v() <= f32::EPSILON as f64 {
        return [S::c(0.0); 4];
    }
    [
        clamp(f(s[0], d[0]), 0.0, a.v()),
        clamp(f(s[1], d[1]), 0.0, a.v()),
        clamp(f(s[2], d[2]), 0.0, a.v()),
        a,
    ]
}

/// One transfer function at a straight channel value `c` in `[0, 1]`.
fn transfer<S: Scalar>(f: &TransferFunction, c: S) -> S {
    match f {
        TransferFunction::Identity => c,
        TransferFunction::Table(v) => {
            let n = v.len() - 1;
            let k = ((c.v() * n as f64).floor().max(0.0) as usize).min(n);
            if k == n {
                S::c(v[k])
            } else {
                let nf = n as f64;
                S::c(v[k]) + (c - S::c(k as f64 / nf)) * S::c(nf * (v[k + 1] - v[k]))
            }
        }
        TransferFunction::Discrete(v) => {
            let n = v.len();
            let k = ((c.v() * n as f64).floor().max(0.0) as usize).min(n - 1);
            S::c(v[k])
        }
        TransferFunction::Linear { slope, intercept } => c * S::c(*slope) + S::c(*intercept),
        TransferFunction::Gamma {
            amplitude,
            exponent,
            offset,
        } => S::c(*amplitude) * c.powf(*exponent) + S::c(*offset),
    }
}

/// `∂T/∂θ` of one transfer function at a straight channel value `c`, for its values
/// `θ` ([`TransferFunction::values_mut`](crate::scene::filter::TransferFunction::values_mut)),
/// into `out`.
fn transfer_value_gradient(f: &TransferFunction, c: f64, out: &mut [f64]) {
    match f {
        TransferFunction::Identity => {}
        TransferFunction::Table(v) => {
            let n = v.len() - 1;
            let k = ((c * n as f64).floor().max(0.0) as usize).min(n);
            if k == n {
                out[k] = 1.0;
            } else {
                let t = c * n as f64 - k as f64;
                out[k] = 1.0 - t;
                out[k + 1] = t;
            }
        }
        TransferFunction::Discrete(v) => {
            let n = v.len();
            out[((c * n as f64).floor().max(0.0) as usize).min(n - 1)] = 1.0;
        }
        TransferFunction::Linear { .. } => {
            out[0] = c;
            out[1] = 1.0;
        }
        TransferFunction::Gamma {
            amplitude,
            exponent,
            ..
        } => {
            let p = c.powf(*exponent);
            out[0] = p;
            out[1] = if c > 0.0 { amplitude * p * c.ln() } else { 0.0 };
            out[2] = 1.0;
        }
    }
}

/// The derivative of [`clamp`]`(x, 0, 1)`: 1 inside (ends included), 0 outside.
fn unit_slope(x: f64) -> f64 {
    if (0.0..=1.0).contains(&x) { 1.0 } else { 0.0 }
}

/// Adds `Σ g · ∂out/∂θ` of [`component_transfer`] at `px` to `grad`, the functions'
/// values `θ` in slot order (R's, G's, B's, then A's).
pub(crate) fn component_transfer_value_gradient(
    px: [f32; 4],
    funcs: &[TransferFunction; 4],
    g: [f32; 4],
    grad: &mut [f64],
) {
    if g == [0.0; 4] {
        return;
    }
    let s = straight(px.map(|v| v as f64));
    let t: [f64; 4] = std::array::from_fn(|c| transfer(&funcs[c], s[c]));
    let a = t[3].clamp(0.0, 1.0);
    let mut at = 0;
    for c in 0..4 {
        let n = funcs[c].value_count();
        let mut d = vec![0.0; n];
        transfer_value_gradient(&funcs[c], s[c], &mut d);
        // out_c = clamp(T_c) · A for a color; A's own values reach every channel.
        let w = if c < 3 {
            g[c] as f64 * unit_slope(t[c]) * a
        } else {
            ((0..3)
                .map(|k| g[k] as f64 * t[k].clamp(0.0, 1.0))
                .sum::<f64>()
                + g[3] as f64)
                * unit_slope(t[3])
        };
        for (o, dv) in grad[at..at + n].iter_mut().zip(&d) {
            *o += w * dv;
        }
        at += n;
    }
}

/// feComponentTransfer on one pixel.
pub(crate) fn component_transfer<S: Scalar>(px: [S; 4], funcs: &[TransferFunction; 4]) -> [S; 4] {
    let s = straight(px);
    premultiplied(std::array::from_fn(|c| transfer(&funcs[c], s[c])))
}

/// feComposite of `s` (`in`) with `d` (`in2`).
pub(crate) fn composite<S: Scalar>(op: CompositeOp, s: [S; 4], d: [S; 4]) -> [S; 4] {
    let one = S::c(1.0);
    let (sa, da) = (s[3], d[3]);
    match op {
        CompositeOp::Over => std::array::from_fn(|c| s[c] + d[c] * (one - sa)),
        CompositeOp::In => std::array::from_fn(|c| s[c] * da),
        CompositeOp::Out => std::array::from_fn(|c| s[c] * (one - da)),
        CompositeOp::Atop => std::array::from_fn(|c| s[c] * da + d[c] * (one - sa)),
        CompositeOp::Xor => std::array::from_fn(|c| s[c] * (one - da) + d[c] * (one - sa)),
        CompositeOp::Lighter => std::array::from_fn(|c| clamp(s[c] + d[c], 0.0, 1.0)),
        CompositeOp::Arithmetic(k) => arithmetic(k.map(S::c), s, d),
    }
}

/// feBlend of `s` (`in`) onto `d` (`in2`): resvg's compositor's blend modes.
pub(crate) fn blend<S: Scalar>(mode: BlendMode, s: [S; 4], d: [S; 4]) -> [S; 4] {
    blend_px(mode, s, d)
}

/// Runs a one-pixel operator on `f32` values.
#[inline]
pub(crate) fn eval1(f: &impl Fn([f64; 4]) -> [f64; 4], px: [f32; 4]) -> [f32; 4] {
    f(px.map(|v| v as f64)).map(|v| v as f32)
}

/// Runs a two-pixel operator on `f32` values.
#[inline]
pub(crate) fn eval2(
    f: &impl Fn([f64; 4], [f64; 4]) -> [f64; 4],
    a: [f32; 4],
    b: [f32; 4],
) -> [f32; 4] {
    f(a.map(|v| v as f64), b.map(|v| v as f64)).map(|v| v as f32)
}

/// The adjoint of a one-pixel operator at `px`: `∂L/∂px` from `∂L/∂out`.
pub(crate) fn adjoint1(
    f: &impl Fn([Jet<4>; 4]) -> [Jet<4>; 4],
    px: [f32; 4],
    g: [f32; 4],
) -> [f32; 4] {
    if g == [0.0; 4] {
        return g;
    }
    let x: [Jet<4>; 4] = std::array::from_fn(|c| Jet::var(px[c] as f64, c));
    let y = f(x);
    std::array::from_fn(|i| (0..4).map(|o| g[o] as f64 * y[o].d[i]).sum::<f64>() as f32)
}

/// The adjoint of a two-pixel operator at `(a, b)`: `(∂L/∂a, ∂L/∂b)` from `∂L/∂out`.
pub(crate) fn adjoint2(
    f: &impl Fn([Jet<8>; 4], [Jet<8>; 4]) -> [Jet<8>; 4],
    a: [f32; 4],
    b: [f32; 4],
    g: [f32; 4],
) -> ([f32; 4], [f32; 4]) {
    if g == [0.0; 4] {
        return (g, g);
    }
    let x: [Jet<8>; 4] = std::array::from_fn(|c| Jet::var(a[c] as f64, c));
    let z: [Jet<8>; 4] = std::array::from_fn(|c| Jet::var(b[c] as f64, 4 + c));
    let y = f(x, z);
    let d = |i: usize| (0..4).map(|o| g[o] as f64 * y[o].d[i]).sum::<f64>() as f32;
    (std::array::from_fn(d), std::array::from_fn(|i| d(4 + i)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The tables are within 2e-7 of the curves, and the derivative of each is that of
    /// its interpolation.
    #[test]
    fn srgb_curves_from_tables() {
        let mut worst: f64 = 0.0;
        for i in 0..=100_000 {
            let u = i as f64 / 100_000.0;
            let lin = if u <= 0.04045 {
                u / 12.92
            } else {
                exact_to_linear(u)
            };
            let enc = if u <= 0.0031308 {
                u * 12.92
            } else {
                exact_to_srgb(u)
            };
            worst = worst
                .max((to_linear(u) - lin).abs())
                .max((to_srgb(u) - enc).abs());
        }
        assert!(worst < 2e-7, "{worst:e}");
        for u in [0.05, 0.2, 0.5377, 0.9] {
            let h = 1e-7;
            for f in [to_linear::<Jet<1>>, to_srgb::<Jet<1>>] {
                let d = f(Jet::var(u, 0)).d[0];
                let num = (f(Jet::c(u + h)).v - f(Jet::c(u - h)).v) / (2.0 * h);
                assert!((d - num).abs() < 1e-4 * num.abs(), "{u}: {d} vs {num}");
            }
        }
    }
}
