//! Group transforms as parameters.
//!
//! A group read from an element with a `transform` (a `<g>`, a `<use>`) keeps that
//! transform as four parameters when it is a **similarity** — a uniform scale, a rotation
//! and a translation, with a positive determinant — relative to the nearest such group
//! above it (or to the canvas): a [`GroupTransform`]. Its children's parameters are then
//! in the group's own frame, so moving, turning or scaling the group moves every child
//! together, and a fit can do that with four numbers.
//!
//! **Storage.** A scene always holds device coordinates: every renderer, the bounds and
//! the checks read them. Only the parameter vector is in local frames:
//! [`Scene::params`](super::Scene::params) maps each transformed group's content back
//! into its frame, and [`Scene::set_params`](super::Scene::set_params) writes local values
//! and maps them forward, innermost group first. So the scene is a function of the
//! parameter vector alone. The backward pass computes gradients of the device values,
//! then `chain_gradient` carries them into the local frames and onto the transforms,
//! outermost group first.
//!
//! **Which groups.** The reader makes one of a group of two or more shapes (one shape has
//! parameters of its own, and usvg puts a shape's own `transform` on a group of its own)
//! whose transform lies in the range a fit keeps it in. The content must be paths with
//! solid paints, undashed strokes drawn in device space, and plain groups (opacity, blend
//! mode, isolation): no clip path, mask, filter, image or gradient paint inside. Those hold device quantities that are not
//! parameters (a gradient's transform, a clip region, a dash pattern) and would need a
//! frame of their own; such a group keeps its transform baked into the points, as every
//! group did before.
//!
//! **Slots**, after the group's opacity: `tx, ty` (device pixels of the parent frame),
//! `angle` (radians, clockwise on screen as [`Primitive::angle`](super::Primitive::angle)),
//! `scale` (> 0), in the group [`ParamGroup::Transform`](super::ParamGroup::Transform).
//! The map is `x ↦ scale · R(angle) · (x − pivot) + pivot + (tx, ty)`, where `pivot` (not
//! a parameter) is the center of the content's bounds in the local frame when the file
//! was read, so that turning or scaling does not also swing the group across the canvas.

use super::geom::{add_scaled, scale};
use super::params::ParamLayout;
use super::shape::Shape;
use super::{Affine, Group, Node, Paint, Path, Point, Role, apply, invert};

/// The least and greatest scale a projected transform keeps.
pub const SCALE_RANGE: [f64; 2] = [1e-3, 1e3];

/// A group's own transform as parameters; see the [module docs](self).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroupTransform {
    /// Translation `(tx, ty)`, pixels of the parent frame.
    pub translate: Point,
    /// Rotation about the pivot, radians, clockwise on screen (y down).
    pub angle: f64,
    /// Uniform scale about the pivot, > 0.
    pub scale: f64,
    /// The fixed point of the rotation and scale, in the group's own frame.
    pub pivot: Point,
}

/// A similarity as it is applied: its matrix, scale and angle.
#[derive(Clone, Copy, Debug)]
struct Map {
    affine: Affine,
    scale: f64,
    angle: f64,
}

impl GroupTransform {
    /// The identity about `pivot`.
    pub fn identity(pivot: Point) -> Self {
        GroupTransform {
            translate: [0.0; 2],
            angle: 0.0,
            scale: 1.0,
            pivot,
        }
    }

    /// The transform that `t` (local frame → parent frame) is, about `pivot`, when it is a
    /// similarity with a positive determinant (to a relative `1e-6`, about `f32`'s precision, in
    /// which usvg composes transforms); `None` otherwise.
    pub fn from_affine(t: &Affine, pivot: Point) -> Option<Self> {
        let [a, b, c, d, e, f] = *t;
        let s = a.hypot(b);
        let similar = (a - d).abs() <= 1e-6 * s && (b + c).abs() <= 1e-6 * s;
        if !(s.is_finite() && s > 0.0 && similar && e.is_finite() && f.is_finite()) {
            return None;
        }
        let angle = b.atan2(a);
        let mut g = GroupTransform {
            translate: [0.0; 2],
            angle,
            scale: s,
            pivot,
        };
        // `A·x + (e, f) = A·(x − pivot) + pivot + translate`.
        let ap = g.linear(pivot);
        g.translate = [e - pivot[0] + ap[0], f - pivot[1] + ap[1]];
        Some(g)
    }

