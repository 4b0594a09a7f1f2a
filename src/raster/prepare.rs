//! Turning a scene into drawable polygons, once per render.

use super::coverage::floor_f64;
use super::dash::{Dashed, Visible, dash, dash_count};
use super::filter::{self, FilterLayer, crop, layer_rect};
use super::flatten::{ChordCounts, Flattened, flatten};
use super::paint::PaintEval;
use super::stroke::{Style, outline};
use crate::limits::{MAX_DASHES_PER_PATH, MAX_DASHES_PER_SCENE};
use crate::scene::geom::{flatten_rect, frame_tolerance};
use crate::scene::{BlendMode, FillRule, Group, MaskKind, Node, Path, Point, Role, Scene, Stroke};
use rayon::prelude::*;

/// Whether an item is a path's fill or its stroke.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum ItemKind {
    /// The fill.
    Fill,
    /// The stroke outline.
    Stroke,
}

/// One polygon set with one paint: a path's fill or its stroke.
#[derive(Clone, Debug)]
pub(crate) struct Item {
    /// Index of the path in paint order ([`Scene::for_each_path`] order).
    pub(crate) path: usize,
    /// Fill or stroke.
    pub(crate) kind: ItemKind,
    /// Polygon vertices, device pixels.
    pub(crate) pts: Vec<Point>,
    /// For a fill, the index in [`PathGeom::flat`] of each vertex (empty when prepared for
    /// a forward render only); for a stroke, empty: vertex `j` is outline vertex `j`.
    pub(crate) src: Vec<u32>,
    /// Closed rings as `(start, len)` into `pts`.
    pub(crate) rings: Vec<(usize, usize)>,
    /// Vertical extent `[ymin, ymax]` of each run of [`RUN_EDGES`] consecutive edges of
    /// each ring (the last run of a ring may be shorter), ring after ring: lets a row band
    /// skip the runs of a long outline that lie wholly above or below it.
    pub(crate) runs: Vec<[f64; 2]>,
    /// Even-odd fill rule (strokes are always nonzero).
    pub(crate) evenodd: bool,
    /// The paint, opacity included.
    pub(crate) paint: PaintEval,
    /// Bounds of `pts`: `[xmin, ymin, xmax, ymax]`.
    pub(crate) bbox: [f64; 4],
    /// Whether some edge lies exactly on a pixel boundary (vertical at integer x or
    /// horizontal at integer y). Only then do pixels with a zero winding integral take
    /// part in the backward pass.
    pub(crate) grid_aligned: bool,
    /// About how many (edge, pixel row) pairs accumulating the item writes: `|Δy| + 1`
    /// summed over its edges that are not horizontal.
    pub(crate) row_crossings: f64,
    /// Whether the winding number can take more than two adjacent values inside one
    /// pixel: anything but simple rings (convex, or monotone in y) apart from each other
    /// ([`rings_cannot_overlap`](super::overlap::rings_cannot_overlap)). Only such items look for the cells whose
    /// coverage [`overlap`](super::overlap) computes exactly.
    pub(crate) can_overlap: bool,
    /// Drawn without anti-aliasing ([`Path::crisp`](crate::scene::Path::crisp)): the
    /// deltas are winding numbers at pixel centers
    /// ([`accumulate_centers`](super::coverage::accumulate_centers)), and its edges get
    /// no gradient.
    pub(crate) crisp: bool,
}

/// Edges per run of [`Item::runs`].
pub(crate) const RUN_EDGES: usize = 16;

/// [`Prepared::work`] below which a scene is drawn on the calling thread alone: the
/// bundled 128×128 glyph outlines (about 24 000) took longer on two threads than on one,
/// drawings from 56 000 up gained from the second thread (`diffsvg bench`, 2 cores).
pub(crate) const SERIAL_WORK: f64 = 40_000.0;

impl Item {
    /// The premultiplied color of this item when it paints every pixel of a `width ×
    /// height` canvas with exact coverage 1 and an opaque solid color: a fill whose one
    /// ring is an axis-aligned rectangle containing the canvas (a background). Its winding
    /// integral is then exactly ±1 in every pixel (each row gains exactly its full height
    /// from each side, the sides clamped to the canvas's columns), so compositing it gives
    /// the color itself, whatever lay below.
    pub(crate) fn opaque_cover(&self, width: u32, height: u32) -> Option<[f32; 4]> {
        let PaintEval::Solid(c) = &self.paint else {
            return None;
        };
        if self.kind != ItemKind::Fill || c.premul[3] != 1.0 || self.rings.len() != 1 {
            return None;
        }
        let (start, n) = self.rings[0];
        let ring = &self.pts[start..start + n];
        if n != 4 {
            return None;
        }
        // Consecutive corners share one coordinate and differ in the other.
        let rectangle = (0..4).all(|k| {
            let (a, b) = (ring[k], ring[(k + 1) % 4]);
            (a[0] == b[0]) != (a[1] == b[1])
        });
        let b = self.bbox;
        let contains = b[0] <= 0.0
            && b[1] <= 0.0
            && b[2] >= width as f64
            && b[3] >= height as f64
            && b.iter().all(|v| v.is_finite());
        (rectangle && contains).then_some(c.premul)
    }

    /// Calls `f(a, b)`, indices into `pts` of an edge's two ends, for every edge in ring
    /// order, except the runs of edges lying wholly above `ylo` or wholly below `yhi`
    /// (device pixels). An edge touching either line is passed; callers test each edge
    /// as before, so skipping changes nothing but the time.
    #[inline]
    pub(crate) fn for_each_edge_near(&self, ylo: f64, yhi: f64, mut f: impl FnMut(usize, usize)) {
        let mut run = self.runs.iter();
        for &(s, n) in &self.rings {
            for k0 in (0..n).step_by(RUN_EDGES) {
                let Some(&[lo, hi]) = run.next() else {
                    return;
                };
                if hi < ylo || lo > yhi {
                    continue;
                }
                for k in k0..(k0 + RUN_EDGES).min(n) {
                    f(s + k, s + if k + 1 == n { 0 } else { k + 1 });
                }
            }
        }
    }
}

