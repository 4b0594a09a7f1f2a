//! Shapes with their own parameters: circles, ellipses and rectangles.
//!
//! A path may carry a [`Primitive`] ([`Path::primitive`]): then its parameters are the
//! primitive's (a circle's center and radius, …), not its control points, and its outline
//! ([`Path::points`], [`Path::subpaths`]) is *built* from them by [`Path::sync_primitive`].
//! The rasterizer sees only the outline; the backward pass chains the control points'
//! gradient to the primitive's parameters (`Primitive::chain`), which is exact because
//! every outline point is `center + R(angle)·o` with `o` linear in the sizes.
//!
//! # Conventions
//!
//! * Device pixels, y down (as every coordinate of a [`Scene`](super::Scene)); under a
//!   general affine group transform, the group's frame instead, the outline mapped by
//!   the primitive's [`frame`](Primitive::frame) (module
//!   [`transform`](super::transform)).
//! * `angle` rotates the shape about its center, in radians; positive turns the x axis
//!   toward the y axis (clockwise on screen). SVG out writes it as
//!   `transform="rotate(degrees cx cy)"`.
//! * Arcs are cubic Béziers, `arcs_per_quarter` per quarter turn, as usvg (kurbo) builds a
//!   `<circle>`: the same outline, so that a loaded shape renders as before.
//! * A rectangle's `x`, `y`, `width`, `height` describe it before its rotation (about its
//!   center `(x + width/2, y + height/2)`); its corner radii exist only on a rounded
//!   rectangle (a sharp one has none to move).
//!
//! # Parameter slots (see [`params`](super::params))
//!
//! | shape | slots |
//! |---|---|
//! | circle | `cx, cy, r` |
//! | ellipse | `cx, cy, rx, ry, angle` |
//! | rectangle | `x, y, width, height, [rx, ry,] angle` |
//!
//! Positions and sizes are in the [`Points`](super::ParamGroup::Points) group, the angle
//! in [`Transform`](super::ParamGroup::Transform). A circle's angle only says where its
//! outline starts (it matters to dashes); it is no parameter.
//!
//! Built in code:
//!
//! ```
//! use diffsvg::scene::{Fill, FillRule, Node, Paint, Path, Primitive, Scene};
//! let mut scene = Scene::new(64, 64);
//! let mut disc = Path::from_primitive("disc", Primitive::circle([30.0, 34.0], 12.0));
//! disc.fill = Some(Fill { paint: Paint::Solid([0.3, 0.5, 0.8]), opacity: 1.0, rule: FillRule::NonZero });
//! scene.nodes.push(Node::Path(disc));
//! assert_eq!(scene.params(), [30.0, 34.0, 12.0, 0.3, 0.5, 0.8, 1.0]);
//! let mut p = scene.params();
//! p[2] = 15.0; // the radius
//! scene.set_params(&p);
//! assert!(scene.to_svg_string().contains(r#"<circle id="disc" cx="30" cy="34" r="15""#));
//! ```

use super::params::Part;
use super::{Affine, FRAME_IDENTITY, ParamGroup, Path, Point, SegmentKind, Subpath};
use crate::limits::MAX_COORDINATE;

/// The smallest size (radius, side, corner radius) a projected primitive keeps, device
/// pixels: SVG drops a circle of radius 0, and a rounded corner of radius 0 is a sharp one.
pub const MIN_SIZE: f64 = 1e-3;

/// The geometry of a [`Primitive`], device pixels.
#[derive(Clone, Debug, PartialEq)]
pub enum Shape {
    /// A circle (`<circle>`).
    Circle {
        /// Center.
        center: Point,
        /// Radius, ≥ 0.
        r: f64,
    },
    /// An ellipse (`<ellipse>`), its axes along the rotated x and y axes.
    Ellipse {
        /// Center.
        center: Point,
        /// Radius along the (rotated) x axis, ≥ 0.
        rx: f64,
        /// Radius along the (rotated) y axis, ≥ 0.
        ry: f64,
    },
    /// A rectangle (`<rect>`), possibly with rounded corners.
    Rect {
        /// Left edge before the rotation.
        x: f64,
        /// Top edge before the rotation.
        y: f64,
        /// Width, ≥ 0.
        width: f64,
        /// Height, ≥ 0.
        height: f64,
        /// Corner radii `[rx, ry]` (each at most half the side), or `None` for sharp
        /// corners.
        radii: Option<[f64; 2]>,
    },
}

/// A shape with its own parameters; see the [module docs](self).
#[derive(Clone, Debug, PartialEq)]
pub struct Primitive {
    /// The geometry.
    pub shape: Shape,
    /// Rotation about the center, radians (clockwise on screen).
    pub angle: f64,
    /// Cubic segments per quarter turn of an arc, ≥ 1 (fixed while fitting).
    pub arcs_per_quarter: u32,
    /// The linear map `[a, b, c, d]` (SVG's `matrix` order) the outline takes about the
    /// center: every outline point is `center + frame·R(angle)·o`. The identity but under
    /// a general affine group transform ([`transform`](super::transform)), which keeps
    /// the primitive in its own frame and maps its outline (a circle's becomes an ellipse
    /// on the canvas, a rectangle's a parallelogram); sizes are then in that frame's units.
    /// No parameter: the group's slots move it.
    pub frame: [f64; 4],
}