    /// `[cos, sin]` of the angle; exactly `[1, 0]` at 0.
    fn rotation(&self) -> [f64; 2] {
        if self.angle == 0.0 {
            [1.0, 0.0]
        } else {
            let (s, c) = self.angle.sin_cos();
            [c, s]
        }
    }

    /// `scale · R · v`.
    fn linear(&self, v: Point) -> Point {
        let [c, s] = self.rotation();
        let k = self.scale;
        [k * (c * v[0] - s * v[1]), k * (s * v[0] + c * v[1])]
    }

    /// The matrix (local → parent), as SVG's `matrix(a b c d e f)`.
    pub fn affine(&self) -> Affine {
        let [c, s] = self.rotation();
        let k = self.scale;
        let lp = self.linear(self.pivot);
        [
            k * c,
            k * s,
            -k * s,
            k * c,
            self.pivot[0] + self.translate[0] - lp[0],
            self.pivot[1] + self.translate[1] - lp[1],
        ]
    }

    fn forward(&self) -> Map {
        Map {
            affine: self.affine(),
            scale: self.scale,
            angle: self.angle,
        }
    }

    fn inverse(&self) -> Map {
        Map {
            affine: invert(&self.affine()).unwrap_or(super::IDENTITY),
            scale: 1.0 / self.scale,
            angle: -self.angle,
        }
    }

    /// The slots' values in order: `tx, ty, angle, scale`.
    pub(crate) fn slots_mut(&mut self) -> [&mut f64; 4] {
        let [tx, ty] = &mut self.translate;
        [tx, ty, &mut self.angle, &mut self.scale]
    }

    /// Clamps into the valid range: translation within ±`MAX_COORDINATE`/8, the angle
    /// finite, the scale in [`SCALE_RANGE`]; NaN becomes 0 (the scale 1).
    pub(crate) fn project(&mut self) {
        const BOUND: f64 = crate::limits::MAX_COORDINATE / 8.0;
        for v in &mut self.translate {
            super::params::clamp_coordinate(v, BOUND);
        }
        if !self.angle.is_finite() {
            self.angle = 0.0;
        }
        self.scale = if self.scale.is_nan() {
            1.0
        } else {
            self.scale.clamp(SCALE_RANGE[0], SCALE_RANGE[1])
        };
    }
}

/// Whether a group's content can live in a frame of its own (module docs).
pub(crate) fn movable(nodes: &[Node]) -> bool {
    nodes.iter().all(|n| match n {
        Node::Group(g) => {
            g.clip.is_none() && g.mask.is_none() && g.filters.is_empty() && movable(&g.children)
        }
        Node::Path(p) => {
            let solid = |paint: &Paint| matches!(paint, Paint::Solid(_));
            p.fill.as_ref().is_none_or(|f| solid(&f.paint))
                && p.stroke.as_ref().is_none_or(|s| {
                    solid(&s.paint) && s.dash.is_none() && s.frame == super::FRAME_IDENTITY
                })
        }
    })
}

/// Applies `m` to every geometric quantity under `nodes` (points, primitives, stroke
/// widths), not to the nested groups' own transforms, which are relative.
fn map_nodes(nodes: &mut [Node], m: &Map) {
    for n in nodes {
        match n {
            Node::Group(g) => map_nodes(&mut g.children, m),
            Node::Path(p) => map_path(p, m),
        }
    }
}

fn map_path(p: &mut Path, m: &Map) {
    if let Some(prim) = &mut p.primitive {
        let c = apply(&m.affine, prim.center());
        prim.scale(m.scale);
        let now = prim.center();
        prim.translate([c[0] - now[0], c[1] - now[1]]);
        // A circle's angle only places its outline's start.
        if !matches!(prim.shape, Shape::Circle { .. }) {
            prim.angle += m.angle;
        }
        p.sync_primitive();
    } else {
        for q in &mut p.points {
            *q = apply(&m.affine, *q);
        }
    }
    if let Some(s) = &mut p.stroke {
        s.width *= m.scale;
    }
}

/// Maps every transformed group's content from device space into its own frame,
/// outermost first: afterwards each value is what [`Scene::params`](super::Scene::params)
/// reports.
pub(crate) fn localize(nodes: &mut [Node]) {
    for n in nodes {
        if let Node::Group(g) = n {
            if let Some(t) = &g.transform {
                map_nodes(&mut g.children, &t.inverse());
            }
            localize_layer(g);
        }
    }
}

