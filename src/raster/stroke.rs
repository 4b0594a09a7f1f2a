//! Strokes as filled outlines.
//!
//! The outline of a flattened centerline is built as closed rings that are filled with the
//! nonzero rule: an open contour gives one ring (left side forward, end cap, right side
//! backward, start cap), a closed contour two rings (left side forward, right side
//! backward). Every band of the stroke is wound the same way, so overlaps add up and clamp
//! to full coverage.
//!
//! * Inner joins use the intersection of the two offset lines when it lies on both chords,
//!   so the outline stays simple and the exact-area coverage stays exact; otherwise they
//!   pivot through the centerline vertex (as Skia does).
//! * Outer joins at original segment ends follow the join style (miter with its limit,
//!   round, bevel); between the chords of one flattened curve they are bevels, whose error
//!   is far below the flattening tolerance.
//!
//! Each outline vertex remembers a [`Recipe`]: a closed-form function of at most three
//! centerline vertices and the half width. [`Recipe::eval`] is generic over [`Scalar`], so
//! the backward pass gets the exact local Jacobian by evaluating it on [`Jet`]s.
//!
//! All of this happens in the stroke frame (where the pen is round); callers map points in
//! and out.

use super::flatten::Contour;
use super::jet::{Jet, Scalar};
use crate::scene::geom::dist;
use crate::scene::{LineCap, LineJoin, Point};

/// "No vertex" in a recipe slot.
pub(crate) const NONE: u32 = u32::MAX;

/// How an outline vertex is computed from centerline vertices `a`, `b`, `c` and the half
/// width `h`. `side` is `+1` for the left of the direction of travel (normal
/// `(−dy, dx)`), `−1` for the right.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Recipe {
    /// Offset of chord `a → b` by `side·h·n`, at `b` when `end`, else at `a`.
    Offset {
        /// Chord start.
        a: u32,
        /// Chord end.
        b: u32,
        /// At the end point.
        end: bool,
        /// Side.
        side: f64,
    },
    /// Intersection of the offset lines of `a → b` and `b → c`: a miter tip or an inner join.
    Meet {
        /// First chord start.
        a: u32,
        /// Shared vertex.
        b: u32,
        /// Second chord end.
        c: u32,
        /// Side.
        side: f64,
    },
    /// Point of a round join at `b`, a fraction `f` of the way from the normal of `a → b`
    /// to the normal of `b → c`.
    JoinArc {
        /// First chord start.
        a: u32,
        /// Center.
        b: u32,
        /// Second chord end.
        c: u32,
        /// Side.
        side: f64,
        /// Fraction of the sweep.
        f: f64,
    },
    /// Point of a round cap at the end `b` of chord `a → b`: `b + h(n cos πf + d sin πf)`.
    CapArc {
        /// Chord start.
        a: u32,
        /// Chord end (the cap's center).
        b: u32,
        /// Side of the normal at `f = 0`.
        side: f64,
        /// Fraction of the half turn.
        f: f64,
    },
    /// Corner of a square cap at the end `b` of chord `a → b`: `b + h(side·n + d)`.
    Square {
        /// Chord start.
        a: u32,
        /// Chord end.
        b: u32,
        /// Side.
        side: f64,
    },
    /// End of a clipped miter (`miter-clip` past the limit): where the offset line of
    /// `a → b` (or of `b → c` when `second`) crosses the line perpendicular to the join's
    /// bisector at distance `limit·h` from `b`.
    Clip {
        /// First chord start.
        a: u32,
        /// Shared vertex.
        b: u32,
        /// Second chord end.
        c: u32,
        /// Side.
        side: f64,
        /// Miter limit.
        limit: f64,
        /// On the second chord's offset line.
        second: bool,
    },
    /// The centerline vertex `b` itself (inner-join pivot).
    Center {
        /// The vertex.
        b: u32,
    },
    /// Around a lone point: `b + h·(ux, uy)` for a fixed vector `u`.
    Dot {
        /// The point.
        b: u32,
        /// Fixed direction (unit for round dots, corners for square dots).
        u: [f64; 2],
    },
}

type V<S> = [S; 2];

