//! The flat parameter vector of a scene.
//!
//! Every number the optimizer may move is one `f64` slot. The order is fixed by a single
//! walk over the scene (`walk`) so that parameters, gradients and learning rates line up:
//!
//! * nodes in paint order, depth first; a [`Group`](super::Group) drawn as a layer
//!   contributes its opacity, then a group with a transform parameter its `tx, ty, angle,
//!   scale` (or `tx, ty, a, b, c, d`, [`transform`](super::transform)), whose content's slots are then in the
//!   group's own frame, then a group with filters its primitives' numbers, filter by
//!   filter ([`FilterPrimitive::slots_mut`](super::filter::FilterPrimitive::slots_mut));
//! * per path: all control points (`x, y` per point, in [`Path::points`] order), or for
//!   a circle, ellipse or rectangle its own parameters instead ([`shape`](super::shape)),
//!   then the fill (paint, then opacity), then the stroke (paint, opacity, width);
//! * a solid paint is `r, g, b`; a linear gradient is `x1, y1, x2, y2`, a radial one
//!   `cx, cy, r, fx, fy, fr`, each followed by its stops as `offset, r, g, b, opacity`;
//!   an image has no slots (its [`PaintOffsets`] start, empty, at the item's opacity).
//!   The points of an image's rectangle are slots like any path's (the gradient reaches
//!   them), which fits freeze with a learning rate of 0.
//!
//! Gradients returned by the backward pass use the same layout.
//!
//! A closed subpath whose last segment ends on its start point
//! ([`Subpath::ends_at_start`](super::Subpath::ends_at_start), a circle's outline for
//! instance) keeps both points' slots, but they are one parameter: `set_params` copies
//! the start's value into the closing point, and its gradient is added to the start's
//! (the closing point's slots get 0). So an optimizer cannot open a gap that the closing
//! line would bridge with a straight chord.
//!
//! ```
//! use diffsvg::scene::{ParamGroup, ParamLayout};
//! use diffsvg::{Scene, Sizing};
//! let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10">
//!   <path d="M1 1 L9 1 L5 8 Z" fill="red" stroke="blue" stroke-width="2"/></svg>"#;
//! let scene = Scene::from_svg_str(svg, "t.svg", Sizing::Natural)?;
//! let layout = ParamLayout::new(&scene);
//! let p = layout.paths[0];
//! // Two lines are two cubics (the close adds no segment): 7 points in 14 slots, then
//! // fill r, g, b and opacity, then stroke r, g, b, opacity and width.
//! assert_eq!((p.points, p.fill_opacity, p.stroke_opacity, p.stroke_width), (0, 17, 21, 22));
//! assert_eq!(layout.slots[22].group, ParamGroup::StrokeWidth);
//! assert_eq!(scene.params()[22], 2.0);
//! # Ok::<(), diffsvg::Error>(())
//! ```

use super::geom::{add_scaled, scale};
use super::tiling::TileSlots;
use super::{GradientKind, Node, Paint, Path, Point, Role, Scene, SegmentKind};

/// What kind of quantity a parameter is; the optimizer gives each group its own learning
/// rate and projection.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ParamGroup {
    /// Control point coordinates, device pixels.
    Points,
    /// Color channels (solid paints and gradient stops), `[0, 1]`.
    Color,
    /// Fill, stroke, stop and group opacities, `[0, 1]`.
    Opacity,
    /// Stroke widths, ≥ 0.
    StrokeWidth,
    /// Gradient geometry (end points, centers, radii) in gradient space.
    PaintGeometry,
    /// Gradient stop offsets, `[0, 1]`, kept ordered.
    StopOffset,
    /// Transform parameters: the rotation of an ellipse or a rectangle
    /// ([`Primitive::angle`](super::Primitive::angle)), radians.
    Transform,
    /// Filter primitives' numbers ([`FilterPrimitive::slots_mut`](super::filter::FilterPrimitive::slots_mut)):
    /// offsets and blur deviations in device pixels, color-matrix values and feComposite's
    /// `k1 … k4` (unitless).
    Filter,
}