fn localize_layer(g: &mut Group) {
    localize(&mut g.children);
    if let Some(c) = &mut g.clip {
        localize_layer(&mut c.content);
    }
    if let Some(m) = &mut g.mask {
        localize_layer(&mut m.content);
    }
}

/// The inverse of [`localize`]: maps local values to device space, innermost group
/// first. Each transform is projected first ([`GroupTransform::project`]).
pub(crate) fn globalize(nodes: &mut [Node]) {
    for n in nodes {
        if let Node::Group(g) = n {
            globalize_layer(g);
            if let Some(t) = &mut g.transform {
                t.project();
                map_nodes(&mut g.children, &t.forward());
            }
        }
    }
}

fn globalize_layer(g: &mut Group) {
    globalize(&mut g.children);
    if let Some(c) = &mut g.clip {
        globalize_layer(&mut c.content);
    }
    if let Some(m) = &mut g.mask {
        globalize_layer(&mut m.content);
    }
}

/// Maps the outermost transforms under `nodes` by `x ↦ k·x + d` (`k > 0`) in device
/// pixels, when the caller maps the device values of their content the same way
/// ([`Scene::scale_to`](super::Scene::scale_to), a pattern's tiles); nested transforms are
/// relative and stay.
pub(crate) fn map_outermost(nodes: &mut [Node], k: f64, d: Point) {
    for n in nodes {
        if let Node::Group(g) = n {
            match &mut g.transform {
                Some(t) => {
                    // `k·(S·R·(x − p) + p + t) + d = k·S·R·(x − p) + p + (k·(p + t) + d − p)`.
                    for i in 0..2 {
                        t.translate[i] = k * (t.pivot[i] + t.translate[i]) + d[i] - t.pivot[i];
                    }
                    t.scale *= k;
                }
                None => {
                    map_outermost(&mut g.children, k, d);
                    if let Some(c) = &mut g.clip {
                        map_outermost(&mut c.content.children, k, d);
                    }
                    if let Some(m) = &mut g.mask {
                        map_outermost(&mut m.content.children, k, d);
                    }
                }
            }
        }
    }
}

/// Per transform, in walk order (as [`ParamLayout::transforms`]): how far its content
/// reaches from its pivot, device pixels (0 for empty content), and its scale. A fit
/// divides the rates of the angle and the scale by it, so that every rate is a motion at
/// the content's edge in pixels.
pub(crate) fn reaches(nodes: &[Node]) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    reach_nodes(nodes, &mut out);
    out
}

fn reach_nodes(nodes: &[Node], out: &mut Vec<(f64, f64)>) {
    for n in nodes {
        if let Node::Group(g) = n {
            reach_group(g, out);
        }
    }
}

fn reach_group(g: &Group, out: &mut Vec<(f64, f64)>) {
    if let Some(t) = &g.transform {
        // Half the diagonal of the content's device bounds.
        let mut b: Option<[f64; 4]> = None;
        super::paths_of(&g.children, Role::Paint, &mut |p, _| {
            if let Some(r) = p.control_bounds() {
                b = Some(b.map_or(r, |o| {
                    [
                        o[0].min(r[0]),
                        o[1].min(r[1]),
                        o[2].max(r[2]),
                        o[3].max(r[3]),
                    ]
                }));
            }
        });
        let reach = b.map_or(0.0, |r| 0.5 * (r[2] - r[0]).hypot(r[3] - r[1]));
        out.push((reach, t.scale));
    }
    reach_nodes(&g.children, out);
    if let Some(c) = &g.clip {
        reach_group(&c.content, out);
    }
    if let Some(m) = &g.mask {
        reach_group(&m.content, out);
    }
}

/// Whether any group under `nodes` has a transform parameter.
pub(crate) fn any(nodes: &[Node]) -> bool {
    nodes.iter().any(|n| match n {
        Node::Group(g) => {
            g.transform.is_some()
                || any(&g.children)
                || g.clip.as_ref().is_some_and(|c| any(&c.content.children))
                || g.mask.as_ref().is_some_and(|m| any(&m.content.children))
        }
        Node::Path(_) => false,
    })
}