/// What a parameter slot of a primitive is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Slot {
    /// A center's or corner's coordinate.
    Position,
    /// A radius, side or corner radius (≥ `MIN_SIZE` once projected).
    Size,
    /// The rotation.
    Angle,
}

/// How each outline point depends on the sizes: its offset from the center before the
/// rotation is `(ax·W + bx·RX, ay·H + by·RY)` (see [`Primitive::sizes`]).
type Coef = [f64; 4];

impl Primitive {
    /// A circle; its arcs are split as usvg splits a circle of radius `r`.
    pub fn circle(center: Point, r: f64) -> Self {
        Primitive {
            shape: Shape::Circle { center, r },
            angle: 0.0,
            arcs_per_quarter: arcs_per_quarter(r),
            frame: FRAME_IDENTITY,
        }
    }

    /// An ellipse rotated by `angle` radians about its center.
    pub fn ellipse(center: Point, rx: f64, ry: f64, angle: f64) -> Self {
        Primitive {
            shape: Shape::Ellipse { center, rx, ry },
            angle,
            arcs_per_quarter: arcs_per_quarter(rx.max(ry)),
            frame: FRAME_IDENTITY,
        }
    }

    /// A rectangle with corner `(x, y)` and size `width × height` before a rotation by
    /// `angle` radians about its center; `radii` rounds its corners.
    pub fn rect(
        x: f64,
        y: f64,
        width: f64,
        height: f64,
        radii: Option<[f64; 2]>,
        angle: f64,
    ) -> Self {
        let r = radii.map_or(0.0, |[a, b]| a.max(b));
        Primitive {
            shape: Shape::Rect {
                x,
                y,
                width,
                height,
                radii,
            },
            angle,
            arcs_per_quarter: arcs_per_quarter(r),
            frame: FRAME_IDENTITY,
        }
    }

