//! Paint evaluation at pixel centers.
//!
//! Images are sampled in `super::image`. Solid colors and gradients give a straight RGBA color; gradient stops are interpolated
//! straight (not premultiplied) and premultiplied afterwards, as tiny-skia does. The item's
//! opacity multiplies alpha. Gradient geometry lives in gradient space; pixel centers are
//! mapped there by the inverse of [`Gradient::transform`].
//!
//! The radial gradient is SVG's two-point conical gradient: `t` is the largest value for
//! which the pixel lies on the circle interpolated between the focal circle `(f, fr)` at
//! `t = 0` and the end circle `(c, r)` at `t = 1` with a non-negative radius. Where no such
//! circle exists the pixel is left unpainted.

use super::coverage::{floor_f32, floor_f64};
use super::image::ImageEval;
use super::jet::{Jet, Scalar};
use crate::scene::geom::dist;
use crate::scene::{Affine, Gradient, GradientKind, Paint, Point, Spread, Stop, apply, invert};
use wide::f64x2;

/// A paint ready for per-pixel evaluation.
#[derive(Clone, Debug)]
pub(crate) enum PaintEval {
    /// A solid color.
    Solid(SolidEval),
    /// A gradient.
    Gradient(GradientEval),
    /// A raster image (see [`super::image`]).
    Image(ImageEval),
}

/// A solid color ready for compositing.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SolidEval {
    /// Premultiplied color, opacity included.
    pub(crate) premul: [f32; 4],
    /// Straight color.
    pub(crate) color: [f64; 3],
    /// Opacity as given (clamped to `[0, 1]` when drawn).
    pub(crate) opacity: f64,
}

/// A gradient ready for evaluation.
#[derive(Clone, Debug)]
pub(crate) struct GradientEval {
    /// Device → gradient space.
    pub(crate) inv: Affine,
    /// Geometry.
    pub(crate) kind: GradientKind,
    /// Spread.
    pub(crate) spread: Spread,
    /// Stops.
    pub(crate) stops: Vec<Stop>,
    /// Item opacity.
    pub(crate) opacity: f64,
    /// A linear gradient whose end points (in gradient space) are closer than
    /// [`DEGENERATE_LENGTH`]: it paints one color, as resvg does.
    pub(crate) degenerate: bool,
    /// The stops in `f32`, for whole rows ([`PaintEval::row`]).
    row_stops: RowStops,
}

/// A gradient's stops in `f32`, for evaluating rows of pixels.
#[derive(Clone, Debug)]
struct RowStops {
    /// Offsets, non-decreasing.
    offsets: Vec<f32>,
    /// Straight RGBA per stop (stop opacity in alpha).
    colors: Vec<[f32; 4]>,
    /// Per pair of neighbouring stops, the change of each channel per unit of `t` (0
    /// between stops at the same offset).
    rates: Vec<[f32; 4]>,
    /// The steepest change of any channel per unit of `t` between two stops; infinite at
    /// a hard stop (two offsets equal, colors not).
    slope: f64,
    /// Whether the colors at `t = 0` and `t = 1` agree, so that `repeat` has no seam.
    seamless: bool,
}

impl RowStops {
    fn new(stops: &[Stop]) -> RowStops {
        let color = |s: &Stop| [s.color[0], s.color[1], s.color[2], s.opacity];
        let mut slope = 0.0f64;
        for w in stops.windows(2) {
            let (a, b) = (color(&w[0]), color(&w[1]));
            let change = (0..4).map(|k| (b[k] - a[k]).abs()).fold(0.0, f64::max);
            let span = w[1].offset - w[0].offset;
            if change > 0.0 {
                slope = slope.max(if span > 0.0 {
                    change / span
                } else {
                    f64::INFINITY
                });
            }
        }
        let rates = stops
            .windows(2)
            .map(|w| {
                let (a, b) = (color(&w[0]), color(&w[1]));
                let span = w[1].offset - w[0].offset;
                std::array::from_fn(|k| {
                    if span > 0.0 {
                        ((b[k] - a[k]) / span) as f32
                    } else {
                        0.0
                    }
                })
            })
            .collect();
        RowStops {
            rates,
            seamless: stop_color(stops, 0.0) == stop_color(stops, 1.0),
            offsets: stops.iter().map(|s| s.offset as f32).collect(),
            colors: stops.iter().map(|s| color(s).map(|v| v as f32)).collect(),
            slope,
        }
    }

    /// Straight RGBA at `t` in `[0, 1]`, as [`stop_color`] computes it, in `f32`: the
    /// color of the stop below plus the distance from it times the pair's rate (no
    /// division per pixel; gradients have few stops, so the pair is found by a scan).
    #[inline(always)]
    fn color(&self, t: f32) -> [f32; 4] {
        let (o, c) = (&self.offsets, &self.colors);
        let n = o.len();
        if t <= o[0] {
            return c[0];
        }
        if t >= o[n - 1] {
            return c[n - 1];
        }
        // The first stop above `t`; one exists since `t < o[n − 1]` (a NaN stops at 1).
        let mut j = 1;
        while j < n - 1 && o[j] <= t {
            j += 1;
        }
        let i = j - 1;
        let u = t - o[i];
        let (a, r) = (c[i], self.rates[i]);
        [
            a[0] + u * r[0],
            a[1] + u * r[1],
            a[2] + u * r[2],
            a[3] + u * r[3],
        ]
    }
}