/// Carries a gradient of the device values (in [`Scene::params`](super::Scene::params)
/// order, as the raster backward pass computes it, the transform slots 0) into the local
/// frames and onto the transforms, outermost group first. Nothing for a scene without
/// transform parameters.
pub(crate) fn chain_gradient(scene: &super::Scene, grad: &mut [f64]) {
    if !any(&scene.nodes) {
        return;
    }
    let layout = ParamLayout::new(scene);
    let mut nodes = scene.nodes.clone();
    let mut c = Chain {
        layout: &layout,
        grad,
        path_ix: 0,
        transform_ix: 0,
    };
    c.nodes(&mut nodes);
}

struct Chain<'a> {
    layout: &'a ParamLayout,
    grad: &'a mut [f64],
    path_ix: usize,
    transform_ix: usize,
}

impl Chain<'_> {
    /// In the walk's order (children, clip content, mask content), so the path and
    /// transform counters match the layout's.
    fn nodes(&mut self, nodes: &mut [Node]) {
        for n in nodes {
            match n {
                Node::Path(_) => self.path_ix += 1,
                Node::Group(g) => self.group(g),
            }
        }
    }

    fn group(&mut self, g: &mut Group) {
        if let Some(t) = g.transform {
            let base = self.layout.transforms[self.transform_ix];
            self.transform_ix += 1;
            // The content in this group's frame (its ancestors' frames are already
            // undone): the values the local gradient is taken at.
            map_nodes(&mut g.children, &t.inverse());
            let mut acc = [0.0; 4];
            let mut k = self.path_ix;
            super::paths_of(&g.children, Role::Paint, &mut |p, _| {
                chain_path(p, &self.layout.paths[k], &t, self.grad, &mut acc);
                k += 1;
            });
            for (i, v) in acc.iter().enumerate() {
                self.grad[base + i] += v;
            }
        }
        self.nodes(&mut g.children);
        if let Some(c) = &mut g.clip {
            self.group(&mut c.content);
        }
        if let Some(m) = &mut g.mask {
            self.group(&mut m.content);
        }
    }
}