/// [`Item::runs`] of `rings` over `pts`.
fn edge_runs(pts: &[Point], rings: &[(usize, usize)]) -> Vec<[f64; 2]> {
    let mut runs = Vec::with_capacity(rings.iter().map(|r| r.1.div_ceil(RUN_EDGES)).sum());
    for &(s, n) in rings {
        for k0 in (0..n).step_by(RUN_EDGES) {
            let k1 = (k0 + RUN_EDGES).min(n);
            // The run's edges end at vertex `k1` (the ring's first for the last run).
            let last = pts[s + if k1 == n { 0 } else { k1 }][1];
            let (lo, hi) = pts[s + k0..s + k1]
                .iter()
                .fold((last, last), |(lo, hi), q| (lo.min(q[1]), hi.max(q[1])));
            runs.push([lo, hi]);
        }
    }
    runs
}

/// What the compositor does, in order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Op {
    /// Draw item `i` onto the current layer.
    Draw(usize),
    /// Start a transparent layer.
    Push,
    /// Composite the current layer onto the one below with `opacity` and `blend`;
    /// `group` numbers the group among those with an opacity parameter, in walk order
    /// (its slot in [`crate::scene::ParamLayout::groups`]); `None` for a group inside a
    /// clip path, drawn opaque.
    Pop {
        /// Layer opacity.
        opacity: f32,
        /// Parameter group index.
        group: Option<usize>,
        /// Blend mode.
        blend: BlendMode,
    },
    /// Start a transparent mask layer (a clip path's shapes or a mask's content).
    PushMask,
    /// Multiply the layer below the current one by the current layer's factor (`kind`),
    /// pixel by pixel, and drop the current layer; where the mask layer has no pixels
    /// the factor is 0.
    PopMask {
        /// Luminance or alpha.
        kind: MaskKind,
    },
}

/// The geometry of one path, kept for the backward pass.
#[derive(Clone, Debug, Default)]
pub(crate) struct PathGeom {
    /// The flattened centerline (device pixels).
    pub(crate) flat: Flattened,
    /// Chord counts used, one per segment.
    pub(crate) counts: ChordCounts,
    /// Device → stroke frame linear map `[a, b, c, d]`, when the path is stroked.
    pub(crate) frame_inv: Option<[f64; 4]>,
    /// The dashed centerline in the stroke frame, when the stroke is dashed (and the
    /// pattern was not dropped for a solid stroke).
    pub(crate) dashed: Option<Dashed>,
}

/// Where a group's layer lies, so that a band it does not touch skips it and a band it
/// touches allocates and composites only the group's box.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct GroupSpan {
    /// Index in [`Prepared::ops`] of the group's [`Op::Pop`] (or [`Op::PopMask`]).
    pub(crate) end: usize,
    /// Number of groups opened up to and including this group's descendants (the next
    /// group opened after it has this index).
    pub(crate) groups_end: usize,
    /// Pixels the group's content can touch, `[x0, y0, x1, y1]` (end exclusive, within
    /// the canvas): the union of the boxes of the items drawn inside. `None` when
    /// nothing inside reaches the canvas.
    pub(crate) rect: Option<[usize; 4]>,
    /// For a group with filters, its index in [`Prepared::filters`]; `rect` is then the
    /// filter layer's.
    pub(crate) filter: Option<usize>,
}

/// A scene ready to be rasterized.
#[derive(Clone, Debug)]
pub struct Prepared {
    /// Canvas width in pixels.
    pub(crate) width: u32,
    /// Canvas height in pixels.
    pub(crate) height: u32,
    /// Compositing program.
    pub(crate) ops: Vec<Op>,
    /// Drawable items.
    pub(crate) items: Vec<Item>,
    /// Per path geometry, in paint order.
    pub(crate) geoms: Vec<PathGeom>,
    /// Per layer, group or mask, in the order of the [`Op::Push`]es and
    /// [`Op::PushMask`]es.
    pub(crate) groups: Vec<GroupSpan>,
    /// Paths (paint order) whose dash pattern was dropped for a solid stroke because it
    /// would cut more than [`MAX_DASHES_PER_PATH`] dashes; see [`warnings`].
    pub(crate) solid_dashes: Vec<usize>,
    /// Whether the geometry the backward pass needs was kept ([`prepare`]) or dropped
    /// ([`prepare_forward`]). Outline recipes are never kept: the backward pass rebuilds
    /// them one stroke at a time from the kept centerline ([`stroke_outline`]).
    pub(crate) for_backward: bool,
    /// The flattening tolerance used, in device pixels.
    pub(crate) tolerance: f64,
    /// [`RenderOptions::exact_overlaps`](super::RenderOptions::exact_overlaps).
    pub(crate) exact_overlaps: bool,
    /// Tests' reference for exact overlaps: every cell of every item searched.
    #[cfg(test)]
    pub(crate) search_everywhere: bool,
    /// Tests' reference for the sparse rows of solid items: every row drawn whole.
    #[cfg(test)]
    pub(crate) dense_rows: bool,
    /// [`RenderOptions::exact_filters`](super::RenderOptions::exact_filters).
    pub(crate) exact_filters: bool,
    /// The groups with filters, in the order of their [`Op::Push`]es.
    pub(crate) filters: Vec<FilterLayer>,
}

impl Prepared {
    /// Prepares `scene` once for any number of [`render_prepared`](super::render_prepared)
    /// and [`backward_with_stats`](super::backward_with_stats) calls, flattened at
    /// `opts.tolerance` with chord counts chosen from the scene as it is now.
    pub fn new(scene: &Scene, opts: &super::RenderOptions) -> Prepared {
        let mut p = prepare_with(scene, opts.tolerance, None, true, opts.exact_filters);
        p.set_exact_overlaps(opts.exact_overlaps);
        p
    }

    /// Turns [`RenderOptions::exact_overlaps`](super::RenderOptions::exact_overlaps) on
    /// or off; on, finds which items can overlap themselves ([`Item::can_overlap`]).
    pub(crate) fn set_exact_overlaps(&mut self, on: bool) {
        self.exact_overlaps = on;
        if on {
            for it in &mut self.items {
                // A crisp item's winding numbers at pixel centers are exact already.
                it.can_overlap =
                    !it.crisp && !super::overlap::rings_cannot_overlap(&it.pts, &it.rings);
            }
        }
    }