impl ParamGroup {
    /// All groups, in a fixed order.
    pub const ALL: [ParamGroup; 8] = [
        ParamGroup::Points,
        ParamGroup::Color,
        ParamGroup::Opacity,
        ParamGroup::StrokeWidth,
        ParamGroup::PaintGeometry,
        ParamGroup::StopOffset,
        ParamGroup::Transform,
        ParamGroup::Filter,
    ];

    /// Lower-case name used on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            ParamGroup::Points => "points",
            ParamGroup::Color => "colors",
            ParamGroup::Opacity => "opacities",
            ParamGroup::StrokeWidth => "widths",
            ParamGroup::PaintGeometry => "paint",
            ParamGroup::StopOffset => "stops",
            ParamGroup::Transform => "transforms",
            ParamGroup::Filter => "filters",
        }
    }
}

/// One scalar of the parameter vector: its group and the node that owns it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ParamSlot {
    /// Kind of quantity.
    pub group: ParamGroup,
    /// Index into [`ParamLayout::owners`].
    pub owner: usize,
}

/// A node that owns parameters.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Owner {
    /// The SVG id (may be empty).
    pub id: String,
    /// `true` for a group (its parameters are its opacity, transform and filters' numbers),
    /// `false` for a path.
    pub is_group: bool,
}

/// Where one paint's parameters start; see the module docs for the order inside.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct PaintOffsets {
    /// First slot of the paint.
    pub base: usize,
    /// First slot of the stops (`base + 4` for linear, `base + 6` for radial); unused for
    /// solid paints.
    pub stops: usize,
}

/// Offsets of one path's parameters.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct PathOffsets {
    /// First slot of the control points (`2k` is point `k`'s x, `2k + 1` its y).
    pub points: usize,
    /// Fill paint.
    pub fill: Option<PaintOffsets>,
    /// Fill opacity.
    pub fill_opacity: usize,
    /// Stroke paint.
    pub stroke: Option<PaintOffsets>,
    /// Stroke opacity.
    pub stroke_opacity: usize,
    /// Stroke width.
    pub stroke_width: usize,
}

/// The layout of a scene's parameter vector.
#[derive(Clone, Debug, PartialEq)]
pub struct ParamLayout {
    /// One entry per scalar.
    pub slots: Vec<ParamSlot>,
    /// Nodes owning parameters, paths and groups, in walk order.
    pub owners: Vec<Owner>,
    /// Offsets per path, in paint order (the order of [`Scene::for_each_path`]).
    pub paths: Vec<PathOffsets>,
    /// Offset of each group's opacity, in walk order (groups drawn as layers only).
    pub groups: Vec<usize>,
    /// Offset of each group transform's first slot (`tx, ty, angle, scale` follow, or
    /// `tx, ty, a, b, c, d` for a general affine one), in walk order
    /// ([`transform`](super::transform)).
    pub transforms: Vec<usize>,
    /// The slots of each filtered group's filter parameters, in walk order (groups whose
    /// filters have parameters only; [`FilterPrimitive::slots_mut`](super::filter::FilterPrimitive::slots_mut)).
    pub filters: Vec<std::ops::Range<usize>>,
}

/// What a slot visited by [`walk`] is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Part {
    /// Opacity of group number `.0` (walk order).
    GroupOpacity(usize),
    /// First slot (`tx`) of transform number `.0` (walk order).
    GroupTransform(usize),
    /// First coordinate of path `.0`'s control points.
    PathPoints(usize),
    /// Any other coordinate of a path's control points.
    Point,
    /// First slot of a fill paint of path `.0`.
    FillPaint(usize),
    /// First slot of a stroke paint of path `.0`.
    StrokePaint(usize),
    /// First stop slot of the current paint.
    Stops,
    /// Another slot inside a paint.
    PaintSlot,
    /// Fill opacity of path `.0`.
    FillOpacity(usize),
    /// Stroke opacity of path `.0`.
    StrokeOpacity(usize),
    /// Stroke width of path `.0`.
    StrokeWidth(usize),
    /// A filter primitive's number; `unitless` for color-matrix values and feComposite's
    /// `k` (the others are device pixels, colors or opacities).
    Filter {
        /// A unitless number.
        unitless: bool,
    },
}