    /// The SVG element name: `circle`, `ellipse` or `rect`.
    pub fn element(&self) -> &'static str {
        match self.shape {
            Shape::Circle { .. } => "circle",
            Shape::Ellipse { .. } => "ellipse",
            Shape::Rect { .. } => "rect",
        }
    }

    /// The center of rotation.
    pub fn center(&self) -> Point {
        match self.shape {
            Shape::Circle { center, .. } | Shape::Ellipse { center, .. } => center,
            Shape::Rect {
                x,
                y,
                width,
                height,
                ..
            } => [x + 0.5 * width, y + 0.5 * height],
        }
    }

    /// How far the outline reaches from the center: the radius (the larger one of an
    /// ellipse), half the diagonal of a rectangle.
    pub fn radius(&self) -> f64 {
        match self.shape {
            Shape::Circle { r, .. } => r,
            Shape::Ellipse { rx, ry, .. } => rx.max(ry),
            Shape::Rect { width, height, .. } => 0.5 * width.hypot(height),
        }
    }

    /// `[W, H, RX, RY]`: the sizes the outline's offsets are linear in.
    fn sizes(&self) -> [f64; 4] {
        match self.shape {
            Shape::Circle { r, .. } => [0.0, 0.0, r, r],
            Shape::Ellipse { rx, ry, .. } => [0.0, 0.0, rx, ry],
            Shape::Rect {
                width,
                height,
                radii,
                ..
            } => {
                let [rx, ry] = radii.unwrap_or([0.0; 2]);
                [width, height, rx, ry]
            }
        }
    }

    /// The outline's points as coefficients of the sizes, its segment kinds, and whether
    /// its last point is its start (the subpath is always one and closed).
    fn template(&self) -> (Vec<Coef>, Vec<SegmentKind>) {
        let m = self.arcs_per_quarter.max(1) as usize;
        let mut pts: Vec<Coef> = Vec::new();
        let mut kinds = Vec::new();
        // A quarter arc about the corner center `(sx·(W/2) − sx·RX, …)` of a rounded
        // rectangle (`corner` = Some((sx, sy))) or about the center of an ellipse, from
        // angle `a0` (multiples of π/2) on, `m` cubics; the start point is already pushed.
        let arc = |pts: &mut Vec<Coef>,
                   kinds: &mut Vec<SegmentKind>,
                   a0: f64,
                   corner: Option<(f64, f64)>| {
            let step = std::f64::consts::FRAC_PI_2 / m as f64;
            let arm = 4.0 / 3.0 * (0.25 * step).tan();
            let (ax, ay) = corner.map_or((0.0, 0.0), |(sx, sy)| (0.5 * sx, 0.5 * sy));
            let (ox, oy) = corner.unwrap_or((0.0, 0.0));
            let at = |u: f64, v: f64| [ax, u - ox, ay, v - oy];
            for k in 0..m {
                let (p0, p1) = (a0 + step * k as f64, a0 + step * (k + 1) as f64);
                let (s0, c0) = p0.sin_cos();
                let (s1, c1) = p1.sin_cos();
                pts.push(at(c0 - arm * s0, s0 + arm * c0));
                pts.push(at(c1 + arm * s1, s1 - arm * c1));
                pts.push(at(c1, s1));
                kinds.push(SegmentKind::Cubic);
            }
        };
        let line = |pts: &mut Vec<Coef>, kinds: &mut Vec<SegmentKind>, to: Coef| {
            let a = *pts.last().expect("a start point");
            let lerp = |t: f64| std::array::from_fn(|i| a[i] + t * (to[i] - a[i]));
            pts.extend([lerp(1.0 / 3.0), lerp(2.0 / 3.0), to]);
            kinds.push(SegmentKind::Line);
        };
        match self.shape {
            Shape::Circle { .. } | Shape::Ellipse { .. } => {
                pts.push([0.0, 1.0, 0.0, 0.0]);
                for q in 0..4 {
                    arc(
                        &mut pts,
                        &mut kinds,
                        q as f64 * std::f64::consts::FRAC_PI_2,
                        None,
                    );
                }
            }
            Shape::Rect { radii: None, .. } => {
                pts.push([-0.5, 0.0, -0.5, 0.0]);
                for to in [
                    [0.5, 0.0, -0.5, 0.0],
                    [0.5, 0.0, 0.5, 0.0],
                    [-0.5, 0.0, 0.5, 0.0],
                ] {
                    line(&mut pts, &mut kinds, to);
                }
            }
            Shape::Rect { radii: Some(_), .. } => {
                // usvg's order: from (x + rx, y) clockwise, each side then its corner.
                use std::f64::consts::{FRAC_PI_2, PI};
                pts.push([-0.5, 1.0, -0.5, 0.0]);
                let corners = [
                    ([0.5, -1.0, -0.5, 0.0], -FRAC_PI_2, (1.0, -1.0)),
                    ([0.5, 0.0, 0.5, -1.0], 0.0, (1.0, 1.0)),
                    ([-0.5, 1.0, 0.5, 0.0], FRAC_PI_2, (-1.0, 1.0)),
                    ([-0.5, 0.0, -0.5, 1.0], PI, (-1.0, -1.0)),
                ];
                for (side_end, a0, corner) in corners {
                    line(&mut pts, &mut kinds, side_end);
                    arc(&mut pts, &mut kinds, a0, Some(corner));
                }
            }
        }
        // The outline ends on its start: one point, exactly.
        if !matches!(self.shape, Shape::Rect { radii: None, .. }) {
            let first = pts[0];
            *pts.last_mut().expect("points") = first;
        }
        (pts, kinds)
    }

    /// The rotation `[cos, sin]`; exactly `[1, 0]` at angle 0.
    fn rotation(&self) -> [f64; 2] {
        if self.angle == 0.0 {
            [1.0, 0.0]
        } else {
            let (s, c) = self.angle.sin_cos();
            [c, s]
        }
    }

    /// The outline: its points (device pixels) and its one closed subpath.
    pub(crate) fn outline(&self) -> (Vec<Point>, Subpath) {
        let (coefs, kinds) = self.template();
        let [w, h, rx, ry] = self.sizes();
        let c = self.center();
        let [cs, sn] = self.rotation();
        let sharp_rect = matches!(self.shape, Shape::Rect { radii: None, .. });
        let f = self.frame;
        let framed = f != FRAME_IDENTITY;
        let points = coefs
            .iter()
            .map(|k| {
                let o = [k[0] * w + k[1] * rx, k[2] * h + k[3] * ry];
                if framed {
                    let v = [cs * o[0] - sn * o[1], sn * o[0] + cs * o[1]];
                    return [
                        c[0] + f[0] * v[0] + f[2] * v[1],
                        c[1] + f[1] * v[0] + f[3] * v[1],
                    ];
                }
                if self.angle == 0.0 {
                    if let (true, Shape::Rect { x, y, .. }) = (sharp_rect, &self.shape) {
                        // The corners exactly where the rectangle's numbers put them.
                        return [x + (k[0] + 0.5) * w, y + (k[2] + 0.5) * h];
                    }
                    [c[0] + o[0], c[1] + o[1]]
                } else {
                    [c[0] + cs * o[0] - sn * o[1], c[1] + sn * o[0] + cs * o[1]]
                }
            })
            .collect();
        let sub = Subpath {
            start: 0,
            kinds,
            closed: true,
            ends_at_start: !sharp_rect,
        };
        (points, sub)
    }

    /// Every parameter in slot order (module docs), with what it is.
    fn slots_mut(&mut self) -> Vec<(Slot, &mut f64)> {
        use Slot::{Angle, Position, Size};
        let mut out: Vec<(Slot, &mut f64)> = match &mut self.shape {
            Shape::Circle {
                center: [cx, cy],
                r,
            } => {
                // A circle's angle only places its outline's start: no slot.
                return vec![(Position, cx), (Position, cy), (Size, r)];
            }
            Shape::Ellipse {
                center: [cx, cy],
                rx,
                ry,
            } => vec![(Position, cx), (Position, cy), (Size, rx), (Size, ry)],
            Shape::Rect {
                x,
                y,
                width,
                height,
                radii,
            } => {
                let mut v = vec![(Position, x), (Position, y), (Size, width), (Size, height)];
                if let Some([rx, ry]) = radii {
                    v.extend([(Size, rx), (Size, ry)]);
                }
                v
            }
        };
        out.push((Angle, &mut self.angle));
        out
    }

    /// Visits the parameters in slot order (module docs); `first` marks the first slot.
    pub(crate) fn walk(
        &mut self,
        owner: usize,
        first: Part,
        f: &mut dyn FnMut(usize, ParamGroup, Part, &mut f64),
    ) {
        let mut first = Some(first);
        for (what, v) in self.slots_mut() {
            let group = match what {
                Slot::Angle => ParamGroup::Transform,
                _ => ParamGroup::Points,
            };
            f(owner, group, first.take().unwrap_or(Part::Point), v);
        }
    }

    /// The slots (from the first, see [`slot_count`](Self::slot_count)) that are sizes:
    /// radii, widths, heights and corner radii.
    pub fn size_slots(&self) -> std::ops::Range<usize> {
        2..2 + self.fields()[1..]
            .iter()
            .filter(|f| f.0 != "angle")
            .map(|f| f.1)
            .sum::<usize>()
    }

    /// The parameters' names and lengths, in slot order: a circle's `center` (2) and
    /// `radius` (1); an ellipse's `center`, `radius` (2: rx, ry) and `angle` (1); a
    /// rectangle's `corner` (2: x, y), `size` (2: width, height), `radii` (2, rounded
    /// corners only) and `angle`. As DiffVG's Python names a circle's.
    pub fn fields(&self) -> Vec<(&'static str, usize)> {
        match self.shape {
            Shape::Circle { .. } => vec![("center", 2), ("radius", 1)],
            Shape::Ellipse { .. } => vec![("center", 2), ("radius", 2), ("angle", 1)],
            Shape::Rect { radii, .. } => {
                let mut v = vec![("corner", 2), ("size", 2)];
                if radii.is_some() {
                    v.push(("radii", 2));
                }
                v.push(("angle", 1));
                v
            }
        }
    }

    /// Number of parameter slots.
    pub fn slot_count(&self) -> usize {
        self.fields().iter().map(|f| f.1).sum()
    }

    /// Chains the gradient of the outline's points (`x, y` per point of
    /// [`outline`](Self::outline)) to the parameters, added into `out` (slot order), and
    /// returns the gradient of the [`frame`](Self::frame) (`∂L/∂[a, b, c, d]`), which a
    /// general group transform carries onto its slots.
    pub(crate) fn chain(&self, point_grad: &[f64], out: &mut [f64]) -> [f64; 4] {
        let (coefs, _) = self.template();
        let [w, h, rx, ry] = self.sizes();
        let [cs, sn] = self.rotation();
        let f = self.frame;
        let mut g_frame = [0.0; 4];
        // Rotating a local vector, and its derivative in the angle.
        let rot = |v: [f64; 2]| [cs * v[0] - sn * v[1], sn * v[0] + cs * v[1]];
        let drot = |v: [f64; 2]| [-sn * v[0] - cs * v[1], cs * v[0] - sn * v[1]];
        let dot = |a: [f64; 2], b: [f64; 2]| a[0] * b[0] + a[1] * b[1];
        // d/dcenter, d/dW, d/dH, d/dRX, d/dRY, d/dangle.
        let mut d = [0.0f64; 7];
        let rect = matches!(self.shape, Shape::Rect { .. });
        for (i, k) in coefs.iter().enumerate() {
            let g = [point_grad[2 * i], point_grad[2 * i + 1]];
            if g == [0.0, 0.0] {
                continue;
            }
            d[0] += g[0];
            d[1] += g[1];
            // A rectangle's center moves by half its growth (device pixels: the corner
            // slots are the center's less half the sides, whatever the frame).
            let half = if rect { 0.5 } else { 0.0 };
            let o = [k[0] * w + k[1] * rx, k[2] * h + k[3] * ry];
            let v = rot(o);
            g_frame[0] += g[0] * v[0];
            g_frame[1] += g[1] * v[0];
            g_frame[2] += g[0] * v[1];
            g_frame[3] += g[1] * v[1];
            let half_g = [half * g[0], half * g[1]];
            // The offsets go through the frame: their gradient is `frameᵀ·g`.
            let g = [f[0] * g[0] + f[1] * g[1], f[2] * g[0] + f[3] * g[1]];
            d[2] += dot(g, rot([k[0], 0.0])) + half_g[0];
            d[3] += dot(g, rot([0.0, k[2]])) + half_g[1];
            d[4] += dot(g, rot([k[1], 0.0]));
            d[5] += dot(g, rot([0.0, k[3]]));
            d[6] += dot(g, drot(o));
        }
        match self.shape {
            Shape::Circle { .. } => {
                out[0] += d[0];
                out[1] += d[1];
                out[2] += d[4] + d[5];
            }
            Shape::Ellipse { .. } => {
                for (o, v) in out.iter_mut().zip([d[0], d[1], d[4], d[5], d[6]]) {
                    *o += v;
                }
            }
            Shape::Rect { radii, .. } => {
                // x and y move the center one for one.
                let mut vals = vec![d[0], d[1], d[2], d[3]];
                if radii.is_some() {
                    vals.extend([d[4], d[5]]);
                }
                vals.push(d[6]);
                for (o, v) in out.iter_mut().zip(vals) {
                    *o += v;
                }
            }
        }
        g_frame
    }

    /// Clamps the parameters into their valid range: positions within
    /// ±[`MAX_COORDINATE`]/8, sizes in `[MIN_SIZE, MAX_COORDINATE/8]` (so that every outline
    /// point stays within the readable ±[`MAX_COORDINATE`], and no shape vanishes from the
    /// SVG written, where a zero radius or side drops the element), a rectangle's corner
    /// radii at most half its sides, the angle finite; NaN becomes 0 (a size `MIN_SIZE`).
    pub(crate) fn project(&mut self) {
        const BOUND: f64 = MAX_COORDINATE / 8.0;
        for (what, v) in self.slots_mut() {
            match what {
                Slot::Position => super::params::clamp_coordinate(v, BOUND),
                Slot::Size => {
                    *v = if v.is_nan() {
                        MIN_SIZE
                    } else {
                        v.clamp(MIN_SIZE, BOUND)
                    }
                }
                Slot::Angle => *v = if v.is_finite() { *v } else { 0.0 },
            }
        }
        if let Shape::Rect {
            width,
            height,
            radii: Some([rx, ry]),
            ..
        } = &mut self.shape
        {
            // Sides are at least MIN_SIZE, so half of one is a valid radius too.
            *rx = rx.min(0.5 * *width).max(MIN_SIZE.min(0.5 * *width));
            *ry = ry.min(0.5 * *height).max(MIN_SIZE.min(0.5 * *height));
        }
    }

    /// Moves by `d` (every position slot; sizes and angle unchanged).
    pub(crate) fn translate(&mut self, d: Point) {
        let mut axis = 0;
        for (what, v) in self.slots_mut() {
            if what == Slot::Position {
                *v += d[axis];
                axis = 1 - axis;
            }
        }
    }

    /// The values of the [`size_slots`](Self::size_slots), in order.
    pub(crate) fn size_values(&self) -> Vec<f64> {
        let mut me = self.clone();
        me.slots_mut()
            .into_iter()
            .filter(|(what, _)| *what == Slot::Size)
            .map(|(_, v)| *v)
            .collect()
    }

    /// Scales about the origin by `s > 0` (every position and size; not the angle).
    pub(crate) fn scale(&mut self, s: f64) {
        for (what, v) in self.slots_mut() {
            if what != Slot::Angle {
                *v *= s;
            }
        }
    }

    /// Maps by `x ↦ k·x + d` (`k > 0`): the sizes scale, or, with a
    /// [`frame`](Self::frame) other than the identity, the frame does (as a stroke's
    /// frame: a general group transform's localized content keeps the identity frame).
    pub(crate) fn scale_translate(&mut self, k: f64, d: Point) {
        let c = self.center();
        if self.frame == FRAME_IDENTITY {
            self.scale(k);
        } else {
            self.frame = self.frame.map(|v| v * k);
        }
        let now = self.center();
        self.translate([k * c[0] + d[0] - now[0], k * c[1] + d[1] - now[1]]);
    }

    /// The primitive that `local`, a shape's outline in its own user space as usvg builds
    /// a `<circle>`, `<ellipse>` or `<rect>`, is under the transform `t` (user space →
    /// device), when `t` keeps it one: a similarity with a positive determinant, or, for a
    /// shape without a stroke (`stroked` false), any axis-aligned positive scale.
    /// `None` otherwise (it stays a path).
    pub(crate) fn recognize(local: &Path, t: &Affine, stroked: bool) -> Option<Primitive> {
        let [a, b, c, d, _, _] = *t;
        let s = a.hypot(b);
        let tol = 1e-9 * s.max(1e-300);
        let similarity = s > 0.0 && (a - d).abs() <= tol && (b + c).abs() <= tol;
        let axis = b == 0.0 && c == 0.0 && a > 0.0 && d > 0.0;
        if !(similarity || (axis && !stroked)) {
            return None;
        }
        let (angle, sx, sy) = if similarity {
            (if b == 0.0 && a > 0.0 { 0.0 } else { b.atan2(a) }, s, s)
        } else {
            (0.0, a, d)
        };
        let local_prim = recognize_local(local)?;
        let center_dev = super::apply(t, local_prim.center());
        let m = local_prim.arcs_per_quarter;
        let shape = match local_prim.shape {
            Shape::Circle { r, .. } if sx == sy => Shape::Circle {
                center: center_dev,
                r: r * sx,
            },
            Shape::Circle { r, .. } => Shape::Ellipse {
                center: center_dev,
                rx: r * sx,
                ry: r * sy,
            },
            Shape::Ellipse { rx, ry, .. } => Shape::Ellipse {
                center: center_dev,
                rx: rx * sx,
                ry: ry * sy,
            },
            Shape::Rect {
                x,
                y,
                width,
                height,
                radii,
            } => {
                let (w, h) = (width * sx, height * sy);
                let (x, y) = if angle == 0.0 {
                    let q = super::apply(t, [x, y]);
                    (q[0], q[1])
                } else {
                    (center_dev[0] - 0.5 * w, center_dev[1] - 0.5 * h)
                };
                Shape::Rect {
                    x,
                    y,
                    width: w,
                    height: h,
                    radii: radii.map(|[rx, ry]| [rx * sx, ry * sy]),
                }
            }
        };
        Some(Primitive {
            shape,
            angle,
            arcs_per_quarter: m,
            frame: FRAME_IDENTITY,
        })
    }
}