    /// Canvas size in pixels, `(width, height)`.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// A rough count of what rendering costs, in pixel-sized units: every item's box
    /// within the canvas (four times over for a gradient paint), plus a few per vertex
    /// (what accumulating an edge costs).
    pub(crate) fn work(&self) -> f64 {
        const PER_EDGE: f64 = 4.0;
        const PER_GRADIENT_PIXEL: f64 = 4.0;
        // Bicubic sampling reads sixteen pixels.
        const PER_IMAGE_PIXEL: f64 = 8.0;
        let (w, h) = (self.width as f64, self.height as f64);
        self.items
            .iter()
            .map(|it| {
                let b = it.bbox;
                let cw = (b[2].min(w) - b[0].max(0.0)).max(0.0);
                let ch = (b[3].min(h) - b[1].max(0.0)).max(0.0);
                let per_pixel = match it.paint {
                    PaintEval::Solid(_) => 1.0,
                    PaintEval::Gradient(_) => PER_GRADIENT_PIXEL,
                    PaintEval::Image(_) => PER_IMAGE_PIXEL,
                };
                cw * ch * per_pixel + PER_EDGE * it.pts.len() as f64
            })
            .sum()
    }

    /// The least number of row bands a parallel task takes: all of them (the calling
    /// thread renders alone) for a scene of less [`work`](Self::work) than
    /// [`SERIAL_WORK`], which would take longer to hand to other threads than to draw;
    /// one otherwise. The bands and their order are the same either way, and so are the
    /// bits.
    pub(crate) fn min_bands_per_task(&self) -> usize {
        if self.work() < SERIAL_WORK {
            usize::MAX
        } else {
            1
        }
    }
}

/// Prepares `scene` with flattening `tolerance` (device pixels). With `counts` (one list
/// per path, as in [`PathGeom::counts`]) the chord counts are fixed instead of computed.
/// Keeps everything the backward pass needs.
pub(crate) fn prepare(scene: &Scene, tolerance: f64, counts: Option<&[ChordCounts]>) -> Prepared {
    prepare_with(scene, tolerance, counts, true, false)
}

/// Like [`prepare`] for a forward render only: the per-path geometry the backward pass
/// reads (flattened points and their provenance, dashes, outline recipes) is not kept,
/// which makes memory a fraction of [`prepare`]'s on scenes with many stroked curves.
/// Filters are evaluated exactly with `exact_filters`
/// ([`RenderOptions::exact_filters`](super::RenderOptions::exact_filters)).
pub(crate) fn prepare_forward(scene: &Scene, tolerance: f64, exact_filters: bool) -> Prepared {
    prepare_with(scene, tolerance, None, false, exact_filters)
}

fn prepare_with(
    scene: &Scene,
    tolerance: f64,
    counts: Option<&[ChordCounts]>,
    for_backward: bool,
    exact_filters: bool,
) -> Prepared {
    let mut p = Prepared {
        width: scene.width,
        height: scene.height,
        ops: Vec::new(),
        items: Vec::new(),
        geoms: Vec::new(),
        groups: Vec::new(),
        solid_dashes: Vec::new(),
        for_backward,
        tolerance,
        exact_overlaps: false,
        #[cfg(test)]
        search_everywhere: false,
        #[cfg(test)]
        dense_rows: false,
        exact_filters,
        filters: Vec::new(),
    };
    // Each path's geometry and items depend on that path alone: built in parallel (in
    // paint order, so the result is the same on any thread count), then placed by the
    // walk that lays out groups.
    let mut paths: Vec<(&Path, Role)> = Vec::new();
    scene.for_each_path_role(|q, role| paths.push((q, role)));
    let fixed = |ix: usize| counts.and_then(|c| c.get(ix)).map(|c| c.as_slice());
    let size = (scene.width, scene.height);
    let only: Vec<&Path> = paths.iter().map(|(q, _)| *q).collect();
    let verdicts = dash_verdicts(&only, size, tolerance, fixed);
    let build = |(ix, &(path, role)): (usize, &(&Path, Role))| {
        let cut = verdicts[ix].as_ref().is_some_and(|v| v.cut);
        build_path(
            (path, role),
            ix,
            size,
            tolerance,
            fixed(ix),
            for_backward,
            cut,
        )
    };
    let built: Vec<Built> = if paths.len() >= PARALLEL_PATHS {
        paths.par_iter().enumerate().map(build).collect()
    } else {
        paths.iter().enumerate().map(build).collect()
    };
    let mut b = Builder {
        built: built.into_iter(),
        out: &mut p,
        param_groups: 0,
        filter_depth: 0,
    };
    b.nodes(&scene.nodes, Role::Paint);
    p
}

/// Scenes with at least this many paths are prepared in parallel (below, the threads'
/// start-up costs more than the work).
const PARALLEL_PATHS: usize = 16;

/// The pixels an item can touch, `[x0, y0, x1, y1]` (end exclusive, clipped to the
/// canvas): its box grown as [`BandRenderer::winding`](super::render) grows it (one pixel
/// each side, two guard columns on the right).
pub(crate) fn item_rect(bbox: [f64; 4], width: u32, height: u32) -> Option<[usize; 4]> {
    let (w, h) = (width as f64, height as f64);
    if bbox[2] <= 0.0 || bbox[0] >= w {
        return None;
    }
    let x0 = (bbox[0].floor() - 1.0).clamp(0.0, w);
    let x1 = (bbox[2].ceil() + 2.0).clamp(0.0, w);
    let y0 = (bbox[1].floor() - 1.0).clamp(0.0, h);
    let y1 = (bbox[3].ceil() + 1.0).clamp(0.0, h);
    (x0 < x1 && y0 < y1).then_some([x0 as usize, y0 as usize, x1 as usize, y1 as usize])
}