/// How large `slope · max|t|` over a row may be for the row to be evaluated in `f32`
/// ([`RowStops::slope`]). The error of `t` computed as `t₀ + i·Δt` in `f32` is at most
/// `4·max|t|·2⁻²⁴`; premultiplied channels change at most twice as fast as straight ones;
/// the `f32` interpolation (a rate rounded to `f32`, one product, one sum) and the
/// premultiplication add about `10⁻⁶`. With the bound 4 the
/// worst case is `2·4·4·2⁻²⁴ + 10⁻⁶ ≈ 2.9·10⁻⁶`, below 1/1024 of an 8-bit color level
/// (`3.8·10⁻⁶`); rows beyond it, `repeat` gradients whose ends differ in color (their
/// seams are jumps) and hard stops are evaluated per pixel in `f64`.
const F32_SLOPE_T: f64 = 4.0;

/// Below this distance between its end points, in gradient space, a linear gradient is
/// degenerate and paints one color: the last stop's with `pad`, the gradient's average
/// with `repeat` and `reflect` (its stripes would be far thinner than a pixel). The value
/// and the fallbacks are tiny-skia's, so diffsvg draws what resvg draws.
pub(crate) const DEGENERATE_LENGTH: f64 = 1.0 / 32768.0;

impl PaintEval {
    /// Prepares `paint` drawn with `opacity`. `None` when nothing would be painted (a
    /// singular gradient transform, no stops).
    pub(crate) fn new(paint: &Paint, opacity: f64) -> Option<PaintEval> {
        match paint {
            Paint::Solid(c) => {
                let a = opacity.clamp(0.0, 1.0);
                Some(PaintEval::Solid(SolidEval {
                    premul: [
                        (c[0] * a) as f32,
                        (c[1] * a) as f32,
                        (c[2] * a) as f32,
                        a as f32,
                    ],
                    color: *c,
                    opacity,
                }))
            }
            Paint::Gradient(g) => Some(PaintEval::Gradient(GradientEval::new(g, opacity)?)),
            Paint::Image(i) => Some(PaintEval::Image(ImageEval::new(i, opacity)?)),
        }
    }

    /// Premultiplied color at device point `p` (a pixel center).
    #[inline]
    pub(crate) fn at(&self, p: Point) -> [f32; 4] {
        match self {
            PaintEval::Solid(c) => c.premul,
            PaintEval::Gradient(g) => g.at(p),
            PaintEval::Image(i) => i.at(p),
        }
    }

    /// Premultiplied colors of the pixels `(x0 + i, y)` for `i` in `0 .. out.len()`, at
    /// their centers: [`at`](Self::at) along a row, within 1/1024 of an 8-bit color level
    /// of it (gradients are evaluated incrementally, in `f32` where that bound holds).
    pub(crate) fn row(&self, x0: usize, y: usize, out: &mut [[f32; 4]]) {
        match self {
            PaintEval::Solid(c) => out.fill(c.premul),
            PaintEval::Gradient(g) => g.row(x0, y, out),
            PaintEval::Image(i) => i.row(x0, y, out),
        }
    }

    /// Length of this paint's gradient vector in [`PaintEval::backward`]: a solid paint has
    /// `r, g, b, opacity`; a gradient its geometry (4 or 6), `offset, r, g, b, opacity`
    /// per stop, then the item opacity, and a radial one [`transform_len`](Self::transform_len)
    /// more; an image only the item opacity (its pixels are fixed).
    pub(crate) fn grad_len(&self) -> usize {
        match self {
            PaintEval::Solid(_) => 4,
            PaintEval::Image(_) => 1,
            PaintEval::Gradient(g) => g.opacity_slot() + 1 + self.transform_len(),
        }
    }

    /// The entries after the item opacity in the gradient vector: for a radial gradient,
    /// `Σ ∂L/∂q ⊗ (q, 1)` over the pixels (`q` the gradient-space point, SVG's matrix
    /// order `qx·gx, qx·gy, qy·gx, qy·gy, gx, gy`), from which the gradient of its
    /// transform follows (`transform::chain_gradient`: a change `M → M·(1 + h·E)` moves
    /// `q` by `−h·E·q`); none for other paints, whose transforms' changes their geometry
    /// can follow.
    pub(crate) fn transform_len(&self) -> usize {
        match self {
            PaintEval::Gradient(g) if matches!(g.kind, GradientKind::Radial { .. }) => 6,
            _ => 0,
        }
    }

    /// Adds to `out` (length [`grad_len`](Self::grad_len)) the gradient of the loss with
    /// respect to this paint's parameters, given `gs = ∂L/∂(premultiplied color)` at the
    /// device point `p`.
    pub(crate) fn backward(&self, p: Point, gs: [f64; 4], out: &mut [f64]) {
        match self {
            PaintEval::Solid(c) => {
                let a = c.opacity.clamp(0.0, 1.0);
                for k in 0..3 {
                    out[k] += gs[k] * a;
                }
                if (0.0..=1.0).contains(&c.opacity) {
                    out[3] += gs[0] * c.color[0] + gs[1] * c.color[1] + gs[2] * c.color[2] + gs[3];
                }
            }
            PaintEval::Gradient(g) => g.backward(p, gs, out),
            PaintEval::Image(i) => i.backward(p, gs, out),
        }
    }
}