/// The primitive whose outline `local` is (in its own space, unrotated), within the
/// precision of `f32` coordinates; `None` when it is no circle, ellipse or rectangle.
fn recognize_local(local: &Path) -> Option<Primitive> {
    let [sp] = local.subpaths.as_slice() else {
        return None;
    };
    if !sp.closed || sp.start != 0 {
        return None;
    }
    let pts = &local.points;
    let (xmin, ymin, xmax, ymax) = {
        let b = local.control_bounds()?;
        (b[0], b[1], b[2], b[3])
    };
    let kinds = &sp.kinds;
    let all_cubic = kinds.iter().all(|k| *k == SegmentKind::Cubic);
    let candidate = if all_cubic && !kinds.is_empty() && kinds.len() % 4 == 0 {
        // An ellipse from (cx + rx, cy), a quarter every m cubics.
        let m = kinds.len() / 4;
        let q = |k: usize| pts[3 * m * k];
        let (cx, rx) = (0.5 * (q(0)[0] + q(2)[0]), 0.5 * (q(0)[0] - q(2)[0]));
        let (cy, ry) = (0.5 * (q(1)[1] + q(3)[1]), 0.5 * (q(1)[1] - q(3)[1]));
        // A circle's radii differ by the rounding of its f32 coordinates at most.
        let shape = if (rx - ry).abs() <= 1e-6 * rx.abs().max(ry.abs()).max(1.0) {
            Shape::Circle {
                center: [cx, cy],
                r: 0.5 * (rx + ry),
            }
        } else {
            Shape::Ellipse {
                center: [cx, cy],
                rx,
                ry,
            }
        };
        (rx > 0.0 && ry > 0.0).then_some(Primitive {
            shape,
            angle: 0.0,
            arcs_per_quarter: m as u32,
            frame: FRAME_IDENTITY,
        })
    } else if kinds.len() == 3 && kinds.iter().all(|k| *k == SegmentKind::Line) {
        Some(Primitive {
            shape: Shape::Rect {
                x: xmin,
                y: ymin,
                width: xmax - xmin,
                height: ymax - ymin,
                radii: None,
            },
            angle: 0.0,
            arcs_per_quarter: 1,
            frame: FRAME_IDENTITY,
        })
    } else if kinds.len() % 4 == 0 && kinds.len() >= 8 && kinds[0] == SegmentKind::Line {
        let m = kinds.len() / 4 - 1;
        let pattern = (0..4).all(|c| {
            kinds[c * (m + 1)] == SegmentKind::Line
                && kinds[c * (m + 1) + 1..(c + 1) * (m + 1)]
                    .iter()
                    .all(|k| *k == SegmentKind::Cubic)
        });
        // The first corner's arc ends at (x + width, y + ry).
        let first_arc_end = pts[3 * (m + 1)];
        let (rx, ry) = (pts[0][0] - xmin, first_arc_end[1] - ymin);
        (pattern && m >= 1 && rx > 0.0 && ry > 0.0).then_some(Primitive {
            shape: Shape::Rect {
                x: xmin,
                y: ymin,
                width: xmax - xmin,
                height: ymax - ymin,
                radii: Some([rx, ry]),
            },
            angle: 0.0,
            arcs_per_quarter: m as u32,
            frame: FRAME_IDENTITY,
        })
    } else {
        None
    };
    let p = candidate?;
    if let Shape::Rect { width, height, .. } = p.shape
        && !(width > 0.0 && height > 0.0)
    {
        return None;
    }
    // The outline it builds must be the one given, point for point (f32 precision).
    let (want, _) = p.outline();
    let scale = xmax
        .abs()
        .max(xmin.abs())
        .max(ymax.abs())
        .max(ymin.abs())
        .max(1.0);
    let close = want.len() == pts.len()
        && want
            .iter()
            .zip(pts)
            .all(|(u, v)| (u[0] - v[0]).abs().max((u[1] - v[1]).abs()) <= 1e-5 * scale);
    close.then_some(p)
}