/// Where a stroke's dashes can show: the canvas grown by how far a cap or join can reach
/// from the centerline, in device pixels (with a pixel to spare).
fn dash_rect(s: &Stroke, width: u32, height: u32) -> [f64; 4] {
    let [a, b, c, d] = s.frame;
    let norm = (a * a + b * b + c * c + d * d).sqrt();
    let m = 2.0 + 0.5 * s.width.abs() * s.miter_limit.max(2.0) * norm;
    [-m, -m, width as f64 + m, height as f64 + m]
}

/// The stroke frame's inverse, when the frame is invertible.
fn frame_inverse(s: &Stroke) -> Option<[f64; 4]> {
    let [a, b, c, d] = s.frame;
    let det = a * d - b * c;
    let inv = [d / det, -b / det, -c / det, a / det];
    inv.iter().all(|v| v.is_finite()).then_some(inv)
}

/// The outline of `path`'s stroke with its recipes, in the stroke frame, rebuilt from a
/// prepared geometry exactly as [`prepare`] built it (vertex `j` is vertex `j` of the
/// stroke item): `fpts` is the flattened centerline mapped into the stroke frame.
pub(crate) fn stroke_outline(
    s: &Stroke,
    geom: &PathGeom,
    fpts: &[Point],
    tolerance: f64,
) -> super::stroke::Outline {
    let style = stroke_style(s, tolerance, true);
    match &geom.dashed {
        Some(d) => outline(&d.pts, &d.corner, &d.contours, style),
        None => outline(fpts, &geom.flat.corner, &geom.flat.contours, style),
    }
}

/// The stroke's style in its frame; `for_backward` keeps recipes instead of points.
pub(crate) fn stroke_style(s: &Stroke, tolerance: f64, for_backward: bool) -> Style {
    Style {
        half_width: 0.5 * s.width,
        join: s.join,
        cap: s.cap,
        miter_limit: s.miter_limit,
        tolerance: frame_tolerance(s, tolerance),
        keep_recipes: for_backward,
        keep_points: !for_backward,
    }
}

/// Upper bound of the cost of dashing `flat` (device pixels) with `s`'s pattern, in
/// butt-capped dashes (a dash whose caps add vertices counts for more), before cutting.
fn dash_cost(
    s: &Stroke,
    pattern: &[f64],
    flat: &Flattened,
    fpts: &[Point],
    style: &Style,
    width: u32,
    height: u32,
) -> f64 {
    let visible = Visible {
        device: &flat.pts,
        rect: dash_rect(s, width, height),
    };
    let n = dash_count(fpts, &flat.contours, pattern, Some(visible));
    n * (1.0 + 0.5 * style.cap_vertices() as f64)
}

/// Warnings about how `scene` will be drawn at `opts`, one line each (the caller adds
/// the file name): strokes whose dash pattern would cut more than
/// [`MAX_DASHES_PER_PATH`] dashes are drawn solid. Flattens only the dashed strokes;
/// call it after loading, before rendering.
pub fn warnings(scene: &Scene, opts: &super::RenderOptions) -> Vec<String> {
    let mut paths: Vec<&Path> = Vec::new();
    scene.for_each_path(|q| paths.push(q));
    let size = (scene.width, scene.height);
    dash_verdicts(&paths, size, opts.tolerance, |_| None)
        .iter()
        .enumerate()
        .filter_map(|(k, v)| {
            let v = v.as_ref().filter(|v| !v.cut)?;
            Some(dash_warning(paths[k], k, v.cost))
        })
        .collect()
}

/// Whether a dashed stroke's dashes are cut, and how many it would cut.
struct DashVerdict {
    /// The count [`dash_cost`] gives.
    cost: f64,
    /// Whether the dashes are cut (else the stroke is drawn solid).
    cut: bool,
}

/// The dashes `path`'s stroke would cut ([`dash_cost`]); `None` without a dash pattern
/// to cut.
fn path_dash_cost(
    path: &Path,
    (width, height): (u32, u32),
    tolerance: f64,
    fixed: Option<&[u32]>,
) -> Option<f64> {
    let s = path.stroke.as_ref()?;
    let pattern = s.dash.as_ref()?;
    if !(s.width > 0.0) {
        return None;
    }
    let inv = frame_inverse(s)?;
    let visible = flatten_rect(path, width, height);
    let (flat, _) = flatten(path, tolerance, visible, fixed, false);
    let fpts: Vec<Point> = flat
        .pts
        .iter()
        .map(|q| [inv[0] * q[0] + inv[2] * q[1], inv[1] * q[0] + inv[3] * q[1]])
        .collect();
    let style = stroke_style(s, tolerance, false);
    Some(dash_cost(s, pattern, &flat, &fpts, &style, width, height))
}

/// Per path (paint order): `None` without a dash pattern, else whether its dashes are
/// cut: at most [`MAX_DASHES_PER_PATH`] from one path, and at most
/// [`MAX_DASHES_PER_SCENE`] from all, granted in paint order (so the same paths on any
/// thread count, and in the forward and backward passes).
fn dash_verdicts<'a>(
    paths: &[&Path],
    size: (u32, u32),
    tolerance: f64,
    fixed: impl Fn(usize) -> Option<&'a [u32]> + Sync,
) -> Vec<Option<DashVerdict>> {
    let cost = |(ix, path): (usize, &&Path)| path_dash_cost(path, size, tolerance, fixed(ix));
    let costs: Vec<Option<f64>> = if paths.len() >= PARALLEL_PATHS {
        paths.par_iter().enumerate().map(cost).collect()
    } else {
        paths.iter().enumerate().map(cost).collect()
    };
    let mut total = 0.0;
    costs
        .into_iter()
        .map(|c| {
            c.map(|cost| {
                let cut = cost <= MAX_DASHES_PER_PATH as f64
                    && total + cost <= MAX_DASHES_PER_SCENE as f64;
                if cut {
                    total += cost;
                }
                DashVerdict { cost, cut }
            })
        })
        .collect()
}