impl GradientEval {
    /// Prepares a gradient; `None` when its transform is singular or it has no stops.
    pub(crate) fn new(g: &Gradient, opacity: f64) -> Option<GradientEval> {
        if g.stops.is_empty() {
            return None;
        }
        let degenerate = match g.kind {
            GradientKind::Linear { p1, p2 } => dist(p1, p2) < DEGENERATE_LENGTH,
            GradientKind::Radial { .. } => false,
        };
        Some(GradientEval {
            inv: invert(&g.transform)?,
            kind: g.kind.clone(),
            spread: g.spread,
            stops: g.stops.clone(),
            opacity: opacity.clamp(0.0, 1.0),
            degenerate,
            row_stops: RowStops::new(&g.stops),
        })
    }

    /// The one straight RGBA color of a degenerate gradient, and the weight of each stop's
    /// color in it: the last stop for `pad`, else the mean of the piecewise-linear color
    /// over `[0, 1]` (ends held flat before the first and after the last stop).
    fn fallback(&self) -> ([f64; 4], Vec<f64>) {
        let st = &self.stops;
        let n = st.len();
        let mut w = vec![0.0; n];
        if self.spread == Spread::Pad || n == 1 {
            w[n - 1] = 1.0;
        } else {
            w[0] += st[0].offset;
            w[n - 1] += 1.0 - st[n - 1].offset;
            for i in 0..n - 1 {
                let half = 0.5 * (st[i + 1].offset - st[i].offset);
                w[i] += half;
                w[i + 1] += half;
            }
        }
        let mut c = [0.0; 4];
        for (s, &wi) in st.iter().zip(&w) {
            for k in 0..3 {
                c[k] += wi * s.color[k];
            }
            c[3] += wi * s.opacity;
        }
        (c, w)
    }

    /// Premultiplied color at device point `p`.
    pub(crate) fn at(&self, p: Point) -> [f32; 4] {
        let c = if self.degenerate {
            self.fallback().0
        } else {
            let q = apply(&self.inv, p);
            let Some(t) = gradient_t(&geometry(&self.kind), q) else {
                return [0.0; 4];
            };
            stop_color(&self.stops, spread(self.spread, t).0)
        };
        self.premultiplied(c)
    }

    /// A straight color with the item opacity, premultiplied.
    #[inline]
    fn premultiplied(&self, c: [f64; 4]) -> [f32; 4] {
        let a = c[3] * self.opacity;
        [
            (c[0] * a) as f32,
            (c[1] * a) as f32,
            (c[2] * a) as f32,
            a as f32,
        ]
    }

