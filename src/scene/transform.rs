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
//! **Which groups.** The reader makes one of a group of one or more shapes whose
//! transform lies in the range a fit keeps it in ([`SCALE_RANGE`], docs/limits.md). A
//! shape's own `transform` (`<rect transform="…">`) is such a group too: usvg puts it on a
//! group of its own, with no id, around the shape, and SVG out writes that group's
//! transform back on the shape. One exception: a circle, ellipse or rectangle turned
//! about its own center (by a rotation alone) keeps that turn as its angle slot
//! ([`shape`](super::shape)), which is how SVG out writes a primitive's angle. A single
//! shape's transform repeats motions its own parameters can make (its points; a
//! primitive's center, sizes and angle), so a fit moves both (README: the effect on
//! `svg-samples/09-transforms.svg`). The group's content must be plain groups (opacity,
//! blend mode, isolation) and paths: no clip path,
//! mask, filter, image, pattern or text inside, which hold device quantities that are no
//! parameters (a clip region, a pattern's tiles) and would need a frame of their own. A
//! group that does not qualify keeps its transform baked into the points, as every group
//! did before. Two kinds:
//!
//! * a **similarity** (a uniform scale, a rotation and a translation, positive
//!   determinant) over paths with solid or gradient paints and undashed strokes drawn in
//!   device space (under a similarity a stroke of the mapped path is the mapped stroke),
//!   circles, ellipses and rectangles included: four slots;
//! * any other invertible map (a skew, a non-uniform scale, a mirror) as a **general
//!   affine** one, over paths with solid or gradient paints, filled or stroked (dashed
//!   too), circles, ellipses and rectangles included: six slots. A stroke under such a
//!   map is drawn as SVG draws it: built
//!   in the local frame, where its pen is round, and mapped, so its pen is an ellipse on
//!   the canvas. Its [`frame`](super::Stroke::frame) takes the map's linear part (its
//!   width and dashes stay, in the frame's units), and the backward pass reports the
//!   gradient of every stroke frame, which `chain_gradient` carries onto the slots
//!   (`∂L/∂L = ∂L/∂F · Fₗᵀ` for the device frame `F = L·Fₗ`) and into the frame of a
//!   nested map. A circle, ellipse or rectangle (rounded too) keeps its own parameters
//!   in the local frame the same way: the affine image of its outline is no such shape on
//!   the canvas, so its [`frame`](super::Primitive::frame) takes the map's linear part
//!   (every outline point `center + F·R(angle)·o`, the center mapped, the sizes and angle
//!   in the frame's units), the backward pass reports the frame's gradient (keyed by the
//!   primitive's first slot) and `chain_gradient` carries it as a stroke frame's. A
//!   primitive's own general transform (`<ellipse transform="skewX(20)">`) is such a
//!   group of one shape; one turned about its own center inside a general map keeps that
//!   turn as its angle, as under a similarity.
//!
//! **Gradient paints** inside either kind: the paint's transform (gradient space →
//! device) is held in the local frame and mapped forward with the content, as points are;
//! its geometry and stops, in gradient space, are parameters as anywhere else. A change
//! `T → T·(1 + h·G)` of the group's map is the change `M → M·(1 + h·E)`, `E = M⁻¹·G·M`,
//! of the paint's. A linear gradient's `t` is an affine function of the point, which its
//! end points can follow exactly: the geometry's gradient is carried onto the group's
//! slots. A radial one's circles follow no change of geometry unless `E` is a similarity,
//! so the backward pass reports `Σ ∂L/∂q ⊗ (q, 1)` over the paint's pixels (`q` the
//! point in gradient space, which the change moves by `−h·E·q`), and its slots get
//! `−⟨Σ, E⟩`: under either kind of map, whatever `M` (an `objectBoundingBox` gradient's
//! ellipses included).
//!
//! **Slots**, after the group's opacity, in the group
//! [`ParamGroup::Transform`](super::ParamGroup::Transform):
//!
//! * similarity: `tx, ty` (device pixels of the parent frame), `angle` (radians,
//!   clockwise on screen as [`Primitive::angle`](super::Primitive::angle)), `scale` (> 0).
//!   The map is `x ↦ scale · R(angle) · (x − pivot) + pivot + (tx, ty)`;
//! * general affine: `tx, ty` (as above), then the linear part `a, b, c, d` (unitless,
//!   SVG's `matrix(a b c d e f)` order: `L·v = (a·vx + c·vy, b·vx + d·vy)`); the map is
//!   `x ↦ L · (x − pivot) + pivot + (tx, ty)` ([`GroupTransform::linear`]).
//!
//! `pivot` (not a parameter) is the center of the content's bounds in the local frame
//! when the file was read, so that turning or scaling does not also swing the group
//! across the canvas. A stroke or primitive drawn in its group's frame has the identity
//! frame there (snapped to it when `f32` leaves it off by less than 1e-6), so it is
//! written plainly inside the group (a primitive as its `<circle>`, `<ellipse>` or
//! `<rect>`; one left in device space with a frame, its group baked, is a path). SVG out writes either kind as `transform="matrix(…)"` (`f32`, as
//! it is read), on the `<g>` or, for a shape's own transform, on the shape's element
//! (when the shape writes no transform of its own: no turned primitive, no stroke
//! frame), so a written file reads back to the same kinds and slots.