fn dash_warning(path: &Path, index: usize, cost: f64) -> String {
    let name = if path.id.is_empty() {
        format!("path #{}", index + 1)
    } else {
        format!("path \"{}\"", path.id)
    };
    let about = if cost.is_finite() {
        format!("about {cost:.0}")
    } else {
        "too many".to_string()
    };
    if cost <= MAX_DASHES_PER_PATH as f64 {
        return format!(
            "{name}: stroke-dasharray would cut {about} dashes, past the drawing's limit of \
             {MAX_DASHES_PER_SCENE} over all paths; stroked solid"
        );
    }
    format!(
        "{name}: stroke-dasharray would cut {about} dashes (limit {MAX_DASHES_PER_PATH}); stroked solid"
    )
}

struct Builder<'a> {
    /// Every path's geometry and items, in paint order.
    built: std::vec::IntoIter<Built>,
    out: &'a mut Prepared,
    /// Groups with an opacity parameter opened so far.
    param_groups: usize,
    /// Filtered groups open around the current node: inside one, a filtered group's
    /// layer is not computed (the outer group's content scene renders it).
    filter_depth: usize,
}

/// One path prepared: its geometry and items (in drawing order).
struct Built {
    geom: PathGeom,
    items: [Option<Item>; 2],
    /// The dash pattern was dropped for a solid stroke.
    solid_dash: bool,
}

impl Builder<'_> {
    fn nodes(&mut self, nodes: &[Node], role: Role) {
        for n in nodes {
            match n {
                Node::Path(_) => self.path(),
                // A group that is only a transform is no layer: its children are drawn
                // as its parent's (it has no opacity parameter either).
                Node::Group(g) if !g.layer => self.nodes(&g.children, role),
                Node::Group(g) => {
                    // The walk order of the parameters: a group's opacity first.
                    let group = (role == Role::Paint).then(|| {
                        self.param_groups += 1;
                        self.param_groups - 1
                    });
                    let span = self.open(Op::Push);
                    if role == Role::Paint && !g.filters.is_empty() {
                        self.filtered(g, span, group.unwrap_or(0));
                        continue;
                    }
                    self.layer(g, role);
                    self.out.ops.push(Op::Pop {
                        opacity: g.opacity.clamp(0.0, 1.0) as f32,
                        group,
                        blend: g.blend,
                    });
                    self.close(span);
                }
            }
        }
    }

    /// A layer's body: the group's children, then its clip path and its mask, each a
    /// mask layer multiplying the layer.
    fn layer(&mut self, g: &Group, role: Role) {
        self.nodes(&g.children, role);
        self.clip_and_mask(g, role);
    }

    /// A group with filters (its [`Op::Push`] opened as `span`, `param_group` its
    /// opacity's group index): its children's ops stay in the program for the backward
    /// pass's numbering but are skipped when drawing; the layer is the filtered
    /// rendering of the children, computed here.
    fn filtered(&mut self, g: &Group, span: (usize, usize), param_group: usize) {
        let fi = self.out.filters.len();
        let (w, h) = (self.out.width, self.out.height);
        let content = Scene {
            width: w,
            height: h,
            nodes: g.children.clone(),
        };
        let rect = layer_rect(&g.filters, w, h);
        let image = match rect {
            Some(r) if self.filter_depth == 0 => {
                let opts = super::RenderOptions {
                    tolerance: self.out.tolerance,
                    exact_overlaps: false,
                    exact_filters: self.out.exact_filters,
                };
                let src = super::render(&content, &opts);
                filter::apply(
                    &g.filters,
                    r,
                    crop(&src.data, w as usize, r),
                    opts.exact_filters,
                )
            }
            _ => Vec::new(),
        };
        self.out.filters.push(FilterLayer {
            rect: rect.unwrap_or([0; 4]),
            image,
            body_end: 0,
            groups_end: 0,
            content,
            filters: g.filters.clone(),
            param_group,
        });
        self.filter_depth += 1;
        self.nodes(&g.children, Role::Paint);
        self.filter_depth -= 1;
        self.out.filters[fi].body_end = self.out.ops.len();
        self.out.filters[fi].groups_end = self.out.groups.len();
        self.clip_and_mask(g, Role::Paint);
        self.out.ops.push(Op::Pop {
            opacity: g.opacity.clamp(0.0, 1.0) as f32,
            group: Some(param_group),
            blend: g.blend,
        });
        self.close(span);
        let s = &mut self.out.groups[span.0];
        s.rect = rect;
        s.filter = Some(fi);
    }

    /// A layer's clip path and mask, each a mask layer multiplying the layer.
    fn clip_and_mask(&mut self, g: &Group, role: Role) {
        if let Some(c) = &g.clip {
            let span = self.open(Op::PushMask);
            self.layer(&c.content, Role::Clip);
            self.out.ops.push(Op::PopMask {
                kind: MaskKind::Alpha,
            });
            self.close(span);
        }
        if let Some(m) = &g.mask {
            let span = self.open(Op::PushMask);
            self.layer(&m.content, role);
            self.out.ops.push(Op::PopMask { kind: m.kind });
            self.close(span);
        }
    }

    /// Pushes `op` and a span to fill in by [`close`](Self::close): `(span, first item)`.
    fn open(&mut self, op: Op) -> (usize, usize) {
        let span = self.out.groups.len();
        self.out.groups.push(GroupSpan {
            end: 0,
            groups_end: 0,
            rect: None,
            filter: None,
        });
        self.out.ops.push(op);
        (span, self.out.items.len())
    }

    /// Fills in a span opened by [`open`](Self::open), once its closing op is pushed:
    /// the union of the boxes of the items drawn inside.
    fn close(&mut self, (span, first_item): (usize, usize)) {
        let (w, h) = (self.out.width, self.out.height);
        let mut rect: Option<[usize; 4]> = None;
        for it in &self.out.items[first_item..] {
            if let Some(r) = item_rect(it.bbox, w, h) {
                rect = Some(union(rect, r));
            }
        }
        // A filtered group inside reaches as far as its filter region.
        for g in &self.out.groups[span + 1..] {
            if let (Some(_), Some(r)) = (g.filter, g.rect) {
                rect = Some(union(rect, r));
            }
        }
        self.out.groups[span] = GroupSpan {
            end: self.out.ops.len() - 1,
            groups_end: self.out.groups.len(),
            rect,
            filter: None,
        };
    }

    fn path(&mut self) {
        let built = self.built.next().expect("a built path per path node");
        let ix = self.out.geoms.len();
        if built.solid_dash {
            self.out.solid_dashes.push(ix);
        }
        for it in built.items.into_iter().flatten() {
            self.out.ops.push(Op::Draw(self.out.items.len()));
            self.out.items.push(it);
        }
        self.out.geoms.push(built.geom);
    }
}