/// usvg's (kurbo's) number of cubics per quarter turn of an arc of radius `r` at its
/// tolerance of 0.1.
pub(crate) fn arcs_per_quarter(r: f64) -> u32 {
    let n_err = (1.1163 * r.abs() / 0.1).powf(1.0 / 6.0).max(3.999_999);
    let n = (n_err * 0.25).ceil();
    if n.is_finite() {
        (n as u32).clamp(1, 64)
    } else {
        1
    }
}

impl super::Scene {
    /// Turns every circle, ellipse and rectangle into a plain path of its outline, whose
    /// control points are then its parameters ([`Path::outline_primitive`]).
    pub fn outline_primitives(&mut self) {
        self.for_each_path_mut(Path::outline_primitive);
    }
}

impl Path {
    /// A path drawn as `primitive` (no paint), its outline built.
    pub fn from_primitive(id: impl Into<String>, primitive: Primitive) -> Path {
        let mut p = Path::new(id);
        p.primitive = Some(primitive);
        p.sync_primitive();
        p
    }

    /// Rebuilds the outline from [`Path::primitive`] (nothing for a plain path).
    pub fn sync_primitive(&mut self) {
        if let Some(prim) = &self.primitive {
            let (points, sub) = prim.outline();
            self.points = points;
            self.subpaths = vec![sub];
        }
    }