/// Visits every parameter of `scene` in the canonical order. `f` receives the owner index
/// (into [`ParamLayout::owners`]), the group, what the slot is, and the value. Returns
/// where each tiled group's tiles' slots are ([`tiling`](super::tiling)), in post-order.
pub(crate) fn walk(
    scene: &mut Scene,
    f: &mut dyn FnMut(usize, ParamGroup, Part, &mut f64),
) -> Vec<TileSlots> {
    let count = std::cell::Cell::new(0usize);
    let mut counted = |o: usize, g: ParamGroup, p: Part, v: &mut f64| {
        count.set(count.get() + 1);
        f(o, g, p, v)
    };
    let mut w = Walk {
        f: &mut counted,
        count: &count,
        tiles: Vec::new(),
        owner: 0,
        path_ix: 0,
        group_ix: 0,
        transform_ix: 0,
    };
    w.nodes(&mut scene.nodes, Role::Paint);
    w.tiles
}

/// The counters of [`walk`].
struct Walk<'a> {
    f: &'a mut dyn FnMut(usize, ParamGroup, Part, &mut f64),
    /// Slots visited so far.
    count: &'a std::cell::Cell<usize>,
    /// The tiled groups' slots met so far.
    tiles: Vec<TileSlots>,
    owner: usize,
    path_ix: usize,
    group_ix: usize,
    transform_ix: usize,
}

impl Walk<'_> {
    fn nodes(&mut self, nodes: &mut [Node], role: Role) {
        for n in nodes {
            match n {
                Node::Group(g) => {
                    // A group inside a clip path is drawn opaque, and a group that is
                    // only a transform is no layer: no opacity parameter.
                    if role == Role::Paint && g.layer {
                        (self.f)(
                            self.owner,
                            ParamGroup::Opacity,
                            Part::GroupOpacity(self.group_ix),
                            &mut g.opacity,
                        );
                        self.group_ix += 1;
                    }
                    if let Some(t) = &mut g.transform {
                        for (i, v) in t.slots_mut().into_iter().enumerate() {
                            let part = if i == 0 {
                                Part::GroupTransform(self.transform_ix)
                            } else {
                                Part::Point
                            };
                            (self.f)(self.owner, ParamGroup::Transform, part, v);
                        }
                        self.transform_ix += 1;
                    }
                    // A filtered group's primitives, after its opacity: its children's
                    // slots follow them.
                    if role == Role::Paint && g.layer {
                        for p in g.filters.iter_mut().flat_map(|f| &mut f.primitives) {
                            let unitless = p.kind.unitless();
                            for (group, v) in p.slots_mut() {
                                let part = Part::Filter {
                                    unitless: unitless && group == ParamGroup::Filter,
                                };
                                (self.f)(self.owner, group, part, v);
                            }
                        }
                    }
                    self.owner += 1;
                    self.layers(g, role);
                }
                Node::Path(p) => {
                    walk_path(p, self.owner, self.path_ix, role, self.f);
                    self.owner += 1;
                    self.path_ix += 1;
                }
            }
        }
    }

    /// A group's children, then its clip path's shapes, then its mask's content (the
    /// order of [`Scene::for_each_path`]).
    fn layers(&mut self, g: &mut super::Group, role: Role) {
        match g.tiling.as_ref().map(|t| t.per_tile) {
            // Tile by tile, noting where each starts; equal tiles have equal lengths.
            Some(n) if n > 0 => {
                let mut starts = Vec::new();
                for tile in g.children.chunks_mut(n) {
                    starts.push(self.count.get());
                    self.nodes(tile, role);
                }
                let len = starts.get(1).map_or(0, |s| s - starts[0]);
                let equal = starts.windows(2).all(|w| w[1] - w[0] == len)
                    && self.count.get() - starts[starts.len() - 1] == len;
                if starts.len() > 1 && equal {
                    self.tiles.push(TileSlots {
                        start: starts[0],
                        len,
                        tiles: starts.len(),
                    });
                }
            }
            _ => self.nodes(&mut g.children, role),
        }
        if let Some(c) = &mut g.clip {
            self.layers(&mut c.content, Role::Clip);
        }
        if let Some(m) = &mut g.mask {
            self.layers(&mut m.content, role);
        }
    }
}