/// The smallest rectangle `[x0, y0, x1, y1]` holding `u` (if any) and `r`.
fn union(u: Option<[usize; 4]>, r: [usize; 4]) -> [usize; 4] {
    match u {
        None => r,
        Some(u) => [
            u[0].min(r[0]),
            u[1].min(r[1]),
            u[2].max(r[2]),
            u[3].max(r[3]),
        ],
    }
}

/// Flattens path `ix` (paint order) of a `width × height` canvas and builds its items,
/// with the chord counts `fixed` when given; `keep` keeps what the backward pass needs;
/// a dashed stroke is cut when `cut_dashes` ([`dash_verdicts`]), else drawn solid.
fn build_path(
    (path, role): (&Path, Role),
    ix: usize,
    (width, height): (u32, u32),
    tolerance: f64,
    fixed: Option<&[u32]>,
    keep: bool,
    cut_dashes: bool,
) -> Built {
    let visible = flatten_rect(path, width, height);
    let (flat, counts) = flatten(path, tolerance, visible, fixed, keep);
    let mut geom = PathGeom {
        flat,
        counts,
        ..PathGeom::default()
    };
    let fill_item = path.fill.as_ref().and_then(|f| {
        // A clip path's shape is drawn opaque black: only its coverage counts.
        let paint = match role {
            Role::Paint => PaintEval::new(&f.paint, f.opacity)?,
            Role::Clip => PaintEval::new(&crate::scene::Paint::Solid([0.0; 3]), 1.0)?,
        };
        let mut pts = Vec::with_capacity(geom.flat.pts.len());
        let mut src = Vec::with_capacity(if keep { geom.flat.pts.len() } else { 0 });
        let mut rings = Vec::new();
        for c in &geom.flat.contours {
            if c.len >= 3 {
                rings.push((pts.len(), c.len));
                pts.extend_from_slice(&geom.flat.pts[c.start..c.start + c.len]);
                if keep {
                    src.extend(c.start as u32..(c.start + c.len) as u32);
                }
            }
        }
        item(
            ix,
            ItemKind::Fill,
            pts,
            src,
            rings,
            f.rule == FillRule::EvenOdd,
            paint,
        )
    });
    let mut solid = false;
    let stroke_item = path.stroke.as_ref().and_then(|s| {
        if !(s.width > 0.0) {
            return None;
        }
        // A clip shape's stroke (a pattern on a stroke) is drawn opaque black too.
        let paint = match role {
            Role::Paint => PaintEval::new(&s.paint, s.opacity)?,
            Role::Clip => PaintEval::new(&crate::scene::Paint::Solid([0.0; 3]), 1.0)?,
        };
        let [a, b, c, d] = s.frame;
        let inv = frame_inverse(s)?;
        let to_frame = |q: &Point| [inv[0] * q[0] + inv[2] * q[1], inv[1] * q[0] + inv[3] * q[1]];
        let fpts: Vec<Point> = geom.flat.pts.iter().map(to_frame).collect();
        let style = stroke_style(s, tolerance, false);
        // Past the dash limits the pattern is dropped and the stroke drawn solid.
        let pattern = s.dash.as_ref().filter(|_| cut_dashes);
        solid = s.dash.is_some() && !cut_dashes;
        let mut ol = match pattern {
            Some(pattern) => {
                let visible = Visible {
                    device: &geom.flat.pts,
                    rect: dash_rect(s, width, height),
                };
                let dashed = dash(
                    &fpts,
                    &geom.flat.corner,
                    &geom.flat.contours,
                    pattern,
                    s.dash_offset,
                    Some(visible),
                );
                drop(fpts);
                let ol = outline(&dashed.pts, &dashed.corner, &dashed.contours, style);
                if keep {
                    geom.dashed = Some(dashed);
                }
                ol
            }
            None => {
                let ol = outline(&fpts, &geom.flat.corner, &geom.flat.contours, style);
                drop(fpts);
                ol
            }
        };
        // The outline's points become the item's, mapped to device space in place.
        let pts: Vec<Point> = std::mem::take(&mut ol.pts)
            .into_iter()
            .map(|q| [a * q[0] + c * q[1], b * q[0] + d * q[1]])
            .collect();
        let rings = std::mem::take(&mut ol.rings);
        let src = Vec::new();
        geom.frame_inv = Some(inv);
        item(ix, ItemKind::Stroke, pts, src, rings, false, paint)
    });
    if !keep {
        // Only the chord counts are read after a forward render (gradient checks).
        geom.flat = Flattened::default();
    }
    let mut items = if path.stroke_first {
        [stroke_item, fill_item]
    } else {
        [fill_item, stroke_item]
    };
    for it in items.iter_mut().flatten() {
        it.crisp = path.crisp;
    }
    Built {
        geom,
        items,
        solid_dash: solid,
    }
}

fn item(
    path: usize,
    kind: ItemKind,
    pts: Vec<Point>,
    src: Vec<u32>,
    rings: Vec<(usize, usize)>,
    evenodd: bool,
    paint: PaintEval,
) -> Option<Item> {
    if rings.is_empty() {
        return None;
    }
    let mut bbox = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for q in &pts {
        bbox[0] = bbox[0].min(q[0]);
        bbox[1] = bbox[1].min(q[1]);
        bbox[2] = bbox[2].max(q[0]);
        bbox[3] = bbox[3].max(q[1]);
    }
    if !bbox.iter().all(|v| v.is_finite()) {
        return None;
    }
    let (mut grid_aligned, mut row_crossings) = (false, 0.0);
    for &(s, n) in &rings {
        for k in 0..n {
            let (a, b) = (pts[s + k], pts[s + (k + 1) % n]);
            grid_aligned |= (a[0] == b[0] && a[0] == floor_f64(a[0]))
                || (a[1] == b[1] && a[1] == floor_f64(a[1]));
            if a[1] != b[1] {
                row_crossings += (a[1] - b[1]).abs() + 1.0;
            }
        }
    }
    Some(Item {
        grid_aligned,
        row_crossings,
        // Found by `Prepared::set_exact_overlaps` when it is asked for.
        can_overlap: true,
        crisp: false,
        path,
        kind,
        runs: edge_runs(&pts, &rings),
        pts,
        src,
        rings,
        evenodd,
        paint,
        bbox,
    })
}