    /// Turns a primitive into a plain path of its outline (its control points become its
    /// parameters); nothing for a plain path.
    pub fn outline_primitive(&mut self) {
        self.primitive = None;
    }

    /// Whether the stroke (if any) is drawn in device space, which a primitive needs.
    pub(crate) fn stroke_in_device_space(&self) -> bool {
        self.stroke
            .as_ref()
            .is_none_or(|s| s.frame == FRAME_IDENTITY)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Scene, Sizing};

    fn primitives_of(svg: &str) -> Vec<Option<Primitive>> {
        let s = Scene::from_svg_str(svg, "t.svg", Sizing::Natural).unwrap();
        let mut out = Vec::new();
        s.for_each_path(|p| out.push(p.primitive.clone()));
        out
    }

    #[test]
    fn shapes_are_read_as_themselves() {
        let got = primitives_of(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="400" height="300">
            <circle cx="50" cy="60" r="20"/>
            <ellipse cx="150" cy="60" rx="30" ry="10" transform="rotate(30 150 60)"/>
            <rect x="10" y="100" width="80" height="40"/>
            <rect x="110" y="100" width="80" height="40" rx="8" ry="5"/>
            <g transform="translate(5 5) scale(2)"><circle cx="100" cy="100" r="10" stroke="red"/></g>
            <circle cx="300" cy="60" r="400"/>
            <path d="M200 200 L250 200 L250 260 Z"/>
            <circle cx="50" cy="250" r="10" transform="skewX(20)"/>
            </svg>"#,
        );
        let shape = |i: usize| got[i].as_ref().map(|p| p.shape.clone());
        assert_eq!(
            shape(0),
            Some(Shape::Circle {
                center: [50.0, 60.0],
                r: 20.0
            })
        );
        let e = got[1].as_ref().unwrap();
        assert!((e.angle - 30f64.to_radians()).abs() < 1e-6, "{e:?}");
        assert!(
            matches!(e.shape, Shape::Ellipse { rx, ry, .. } if (rx - 30.0).abs() < 1e-4 && (ry - 10.0).abs() < 1e-4)
        );
        assert_eq!(
            shape(2),
            Some(Shape::Rect {
                x: 10.0,
                y: 100.0,
                width: 80.0,
                height: 40.0,
                radii: None
            })
        );
        assert_eq!(
            shape(3),
            Some(Shape::Rect {
                x: 110.0,
                y: 100.0,
                width: 80.0,
                height: 40.0,
                radii: Some([8.0, 5.0])
            })
        );
        assert_eq!(
            shape(4),
            Some(Shape::Circle {
                center: [205.0, 205.0],
                r: 20.0
            })
        );
        // A large circle has more arcs per quarter (kurbo's tolerance), kept.
        assert_eq!(got[5].as_ref().unwrap().arcs_per_quarter, 2);
        assert_eq!(shape(6), None, "a triangle is a path");
        // A skewed circle is one in its own frame, its outline mapped (issue 30).
        let skewed = got[7].as_ref().unwrap();
        let k = 20f64.to_radians().tan();
        let Shape::Circle { center, r } = skewed.shape else {
            panic!("{skewed:?}")
        };
        assert!((center[0] - 50.0 - 250.0 * k).abs() < 1e-4 && (center[1] - 250.0).abs() < 1e-4);
        assert!((r - 10.0).abs() < 1e-5, "{r}");
        assert!((skewed.frame[2] - k).abs() < 1e-6, "{:?}", skewed.frame);
    }