/// A path's slots; a clip path's shape has only its points.
fn walk_path(
    p: &mut Path,
    owner: usize,
    ix: usize,
    role: Role,
    f: &mut dyn FnMut(usize, ParamGroup, Part, &mut f64),
) {
    if let Some(prim) = &mut p.primitive {
        prim.walk(owner, Part::PathPoints(ix), f);
    } else {
        walk_points(p, ix, owner, f);
    }
    if role == Role::Clip {
        return;
    }
    walk_paints(p, owner, ix, f);
}

/// A plain path's control points.
fn walk_points(
    p: &mut Path,
    ix: usize,
    owner: usize,
    f: &mut dyn FnMut(usize, ParamGroup, Part, &mut f64),
) {
    for (k, q) in p.points.iter_mut().enumerate() {
        let first = if k == 0 {
            Part::PathPoints(ix)
        } else {
            Part::Point
        };
        f(owner, ParamGroup::Points, first, &mut q[0]);
        f(owner, ParamGroup::Points, Part::Point, &mut q[1]);
    }
}

/// A path's fill and stroke slots.
fn walk_paints(
    p: &mut Path,
    owner: usize,
    ix: usize,
    f: &mut dyn FnMut(usize, ParamGroup, Part, &mut f64),
) {
    if let Some(fill) = &mut p.fill {
        walk_paint(&mut fill.paint, owner, Part::FillPaint(ix), f);
        f(
            owner,
            ParamGroup::Opacity,
            Part::FillOpacity(ix),
            &mut fill.opacity,
        );
    }
    if let Some(s) = &mut p.stroke {
        walk_paint(&mut s.paint, owner, Part::StrokePaint(ix), f);
        f(
            owner,
            ParamGroup::Opacity,
            Part::StrokeOpacity(ix),
            &mut s.opacity,
        );
        f(
            owner,
            ParamGroup::StrokeWidth,
            Part::StrokeWidth(ix),
            &mut s.width,
        );
    }
}

fn walk_paint(
    paint: &mut Paint,
    owner: usize,
    first: Part,
    f: &mut dyn FnMut(usize, ParamGroup, Part, &mut f64),
) {
    let mut first = Some(first);
    let next = |fp: &mut Option<Part>| fp.take().unwrap_or(Part::PaintSlot);
    match paint {
        Paint::Solid(c) => {
            for v in c.iter_mut() {
                f(owner, ParamGroup::Color, next(&mut first), v);
            }
        }
        Paint::Gradient(g) => {
            let geo: Vec<&mut f64> = match &mut g.kind {
                GradientKind::Linear { p1, p2 } => {
                    let [a, b] = p1;
                    let [c, d] = p2;
                    vec![a, b, c, d]
                }
                GradientKind::Radial { c, r, f: fp, fr } => {
                    let [a, b] = c;
                    let [x, y] = fp;
                    vec![a, b, r, x, y, fr]
                }
            };
            for v in geo {
                f(owner, ParamGroup::PaintGeometry, next(&mut first), v);
            }
            for (i, s) in g.stops.iter_mut().enumerate() {
                let part = if i == 0 { Part::Stops } else { Part::PaintSlot };
                f(owner, ParamGroup::StopOffset, part, &mut s.offset);
                for v in s.color.iter_mut() {
                    f(owner, ParamGroup::Color, Part::PaintSlot, v);
                }
                f(owner, ParamGroup::Opacity, Part::PaintSlot, &mut s.opacity);
            }
        }
        // An image's pixels are fixed: no slots.
        Paint::Image(_) => {}
    }
}