#[cfg(test)]
mod tests {
    #[test]
    /// The load-time chord limit (`Scene::chord_estimate`) counts what the flattener makes.
    fn chord_estimate_matches_the_flattener() {
        use crate::scene::{Paint, Stroke};
        let mut p = Path::new("c");
        p.move_to([0.0, 0.0]);
        p.cubic_to([90.0, 0.0], [0.0, 90.0], [90.0, 90.0]);
        p.line_to([10.0, 50.0]);
        p.close();
        p.stroke = Some(Stroke::new(Paint::Solid([0.0; 3]), 2.0));
        let mut s = Scene::new(100, 100);
        s.nodes.push(Node::Path(p));
        let tol = crate::raster::RenderOptions::default().tolerance;
        let prepared = prepare(&s, tol, None);
        let flat = prepared.geoms[0].counts.iter().sum::<u32>() as u64;
        // Every chord plus one start point per subpath.
        assert_eq!(s.chord_estimate(tol), flat + 1);
    }

    use super::*;
    use crate::Sizing;
    use crate::raster::{RenderOptions, render, render_backward};

    fn load(svg: &str) -> Scene {
        Scene::from_svg_str(svg, "t.svg", Sizing::Natural).unwrap()
    }

    #[test]
    fn small_scenes_are_drawn_on_one_thread_large_ones_on_all() {
        let small = load(
            r##"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64">
            <rect width="64" height="64" fill="#fff"/>
            <circle cx="32" cy="32" r="20" fill="#123"/></svg>"##,
        );
        let p = prepare(&small, 0.02, None);
        assert!(
            p.work() > 64.0 * 64.0 && p.work() < SERIAL_WORK,
            "{}",
            p.work()
        );
        assert_eq!(p.min_bands_per_task(), usize::MAX);
        let large = crate::scene::random::curved_paths(100, 256, 3);
        let p = prepare(&large, 0.02, None);
        assert!(p.work() >= SERIAL_WORK, "{}", p.work());
        assert_eq!(p.min_bands_per_task(), 1);
        // A gradient paint counts its box four times over.
        let gradient = load(
            r##"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64">
            <linearGradient id="g"><stop offset="0" stop-color="red"/>
            <stop offset="1" stop-color="blue"/></linearGradient>
            <rect width="64" height="64" fill="url(#g)"/></svg>"##,
        );
        let p = prepare(&gradient, 0.02, None);
        let rect = 4.0 * 64.0 * 64.0;
        assert!(p.work() >= rect && p.work() < rect + 100.0, "{}", p.work());
    }