    /// `prim.chain` of a linear function of the outline's points against central
    /// differences of every parameter and every entry of the frame.
    fn assert_chain_matches_differences(prim: &Primitive) {
        let n = prim.outline().0.len();
        let a: Vec<f64> = (0..2 * n)
            .map(|i| ((i * 37 % 19) as f64 - 9.0) / 7.0)
            .collect();
        let f = |p: &Primitive| -> f64 {
            let pts = p.outline().0;
            pts.iter()
                .flat_map(|q| [q[0], q[1]])
                .zip(&a)
                .map(|(x, y)| x * y)
                .sum()
        };
        let mut g = vec![0.0; prim.slot_count()];
        let g_frame = prim.chain(&a, &mut g);
        // The change `nudge(q, h)` makes, against `got`.
        let check = |what: String, got: f64, nudge: &dyn Fn(&mut Primitive, f64)| {
            let h = 1e-5;
            let at = |h: f64| {
                let mut q = prim.clone();
                nudge(&mut q, h);
                f(&q)
            };
            let num = (at(h) - at(-h)) / (2.0 * h);
            assert!(
                (num - got).abs() < 1e-6 * (1.0 + num.abs()),
                "{prim:?} {what}: {got} vs {num}"
            );
        };
        for j in 0..prim.slot_count() {
            check(format!("slot {j}"), g[j], &|q, h| {
                let mut k = 0;
                q.walk(0, Part::Point, &mut |_, _, _, v| {
                    if k == j {
                        *v += h;
                    }
                    k += 1;
                });
            });
        }
        for j in 0..4 {
            check(format!("frame {j}"), g_frame[j], &|q, h| q.frame[j] += h);
        }
    }