impl ParamLayout {
    /// Computes the layout of `scene`'s parameter vector.
    pub fn new(scene: &Scene) -> Self {
        let mut owners = Vec::new();
        collect_owners(&scene.nodes, &mut owners);
        let mut layout = ParamLayout {
            slots: Vec::new(),
            owners,
            paths: vec![PathOffsets::default(); scene.path_count()],
            groups: Vec::new(),
            transforms: Vec::new(),
            filters: Vec::new(),
        };
        // The walk needs `&mut`; a clone keeps this function's signature honest.
        let mut s = scene.clone();
        let mut current_paint: Option<(usize, bool)> = None;
        walk(&mut s, &mut |owner, group, part, _| {
            let at = layout.slots.len();
            layout.slots.push(ParamSlot { group, owner });
            match part {
                Part::GroupOpacity(_) => layout.groups.push(at),
                Part::GroupTransform(_) => layout.transforms.push(at),
                Part::PathPoints(i) => layout.paths[i].points = at,
                Part::FillPaint(i) => {
                    layout.paths[i].fill = Some(PaintOffsets {
                        base: at,
                        stops: at,
                    });
                    current_paint = Some((i, false));
                }
                Part::StrokePaint(i) => {
                    layout.paths[i].stroke = Some(PaintOffsets {
                        base: at,
                        stops: at,
                    });
                    current_paint = Some((i, true));
                }
                Part::Stops => {
                    if let Some((i, stroke)) = current_paint {
                        let p = &mut layout.paths[i];
                        let po = if stroke { &mut p.stroke } else { &mut p.fill };
                        if let Some(po) = po {
                            po.stops = at;
                        }
                    }
                }
                // A paint without slots (an image) starts, empty, at its opacity.
                Part::FillOpacity(i) => {
                    let p = &mut layout.paths[i];
                    p.fill_opacity = at;
                    p.fill.get_or_insert(PaintOffsets {
                        base: at,
                        stops: at,
                    });
                }
                Part::StrokeOpacity(i) => {
                    let p = &mut layout.paths[i];
                    p.stroke_opacity = at;
                    p.stroke.get_or_insert(PaintOffsets {
                        base: at,
                        stops: at,
                    });
                }
                Part::StrokeWidth(i) => layout.paths[i].stroke_width = at,
                // A group's filter slots are one run: the first opens it.
                Part::Filter { .. } => match layout.filters.last_mut() {
                    Some(r) if r.end == at => r.end = at + 1,
                    _ => layout.filters.push(at..at + 1),
                },
                Part::Point | Part::PaintSlot => {}
            }
        });
        layout
    }

    /// Number of scalars.
    pub fn len(&self) -> usize {
        self.slots.len()
    }

    /// Whether the scene has no parameters.
    pub fn is_empty(&self) -> bool {
        self.slots.is_empty()
    }
}

fn collect_owners(nodes: &[Node], out: &mut Vec<Owner>) {
    for n in nodes {
        match n {
            Node::Group(g) => {
                out.push(Owner {
                    id: g.id.clone(),
                    is_group: true,
                });
                collect_layer_owners(g, out);
            }
            Node::Path(p) => out.push(Owner {
                id: p.id.clone(),
                is_group: false,
            }),
        }
    }
}

/// The owners in a group's children, clip path and mask, in walk order.
fn collect_layer_owners(g: &super::Group, out: &mut Vec<Owner>) {
    collect_owners(&g.children, out);
    if let Some(c) = &g.clip {
        collect_layer_owners(&c.content, out);
    }
    if let Some(m) = &g.mask {
        collect_layer_owners(&m.content, out);
    }
}

impl Scene {
    /// The parameter vector, in the canonical order (module docs). A transformed group's
    /// content is reported in the group's own frame ([`transform`](super::transform)).
    pub fn params(&self) -> Vec<f64> {
        let mut out = Vec::new();
        let mut s = self.clone();
        super::transform::localize(&mut s.nodes);
        walk(&mut s, &mut |_, _, _, v| out.push(*v));
        out
    }

    /// Writes a parameter vector back into the scene. Panics if the length differs from
    /// [`ParamLayout::len`]; callers build vectors from [`Scene::params`].
    pub fn set_params(&mut self, values: &[f64]) {
        // What a transformed group holds that is no parameter (a gradient paint's
        // transform) into its frame first, so that mapping forward below is exact.
        if super::transform::any(&self.nodes) {
            super::transform::localize(&mut self.nodes);
        }
        let mut i = 0;
        walk(self, &mut |_, _, _, v| {
            *v = values[i];
            i += 1;
        });
        assert_eq!(i, values.len(), "parameter vector length mismatch");
        self.for_each_path_mut(|p| {
            p.sync_primitive();
            p.join_closing_points();
        });
        super::transform::globalize(&mut self.nodes);
        super::tiling::retile(&mut self.nodes);
    }
}