    /// See [`PaintEval::row`]. Linear gradients step `t` along the row (it is affine in
    /// x); radial ones step the gradient-space point and solve the exact quadratic per
    /// pixel. Colors come from the `f32` stops where [`F32_SLOPE_T`] allows, else from
    /// [`at`](Self::at)'s `f64` path.
    fn row(&self, x0: usize, y: usize, out: &mut [[f32; 4]]) {
        let p0 = [x0 as f64 + 0.5, y as f64 + 0.5];
        if out.is_empty() {
            return;
        }
        if self.degenerate {
            out.fill(self.at(p0));
            return;
        }
        let q0 = apply(&self.inv, p0);
        let q1 = apply(&self.inv, [p0[0] + 1.0, p0[1]]);
        let dq = [q1[0] - q0[0], q1[1] - q0[1]];
        let op = self.opacity as f32;
        let premul = |c: [f32; 4]| {
            let a = c[3] * op;
            [c[0] * a, c[1] * a, c[2] * a, a]
        };
        // `t − 2⌊t/2⌋` is exact (Sterbenz), as `rem_euclid(2)` is, without its call.
        let f32_spread = |t: f32| match self.spread {
            Spread::Pad => t.clamp(0.0, 1.0),
            Spread::Reflect => {
                let m = t - 2.0 * floor_f32(0.5 * t);
                if m <= 1.0 { m } else { 2.0 - m }
            }
            // Only without a seam (see `fast`): a `t` off by a rounding across an integer
            // then changes the color by no more than elsewhere.
            Spread::Repeat => t - floor_f32(t),
        };
        let fast = self.spread != Spread::Repeat || self.row_stops.seamless;
        let geo = geometry(&self.kind);
        match geo {
            Geometry::Linear(_) => {
                let n = out.len() - 1;
                let t0 = gradient_t(&geo, q0).unwrap_or(0.0);
                let dt = gradient_t(&geo, q1).unwrap_or(0.0) - t0;
                let tn = t0 + n as f64 * dt;
                if fast && self.row_stops.slope * t0.abs().max(tn.abs()) <= F32_SLOPE_T {
                    let (t0, dt) = (t0 as f32, dt as f32);
                    for (i, o) in out.iter_mut().enumerate() {
                        let t = t0 + i as f32 * dt;
                        *o = premul(self.row_stops.color(f32_spread(t)));
                    }
                    return;
                }
            }
            Geometry::Radial(v) => {
                let solver = RadialRow::new(v);
                let fast_radial = fast && self.row_stops.slope <= F32_SLOPE_T;
                if let (Some(r), true) = (&solver, fast_radial) {
                    // The common case, in a loop of its own for the compiler. The spread
                    // is taken in `f64` (exactly), so only the spread `t` in `[0, 1]` is
                    // rounded to `f32`: its error, at most 2⁻²⁵, times the slope is what
                    // the colors can be off by, whatever `t` was.
                    let mode = self.spread;
                    // Per run of up to 64 pixels: first the spread `t`s, two at a time
                    // (the same values as one at a time) in a loop short enough for the
                    // square roots of several pairs to overlap, then the colors.
                    const RUN: usize = 64;
                    let mut ts = [0.0f32; RUN];
                    for (run, outs) in out.chunks_mut(RUN).enumerate() {
                        let base = (run * RUN) as f64;
                        let mut defined = 0u64;
                        for j in (0..outs.len()).step_by(2) {
                            let k = f64x2::new([base + j as f64, base + j as f64 + 1.0]);
                            let qx = f64x2::splat(q0[0]) + k * f64x2::splat(dq[0]);
                            let qy = f64x2::splat(q0[1]) + k * f64x2::splat(dq[1]);
                            let (t, ok) = r.t2(qx, qy);
                            let t = spread2(mode, t).to_array();
                            ts[j] = t[0] as f32;
                            ts[j + 1] = t[1] as f32;
                            defined |= (ok.to_bitmask() as u64) << j;
                        }
                        for (j, o) in outs.iter_mut().enumerate() {
                            *o = if defined & (1 << j) != 0 {
                                premul(self.row_stops.color(ts[j]))
                            } else {
                                [0.0; 4]
                            };
                        }
                    }
                    return;
                }
                for (i, o) in out.iter_mut().enumerate() {
                    let k = i as f64;
                    let q = [q0[0] + k * dq[0], q0[1] + k * dq[1]];
                    let t = match &solver {
                        Some(r) => r.t(q),
                        None => gradient_t(&geo, q),
                    };
                    *o = match t {
                        None => [0.0; 4],
                        Some(t) if fast_radial => {
                            premul(self.row_stops.color(spread(self.spread, t).0 as f32))
                        }
                        Some(t) => {
                            self.premultiplied(stop_color(&self.stops, spread(self.spread, t).0))
                        }
                    };
                }
                return;
            }
        }
        for (i, o) in out.iter_mut().enumerate() {
            *o = self.at([p0[0] + i as f64, p0[1]]);
        }
    }
}

impl GradientEval {
    /// Where the item opacity is in the gradient vector (after the geometry and stops).
    fn opacity_slot(&self) -> usize {
        geometry(&self.kind).len() + 5 * self.stops.len()
    }

    /// See [`PaintEval::backward`].
    fn backward(&self, p: Point, gs: [f64; 4], out: &mut [f64]) {
        if self.degenerate {
            return self.fallback_backward(gs, out);
        }
        let q = apply(&self.inv, p);
        let geo = geometry(&self.kind);
        let ng = geo.len();
        let jet = geo.to_jets();
        let Some(t) = gradient_t(&jet, q) else {
            return;
        };
        let (ts, dts) = spread(self.spread, t);
        let (i, j, u) = bracket(&self.stops, ts);
        let c = stop_color(&self.stops, ts);
        let op = self.opacity;
        // s = (C_rgb·C_a·op, C_a·op).
        let mut gc = [0.0; 4];
        for k in 0..3 {
            gc[k] = gs[k] * c[3] * op;
        }
        gc[3] = (gs[0] * c[0] + gs[1] * c[1] + gs[2] * c[2] + gs[3]) * op;
        let o = self.opacity_slot();
        out[o] += (gs[0] * c[0] + gs[1] * c[1] + gs[2] * c[2] + gs[3]) * c[3];
        // C = (1 − u)·stop_i + u·stop_j, per channel (stop opacity as alpha).
        let stop_slot = |s: usize| ng + 5 * s;
        let weights: &[(usize, f64)] = if i == j {
            &[(i, 1.0)]
        } else {
            &[(i, 1.0 - u), (j, u)]
        };
        for &(s, w) in weights {
            for k in 0..3 {
                out[stop_slot(s) + 1 + k] += w * gc[k];
            }
            out[stop_slot(s) + 4] += w * gc[3];
        }
        if i == j {
            return;
        }
        let (a, b) = (&self.stops[i], &self.stops[j]);
        let span = b.offset - a.offset;
        if !(span > 0.0) {
            return;
        }
        let ca = [a.color[0], a.color[1], a.color[2], a.opacity];
        let cb = [b.color[0], b.color[1], b.color[2], b.opacity];
        let gu: f64 = (0..4).map(|k| gc[k] * (cb[k] - ca[k])).sum();
        // u = (t' − o_i) / (o_j − o_i).
        out[stop_slot(i)] += -gu * (1.0 - u) / span;
        out[stop_slot(j)] += -gu * u / span;
        let gt = gu / span * dts;
        if gt != 0.0 {
            for k in 0..ng {
                out[k] += gt * t.d[k];
            }
            if let Geometry::Radial(_) = geo {
                // `t` depends on `q − f` and `c − f`: `∂t/∂q = −(∂t/∂c + ∂t/∂f)`.
                let gq = [-gt * (t.d[0] + t.d[3]), -gt * (t.d[1] + t.d[4])];
                let m = &mut out[o + 1..o + 7];
                m[0] += gq[0] * q[0];
                m[1] += gq[1] * q[0];
                m[2] += gq[0] * q[1];
                m[3] += gq[1] * q[1];
                m[4] += gq[0];
                m[5] += gq[1];
            }
        }
    }