use super::geom::{add_scaled, scale};
use super::params::ParamLayout;
use super::shape::Shape;
use super::{Affine, GradientKind, Group, Node, Paint, Path, Point, Role, apply, concat, invert};

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
    /// A general affine transform's linear part `[a, b, c, d]` (SVG's `matrix` order:
    /// `x ↦ (a·x + c·y, b·x + d·y)`) about the pivot; then `angle` is 0 and `scale` 1, and
    /// neither is a slot (module docs).
    pub linear: Option<[f64; 4]>,
}

/// A map as it is applied: its matrix, scale and angle (a similarity's), and whether it
/// is a general affine one, which maps stroke frames rather than widths.
#[derive(Clone, Copy, Debug)]
struct Map {
    affine: Affine,
    scale: f64,
    angle: f64,
    general: bool,
}

impl GroupTransform {
    /// The identity about `pivot`.
    pub fn identity(pivot: Point) -> Self {
        GroupTransform {
            translate: [0.0; 2],
            angle: 0.0,
            scale: 1.0,
            pivot,
            linear: None,
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
            linear: None,
        };
        // `A·x + (e, f) = A·(x − pivot) + pivot + translate`.
        let ap = g.apply_linear(pivot);
        g.translate = [e - pivot[0] + ap[0], f - pivot[1] + ap[1]];
        Some(g)
    }

    /// `t` (local frame → parent frame) as a general affine transform about `pivot`
    /// ([`linear`](GroupTransform::linear) set), when it is invertible and finite; `None` otherwise.
    pub fn from_affine_general(t: &Affine, pivot: Point) -> Option<Self> {
        let [a, b, c, d, e, f] = *t;
        let det = a * d - b * c;
        if !(t.iter().all(|v| v.is_finite()) && det != 0.0 && det.is_finite()) {
            return None;
        }
        let mut g = GroupTransform {
            linear: Some([a, b, c, d]),
            ..GroupTransform::identity(pivot)
        };
        let ap = g.apply_linear(pivot);
        g.translate = [e - pivot[0] + ap[0], f - pivot[1] + ap[1]];
        Some(g)
    }

    /// The number of slots: 4 for a similarity, 6 for a general affine transform.
    pub fn slot_count(&self) -> usize {
        if self.linear.is_some() { 6 } else { 4 }
    }