/// Turns the gradient of every slot's device value (what the backward pass computes) into
/// the gradient of the parameter vector: each pattern tile's copy is added to its tile 0
/// ([`tiling`](super::tiling)), then the content of transformed groups is carried into
/// their frames ([`chain_gradient`](super::transform::chain_gradient)), with the
/// gradients of stroke frames and radial paints' transforms (`frames`, by slot) that the
/// backward pass computes.
pub(crate) fn parameter_gradient(scene: &Scene, grad: &mut [f64], frames: &[(usize, [f64; 6])]) {
    if super::tiling::any(&scene.nodes) {
        let mut s = scene.clone();
        let tiles = walk(&mut s, &mut |_, _, _, _| {});
        super::tiling::tie_gradients(&tiles, grad);
    }
    super::transform::chain_gradient(scene, grad, frames);
}

/// Moves the gradient of each closing point that is its subpath's start
/// ([`Subpath::ends_at_start`](super::Subpath::ends_at_start)) onto the start's slots:
/// the two are one parameter, read from the start ([`Scene::set_params`] writes the start's
/// value into both), so the start's slots get the sum and the closing point's get 0 (a
/// change written there alone is overwritten, and changes nothing). `points` is the
/// path's first point slot in `grad`.
pub(crate) fn join_closing_gradients(path: &Path, points: usize, grad: &mut [f64]) {
    for sp in &path.subpaths {
        if sp.ends_at_start {
            let (a, b) = (points + 2 * sp.start, points + 2 * (sp.end() - 1));
            for c in 0..2 {
                grad[a + c] += grad[b + c];
                grad[b + c] = 0.0;
            }
        }
    }
}

/// Chains the gradient of a path's control points to the points as written in its path
/// data.
///
/// `point_grad` is the part of a gradient (in this module's layout) that belongs to the
/// path's control points: `x, y` per entry of [`Path::points`], `2 · points.len()` values
/// from [`PathOffsets::points`] on. Internally every segment is a cubic; a segment
/// written as a line or a quadratic has derived control points (a line's at 1/3 and 2/3,
/// a quadratic's elevated exactly: see [`Path::line_to`], [`Path::quad_to`]), whose
/// gradients are passed on to the written points they depend on.
///
/// Returns one gradient per written point, subpath by subpath: its start, then per
/// segment one for a line (its end point), two for a quadratic (its control and end
/// point), three for a cubic. Panics if `point_grad` is shorter than `2 · points.len()`.
pub fn written_point_gradient(path: &Path, point_grad: &[f64]) -> Vec<Point> {
    let g = |k: usize| -> Point { [point_grad[2 * k], point_grad[2 * k + 1]] };
    let mut points: Vec<Point> = Vec::new();
    for sp in &path.subpaths {
        // Accumulate into the written points: start, then per segment.
        let mut start = g(sp.start);
        let mut seg_points: Vec<Point> = Vec::new();
        for (k, kind) in sp.kinds.iter().enumerate() {
            let i = sp.start + 3 * k;
            let (c1, c2, end) = (g(i + 1), g(i + 2), g(i + 3));
            // The previous written point (start or last end) receives the share of derived
            // control points that depend on it.
            let dprev = match kind {
                SegmentKind::Line => {
                    // c1 = p0 + (p3 − p0)/3, c2 = p0 + 2(p3 − p0)/3.
                    seg_points.push(add_scaled(add_scaled(end, c1, 1.0 / 3.0), c2, 2.0 / 3.0));
                    add_scaled(scale(c1, 2.0 / 3.0), c2, 1.0 / 3.0)
                }
                SegmentKind::Quad => {
                    // c1 = p0 + 2(q − p0)/3, c2 = p3 + 2(q − p3)/3.
                    seg_points.push(add_scaled(scale(c1, 2.0 / 3.0), c2, 2.0 / 3.0));
                    seg_points.push(add_scaled(end, c2, 1.0 / 3.0));
                    scale(c1, 1.0 / 3.0)
                }
                SegmentKind::Cubic => {
                    seg_points.extend([c1, c2, end]);
                    [0.0; 2]
                }
            };
            let n = seg_points.len();
            let written = match kind {
                SegmentKind::Line => 1,
                SegmentKind::Quad => 2,
                SegmentKind::Cubic => 3,
            };
            let prev = if n > written {
                &mut seg_points[n - written - 1]
            } else {
                &mut start
            };
            *prev = add_scaled(*prev, dprev, 1.0);
        }
        points.push(start);
        points.extend(seg_points);
    }
    points
}