    /// [`backward`](Self::backward) of a degenerate gradient: no geometry gradient; stop
    /// colors through their weights, stop offsets through the interval lengths.
    fn fallback_backward(&self, gs: [f64; 4], out: &mut [f64]) {
        let (c, w) = self.fallback();
        let op = self.opacity;
        let g_rgb = |k: usize| gs[k] * c[3] * op;
        let g_alpha = (gs[0] * c[0] + gs[1] * c[1] + gs[2] * c[2] + gs[3]) * op;
        out[self.opacity_slot()] += (gs[0] * c[0] + gs[1] * c[1] + gs[2] * c[2] + gs[3]) * c[3];
        let ng = geometry(&self.kind).len();
        let slot = |s: usize| ng + 5 * s;
        for (s, &ws) in w.iter().enumerate() {
            for k in 0..3 {
                out[slot(s) + 1 + k] += ws * g_rgb(k);
            }
            out[slot(s) + 4] += ws * g_alpha;
        }
        let st = &self.stops;
        if self.spread == Spread::Pad || st.len() == 1 {
            return;
        }
        // ∂c/∂o_i = (c_{i−1} − c_{i+1}) / 2, with c_{−1} = c_0 and c_n = c_{n−1}.
        let rgba = |i: usize| {
            let s = &st[i];
            [s.color[0], s.color[1], s.color[2], s.opacity]
        };
        let last = st.len() - 1;
        for i in 0..=last {
            let (a, b) = (rgba(i.saturating_sub(1)), rgba((i + 1).min(last)));
            let d: f64 =
                (0..3).map(|k| g_rgb(k) * (a[k] - b[k])).sum::<f64>() + g_alpha * (a[3] - b[3]);
            out[slot(i)] += 0.5 * d;
        }
    }
}

/// Geometry parameters as a flat array: linear `x1 y1 x2 y2`, radial `cx cy r fx fy fr`.
pub(crate) fn geometry(kind: &GradientKind) -> Geometry<f64> {
    match *kind {
        GradientKind::Linear { p1, p2 } => Geometry::Linear([p1[0], p1[1], p2[0], p2[1]]),
        GradientKind::Radial { c, r, f, fr } => Geometry::Radial([c[0], c[1], r, f[0], f[1], fr]),
    }
}

/// Gradient geometry over any scalar (so the backward pass can differentiate it).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Geometry<S> {
    /// `x1 y1 x2 y2`.
    Linear([S; 4]),
    /// `cx cy r fx fy fr`.
    Radial([S; 6]),
}

impl Geometry<f64> {
    /// Number of parameters.
    pub(crate) fn len(&self) -> usize {
        match self {
            Geometry::Linear(_) => 4,
            Geometry::Radial(_) => 6,
        }
    }

    /// The parameters as dual numbers, parameter `k` seeded in slot `k`.
    pub(crate) fn to_jets(self) -> Geometry<Jet> {
        match self {
            Geometry::Linear(v) => Geometry::Linear(std::array::from_fn(|k| <Jet>::var(v[k], k))),
            Geometry::Radial(v) => Geometry::Radial(std::array::from_fn(|k| <Jet>::var(v[k], k))),
        }
    }
}

/// [`gradient_t`] of a radial gradient with its per-gradient terms computed once, for
/// rows of pixels: the same quadratic in `f64`, solved for the larger root only unless
/// its radius is negative. Not for the near-linear case (`a ≈ 0`).
struct RadialRow {
    /// Focal point, `c − f`, `r − fr` and `fr`.
    f: Point,
    cd: Point,
    dr: f64,
    fr: f64,
    a: f64,
    inv_a: f64,
}

impl RadialRow {
    fn new([cx, cy, r, fx, fy, fr]: [f64; 6]) -> Option<RadialRow> {
        let (cdx, cdy) = (cx - fx, cy - fy);
        let dr = r - fr;
        let a = cdx * cdx + cdy * cdy - dr * dr;
        // As in `gradient_t`, which handles the near-linear case.
        if a.abs() < 1e-9 * (r * r).max(1e-12) {
            return None;
        }
        Some(RadialRow {
            f: [fx, fy],
            cd: [cdx, cdy],
            dr,
            fr,
            a,
            inv_a: 1.0 / a,
        })
    }