#[inline]
fn sub<S: Scalar>(a: V<S>, b: V<S>) -> V<S> {
    [a[0] - b[0], a[1] - b[1]]
}
#[inline]
fn add<S: Scalar>(a: V<S>, b: V<S>) -> V<S> {
    [a[0] + b[0], a[1] + b[1]]
}
#[inline]
fn scale<S: Scalar>(a: V<S>, s: S) -> V<S> {
    [a[0] * s, a[1] * s]
}
#[inline]
fn dot<S: Scalar>(a: V<S>, b: V<S>) -> S {
    a[0] * b[0] + a[1] * b[1]
}
#[inline]
fn cross<S: Scalar>(a: V<S>, b: V<S>) -> S {
    a[0] * b[1] - a[1] * b[0]
}

/// Unit direction and left normal of `a → b` (zero for a zero-length chord).
#[inline]
fn frame<S: Scalar>(a: V<S>, b: V<S>) -> (V<S>, V<S>) {
    let d = sub(b, a);
    let len = dot(d, d).sqrt();
    if len.v() == 0.0 {
        let z = S::c(0.0);
        return ([z, z], [z, z]);
    }
    let d = [d[0] / len, d[1] / len];
    (d, [-d[1], d[0]])
}

impl Recipe {
    /// The vertices this recipe reads, `NONE` where unused: `(a, b, c)`.
    pub(crate) fn inputs(&self) -> [u32; 3] {
        match *self {
            Recipe::Offset { a, b, .. } => [a, b, NONE],
            Recipe::Meet { a, b, c, .. }
            | Recipe::JoinArc { a, b, c, .. }
            | Recipe::Clip { a, b, c, .. } => [a, b, c],
            Recipe::CapArc { a, b, .. } | Recipe::Square { a, b, .. } => [a, b, NONE],
            Recipe::Center { b } | Recipe::Dot { b, .. } => [NONE, b, NONE],
        }
    }

    /// Evaluates the recipe on the points `pa`, `pb`, `pc` (unused ones are ignored) and
    /// half width `h`.
    pub(crate) fn eval<S: Scalar>(&self, pa: V<S>, pb: V<S>, pc: V<S>, h: S) -> V<S> {
        match *self {
            Recipe::Offset { end, side, .. } => {
                let (_, n) = frame(pa, pb);
                let base = if end { pb } else { pa };
                add(base, scale(n, h * S::c(side)))
            }
            Recipe::Meet { side, .. } => {
                let (_, n0) = frame(pa, pb);
                let (_, n1) = frame(pb, pc);
                let s = S::c(side);
                let (n0, n1) = (scale(n0, s), scale(n1, s));
                let denom = S::c(1.0) + dot(n0, n1);
                if denom.v() <= 1e-12 {
                    return add(pb, scale(n0, h));
                }
                add(pb, scale(add(n0, n1), h / denom))
            }
            Recipe::Clip {
                side,
                limit,
                second,
                ..
            } => {
                let (d0, n0) = frame(pa, pb);
                let (d1, n1) = frame(pb, pc);
                let s = S::c(side);
                let (n0, n1) = (scale(n0, s), scale(n1, s));
                let sum = add(n0, n1);
                let len = dot(sum, sum).sqrt();
                // The bisector; for a full reversal, straight ahead.
                let m = if len.v() > 1e-9 {
                    [sum[0] / len, sum[1] / len]
                } else {
                    d0
                };
                let (n, d) = if second { (n1, d1) } else { (n0, d0) };
                let dm = dot(d, m);
                if dm.v().abs() <= 1e-12 {
                    return add(pb, scale(n, h));
                }
                let along = h * (S::c(limit) - dot(n, m)) / dm;
                add(pb, add(scale(n, h), scale(d, along)))
            }
            Recipe::JoinArc { side, f, .. } => {
                let (_, n0) = frame(pa, pb);
                let (_, n1) = frame(pb, pc);
                let s = S::c(side);
                let (n0, n1) = (scale(n0, s), scale(n1, s));
                let theta = cross(n0, n1).atan2(dot(n0, n1));
                let phi = theta * S::c(f);
                let (c, sn) = (phi.cos(), phi.sin());
                let r = [n0[0] * c - n0[1] * sn, n0[0] * sn + n0[1] * c];
                add(pb, scale(r, h))
            }
            Recipe::CapArc { side, f, .. } => {
                let (d, n) = frame(pa, pb);
                let n = scale(n, S::c(side));
                let ang = std::f64::consts::PI * f;
                let r = add(scale(n, S::c(ang.cos())), scale(d, S::c(ang.sin())));
                add(pb, scale(r, h))
            }
            Recipe::Square { side, .. } => {
                let (d, n) = frame(pa, pb);
                add(pb, scale(add(scale(n, S::c(side)), d), h))
            }
            Recipe::Center { .. } => pb,
            Recipe::Dot { u, .. } => add(pb, scale([S::c(u[0]), S::c(u[1])], h)),
        }
    }