    /// The linear part's `√|det|`: the scale of a similarity, a general map's mean scale.
    pub fn mean_scale(&self) -> f64 {
        match self.linear {
            Some([a, b, c, d]) => (a * d - b * c).abs().sqrt(),
            None => self.scale,
        }
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

    /// `scale · R · v`, or the general linear part applied to `v`.
    fn apply_linear(&self, v: Point) -> Point {
        if let Some([a, b, c, d]) = self.linear {
            return [a * v[0] + c * v[1], b * v[0] + d * v[1]];
        }
        let [c, s] = self.rotation();
        let k = self.scale;
        [k * (c * v[0] - s * v[1]), k * (s * v[0] + c * v[1])]
    }

    /// The matrix (local → parent), as SVG's `matrix(a b c d e f)`.
    pub fn affine(&self) -> Affine {
        let [a, b, c, d] = self.linear_part();
        let lp = self.apply_linear(self.pivot);
        [
            a,
            b,
            c,
            d,
            self.pivot[0] + self.translate[0] - lp[0],
            self.pivot[1] + self.translate[1] - lp[1],
        ]
    }

    /// The linear part `[a, b, c, d]`, either kind.
    fn linear_part(&self) -> [f64; 4] {
        match self.linear {
            Some(l) => l,
            None => {
                let [c, s] = self.rotation();
                let k = self.scale;
                [k * c, k * s, -k * s, k * c]
            }
        }
    }

    /// (A general map's `scale` and `angle` are those of no similarity: its strokes' and
    /// primitives' frames take its linear part instead.)
    fn forward(&self) -> Map {
        Map {
            affine: self.affine(),
            scale: self.mean_scale(),
            angle: self.angle,
            general: self.linear.is_some(),
        }
    }

    fn inverse(&self) -> Map {
        Map {
            affine: invert(&self.affine()).unwrap_or(super::IDENTITY),
            scale: 1.0 / self.mean_scale(),
            angle: -self.angle,
            general: self.linear.is_some(),
        }
    }

    /// Per slot, the derivative of the linear part `[a, b, c, d]` (SVG order) in it: 0 for
    /// the translation's two.
    fn linear_derivatives(&self) -> Vec<[f64; 4]> {
        let mut d_a: Vec<[f64; 4]> = vec![[0.0; 4]; 2];
        match self.linear {
            Some(_) => {
                for i in 0..4 {
                    let mut u = [0.0; 4];
                    u[i] = 1.0;
                    d_a.push(u);
                }
            }
            None => {
                let [c, s] = self.rotation();
                let k = self.scale;
                d_a.push([-k * s, k * c, -k * c, -k * s]);
                d_a.push([c, s, -s, c]);
            }
        }
        d_a
    }

    /// The slots' values in order: `tx, ty, angle, scale`, or `tx, ty, a, b, c, d`.
    pub(crate) fn slots_mut(&mut self) -> Vec<&mut f64> {
        let [tx, ty] = &mut self.translate;
        match &mut self.linear {
            Some([a, b, c, d]) => vec![tx, ty, a, b, c, d],
            None => vec![tx, ty, &mut self.angle, &mut self.scale],
        }
    }

    /// Clamps into the valid range: translation within ±`MAX_COORDINATE`/8, the angle
    /// finite, the scale in [`SCALE_RANGE`]; NaN becomes 0 (the scale 1). A general
    /// linear part: each entry within ±`SCALE_RANGE[1]` (NaN: the identity's), and one
    /// whose `|det|` falls below `SCALE_RANGE[0]²` (near singular) becomes
    /// `SCALE_RANGE[0]` times the identity.
    pub(crate) fn project(&mut self) {
        const BOUND: f64 = crate::limits::MAX_COORDINATE / 8.0;
        for v in &mut self.translate {
            super::params::clamp_coordinate(v, BOUND);
        }
        if let Some(l) = &mut self.linear {
            for (i, v) in l.iter_mut().enumerate() {
                let id = if i == 0 || i == 3 { 1.0 } else { 0.0 };
                *v = if v.is_nan() {
                    id
                } else {
                    v.clamp(-SCALE_RANGE[1], SCALE_RANGE[1])
                };
            }
            let det = l[0] * l[3] - l[1] * l[2];
            if !(det.abs() >= SCALE_RANGE[0] * SCALE_RANGE[0]) {
                *l = [SCALE_RANGE[0], 0.0, 0.0, SCALE_RANGE[0]];
            }
            return;
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

/// Whether a group's content can live in a frame of its own (module docs): under a
/// similarity, or under a general affine transform when `general`.
pub(crate) fn movable(nodes: &[Node], general: bool) -> bool {
    nodes.iter().all(|n| match n {
        Node::Group(g) => {
            g.clip.is_none()
                && g.mask.is_none()
                && g.filters.is_empty()
                && g.tiling.is_none()
                && movable(&g.children, general)
        }
        Node::Path(p) => {
            let paint_ok = |paint: &Paint| match paint {
                Paint::Solid(_) => true,
                // A radial gradient's transform gets its gradient from the backward pass
                // (`chain_gradient`), whatever the map.
                Paint::Gradient(_) => true,
                Paint::Image(_) => false,
            };
            p.fill.as_ref().is_none_or(|f| paint_ok(&f.paint))
                && if general {
                    // A stroke's frame takes the map (its pen, round in the local frame,
                    // an ellipse on the canvas), dashes included; so does a primitive's.
                    p.stroke.as_ref().is_none_or(|s| paint_ok(&s.paint))
                } else {
                    p.stroke.as_ref().is_none_or(|s| {
                        paint_ok(&s.paint) && s.dash.is_none() && s.frame == super::FRAME_IDENTITY
                    }) && p
                        .primitive
                        .as_ref()
                        .is_none_or(|q| q.frame == super::FRAME_IDENTITY)
                }
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
        if m.general || prim.frame != super::FRAME_IDENTITY {
            // The outline is the map's image: the frame takes its linear part, the
            // sizes and angle stay (in the frame's units).
            let l = [m.affine[0], m.affine[1], m.affine[2], m.affine[3]];
            prim.frame = lin_mul(l, prim.frame);
        } else {
            prim.scale(m.scale);
            // A circle's angle only places its outline's start.
            if !matches!(prim.shape, Shape::Circle { .. }) {
                prim.angle += m.angle;
            }
        }
        let now = prim.center();
        prim.translate([c[0] - now[0], c[1] - now[1]]);
        p.sync_primitive();
    } else {
        for q in &mut p.points {
            *q = apply(&m.affine, *q);
        }
    }
    if let Some(s) = &mut p.stroke {
        if m.general {
            // The pen is round in the stroke's frame, which rides with the content (its
            // width and dashes are in that frame's units).
            let l = [m.affine[0], m.affine[1], m.affine[2], m.affine[3]];
            s.frame = lin_mul(l, s.frame);
        } else {
            s.width *= m.scale;
        }
    }
    // A gradient's own space rides with the content: its geometry (in that space) stays.
    let paints = [
        p.fill.as_mut().map(|f| &mut f.paint),
        p.stroke.as_mut().map(|s| &mut s.paint),
    ];
    for paint in paints.into_iter().flatten() {
        if let Paint::Gradient(g) = paint {
            g.transform = concat(&m.affine, &g.transform);
        }
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
                snap_frames(&mut g.children);
            }
            localize_layer(g);
        }
    }
}

/// Sets every stroke frame under `nodes` that is the identity to `f32`'s precision (a
/// stroke drawn in its group's frame, the group's map read in `f32` as the frame was) to
/// exactly the identity, so that the local stroke is written as it was read.
fn snap_frames(nodes: &mut [Node]) {
    let near = |f: &[f64; 4]| {
        f.iter()
            .zip(super::FRAME_IDENTITY)
            .all(|(a, b)| (a - b).abs() <= 1e-6)
    };
    super::paths_of_mut(nodes, &mut |p| {
        if let Some(s) = &mut p.stroke
            && near(&s.frame)
        {
            s.frame = super::FRAME_IDENTITY;
        }
        // A primitive's too (its outline then rebuilt from its own parameters).
        if let Some(q) = &mut p.primitive
            && q.frame != super::FRAME_IDENTITY
            && near(&q.frame)
        {
            q.frame = super::FRAME_IDENTITY;
            p.sync_primitive();
        }
    });
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
                    match &mut t.linear {
                        Some(l) => l.iter_mut().for_each(|v| *v *= k),
                        None => t.scale *= k,
                    }
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
/// reaches from its pivot, device pixels (0 for empty content), its scale
/// ([`GroupTransform::mean_scale`]) and its slot count. A fit
/// divides the rates of the angle and the scale by it, so that every rate is a motion at
/// the content's edge in pixels.
pub(crate) fn reaches(nodes: &[Node]) -> Vec<(f64, f64, usize)> {
    let mut out = Vec::new();
    reach_nodes(nodes, &mut out);
    out
}

fn reach_nodes(nodes: &[Node], out: &mut Vec<(f64, f64, usize)>) {
    for n in nodes {
        if let Node::Group(g) = n {
            reach_group(g, out);
        }
    }
}

fn reach_group(g: &Group, out: &mut Vec<(f64, f64, usize)>) {
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
        out.push((reach, t.mean_scale(), t.slot_count()));
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
/// frames and onto the transforms, outermost group first. `frames` holds what the
/// backward pass computes beside: the gradient of stroke frames (`∂L/∂[a, b, c, d]` of
/// [`Stroke::frame`](super::Stroke::frame), device frame, then two zeros) keyed by the
/// stroke's width slot, which a general map's strokes carry onto its slots; and a radial
/// gradient paint's `Σ ∂L/∂q ⊗ (q, 1)` (`q` in gradient space) keyed by its first slot,
/// which gives the gradient of its transform. Nothing for a scene without transform
/// parameters.
pub(crate) fn chain_gradient(scene: &super::Scene, grad: &mut [f64], frames: &[(usize, [f64; 6])]) {
    if !any(&scene.nodes) {
        return;
    }
    let layout = ParamLayout::new(scene);
    let mut nodes = scene.nodes.clone();
    let mut by_slot = std::collections::HashMap::new();
    for &(k, g) in frames {
        let e: &mut [f64; 6] = by_slot.entry(k).or_default();
        for (a, b) in e.iter_mut().zip(g) {
            *a += b;
        }
    }
    let mut c = Chain {
        layout: &layout,
        grad,
        frames: by_slot,
        path_ix: 0,
        transform_ix: 0,
    };
    c.nodes(&mut nodes);
}

struct Chain<'a> {
    layout: &'a ParamLayout,
    grad: &'a mut [f64],
    /// Stroke frames' gradients by width slot, carried into each group's frame as the
    /// walk descends.
    frames: std::collections::HashMap<usize, [f64; 6]>,
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
            snap_frames(&mut g.children);
            let mut acc = [0.0; 6];
            let gens = generators(&t);
            let d_lin = t.linear_derivatives();
            let mut k = self.path_ix;
            super::paths_of(&g.children, Role::Paint, &mut |p, _| {
                let off = &self.layout.paths[k];
                chain_path(p, off, &t, self.grad, &mut acc);
                chain_paints(p, off, &gens, self.grad, &self.frames, &mut acc);
                if let (Some(s), Some(l), Some(g)) =
                    (&p.stroke, t.linear, self.frames.get_mut(&off.stroke_width))
                {
                    let mut gf = [g[0], g[1], g[2], g[3]];
                    chain_frame(s.frame, l, &d_lin, &mut gf, &mut acc);
                    g[..4].copy_from_slice(&gf);
                }
                // A primitive's frame, keyed by its first slot, likewise.
                if let (Some(q), Some(l), Some(g)) =
                    (&p.primitive, t.linear, self.frames.get_mut(&off.points))
                {
                    let mut gf = [g[0], g[1], g[2], g[3]];
                    chain_frame(q.frame, l, &d_lin, &mut gf, &mut acc);
                    g[..4].copy_from_slice(&gf);
                }
                k += 1;
            });
            for (i, v) in acc.iter().take(t.slot_count()).enumerate() {
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

/// A linear part `[a, b, c, d]` (SVG order) applied to `v`.
fn lin(l: [f64; 4], v: Point) -> Point {
    [l[0] * v[0] + l[2] * v[1], l[1] * v[0] + l[3] * v[1]]
}

/// `l · m` (apply `m` first).
fn lin_mul(l: [f64; 4], m: [f64; 4]) -> [f64; 4] {
    let [a, b] = lin(l, [m[0], m[1]]);
    let [c, d] = lin(l, [m[2], m[3]]);
    [a, b, c, d]
}

/// Per slot `j`, the transform's derivative `T⁻¹·∂T/∂θⱼ` in its own frame: an
/// infinitesimal affine map `x ↦ L·x + e`, as `[L (SVG order), e]`.
fn generators(t: &GroupTransform) -> Vec<Affine> {
    let inv = invert(&t.affine()).unwrap_or(super::IDENTITY);
    let li = [inv[0], inv[1], inv[2], inv[3]];
    // `T(x) = A·(x − p) + p + t`: `∂T = [∂A | ∂t − ∂A·p]`.
    t.linear_derivatives()
        .iter()
        .enumerate()
        .map(|(j, &da)| {
            let ap = lin(da, t.pivot);
            let mut dt = [-ap[0], -ap[1]];
            if j < 2 {
                dt[j] += 1.0;
            }
            let l = lin_mul(li, da);
            let e = lin(li, dt);
            [l[0], l[1], l[2], l[3], e[0], e[1]]
        })
        .collect()
}

/// The change of a linear gradient's geometry (in its own space, slot order) that draws
/// as the change `M → M·(1 + h·E)` of its transform does, to first order in `h`: `None`
/// for a radial gradient (whose transform's gradient the backward pass reports) or a
/// degenerate geometry.
fn geometry_change(kind: &GradientKind, e: &Affine) -> Option<Vec<f64>> {
    let l = [e[0], e[1], e[2], e[3]];
    let map = |v: Point| add_scaled(lin(l, v), [e[4], e[5]], 1.0);
    let dot = |a: Point, b: Point| a[0] * b[0] + a[1] * b[1];
    match *kind {
        GradientKind::Linear { p1, p2 } => {
            // `t(q) = (q − p1)·d/|d|²` pulled back by `1 − h·E`: `p1` rides along (it
            // stays on the level 0), `d` follows the level lines' normal.
            let d = add_scaled(p2, p1, -1.0);
            let dd = dot(d, d);
            if !(dd > 0.0) {
                return None;
            }
            let lt_d = [l[0] * d[0] + l[1] * d[1], l[2] * d[0] + l[3] * d[1]];
            let w = 2.0 * dot(d, lin(l, d)) / dd;
            let dp1 = map(p1);
            let dd_ = [w * d[0] - lt_d[0], w * d[1] - lt_d[1]];
            Some(vec![dp1[0], dp1[1], dp1[0] + dd_[0], dp1[1] + dd_[1]])
        }
        // A radial gradient's transform has a gradient of its own (`chain_paints`).
        GradientKind::Radial { .. } => None,
    }
}

/// A stroke frame's share of `acc` under a general map with linear part `l` (`d_lin`
/// its derivative per slot), the device frame being `l · local` (`local` the frame in
/// the group's own frame): `gf`, the gradient of the frame the map takes it to, becomes
/// that of `local`.
fn chain_frame(
    local: [f64; 4],
    l: [f64; 4],
    d_lin: &[[f64; 4]],
    gf: &mut [f64; 4],
    acc: &mut [f64; 6],
) {
    let frob = |a: [f64; 4], b: [f64; 4]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    for (j, d) in d_lin.iter().enumerate() {
        acc[j] += frob(*gf, lin_mul(*d, local));
    }
    // `∂L/∂local = lᵀ · ∂L/∂frame`.
    *gf = lin_mul([l[0], l[2], l[1], l[3]], *gf);
}

/// A path's gradient paints' share of `acc`: their geometry's gradient (which stays
/// as it is: the geometry is in the paint's own space) carried onto the transform's
/// slots through the paint's transform `M` (local values in `p`).
fn chain_paints(
    p: &Path,
    off: &super::params::PathOffsets,
    gens: &[Affine],
    grad: &[f64],
    maps: &std::collections::HashMap<usize, [f64; 6]>,
    acc: &mut [f64; 6],
) {
    let paints = [
        (p.fill.as_ref().map(|f| &f.paint), off.fill),
        (p.stroke.as_ref().map(|s| &s.paint), off.stroke),
    ];
    for (paint, at) in paints {
        let (Some(Paint::Gradient(g)), Some(at)) = (paint, at) else {
            continue;
        };
        let Some(mi) = invert(&g.transform) else {
            continue;
        };
        let m = g.transform;
        let (ml, mi_l) = ([m[0], m[1], m[2], m[3]], [mi[0], mi[1], mi[2], mi[3]]);
        let g_geo = &grad[at.base..at.stops];
        for (j, generator) in gens.iter().enumerate() {
            // `E = M⁻¹·G·M`: `[Mi·GL·ML | Mi·(GL·m + g)]` (G has no homogeneous 1).
            let gl = [generator[0], generator[1], generator[2], generator[3]];
            let l = lin_mul(mi_l, lin_mul(gl, ml));
            let e = lin(
                mi_l,
                add_scaled(lin(gl, [m[4], m[5]]), [generator[4], generator[5]], 1.0),
            );
            let e = [l[0], l[1], l[2], l[3], e[0], e[1]];
            if let GradientKind::Radial { .. } = g.kind {
                // `q` moves by `−h·E·q` (`chain_gradient`'s `frames`).
                if let Some(m) = maps.get(&at.base) {
                    acc[j] -= m.iter().zip(&e).map(|(a, b)| a * b).sum::<f64>();
                }
            } else if let Some(dg) = geometry_change(&g.kind, &e) {
                acc[j] += g_geo.iter().zip(&dg).map(|(a, b)| a * b).sum::<f64>();
            }
        }
    }
}

/// One path's share: `acc` gets `∂L/∂(tx, ty, angle, scale)` (or `tx, ty, a, b, c, d`)
/// through its geometry, and the path's slots in `grad` are turned from device into
/// local gradients. `p` holds local values.
fn chain_path(
    p: &Path,
    off: &super::params::PathOffsets,
    t: &GroupTransform,
    grad: &mut [f64],
    acc: &mut [f64; 6],
) {
    if let Some(l) = t.linear {
        // A position `v` mapped to `x = L·(v − p) + p + t`, with gradient `g` at `x`:
        // the slots' share, and `Lᵀ·g`. A stroke's width stays (its frame takes the
        // map: `chain_frame`), as do a primitive's sizes and angle (its frame takes it).
        let position = |v: Point, g: Point, acc: &mut [f64; 6]| -> Point {
            let r = [v[0] - t.pivot[0], v[1] - t.pivot[1]];
            acc[0] += g[0];
            acc[1] += g[1];
            acc[2] += g[0] * r[0];
            acc[3] += g[1] * r[0];
            acc[4] += g[0] * r[1];
            acc[5] += g[1] * r[1];
            [l[0] * g[0] + l[1] * g[1], l[2] * g[0] + l[3] * g[1]]
        };
        if let Some(prim) = &p.primitive {
            // The center is mapped; a rectangle's corner slots are the center's less
            // half the sides (device and local alike), so a side also moves the mapped
            // corner by `½·(Lᵀ − I)·g` along its axis.
            let at = off.points;
            let g = [grad[at], grad[at + 1]];
            let local = position(prim.center(), g, acc);
            grad[at] = local[0];
            grad[at + 1] = local[1];
            if let Shape::Rect { .. } = prim.shape {
                let w = prim.size_slots().start;
                grad[at + w] += 0.5 * (local[0] - g[0]);
                grad[at + w + 1] += 0.5 * (local[1] - g[1]);
            }
            return;
        }
        for (i, q) in p.points.iter().enumerate() {
            let at = off.points + 2 * i;
            let local = position(*q, [grad[at], grad[at + 1]], acc);
            grad[at] = local[0];
            grad[at + 1] = local[1];
        }
        return;
    }
    let [c, s] = t.rotation();
    let k = t.scale;
    // `R·v`, `R′·v` (the derivative in the angle) and `Rᵀ·g`.
    let rot = |v: Point| [c * v[0] - s * v[1], s * v[0] + c * v[1]];
    let drot = |v: Point| [-s * v[0] - c * v[1], c * v[0] - s * v[1]];
    let rot_t = |g: Point| [c * g[0] + s * g[1], -s * g[0] + c * g[1]];
    let dot = |a: Point, b: Point| a[0] * b[0] + a[1] * b[1];
    // A position `v` mapped to `k·R·(v − pivot) + pivot + t`, with gradient `g` there.
    let position = |v: Point, g: Point, acc: &mut [f64; 6]| -> Point {
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
    /// stroked circle) and a skewed stroke, a general map.
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
      <g id="kept" transform="skewX(20)"><path d="M5 50 L20 50 L15 58 Z" fill="#777"
        stroke="#000"/></g>
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
        // The skewed group of a stroked path: a general map.
        let Node::Group(kept) = &s.nodes[1] else {
            panic!("{:?}", s.nodes[1])
        };
        assert_eq!(kept.transform.map(|t| t.slot_count()), Some(6));
        let layout = ParamLayout::new(&s);
        assert_eq!(layout.transforms.len(), 3);
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
            angle: 0.3,
            ..GroupTransform::identity(pivot)
        };
        let (before, after) = (device_points(&s), device_points(&moved));
        // The skewed triangle, last, does not move.
        let Node::Group(kept) = &s.nodes[1] else {
            panic!()
        };
        let Node::Path(tri) = &kept.children[0] else {
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
        assert_eq!(ParamLayout::new(&back).transforms.len(), 3);
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
    fn general_maps_round_trip_and_project() {
        let m = [1.2, 0.3, -0.5, 0.7, 4.0, -3.0];
        let t = GroupTransform::from_affine_general(&m, [10.0, 20.0]).unwrap();
        assert_eq!(t.slot_count(), 6);
        let back = t.affine();
        assert!(
            m.iter().zip(&back).all(|(a, b)| (a - b).abs() < 1e-12),
            "{back:?}"
        );
        // The pivot moves by the translation only.
        let p = apply(&back, t.pivot);
        assert!((p[0] - 10.0 - t.translate[0]).abs() < 1e-12);
        assert!((p[1] - 20.0 - t.translate[1]).abs() < 1e-12);
        for bad in [
            [1.0, 2.0, 0.5, 1.0, 0.0, 0.0],
            [1.0, 0.0, 0.0, f64::NAN, 0.0, 0.0],
        ] {
            assert!(GroupTransform::from_affine_general(&bad, [0.0; 2]).is_none());
        }
        // Projection: entries clamped, NaN back to the identity's, a near-singular part
        // replaced.
        let mut q = t;
        q.linear = Some([f64::NAN, 5e3, 0.0, 1.0]);
        q.project();
        assert_eq!(q.linear, Some([1.0, 1e3, 0.0, 1.0]));
        q.linear = Some([1e-4, 0.0, 0.0, 1e-4]);
        q.project();
        assert_eq!(q.linear, Some([1e-3, 0.0, 0.0, 1e-3]));
    }

    /// A skewed group of fills (one with a linear gradient): six slots, local values as
    /// written, and `set_params` the inverse of `params`, paint transforms included.
    #[test]
    fn skewed_group_keeps_a_general_transform() {
        let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="30">
          <defs><linearGradient id="l" gradientUnits="userSpaceOnUse" x1="2" y1="2" x2="20"
            y2="12"><stop offset="0" stop-color="#000"/><stop offset="1" stop-color="#fff"/>
          </linearGradient></defs>
          <g id="k" transform="translate(3 2) skewX(20) scale(1 1.5)">
            <path d="M2 2 L20 2 L12 14 Z" fill="url(#l)"/>
            <path d="M14 4 L24 4 L20 12 Z" fill="#a33"/>
          </g></svg>"##;
        let s = Scene::from_svg_str(svg, "k.svg", Sizing::Natural).unwrap();
        let layout = ParamLayout::new(&s);
        assert_eq!(layout.transforms.len(), 1);
        let Node::Group(g) = &s.nodes[0] else {
            panic!("{:?}", s.nodes[0])
        };
        let t = g.transform.unwrap();
        let k = 20f64.to_radians().tan();
        assert_eq!(t.slot_count(), 6);
        let l = t.linear.unwrap();
        assert!((l[0] - 1.0).abs() < 1e-6 && l[1].abs() < 1e-6, "{l:?}");
        assert!(
            (l[2] - 1.5 * k).abs() < 1e-6 && (l[3] - 1.5).abs() < 1e-6,
            "{l:?}"
        );
        // The first path's points are in the group's frame: as written.
        let v = s.params();
        let at = layout.paths[0].points;
        assert!(
            (v[at] - 2.0).abs() < 1e-5 && (v[at + 1] - 2.0).abs() < 1e-5,
            "{v:?}"
        );
        let mut again = s.clone();
        again.set_params(&v);
        assert!(close(&device_points(&again), &device_points(&s), 1e-9));
        let paint = |s: &Scene| {
            let mut out = Vec::new();
            s.for_each_path(|p| {
                if let Some(Paint::Gradient(g)) = p.fill.as_ref().map(|f| &f.paint) {
                    out.push(g.transform);
                }
            });
            out
        };
        let (a, b) = (paint(&s), paint(&again));
        assert_eq!(a.len(), 1);
        assert!(a[0].iter().zip(&b[0]).all(|(x, y)| (x - y).abs() < 1e-9));
        // The device paint transform is the group's map of the local one.
        assert!((a[0][2] - 1.5 * k).abs() < 1e-6, "{:?}", a[0]);
        // A stroke keeps the map too: its frame, in the group's frame, is the identity,
        // and takes the map on the canvas.
        let stroked = svg.replace("fill=\"#a33\"", "fill=\"#a33\" stroke=\"#000\"");
        let s = Scene::from_svg_str(&stroked, "k.svg", Sizing::Natural).unwrap();
        assert_eq!(ParamLayout::new(&s).transforms.len(), 1);
        let mut local = s.nodes.clone();
        localize(&mut local);
        let mut frames = Vec::new();
        super::super::paths_of(&local, Role::Paint, &mut |p, _| {
            frames.extend(p.stroke.as_ref().map(|s| s.frame));
        });
        assert_eq!(frames, [super::super::FRAME_IDENTITY]);
        let mut device = Vec::new();
        s.for_each_path(|p| device.extend(p.stroke.as_ref().map(|s| s.frame)));
        assert!((device[0][2] - 1.5 * k).abs() < 1e-6, "{device:?}");
    }

    /// A shape's own transform (usvg's group around it): the group's slots, the shape's
    /// parameters as written, and the file written back carries it on the shape itself
    /// and reads back with the same slots and the same `f32` values.
    #[test]
    fn a_shapes_own_transform_is_a_parameter() {
        let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="60" height="40">
          <rect id="r" x="10" y="8" width="20" height="10" fill="#c42"
                transform="rotate(30 10 8)"/>
          <rect id="a" x="2" y="2" width="6" height="4" transform="rotate(20 5 4)"/>
          <path id="k" d="M30 20 L50 22 L40 34 Z" fill="#249" transform="skewX(15) scale(1 0.9)"/>
          <circle id="c" cx="12" cy="30" r="4" fill="#4a4" stroke="#000"
                  transform="translate(2 1) scale(1.5)"/>
          <g id="one" transform="rotate(-10 40 10)"><ellipse cx="45" cy="8" rx="6" ry="3"/></g>
        </svg>"##;
        let s = Scene::from_svg_str(svg, "one.svg", Sizing::Natural).unwrap();
        let layout = ParamLayout::new(&s);
        let kinds = |s: &Scene| -> Vec<(String, usize)> {
            let mut out = Vec::new();
            for n in &s.nodes {
                let Node::Group(g) = n else { continue };
                let Some(t) = g.transform else { continue };
                assert!(!g.layer && g.children.len() == 1, "{g:?}");
                let Node::Path(p) = &g.children[0] else {
                    panic!()
                };
                out.push((p.id.clone(), t.slot_count()));
            }
            out
        };
        let want = [("r", 4), ("k", 6), ("c", 4), ("", 4)].map(|(a, b)| (a.to_string(), b));
        assert_eq!(kinds(&s), want);
        assert_eq!(layout.transforms.len(), 4);
        // The rectangle in its own frame: as written, unturned (its angle slot 0); the one
        // turned about its center has that angle instead, and no transform.
        let v = s.params();
        let at = layout.paths[0].points;
        for (got, want) in v[at..at + 5].iter().zip([10.0, 8.0, 20.0, 10.0, 0.0]) {
            assert!((got - want).abs() < 1e-5, "{:?}", &v[at..at + 5]);
        }
        let Node::Path(a) = &s.nodes[1] else {
            panic!("{:?}", s.nodes[1])
        };
        let angle = a.primitive.as_ref().unwrap().angle;
        assert!((angle - 20f64.to_radians()).abs() < 1e-6, "{angle}");
        // Moved, written, read back: the transform on the element, the same slots.
        let mut moved = s.clone();
        let mut w = v.clone();
        for &t in &layout.transforms {
            w[t] += 0.5;
            w[t + 2] += 0.05;
        }
        moved.set_params(&w);
        let text = moved.to_svg_string();
        assert!(
            text.contains("<rect id=\"r\" transform=\"matrix("),
            "{text}"
        );
        assert!(
            text.contains("<path id=\"k\" transform=\"matrix("),
            "{text}"
        );
        assert!(text.contains("<g id=\"one\" transform=\"matrix("), "{text}");
        let back = Scene::from_svg_str(&text, "b.svg", Sizing::Natural).unwrap();
        assert_eq!(kinds(&back), want);
        let (a, b) = (moved.params(), back.params());
        assert_eq!(a.len(), b.len());
        for (i, (x, y)) in a.iter().zip(&b).enumerate() {
            assert!(
                (*x as f32 - *y as f32).abs() <= 2e-6 * x.abs().max(1.0) as f32,
                "slot {i}: {x} vs {y}\n{text}"
            );
        }
        // Inside a pattern, or with an image, it stays baked.
        let img = r##"<svg xmlns="http://www.w3.org/2000/svg" width="8" height="8">
          <image width="4" height="4" transform="rotate(10)" href="data:image/png;base64,iVBORw0KGgoAAAANSUhEUgAAAAEAAAABCAYAAAAfFcSJAAAADUlEQVR42mP8z8BQDwAEhQGAhKmMIQAAAABJRU5ErkJggg=="/>
        </svg>"##;
        let s = Scene::from_svg_str(img, "i.svg", Sizing::Natural).unwrap();
        assert!(ParamLayout::new(&s).transforms.is_empty());
    }

    #[test]
    fn from_affine_round_trips_and_refuses_non_similarities() {
        let t = GroupTransform {
            translate: [3.0, -2.0],
            angle: 0.7,
            scale: 1.5,
            ..GroupTransform::identity([10.0, 20.0])
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