    /// `t` at gradient-space point `q`; `None` where the gradient is undefined.
    #[inline]
    fn t(&self, q: Point) -> Option<f64> {
        let (px, py) = (q[0] - self.f[0], q[1] - self.f[1]);
        let b = px * self.cd[0] + py * self.cd[1] + self.fr * self.dr;
        let c = px * px + py * py - self.fr * self.fr;
        let disc = b * b - self.a * c;
        if disc < 0.0 {
            return None;
        }
        let s = disc.sqrt();
        // The larger root is `(b + s)/a` for `a > 0`, `(b − s)/a` for `a < 0`.
        let (hi, lo) = if self.a > 0.0 {
            ((b + s) * self.inv_a, (b - s) * self.inv_a)
        } else {
            ((b - s) * self.inv_a, (b + s) * self.inv_a)
        };
        if self.fr + hi * self.dr >= 0.0 {
            Some(hi)
        } else if self.fr + lo * self.dr >= 0.0 {
            Some(lo)
        } else {
            None
        }
    }
}

impl RadialRow {
    /// [`t`](Self::t) at two points, lane by lane with the same bits: the values, and a
    /// mask of the lanes where `t` is defined (the others hold anything).
    #[inline]
    fn t2(&self, qx: f64x2, qy: f64x2) -> (f64x2, f64x2) {
        let splat = f64x2::splat;
        let zero = f64x2::ZERO;
        let (px, py) = (qx - splat(self.f[0]), qy - splat(self.f[1]));
        let b = px * splat(self.cd[0]) + py * splat(self.cd[1]) + splat(self.fr * self.dr);
        let c = px * px + py * py - splat(self.fr * self.fr);
        let disc = b * b - splat(self.a) * c;
        // `disc ≥ 0` is false for NaN, as `disc < 0` then `sqrt` make `None` one at a time.
        let real = disc.simd_ge(zero);
        let s = real.select(disc, zero).sqrt();
        let inv_a = splat(self.inv_a);
        let (hi, lo) = if self.a > 0.0 {
            ((b + s) * inv_a, (b - s) * inv_a)
        } else {
            ((b - s) * inv_a, (b + s) * inv_a)
        };
        let (fr, dr) = (splat(self.fr), splat(self.dr));
        let hi_ok = (fr + hi * dr).simd_ge(zero);
        let lo_ok = (fr + lo * dr).simd_ge(zero);
        (hi_ok.select(hi, lo), real & (hi_ok | lo_ok))
    }
}

/// [`spread`]'s `t` at two values, with the same bits; lanes of 2⁵¹ or more in size (and
/// NaN) are spread one at a time.
#[inline]
fn spread2(mode: Spread, v: f64x2) -> f64x2 {
    let one = f64x2::ONE;
    if !v.abs().simd_lt(f64x2::splat(2f64.powi(51))).all() {
        return f64x2::new(v.to_array().map(|x| spread(mode, x).0));
    }
    // `floor`, exactly: rounding to the nearest integer by adding and taking away
    // 1.5·2⁵², then one less where that rounded up.
    let floor = |x: f64x2| {
        let m = f64x2::splat(1.5 * 2f64.powi(52));
        let r = (x + m) - m;
        r - (r.simd_gt(x) & one)
    };
    match mode {
        Spread::Pad => v
            .simd_le(f64x2::ZERO)
            .select(f64x2::ZERO, v.simd_ge(one).select(one, v)),
        Spread::Repeat => v - floor(v),
        Spread::Reflect => {
            let m = v - f64x2::splat(2.0) * floor(f64x2::splat(0.5) * v);
            m.simd_le(one).select(m, f64x2::splat(2.0) - m)
        }
    }
}

/// The gradient parameter `t` at gradient-space point `q`, before spreading. `None` where
/// a two-point conical gradient is undefined.
pub(crate) fn gradient_t<S: Scalar>(g: &Geometry<S>, q: Point) -> Option<S> {
    match *g {
        Geometry::Linear([x1, y1, x2, y2]) => {
            let (dx, dy) = (x2 - x1, y2 - y1);
            let len2 = dx * dx + dy * dy;
            if len2.v() <= 0.0 {
                // Degenerate: SVG paints the last stop's color.
                return Some(S::c(1.0));
            }
            Some(((S::c(q[0]) - x1) * dx + (S::c(q[1]) - y1) * dy) / len2)
        }
        Geometry::Radial([cx, cy, r, fx, fy, fr]) => {
            // |q − f − t·cd| = fr + t·dr with cd = c − f, dr = r − fr.
            let (cdx, cdy) = (cx - fx, cy - fy);
            let dr = r - fr;
            let (px, py) = (S::c(q[0]) - fx, S::c(q[1]) - fy);
            let a = cdx * cdx + cdy * cdy - dr * dr;
            let b = px * cdx + py * cdy + fr * dr;
            let c = px * px + py * py - fr * fr;
            let radius_ok = |t: S| (fr + t * dr).v() >= 0.0;
            if a.v().abs() < 1e-9 * (r.v() * r.v()).max(1e-12) {
                // Linear case: 2bt = c.
                if b.v() == 0.0 {
                    return None;
                }
                let t = c / (S::c(2.0) * b);
                return radius_ok(t).then_some(t);
            }
            let disc = b * b - a * c;
            if disc.v() < 0.0 {
                return None;
            }
            let s = disc.sqrt();
            let (t1, t2) = ((b + s) / a, (b - s) / a);
            let (hi, lo) = if t1.v() >= t2.v() { (t1, t2) } else { (t2, t1) };
            if radius_ok(hi) {
                Some(hi)
            } else if radius_ok(lo) {
                Some(lo)
            } else {
                None
            }
        }
    }
}