    /// Vector-Jacobian product: given `g = ∂L/∂(outline vertex)`, returns `∂L/∂pa`,
    /// `∂L/∂pb`, `∂L/∂pc` and `∂L/∂h`.
    pub(crate) fn vjp(
        &self,
        pa: Point,
        pb: Point,
        pc: Point,
        h: f64,
        g: Point,
    ) -> ([Point; 3], f64) {
        let j = |p: Point, i: usize| [<Jet>::var(p[0], i), <Jet>::var(p[1], i + 1)];
        let out = self.eval(j(pa, 0), j(pb, 2), j(pc, 4), <Jet>::var(h, 6));
        let mut d = [0.0; 7];
        for (i, v) in d.iter_mut().enumerate() {
            *v = g[0] * out[0].d[i] + g[1] * out[1].d[i];
        }
        ([[d[0], d[1]], [d[2], d[3]], [d[4], d[5]]], d[6])
    }
}

/// Stroke style in the stroke frame.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Style {
    /// Half the stroke width.
    pub(crate) half_width: f64,
    /// Join.
    pub(crate) join: LineJoin,
    /// Cap.
    pub(crate) cap: LineCap,
    /// Miter limit.
    pub(crate) miter_limit: f64,
    /// Chord tolerance for round joins and caps, in frame units.
    pub(crate) tolerance: f64,
    /// Whether to keep each vertex's [`Recipe`] (the backward pass needs them; a forward
    /// render does not, and they are most of an outline's memory).
    pub(crate) keep_recipes: bool,
    /// Whether to keep each vertex's position (the backward pass, which rebuilds an
    /// outline only for its recipes, does not need them).
    pub(crate) keep_points: bool,
}

impl Style {
    /// Chords of a round join or cap sweeping `angle` radians (1 to 256).
    pub(crate) fn arc_steps(&self, angle: f64) -> usize {
        crate::scene::geom::arc_steps(self.half_width, self.tolerance, angle)
    }

    /// Vertices one end cap adds to an outline (0 for butt caps).
    pub(crate) fn cap_vertices(&self) -> usize {
        crate::scene::geom::cap_vertices(self.cap, self.half_width, self.tolerance)
    }
}

/// Outline rings: vertices with their recipes; ring `r` spans `rings[r]` as `(start, len)`.
#[derive(Clone, Debug, Default)]
pub(crate) struct Outline {
    /// Vertex positions (stroke frame); empty without [`Style::keep_points`].
    pub(crate) pts: Vec<Point>,
    /// How each vertex was made; empty without [`Style::keep_recipes`].
    pub(crate) recipes: Vec<Recipe>,
    /// Closed rings as `(start, len)`.
    pub(crate) rings: Vec<(usize, usize)>,
}

struct Builder<'a> {
    /// Vertices pushed so far (kept or not).
    count: usize,
    pts: &'a [Point],
    style: Style,
    out: Outline,
}