/// `v` clamped to `[-bound, bound]`, NaN to 0.
pub(crate) fn clamp_coordinate(v: &mut f64, bound: f64) {
    *v = if v.is_nan() {
        0.0
    } else {
        v.clamp(-bound, bound)
    };
}

/// Largest control-point magnitude for `p`, in device pixels: [`MAX_COORDINATE`](crate::limits::MAX_COORDINATE), divided
/// by the row-sum norm of the inverse stroke frame when that frame magnifies.
pub(crate) fn point_bound(p: &Path) -> f64 {
    let frame = p
        .stroke
        .as_ref()
        .map(|s| s.frame)
        .filter(|f| *f != super::FRAME_IDENTITY);
    let gain = match frame.and_then(|[a, b, c, d]| super::invert(&[a, b, c, d, 0.0, 0.0])) {
        Some(i) => (i[0].abs() + i[2].abs()).max(i[1].abs() + i[3].abs()),
        None => 1.0,
    };
    crate::limits::MAX_COORDINATE / gain.max(1.0)
}

/// Clamps the control points of `p` into the readable range (see [`crate::scene::project`]),
/// or a primitive's parameters into theirs (then rebuilds its outline).
pub(crate) fn clamp_points(p: &mut Path) {
    if let Some(prim) = &mut p.primitive {
        prim.project();
        p.sync_primitive();
        return;
    }
    let bound = point_bound(p);
    for q in &mut p.points {
        clamp_coordinate(&mut q[0], bound);
        clamp_coordinate(&mut q[1], bound);
    }
}

impl crate::choice::Choice for ParamGroup {
    const WHAT: &'static str = "parameter group";
    const ALL: &'static [Self] = &ParamGroup::ALL;
    fn name(self) -> &'static str {
        ParamGroup::name(self)
    }
    fn aliases(self) -> &'static [&'static str] {
        match self {
            Self::Points => &["point"],
            Self::Color => &["color"],
            Self::Opacity => &["opacity"],
            Self::StrokeWidth => &["width"],
            Self::PaintGeometry => &[],
            Self::StopOffset => &["stop"],
            Self::Transform => &["transform", "angle", "angles"],
            Self::Filter => &["filter"],
        }
    }
}