/// Applies the spread method; returns `t` in `[0, 1]` and `∂t'/∂t` (±1, or 0 where padded).
#[inline]
pub(crate) fn spread<S: Scalar>(mode: Spread, t: S) -> (f64, f64) {
    let v = t.v();
    match mode {
        Spread::Pad => {
            if v <= 0.0 {
                (0.0, 0.0)
            } else if v >= 1.0 {
                (1.0, 0.0)
            } else {
                (v, 1.0)
            }
        }
        // `v − 2⌊v/2⌋` is exact (Sterbenz), the value `rem_euclid(2)` gives.
        Spread::Repeat => (v - floor_f64(v), 1.0),
        Spread::Reflect => {
            let m = v - 2.0 * floor_f64(0.5 * v);
            if m <= 1.0 { (m, 1.0) } else { (2.0 - m, -1.0) }
        }
    }
}

/// Which stops bracket `t` and the interpolation weight: `(i, j, u)` with the color
/// `stops[i] + u·(stops[j] − stops[i])`.
#[inline]
pub(crate) fn bracket(stops: &[Stop], t: f64) -> (usize, usize, f64) {
    let n = stops.len();
    if t <= stops[0].offset {
        return (0, 0, 0.0);
    }
    if t >= stops[n - 1].offset {
        return (n - 1, n - 1, 0.0);
    }
    // First stop with offset > t.
    let j = stops.partition_point(|s| s.offset <= t).clamp(1, n - 1);
    let i = j - 1;
    let span = stops[j].offset - stops[i].offset;
    let u = if span > 0.0 {
        (t - stops[i].offset) / span
    } else {
        1.0
    };
    (i, j, u)
}