    #[test]
    fn outline_gradient_chains_to_every_parameter() {
        // A linear function of the outline's points; its gradient through `chain` must
        // match central differences of the parameters.
        for prim in [
            Primitive::circle([10.0, 12.0], 5.0),
            Primitive::ellipse([10.0, 12.0], 5.0, 3.0, 0.4),
            Primitive::rect(3.0, 4.0, 12.0, 7.0, None, -0.3),
            Primitive::rect(3.0, 4.0, 12.0, 7.0, Some([2.0, 1.5]), 0.7),
            Primitive::rect(3.0, 4.0, 12.0, 7.0, Some([2.0, 1.5]), 0.0),
        ] {
            assert_chain_matches_differences(&prim);
        }
    }

    /// Under a frame (a general map's linear part) the outline is the frame's image of
    /// the unframed one about the center, and `chain` gives the parameters' and the
    /// frame's gradients, against central differences.
    #[test]
    fn framed_outlines_chain_to_parameters_and_frame() {
        let frame = [1.1, 0.15, 0.4, 0.75];
        for mut prim in [
            Primitive::circle([10.0, 12.0], 5.0),
            Primitive::ellipse([10.0, 12.0], 5.0, 3.0, 0.4),
            Primitive::rect(3.0, 4.0, 12.0, 7.0, None, 0.0),
            Primitive::rect(3.0, 4.0, 12.0, 7.0, Some([2.0, 1.5]), 0.7),
        ] {
            let plain = prim.outline().0;
            prim.frame = frame;
            let c = prim.center();
            for (q, p) in prim.outline().0.iter().zip(&plain) {
                let v = [p[0] - c[0], p[1] - c[1]];
                let want = [
                    c[0] + frame[0] * v[0] + frame[2] * v[1],
                    c[1] + frame[1] * v[0] + frame[3] * v[1],
                ];
                assert!((q[0] - want[0]).abs() < 1e-12 && (q[1] - want[1]).abs() < 1e-12);
            }
            assert_chain_matches_differences(&prim);
        }
    }

    #[test]
    fn arcs_follow_kurbo() {
        assert_eq!(arcs_per_quarter(1.0), 1);
        assert_eq!(arcs_per_quarter(300.0), 1);
        assert_eq!(arcs_per_quarter(400.0), 2);
    }
}