impl Builder<'_> {
    fn push(&mut self, r: Recipe) {
        self.count += 1;
        if self.style.keep_points {
            let [a, b, c] = r.inputs();
            let p = |i: u32| {
                if i == NONE {
                    [0.0, 0.0]
                } else {
                    self.pts[i as usize]
                }
            };
            let q = r.eval(p(a), p(b), p(c), self.style.half_width);
            self.out.pts.push(q);
        }
        if self.style.keep_recipes {
            self.out.recipes.push(r);
        }
    }

    fn arc_steps(&self, angle: f64) -> usize {
        self.style.arc_steps(angle)
    }

    /// One side of a polyline (left of travel), joins included, from the start offset of
    /// the first chord to the end offset of the last one. `corner[i]` marks vertices where
    /// the join style applies.
    fn side(&mut self, v: &[u32], corner: &[bool]) {
        let m = v.len();
        self.push(Recipe::Offset {
            a: v[0],
            b: v[1],
            end: false,
            side: 1.0,
        });
        for i in 1..m - 1 {
            self.join(v[i - 1], v[i], v[i + 1], corner[i]);
        }
        self.push(Recipe::Offset {
            a: v[m - 2],
            b: v[m - 1],
            end: true,
            side: 1.0,
        });
    }

    /// Join at `b` on the left side, from the end offset of `a → b` to the start offset of
    /// `b → c` (both included).
    fn join(&mut self, a: u32, b: u32, c: u32, corner: bool) {
        let (pa, pb, pc) = (
            self.pts[a as usize],
            self.pts[b as usize],
            self.pts[c as usize],
        );
        let (d0, n0) = frame(pa, pb);
        let (d1, _) = frame(pb, pc);
        let turn = dot(n0, d1); // > 0: turning toward this side, the inner side
        let cos = dot(d0, d1);
        let end = Recipe::Offset {
            a,
            b,
            end: true,
            side: 1.0,
        };
        let start = Recipe::Offset {
            a: b,
            b: c,
            end: false,
            side: 1.0,
        };
        let h = self.style.half_width;
        if turn > 0.0 {
            // Inner join: the offset lines meet this far back along each chord.
            let back = h * turn / (1.0 + cos).max(1e-300);
            let la = dist(pa, pb);
            let lc = dist(pb, pc);
            if 1.0 + cos > 1e-9 && back <= la.min(lc) {
                self.push(Recipe::Meet { a, b, c, side: 1.0 });
            } else {
                self.push(end);
                self.push(Recipe::Center { b });
                self.push(start);
            }
            return;
        }
        if turn == 0.0 && cos > 0.0 {
            self.push(end);
            self.push(start);
            return;
        }
        // Outer join (or a full reversal).
        self.push(end);
        if corner {
            match self.style.join {
                LineJoin::Miter | LineJoin::MiterClip => {
                    // Miter length / width = 1 / cos(φ/2), cos²(φ/2) = (1 + cos) / 2.
                    let limit = self.style.miter_limit.max(1.0);
                    if (1.0 + cos) * 0.5 * limit * limit >= 1.0 {
                        self.push(Recipe::Meet { a, b, c, side: 1.0 });
                    } else if self.style.join == LineJoin::MiterClip {
                        for second in [false, true] {
                            self.push(Recipe::Clip {
                                a,
                                b,
                                c,
                                side: 1.0,
                                limit,
                                second,
                            });
                        }
                    }
                }
                LineJoin::Round => {
                    let ang = cross(n0, frame(pb, pc).1).atan2(dot(n0, frame(pb, pc).1));
                    let k = self.arc_steps(ang);
                    for j in 1..k {
                        self.push(Recipe::JoinArc {
                            a,
                            b,
                            c,
                            side: 1.0,
                            f: j as f64 / k as f64,
                        });
                    }
                }
                LineJoin::Bevel => {}
            }
        }
        self.push(start);
    }

    /// Cap at the end `b` of chord `a → b`, from the left offset to the right offset
    /// (neither included).
    fn cap(&mut self, a: u32, b: u32) {
        match self.style.cap {
            LineCap::Butt => {}
            LineCap::Square => {
                self.push(Recipe::Square { a, b, side: 1.0 });
                self.push(Recipe::Square { a, b, side: -1.0 });
            }
            LineCap::Round => {
                let k = self.arc_steps(std::f64::consts::PI);
                let k = k.max(2);
                for j in 1..k {
                    self.push(Recipe::CapArc {
                        a,
                        b,
                        side: 1.0,
                        f: j as f64 / k as f64,
                    });
                }
            }
        }
    }

    fn ring_from(&mut self, start: usize) {
        let len = self.count - start;
        if len >= 3 {
            self.out.rings.push((start, len));
        } else {
            self.count = start;
            self.out.pts.truncate(start);
            self.out.recipes.truncate(start);
        }
    }

    fn dot_ring(&mut self, b: u32) {
        let start = self.count;
        match self.style.cap {
            LineCap::Butt => return,
            LineCap::Square => {
                for u in [[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]] {
                    self.push(Recipe::Dot { b, u });
                }
            }
            LineCap::Round => {
                let k = self.arc_steps(2.0 * std::f64::consts::PI).max(8);
                for j in 0..k {
                    let a = 2.0 * std::f64::consts::PI * j as f64 / k as f64;
                    self.push(Recipe::Dot {
                        b,
                        u: [a.cos(), a.sin()],
                    });
                }
            }
        }
        self.ring_from(start);
    }

    fn contour(&mut self, c: &Contour, corner: &[bool]) {
        // Distinct consecutive vertices; a dropped duplicate passes its corner flag on.
        let mut v: Vec<u32> = Vec::with_capacity(c.len);
        let mut vc: Vec<bool> = Vec::with_capacity(c.len);
        let same = |p: Point, q: Point| {
            let tol = 1e-9 * (1.0 + p[0].abs().max(p[1].abs()));
            (p[0] - q[0]).abs() <= tol && (p[1] - q[1]).abs() <= tol
        };
        for i in c.start..c.start + c.len {
            match v.last() {
                Some(&l) if same(self.pts[l as usize], self.pts[i]) => {
                    let k = vc.len() - 1;
                    vc[k] |= corner[i];
                }
                _ => {
                    v.push(i as u32);
                    vc.push(corner[i]);
                }
            }
        }
        if c.closed {
            while v.len() > 1 && same(self.pts[v[v.len() - 1] as usize], self.pts[v[0] as usize]) {
                v.pop();
                let k = vc.pop().unwrap_or(false);
                vc[0] |= k;
            }
        }
        if v.len() < 2 {
            if c.drawn && !v.is_empty() {
                self.dot_ring(v[0]);
            }
            return;
        }
        if c.closed {
            // Every vertex of a closed contour is joined; the closing vertex is a corner.
            let m = v.len();
            for pass in 0..2 {
                let (vv, cc): (Vec<u32>, Vec<bool>) = if pass == 0 {
                    (v.clone(), vc.clone())
                } else {
                    (
                        v.iter().rev().copied().collect(),
                        vc.iter().rev().copied().collect(),
                    )
                };
                let start = self.count;
                for i in 0..m {
                    let prev = vv[(i + m - 1) % m];
                    let next = vv[(i + 1) % m];
                    self.join(prev, vv[i], next, cc[i] || i == 0);
                }
                self.ring_from(start);
            }
        } else {
            let start = self.count;
            let m = v.len();
            self.side(&v, &vc);
            self.cap(v[m - 2], v[m - 1]);
            let rv: Vec<u32> = v.iter().rev().copied().collect();
            let rc: Vec<bool> = vc.iter().rev().copied().collect();
            self.side(&rv, &rc);
            self.cap(rv[m - 2], rv[m - 1]);
            self.ring_from(start);
        }
    }
}