/// Straight RGBA at `t` in `[0, 1]` (stop opacity in alpha).
pub(crate) fn stop_color(stops: &[Stop], t: f64) -> [f64; 4] {
    let (i, j, u) = bracket(stops, t);
    let a = &stops[i];
    let b = &stops[j];
    let ca = [a.color[0], a.color[1], a.color[2], a.opacity];
    let cb = [b.color[0], b.color[1], b.color[2], b.opacity];
    [0, 1, 2, 3].map(|k| ca[k] + u * (cb[k] - ca[k]))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stop(o: f64, c: f64) -> Stop {
        Stop {
            offset: o,
            color: [c, c, c],
            opacity: 1.0,
        }
    }

    /// Rows of gradient colors stay within 1/1024 of an 8-bit level of the per-pixel
    /// `f64` evaluation: linear and radial, every spread, close and hard stops, rotated
    /// and scaled transforms, rows far from the gradient's origin.
    #[test]
    fn rows_match_pixels_within_a_thousandth_of_a_level() {
        use crate::scene::random::Rng;
        let mut rng = Rng::new(7);
        let mut worst = 0.0f32;
        let mut fast_rows = 0;
        for case in 0..3000 {
            let n = 2 + (rng.next_u64() % 4) as usize;
            let mut offsets: Vec<f64> = (0..n).map(|_| rng.range(0.0, 1.0)).collect();
            offsets.sort_by(f64::total_cmp);
            if case % 7 == 0 {
                offsets[1] = offsets[0]; // a hard stop
            }
            let mut stops: Vec<Stop> = offsets
                .iter()
                .map(|&o| Stop {
                    offset: o,
                    color: [
                        rng.range(0.0, 1.0),
                        rng.range(0.0, 1.0),
                        rng.range(0.0, 1.0),
                    ],
                    opacity: rng.range(0.2, 1.0),
                })
                .collect();
            if case % 5 == 0 {
                // Seamless ends (repeat without a jump).
                stops[n - 1].color = stops[0].color;
                stops[n - 1].opacity = stops[0].opacity;
            }
            let (a, sc) = (rng.range(0.0, 6.3), rng.range(0.3, 3.0));
            let transform = [
                sc * a.cos(),
                sc * a.sin(),
                -sc * a.sin(),
                sc * a.cos(),
                rng.range(-50.0, 50.0),
                rng.range(-50.0, 50.0),
            ];
            let kind = if case % 2 == 0 {
                GradientKind::Linear {
                    p1: [rng.range(-20.0, 60.0), rng.range(-20.0, 60.0)],
                    p2: [rng.range(-20.0, 60.0), rng.range(-20.0, 60.0)],
                }
            } else {
                GradientKind::Radial {
                    c: [rng.range(0.0, 40.0), rng.range(0.0, 40.0)],
                    r: rng.range(1.0, 40.0),
                    f: [rng.range(0.0, 40.0), rng.range(0.0, 40.0)],
                    fr: rng.range(0.0, 5.0),
                }
            };
            let spread = [Spread::Pad, Spread::Reflect, Spread::Repeat][case % 3];
            let g = Gradient {
                id: String::new(),
                kind,
                spread,
                stops,
                transform,
            };
            let Some(eval) = GradientEval::new(&g, rng.range(0.3, 1.0)) else {
                continue;
            };
            let paint = PaintEval::Gradient(eval);
            let x0 = (rng.next_u64() % 300) as usize;
            let y = (rng.next_u64() % 300) as usize;
            let len = 1 + (rng.next_u64() % 80) as usize;
            let mut row = vec![[0.0f32; 4]; len];
            paint.row(x0, y, &mut row);
            if let PaintEval::Gradient(g) = &paint {
                // Rows that may take the f32 path (a finite slope, no repeat seams).
                fast_rows += ((g.spread != Spread::Repeat || g.row_stops.seamless)
                    && g.row_stops.slope.is_finite()) as usize;
            }
            for (i, c) in row.iter().enumerate() {
                let want = paint.at([(x0 + i) as f64 + 0.5, y as f64 + 0.5]);
                for k in 0..4 {
                    let e = (c[k] - want[k]).abs();
                    worst = worst.max(e);
                    assert!(
                        e <= 1.0 / (255.0 * 1024.0),
                        "case {case} pixel {i}: {c:?} vs {want:?}"
                    );
                }
            }
        }
        assert!(fast_rows > 1000, "{fast_rows} rows took the f32 path");
        println!(
            "worst difference {worst:e} (bound {:e})",
            1.0 / (255.0 * 1024.0)
        );
    }

    #[test]
    fn linear_t_and_spread() {
        let g = Geometry::Linear([0.0, 0.0, 10.0, 0.0]);
        assert_eq!(gradient_t(&g, [2.5, 7.0]), Some(0.25));
        assert_eq!(spread(Spread::Pad, 1.5).0, 1.0);
        assert!((spread(Spread::Repeat, 1.25).0 - 0.25).abs() < 1e-12);
        assert!((spread(Spread::Reflect, 1.25).0 - 0.75).abs() < 1e-12);
        assert!((spread(Spread::Reflect, -0.25).0 - 0.25).abs() < 1e-12);
    }

    /// Two lanes at a time give the bits of one at a time: radial `t` (focal points
    /// inside and outside the circle, so `a` of both signs and undefined points) and
    /// every spread, near integers, far out and at NaN.
    #[test]
    fn pairs_have_the_bits_of_single_pixels() {
        let mut rng = crate::scene::random::Rng::new(11);
        let mut rnd = || rng.range(0.0, 1.0);
        for _ in 0..2000 {
            let g = [
                rnd() * 100.0,
                rnd() * 100.0,
                1.0 + rnd() * 50.0,
                rnd() * 150.0 - 25.0,
                rnd() * 150.0 - 25.0,
                rnd() * 10.0,
            ];
            let Some(r) = RadialRow::new(g) else {
                continue;
            };
            let q = [
                [rnd() * 300.0 - 100.0, rnd() * 300.0 - 100.0],
                [rnd() * 100.0, rnd() * 100.0],
            ];
            let (t, ok) = r.t2(
                f64x2::new([q[0][0], q[1][0]]),
                f64x2::new([q[0][1], q[1][1]]),
            );
            let (t, ok) = (t.to_array(), ok.to_bitmask());
            for lane in 0..2 {
                match r.t(q[lane]) {
                    Some(v) => {
                        assert!(ok & (1 << lane) != 0);
                        assert_eq!(v.to_bits(), t[lane].to_bits());
                    }
                    None => assert_eq!(ok & (1 << lane), 0),
                }
            }
        }
        let values = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.5,
            2.0,
            3.0 - 1e-15,
            -7.25,
            1e9 + 0.5,
            3e15,
            1e300,
        ];
        for mode in [Spread::Pad, Spread::Repeat, Spread::Reflect] {
            for pair in values.windows(2) {
                let got = spread2(mode, f64x2::new([pair[0], pair[1]])).to_array();
                for lane in 0..2 {
                    let want = spread(mode, pair[lane]).0;
                    assert_eq!(
                        got[lane].to_bits(),
                        want.to_bits(),
                        "{mode:?} {}",
                        pair[lane]
                    );
                }
            }
            assert!(
                spread2(mode, f64x2::new([f64::NAN, 0.5])).to_array()[1] == spread(mode, 0.5).0
            );
        }
    }

    #[test]
    fn radial_t_on_circles() {
        // Concentric: t = distance / r.
        let g = Geometry::Radial([5.0, 5.0, 4.0, 5.0, 5.0, 0.0]);
        let t = gradient_t(&g, [7.0, 5.0]).unwrap();
        assert!((t - 0.5).abs() < 1e-12);
        // Focal point: t = 0 there, 1 on the end circle.
        let g = Geometry::Radial([5.0, 5.0, 4.0, 3.0, 5.0, 0.0]);
        assert!(gradient_t(&g, [3.0, 5.0]).unwrap().abs() < 1e-12);
        assert!((gradient_t(&g, [9.0, 5.0]).unwrap() - 1.0).abs() < 1e-12);
        assert!((gradient_t(&g, [1.0, 5.0]).unwrap() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn stops_interpolate_and_clamp() {
        let stops = [
            stop(0.2, 0.0),
            stop(0.6, 1.0),
            stop(0.6, 0.5),
            stop(1.0, 0.0),
        ];
        assert_eq!(stop_color(&stops, 0.0)[0], 0.0);
        assert!((stop_color(&stops, 0.4)[0] - 0.5).abs() < 1e-12);
        assert!((stop_color(&stops, 0.7)[0] - 0.375).abs() < 1e-12);
        assert_eq!(stop_color(&stops, 1.0)[0], 0.0);
    }
}