/// One path's share: `acc` gets `∂L/∂(tx, ty, angle, scale)`, and the path's slots in
/// `grad` are turned from device into local gradients. `p` holds local values.
fn chain_path(
    p: &Path,
    off: &super::params::PathOffsets,
    t: &GroupTransform,
    grad: &mut [f64],
    acc: &mut [f64; 4],
) {
    let [c, s] = t.rotation();
    let k = t.scale;
    // `R·v`, `R′·v` (the derivative in the angle) and `Rᵀ·g`.
    let rot = |v: Point| [c * v[0] - s * v[1], s * v[0] + c * v[1]];
    let drot = |v: Point| [-s * v[0] - c * v[1], c * v[0] - s * v[1]];
    let rot_t = |g: Point| [c * g[0] + s * g[1], -s * g[0] + c * g[1]];
    let dot = |a: Point, b: Point| a[0] * b[0] + a[1] * b[1];
    // A position `v` mapped to `k·R·(v − pivot) + pivot + t`, with gradient `g` there.
    let position = |v: Point, g: Point, acc: &mut [f64; 4]| -> Point {
        let r = [v[0] - t.pivot[0], v[1] - t.pivot[1]];
        acc[0] += g[0];
        acc[1] += g[1];
        acc[2] += k * dot(drot(r), g);
        acc[3] += dot(rot(r), g);
        scale(rot_t(g), k)
    };
    if let Some(prim) = &p.primitive {
        let at = off.points;
        let g_pos = [grad[at], grad[at + 1]];
        let center = prim.center();
        let corner = [grad[at], grad[at + 1]];
        let local_pos = position(center, g_pos, acc);
        // A rectangle's corner is its center less half its sides, both mapped.
        let half = match prim.shape {
            Shape::Rect { width, height, .. } => [0.5 * width, 0.5 * height],
            _ => [0.0; 2],
        };
        acc[3] -= dot(half, corner);
        grad[at] = local_pos[0];
        grad[at + 1] = local_pos[1];
        let sizes = prim.size_slots();
        let values = prim.size_values();
        for (j, v) in sizes.clone().zip(values) {
            acc[3] += v * grad[at + j];
            grad[at + j] *= k;
        }
        if let Shape::Rect { .. } = prim.shape {
            // The sides also move the mapped corner: `k·(R − I)·½` per side.
            let d = add_scaled(rot_t(corner), corner, -1.0);
            grad[at + sizes.start] += 0.5 * k * d[0];
            grad[at + sizes.start + 1] += 0.5 * k * d[1];
        }
        if prim.slot_count() > sizes.end {
            // The angle adds.
            acc[2] += grad[at + prim.slot_count() - 1];
        }
    } else {
        for (i, q) in p.points.iter().enumerate() {
            let at = off.points + 2 * i;
            let l = position(*q, [grad[at], grad[at + 1]], acc);
            grad[at] = l[0];
            grad[at + 1] = l[1];
        }
    }
    if let Some(st) = &p.stroke {
        let at = off.stroke_width;
        acc[3] += st.width * grad[at];
        grad[at] *= k;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{ParamGroup, Scene, Sizing};

    /// Nested transformed groups (a path, a stroke, a rounded rectangle, an ellipse, a
    /// stroked circle) and a skewed group, which stays baked.
    pub(crate) const NESTED: &str = r##"<svg xmlns="http://www.w3.org/2000/svg" width="80" height="60">
      <g id="outer" transform="translate(6 4) rotate(12 40 30)">
        <path id="blob" d="M10 10 C30 0 40 20 30 30 Q20 40 10 30 Z" fill="#3366aa"
              stroke="#112244" stroke-width="2"/>
        <g id="inner" transform="translate(40 20) scale(0.8) rotate(-20)">
          <rect id="r" x="0" y="0" width="20" height="12" rx="3" fill="#cc4422"/>
          <ellipse id="e" cx="10" cy="24" rx="8" ry="4" fill="#22aa66"/>
          <circle id="c" cx="26" cy="20" r="5" fill="#eeaa00" stroke="#553300"
                  stroke-width="1.5"/>
        </g>
      </g>
      <g id="kept" transform="skewX(20)"><path d="M5 50 L20 50 L15 58 Z" fill="#777"/></g>
    </svg>"##;

    /// Every outline point but a circle's, whose outline starts at the same place however
    /// it is turned; its center instead.
    fn device_points(s: &Scene) -> Vec<Point> {
        let mut out = Vec::new();
        s.for_each_path(|p| match &p.primitive {
            Some(q) if matches!(q.shape, Shape::Circle { .. }) => out.push(q.center()),
            _ => out.extend(p.points.iter().copied()),
        });
        out
    }

    fn close(a: &[Point], b: &[Point], tol: f64) -> bool {
        a.len() == b.len()
            && a.iter()
                .zip(b)
                .all(|(p, q)| (p[0] - q[0]).abs() <= tol && (p[1] - q[1]).abs() <= tol)
    }

    #[test]
    fn transformed_groups_are_read_as_parameters() {
        let s = Scene::from_svg_str(NESTED, "n.svg", Sizing::Natural).unwrap();
        let Node::Group(outer) = &s.nodes[0] else {
            panic!("{:?}", s.nodes[0])
        };
        assert!(!outer.layer && outer.transform.is_some());
        let t = outer.transform.unwrap();
        assert!((t.angle - 12f64.to_radians()).abs() < 1e-6 && (t.scale - 1.0).abs() < 1e-6);
        let Node::Group(inner) = &outer.children[1] else {
            panic!()
        };
        // Relative to the outer group's frame.
        let t = inner.transform.unwrap();
        assert!((t.angle + 20f64.to_radians()).abs() < 1e-6, "{t:?}");
        assert!((t.scale - 0.8).abs() < 1e-6, "{t:?}");
        // The skewed group is baked: its path sits at the top level.
        assert!(matches!(s.nodes[1], Node::Path(_)), "{:?}", s.nodes[1]);
        let layout = ParamLayout::new(&s);
        assert_eq!(layout.transforms.len(), 2);
        // No opacity slots: neither group is a layer.
        assert!(layout.groups.is_empty());
        for &at in &layout.transforms {
            assert!((at..at + 4).all(|i| layout.slots[i].group == ParamGroup::Transform));
        }
        // The inner rectangle's parameters are in the inner frame: as written.
        let v = s.params();
        let r = layout.paths[1].points;
        for (got, want) in v[r..r + 4].iter().zip([0.0, 0.0, 20.0, 12.0]) {
            assert!((got - want).abs() < 1e-4, "{:?}", &v[r..r + 4]);
        }
    }

    #[test]
    fn set_params_is_the_inverse_of_params() {
        let s = Scene::from_svg_str(NESTED, "n.svg", Sizing::Natural).unwrap();
        let mut moved = s.clone();
        moved.set_params(&s.params());
        assert!(close(&device_points(&s), &device_points(&moved), 1e-9));
        // Turning the outer group turns everything in it about its pivot.
        let layout = ParamLayout::new(&s);
        let mut v = s.params();
        v[layout.transforms[0] + 2] += 0.3;
        moved.set_params(&v);
        let Node::Group(g) = &s.nodes[0] else {
            panic!()
        };
        let t = g.transform.unwrap();
        let pivot = apply(&t.affine(), t.pivot);
        let turn = GroupTransform {
            translate: [0.0; 2],
            angle: 0.3,
            scale: 1.0,
            pivot,
        };
        let (before, after) = (device_points(&s), device_points(&moved));
        // The baked triangle, last, does not move.
        let Node::Path(tri) = &s.nodes[1] else {
            panic!()
        };
        let n = before.len() - tri.points.len();
        let want: Vec<Point> = before[..n]
            .iter()
            .map(|&p| apply(&turn.affine(), p))
            .collect();
        assert!(close(&after[..n], &want, 1e-6));
        assert!(close(&after[n..], &before[n..], 0.0));
        // Written and read back: the same device geometry and the same transforms.
        let back = Scene::from_svg_str(&moved.to_svg_string(), "b.svg", Sizing::Natural).unwrap();
        assert_eq!(ParamLayout::new(&back).transforms.len(), 2);
        assert!(close(&device_points(&back), &after, 2e-3));
        let (a, b) = (moved.params(), back.params());
        assert!(
            a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 2e-3),
            "{a:?}\n{b:?}"
        );
    }

    #[test]
    fn transforms_outside_the_fitted_range_stay_baked() {
        for t in ["scale(1e-5)", "scale(5000)", "translate(5e29 0)"] {
            let svg = format!(
                r#"<svg xmlns="http://www.w3.org/2000/svg" width="20" height="20">
                <g transform="{t}"><rect width="4" height="4"/><rect x="5" width="4" height="4"/>
                </g></svg>"#
            );
            let s = Scene::from_svg_str(&svg, "t.svg", Sizing::Natural).unwrap();
            assert!(ParamLayout::new(&s).transforms.is_empty(), "{t}");
        }
    }

    #[test]
    fn scaling_the_scene_scales_the_outermost_transform() {
        let s = Scene::from_svg_str(NESTED, "n.svg", Sizing::Natural).unwrap();
        let mut big = s.clone();
        big.scale_to(2.0, 160, 120);
        let want: Vec<Point> = device_points(&s).iter().map(|p| scale(*p, 2.0)).collect();
        assert!(close(&device_points(&big), &want, 1e-9));
        // The parameters still describe the scaled scene.
        let mut again = big.clone();
        again.set_params(&big.params());
        assert!(close(&device_points(&again), &want, 1e-9));
    }

    #[test]
    fn from_affine_round_trips_and_refuses_non_similarities() {
        let t = GroupTransform {
            translate: [3.0, -2.0],
            angle: 0.7,
            scale: 1.5,
            pivot: [10.0, 20.0],
        };
        let back = GroupTransform::from_affine(&t.affine(), t.pivot).unwrap();
        for (a, b) in [
            (back.translate[0], 3.0),
            (back.translate[1], -2.0),
            (back.angle, 0.7),
            (back.scale, 1.5),
        ] {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
        // The pivot is fixed by the rotation and scale: it moves by the translation only.
        let p = apply(&t.affine(), t.pivot);
        assert!((p[0] - 13.0).abs() < 1e-12 && (p[1] - 18.0).abs() < 1e-12);
        let skew = [1.0, 0.0, 0.5, 1.0, 0.0, 0.0];
        let mirror = [-1.0, 0.0, 0.0, 1.0, 0.0, 0.0];
        let stretch = [2.0, 0.0, 0.0, 1.0, 0.0, 0.0];
        for m in [skew, mirror, stretch] {
            assert!(GroupTransform::from_affine(&m, [0.0; 2]).is_none(), "{m:?}");
        }
    }
}