    #[test]
    fn paths_prepared_in_parallel_come_out_in_paint_order() {
        // More paths than `PARALLEL_PATHS`, in nested groups, filled, stroked, dashed.
        let mut body = String::new();
        for k in 0..3 * PARALLEL_PATHS {
            let (x, y) = (5 + (k * 37) % 180, 5 + (k * 53) % 180);
            let shape = format!(
                r#"<path d="M{x} {y} c20 -10 30 25 10 30 s-25 5 -10 -30z" fill="rgb({k},90,200)" stroke="black" stroke-width="{}" {}/>"#,
                1 + k % 4,
                if k % 5 == 0 {
                    r#"stroke-dasharray="4 3""#
                } else {
                    ""
                }
            );
            body += &if k % 7 == 3 {
                format!(r#"<g opacity="0.5">{shape}</g>"#)
            } else {
                shape
            };
        }
        let scene = load(&format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="200" height="200">{body}</svg>"#
        ));
        let in_pool = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| prepare(&scene, 0.02, None))
        };
        let (one, four) = (in_pool(1), in_pool(4));
        assert_eq!(one.items.len(), four.items.len());
        assert!(
            one.items.len() > 4 * PARALLEL_PATHS,
            "{} items",
            one.items.len()
        );
        assert_eq!(
            (&one.ops, &one.solid_dashes),
            (&four.ops, &four.solid_dashes)
        );
        for (a, b) in one.items.iter().zip(&four.items) {
            assert_eq!((a.path, a.kind, a.evenodd), (b.path, b.kind, b.evenodd));
            assert_eq!(
                (&a.pts, &a.src, &a.rings, &a.runs, a.bbox),
                (&b.pts, &b.src, &b.rings, &b.runs, b.bbox)
            );
        }
        // Items follow the paths' paint order.
        assert!(one.items.windows(2).all(|w| w[0].path <= w[1].path));
        let counts = |p: &Prepared| p.geoms.iter().map(|g| g.counts.clone()).collect::<Vec<_>>();
        assert_eq!(counts(&one), counts(&four));
        let fixed = prepare(&scene, 0.5, Some(&counts(&one)));
        assert_eq!(
            counts(&fixed),
            counts(&one),
            "fixed chord counts reach their own paths"
        );
    }

    #[test]
    fn edge_runs_skip_only_edges_away_from_the_band() {
        // Two rings (an outer circle and a star-shaped hole) of many short edges each.
        let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="200" height="200">
          <path fill-rule="evenodd" d="M100 10 A90 90 0 1 1 99.9 10 Z
            M100 40 L120 90 L170 100 L120 110 L100 160 L80 110 L30 100 L80 90 Z"/></svg>"#;
        let p = prepare(&load(svg), 0.02, None);
        let it = &p.items[0];
        assert_eq!(it.rings.len(), 2);
        assert!(it.pts.len() > 10 * RUN_EDGES, "{} vertices", it.pts.len());
        let mut all = Vec::new();
        for &(s, n) in &it.rings {
            for k in 0..n {
                all.push((s + k, s + (k + 1) % n));
            }
        }
        let bands = (0..=420)
            .map(|k| k as f64 * 0.5)
            .flat_map(|y| [(y, y), (y, y + 16.0)]);
        for (ylo, yhi) in bands {
            let mut seen = Vec::new();
            it.for_each_edge_near(ylo, yhi, |a, b| seen.push((a, b)));
            // In ring order, a subsequence of all edges…
            let mut rest = all.iter();
            assert!(
                seen.iter().all(|e| rest.any(|f| f == e)),
                "band {ylo}..{yhi}"
            );
            // …holding every edge that touches the band.
            for &(a, b) in &all {
                let (ya, yb) = (it.pts[a][1], it.pts[b][1]);
                if ya.max(yb) >= ylo && ya.min(yb) <= yhi {
                    assert!(
                        seen.contains(&(a, b)),
                        "band {ylo}..{yhi} lost edge {a}-{b}"
                    );
                }
            }
            if yhi - ylo < 20.0 {
                assert!(
                    seen.len() < all.len() / 2,
                    "band {ylo}..{yhi}: {} of {}",
                    seen.len(),
                    all.len()
                );
            }
        }
    }

    fn rect(dash: &str) -> String {
        format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="40"><rect x="5" y="5" width="28" height="28" fill="none" stroke="black" stroke-width="3" {dash}/></svg>"#
        )
    }

    #[test]
    fn dasharray_past_the_limit_strokes_solid_forward_and_backward() {
        let opts = RenderOptions::default();
        let dashed = load(&rect(r#"stroke-dasharray="1e-5""#));
        let solid = load(&rect(""));
        let w = warnings(&dashed, &opts);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(
            w[0].contains("stroked solid") && w[0].contains("100000"),
            "{w:?}"
        );
        assert!(warnings(&solid, &opts).is_empty());
        // An ordinary pattern is cut, with no warning.
        let ordinary = load(&rect(r#"stroke-dasharray="4 2""#));
        assert!(warnings(&ordinary, &opts).is_empty());
        let p = prepare(&ordinary, opts.tolerance, None);
        assert!(p.solid_dashes.is_empty() && p.geoms[0].dashed.is_some());

        let p = prepare(&dashed, opts.tolerance, None);
        assert_eq!(p.solid_dashes, vec![0]);
        assert!(p.geoms[0].dashed.is_none());
        let q = prepare(&solid, opts.tolerance, None);
        assert_eq!(p.items[0].pts, q.items[0].pts);
        assert_eq!(render(&dashed, &opts).data, render(&solid, &opts).data);
        // The backward pass sees the same solid stroke.
        let mut d = crate::Image::new(40, 40);
        for (i, px) in d.data.iter_mut().enumerate() {
            *px = [0.1, -0.2, 0.3, (i % 7) as f32 * 0.05];
        }
        assert_eq!(
            render_backward(&dashed, &opts, &d),
            render_backward(&solid, &opts, &d)
        );
    }

    /// Dashed strokes each within the per-path limit but together past the drawing's
    /// (a pattern's tiles, a style dashing every element): the first ones in paint order
    /// are cut, the rest drawn solid and named.
    #[test]
    fn dashes_past_the_drawing_limit_stroke_solid_in_paint_order() {
        let opts = RenderOptions::default();
        let one = r#"<rect x="5" y="5" width="28" height="28" fill="none" stroke="black" stroke-width="3" stroke-dasharray="0.001"/>"#;
        let svg = format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="40">{}</svg>"#,
            one.repeat(30)
        );
        let s = load(&svg);
        let mut paths = Vec::new();
        s.for_each_path(|q| paths.push(q));
        let verdicts = dash_verdicts(&paths, (40, 40), opts.tolerance, |_| None);
        let cost = verdicts[0].as_ref().unwrap().cost;
        assert!(
            cost <= MAX_DASHES_PER_PATH as f64 && cost * 30.0 > MAX_DASHES_PER_SCENE as f64,
            "{cost}"
        );
        let granted = (MAX_DASHES_PER_SCENE as f64 / cost).floor() as usize;
        for (k, v) in verdicts.iter().enumerate() {
            assert_eq!(v.as_ref().unwrap().cut, k < granted, "path {k}");
        }
        let w = warnings(&s, &opts);
        assert_eq!(w.len(), 30 - granted, "{w:?}");
        assert!(
            w[0].starts_with(&format!("path #{}:", granted + 1)),
            "{w:?}"
        );
        assert!(w[0].contains("over all paths"), "{w:?}");
    }

    #[test]
    fn forward_prepare_draws_the_same_items() {
        let s = load(&rect(r#"stroke-dasharray="4 2" stroke-linejoin="round""#));
        let full = prepare(&s, 0.02, None);
        let fwd = prepare_forward(&s, 0.02, false);
        assert!(!fwd.for_backward && fwd.geoms[0].flat.pts.is_empty());
        assert_eq!(full.items.len(), fwd.items.len());
        for (a, b) in full.items.iter().zip(&fwd.items) {
            assert_eq!((&a.pts, &a.rings, a.bbox), (&b.pts, &b.rings, b.bbox));
        }
        assert_eq!(full.geoms[0].counts, fwd.geoms[0].counts);
    }

    #[test]
    fn group_rect_is_the_union_of_its_items() {
        let s = load(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="100" height="100"><g opacity="0.5"><rect x="10.5" y="20" width="5" height="5"/><g opacity="0.5"><rect x="50" y="60" width="10" height="10"/></g></g><g opacity="0.5"><rect x="-50" y="0" width="10" height="10"/></g></svg>"#,
        );
        let p = prepare(&s, 0.02, None);
        assert_eq!(p.groups.len(), 3);
        assert_eq!(p.groups[0].rect, Some([9, 19, 62, 71]));
        assert_eq!(p.groups[0].groups_end, 2);
        assert_eq!(p.groups[1].rect, Some([49, 59, 62, 71]));
        assert_eq!(p.groups[2].rect, None);
        assert!(matches!(
            p.ops[p.groups[0].end],
            Op::Pop { group: Some(0), .. }
        ));
    }
}