/// Builds the outline of the polylines `pts` (stroke frame) split into `contours`.
/// `corner[i]` tells whether vertex `i` ends an original segment.
pub(crate) fn outline(
    pts: &[Point],
    corner: &[bool],
    contours: &[Contour],
    style: Style,
) -> Outline {
    let mut b = Builder {
        count: 0,
        pts,
        style,
        out: Outline::default(),
    };
    for c in contours {
        b.contour(c, corner);
    }
    b.out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn style(h: f64, join: LineJoin, cap: LineCap) -> Style {
        Style {
            half_width: h,
            join,
            cap,
            miter_limit: 4.0,
            tolerance: 0.01,
            keep_recipes: true,
            keep_points: true,
        }
    }

    fn ring_area(o: &Outline, r: usize) -> f64 {
        let (s, n) = o.rings[r];
        let mut a = 0.0;
        for i in 0..n {
            let p = o.pts[s + i];
            let q = o.pts[s + (i + 1) % n];
            a += p[0] * q[1] - q[0] * p[1];
        }
        0.5 * a
    }

    fn open(n: usize) -> Contour {
        Contour {
            start: 0,
            len: n,
            closed: false,
            drawn: true,
        }
    }

    #[test]
    fn butt_segment_is_a_rectangle() {
        let pts = [[0.0, 0.0], [10.0, 0.0]];
        let o = outline(
            &pts,
            &[true, true],
            &[open(2)],
            style(2.0, LineJoin::Miter, LineCap::Butt),
        );
        assert_eq!(o.rings.len(), 1);
        assert!((ring_area(&o, 0).abs() - 40.0).abs() < 1e-9);
    }

    #[test]
    fn square_and_round_caps_add_area() {
        let pts = [[0.0, 0.0], [10.0, 0.0]];
        let sq = outline(
            &pts,
            &[true, true],
            &[open(2)],
            style(2.0, LineJoin::Miter, LineCap::Square),
        );
        assert!((ring_area(&sq, 0).abs() - 56.0).abs() < 1e-9);
        let rd = outline(
            &pts,
            &[true, true],
            &[open(2)],
            style(2.0, LineJoin::Miter, LineCap::Round),
        );
        // Two half discs of radius 2, inscribed polygons within the 0.01 tolerance: the
        // missing area is below arc length × tolerance.
        let want = 40.0 + std::f64::consts::PI * 4.0;
        let got = ring_area(&rd, 0).abs();
        assert!(
            got < want && want - got < 2.0 * std::f64::consts::PI * 0.01 * 2.0,
            "{got}"
        );
    }

    #[test]
    fn miter_join_of_right_angle() {
        // L shape (0,0) → (10,0) → (10,10), width 2: the arms [0,11]×[−1,1] and
        // [9,11]×[1,10] (area 22 + 18); a bevel cuts half of the unit corner square.
        let pts = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]];
        let o = outline(
            &pts,
            &[true; 3],
            &[open(3)],
            style(1.0, LineJoin::Miter, LineCap::Butt),
        );
        assert!(
            (ring_area(&o, 0).abs() - 40.0).abs() < 1e-9,
            "{}",
            ring_area(&o, 0)
        );
        let b = outline(
            &pts,
            &[true; 3],
            &[open(3)],
            style(1.0, LineJoin::Bevel, LineCap::Butt),
        );
        assert!(
            (ring_area(&b, 0).abs() - 39.5).abs() < 1e-9,
            "{}",
            ring_area(&b, 0)
        );
    }

    #[test]
    fn miter_clip_cuts_at_the_limit() {
        // Right angle at (10, 0), half width 1, limit 1.2 (< √2). The full miter (area 40)
        // has its tip at (11, −1), √2 from the corner; the clip line is perpendicular to
        // the bisector 1.2 from the corner, so it cuts off a right isosceles triangle of
        // height h = √2 − 1.2, whose area is h².
        let pts = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]];
        let mut st = style(1.0, LineJoin::MiterClip, LineCap::Butt);
        st.miter_limit = 1.2;
        let o = outline(&pts, &[true; 3], &[open(3)], st);
        let want = 40.0 - (2.0f64.sqrt() - 1.2).powi(2);
        assert!(
            (ring_area(&o, 0).abs() - want).abs() < 1e-9,
            "{} vs {want}",
            ring_area(&o, 0)
        );
        // Plain miter with the same limit falls back to a bevel.
        st.join = LineJoin::Miter;
        let b = outline(&pts, &[true; 3], &[open(3)], st);
        assert!((ring_area(&b, 0).abs() - 39.5).abs() < 1e-9);
    }

    #[test]
    fn closed_square_gives_two_rings() {
        let pts = [[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];
        let c = Contour {
            start: 0,
            len: 4,
            closed: true,
            drawn: true,
        };
        let o = outline(
            &pts,
            &[true; 4],
            &[c],
            style(1.0, LineJoin::Miter, LineCap::Butt),
        );
        assert_eq!(o.rings.len(), 2);
        let total = ring_area(&o, 0) + ring_area(&o, 1);
        assert!((total.abs() - (144.0 - 64.0)).abs() < 1e-9, "{total}");
    }

    #[test]
    fn vjp_matches_differences() {
        let (pa, pb, pc, h) = ([0.3, 0.1], [4.0, 1.0], [5.5, 4.0], 1.3);
        let recipes = [
            Recipe::Offset {
                a: 0,
                b: 1,
                end: true,
                side: -1.0,
            },
            Recipe::Meet {
                a: 0,
                b: 1,
                c: 2,
                side: 1.0,
            },
            Recipe::JoinArc {
                a: 0,
                b: 1,
                c: 2,
                side: -1.0,
                f: 0.3,
            },
            Recipe::CapArc {
                a: 0,
                b: 1,
                side: 1.0,
                f: 0.7,
            },
            Recipe::Square {
                a: 0,
                b: 1,
                side: -1.0,
            },
        ];
        let g = [0.7, -0.4];
        for r in recipes {
            let (dp, dh) = r.vjp(pa, pb, pc, h, g);
            let f = |pa: Point, pb: Point, pc: Point, h: f64| {
                let q = r.eval(pa, pb, pc, h);
                g[0] * q[0] + g[1] * q[1]
            };
            let e = 1e-6;
            let fd_h = (f(pa, pb, pc, h + e) - f(pa, pb, pc, h - e)) / (2.0 * e);
            assert!((fd_h - dh).abs() < 1e-6, "{r:?} h");
            for (k, base) in [pa, pb, pc].into_iter().enumerate() {
                for c in 0..2 {
                    let mut p = [pa, pb, pc];
                    p[k][c] = base[c] + e;
                    let up = f(p[0], p[1], p[2], h);
                    p[k][c] = base[c] - e;
                    let dn = f(p[0], p[1], p[2], h);
                    let fd = (up - dn) / (2.0 * e);
                    assert!(
                        (fd - dp[k][c]).abs() < 1e-6,
                        "{r:?} p{k} c{c}: {fd} vs {}",
                        dp[k][c]
                    );
                }
            }
        }
    }
}