crate::choice::from_str_by_name!(ParamGroup);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Fill, FillRule, Gradient, IDENTITY, Spread, Stop};

    fn sample() -> Scene {
        let mut s = Scene::new(10, 10);
        let mut p = Path::new("a");
        p.move_to([1.0, 1.0]);
        p.line_to([5.0, 1.0]);
        p.cubic_to([6.0, 2.0], [6.0, 4.0], [5.0, 5.0]);
        p.close();
        p.fill = Some(Fill {
            paint: Paint::Gradient(Gradient {
                id: "g".into(),
                kind: GradientKind::Radial {
                    c: [5.0, 5.0],
                    r: 3.0,
                    f: [4.0, 4.0],
                    fr: 0.0,
                },
                transform: IDENTITY,
                spread: Spread::Pad,
                stops: vec![
                    Stop {
                        offset: 0.0,
                        color: [1.0, 0.0, 0.0],
                        opacity: 1.0,
                    },
                    Stop {
                        offset: 1.0,
                        color: [0.0, 0.0, 1.0],
                        opacity: 0.5,
                    },
                ],
            }),
            opacity: 0.8,
            rule: FillRule::NonZero,
        });
        s.nodes.push(Node::Group(crate::scene::Group::new(
            "grp",
            0.5,
            vec![Node::Path(p)],
        )));
        s
    }

    #[test]
    fn layout_offsets_match_walk() {
        let s = sample();
        let l = ParamLayout::new(&s);
        let v = s.params();
        assert_eq!(l.len(), v.len());
        // group opacity, 7 points, radial (6) + 2 stops (10), fill opacity
        assert_eq!(v.len(), 1 + 14 + 6 + 10 + 1);
        assert_eq!(l.groups, vec![0]);
        assert_eq!(v[l.groups[0]], 0.5);
        let po = l.paths[0];
        assert_eq!(v[po.points], 1.0);
        let fill = po.fill.unwrap();
        assert_eq!(v[fill.base + 2], 3.0); // r
        assert_eq!(fill.stops, fill.base + 6);
        assert_eq!(v[fill.stops + 5 + 4], 0.5); // second stop opacity
        assert_eq!(v[po.fill_opacity], 0.8);
        assert_eq!(l.owners.len(), 2);
        assert!(l.owners[0].is_group);
    }

    /// The written points of a path with every kind of segment, in the order of
    /// [`written_point_gradient`].
    fn written_path(w: &[Point]) -> Path {
        let mut p = Path::new("w");
        p.move_to(w[0]);
        p.line_to(w[1]);
        p.quad_to(w[2], w[3]);
        p.cubic_to(w[4], w[5], w[6]);
        p.line_to(w[7]);
        p.close();
        p.move_to(w[8]);
        p.quad_to(w[9], w[10]);
        p.line_to(w[11]);
        p
    }

    #[test]
    fn written_point_gradient_matches_differences() {
        let w: Vec<Point> = (0..12)
            .map(|i| [(i * 7 % 11) as f64, (i * 5 % 13) as f64 * 0.5])
            .collect();
        let path = written_path(&w);
        // A linear loss of the control points: its gradient is `a`.
        let a: Vec<f64> = (0..2 * path.points.len())
            .map(|i| ((i * 37 % 17) as f64 - 8.0) / 8.0)
            .collect();
        let loss = |p: &Path| -> f64 {
            let flat = p.points.iter().flat_map(|q| [q[0], q[1]]);
            flat.zip(&a).map(|(x, y)| x * y).sum()
        };
        let got = written_point_gradient(&path, &a);
        assert_eq!(got.len(), w.len());
        let h = 1e-3;
        for (j, g) in got.iter().enumerate() {
            for d in 0..2 {
                let (mut up, mut down) = (w.clone(), w.clone());
                up[j][d] += h;
                down[j][d] -= h;
                let num = (loss(&written_path(&up)) - loss(&written_path(&down))) / (2.0 * h);
                assert!(
                    (num - g[d]).abs() < 1e-9,
                    "point {j}.{d}: {} vs {num}",
                    g[d]
                );
            }
        }
    }

    #[test]
    fn a_closing_point_on_the_start_is_the_starts_parameter() {
        let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="20" height="20">
            <path d="M2 2 C8 0 12 4 18 10 C10 18 4 12 2 2 Z M3 15 L6 15 L6 18 Z"/></svg>"#;
        let mut s = Scene::from_svg_str(svg, "t.svg", crate::Sizing::Natural).unwrap();
        let Node::Path(p) = &s.nodes[0] else { panic!() };
        let (a, b) = (p.subpaths[0].clone(), p.subpaths[1].clone());
        assert!(a.ends_at_start && !b.ends_at_start, "{:?}", p.subpaths);
        let end = 2 * (a.end() - 1);
        let mut v = s.params();
        v[0] += 0.5; // the start's x
        v[end + 1] -= 3.0; // the closing point's y alone: overwritten
        s.set_params(&v);
        let Node::Path(p) = &s.nodes[0] else { panic!() };
        assert_eq!(p.points[a.end() - 1], p.points[0]);
        assert_eq!(p.points[0], [2.5, 2.0]);
        // The gradient: the start's slots get the sum, the closing point's 0.
        let mut g: Vec<f64> = (0..2 * p.points.len()).map(|i| i as f64).collect();
        join_closing_gradients(p, 0, &mut g);
        assert_eq!((g[0], g[1]), (end as f64, 1.0 + (end + 1) as f64));
        assert_eq!((g[end], g[end + 1]), (0.0, 0.0));
        // The triangle's closing line is a real segment: its points stay apart.
        let t = 2 * (b.end() - 1);
        assert_eq!(g[t], t as f64);
    }

    #[test]
    fn set_params_round_trips() {
        let mut s = sample();
        let mut v = s.params();
        for (i, x) in v.iter_mut().enumerate() {
            *x += i as f64 * 0.001;
        }
        s.set_params(&v);
        assert_eq!(s.params(), v);
    }

    #[test]
    fn group_names_round_trip() {
        crate::choice::tests::round_trip::<ParamGroup>();
    }
}
