//! Turning a scene into drawable polygons, once per render.

use super::dash::{Dashed, dash};
use super::flatten::{ChordCounts, Flattened, flatten};
use super::paint::PaintEval;
use super::stroke::{Outline, Style, outline};
use crate::scene::{FillRule, Node, Path, Point, Scene};

/// Whether an item is a path's fill or its stroke.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ItemKind {
    /// The fill.
    Fill,
    /// The stroke outline.
    Stroke,
}

/// One polygon set with one paint: a path's fill or its stroke.
#[derive(Clone, Debug)]
pub struct Item {
    /// Index of the path in paint order ([`Scene::for_each_path`] order).
    pub path: usize,
    /// Fill or stroke.
    pub kind: ItemKind,
    /// Polygon vertices, device pixels.
    pub pts: Vec<Point>,
    /// For a fill, the index in [`PathGeom::flat`] of each vertex; for a stroke, the index
    /// in [`PathGeom::outline`] (the identity).
    pub src: Vec<u32>,
    /// Closed rings as `(start, len)` into `pts`.
    pub rings: Vec<(usize, usize)>,
    /// Even-odd fill rule (strokes are always nonzero).
    pub evenodd: bool,
    /// The paint, opacity included.
    pub paint: PaintEval,
    /// Bounds of `pts`: `[xmin, ymin, xmax, ymax]`.
    pub bbox: [f64; 4],
    /// Whether some edge lies exactly on a pixel boundary (vertical at integer x or
    /// horizontal at integer y). Only then do pixels with a zero winding integral take
    /// part in the backward pass.
    pub grid_aligned: bool,
}

/// What the compositor does, in order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Op {
    /// Draw item `i` onto the current layer.
    Draw(usize),
    /// Start a transparent layer.
    Push,
    /// Composite the current layer onto the one below with `opacity`; `group` numbers the
    /// group in walk order (its slot in [`crate::scene::ParamLayout::groups`]).
    Pop {
        /// Layer opacity.
        opacity: f32,
        /// Group index.
        group: usize,
    },
}

/// The geometry of one path, kept for the backward pass.
#[derive(Clone, Debug, Default)]
pub struct PathGeom {
    /// The flattened centerline (device pixels).
    pub flat: Flattened,
    /// Chord counts used, one per segment.
    pub counts: ChordCounts,
    /// Device → stroke frame linear map `[a, b, c, d]`, when the path is stroked.
    pub frame_inv: Option<[f64; 4]>,
    /// The dashed centerline in the stroke frame, when the stroke is dashed.
    pub dashed: Option<Dashed>,
    /// The stroke outline in the stroke frame.
    pub outline: Option<Outline>,
}

/// A scene ready to be rasterized.
#[derive(Clone, Debug)]
pub struct Prepared {
    /// Canvas width in pixels.
    pub width: u32,
    /// Canvas height in pixels.
    pub height: u32,
    /// Compositing program.
    pub ops: Vec<Op>,
    /// Drawable items.
    pub items: Vec<Item>,
    /// Per path geometry, in paint order.
    pub geoms: Vec<PathGeom>,
}

/// Prepares `scene` with flattening `tolerance` (device pixels). With `counts` (one list
/// per path, as in [`PathGeom::counts`]) the chord counts are fixed instead of computed.
pub fn prepare(scene: &Scene, tolerance: f64, counts: Option<&[ChordCounts]>) -> Prepared {
    let mut p = Prepared {
        width: scene.width,
        height: scene.height,
        ops: Vec::new(),
        items: Vec::new(),
        geoms: Vec::new(),
    };
    let mut b = Builder {
        groups: 0,
        tolerance,
        counts,
        out: &mut p,
    };
    b.nodes(&scene.nodes);
    p
}

struct Builder<'a> {
    groups: usize,
    tolerance: f64,
    counts: Option<&'a [ChordCounts]>,
    out: &'a mut Prepared,
}

impl Builder<'_> {
    fn nodes(&mut self, nodes: &[Node]) {
        for n in nodes {
            match n {
                Node::Path(p) => self.path(p),
                Node::Group(g) => {
                    let group = self.groups;
                    self.groups += 1;
                    self.out.ops.push(Op::Push);
                    self.nodes(&g.children);
                    self.out.ops.push(Op::Pop {
                        opacity: g.opacity.clamp(0.0, 1.0) as f32,
                        group,
                    });
                }
            }
        }
    }

    fn path(&mut self, path: &Path) {
        let ix = self.out.geoms.len();
        let (w, h) = (self.out.width as f64, self.out.height as f64);
        // Strokes reach beyond the centerline; flatten generously near the canvas.
        let margin = path.stroke.as_ref().map_or(1.0, |s| {
            let [a, b, c, d] = s.frame;
            let norm = a.hypot(b).max(c.hypot(d));
            1.0 + 0.5 * s.width.abs() * s.miter_limit.max(1.0) * norm
        });
        let visible = [-margin, -margin, w + margin, h + margin];
        let fixed = self.counts.and_then(|c| c.get(ix)).map(|c| c.as_slice());
        let (flat, counts) = flatten(path, self.tolerance, visible, fixed);
        let mut geom = PathGeom {
            flat,
            counts,
            ..PathGeom::default()
        };
        let fill_item = path.fill.as_ref().and_then(|f| {
            let paint = PaintEval::new(&f.paint, f.opacity)?;
            let mut pts = Vec::with_capacity(geom.flat.pts.len());
            let mut src = Vec::with_capacity(geom.flat.pts.len());
            let mut rings = Vec::new();
            for c in &geom.flat.contours {
                if c.len >= 3 {
                    rings.push((pts.len(), c.len));
                    pts.extend_from_slice(&geom.flat.pts[c.start..c.start + c.len]);
                    src.extend(c.start as u32..(c.start + c.len) as u32);
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
        let stroke_item = path.stroke.as_ref().and_then(|s| {
            if !(s.width > 0.0) {
                return None;
            }
            let paint = PaintEval::new(&s.paint, s.opacity)?;
            let [a, b, c, d] = s.frame;
            let det = a * d - b * c;
            let inv = [d / det, -b / det, -c / det, a / det];
            if !inv.iter().all(|v| v.is_finite()) {
                return None;
            }
            let to_frame =
                |q: &Point| [inv[0] * q[0] + inv[2] * q[1], inv[1] * q[0] + inv[3] * q[1]];
            let fpts: Vec<Point> = geom.flat.pts.iter().map(to_frame).collect();
            let style = Style {
                half_width: 0.5 * s.width,
                join: s.join,
                cap: s.cap,
                miter_limit: s.miter_limit,
                tolerance: self.tolerance / det.abs().sqrt(),
            };
            let ol = match &s.dash {
                Some(pattern) => {
                    let dashed = dash(
                        &fpts,
                        &geom.flat.corner,
                        &geom.flat.contours,
                        pattern,
                        s.dash_offset,
                    );
                    let ol = outline(&dashed.pts, &dashed.corner, &dashed.contours, style);
                    geom.dashed = Some(dashed);
                    ol
                }
                None => outline(&fpts, &geom.flat.corner, &geom.flat.contours, style),
            };
            let pts: Vec<Point> = ol
                .pts
                .iter()
                .map(|q| [a * q[0] + c * q[1], b * q[0] + d * q[1]])
                .collect();
            let rings = ol.rings.clone();
            let src = (0..pts.len() as u32).collect();
            geom.frame_inv = Some(inv);
            geom.outline = Some(ol);
            item(ix, ItemKind::Stroke, pts, src, rings, false, paint)
        });
        let mut push = |it: Option<Item>| {
            if let Some(it) = it {
                self.out.ops.push(Op::Draw(self.out.items.len()));
                self.out.items.push(it);
            }
        };
        if path.stroke_first {
            push(stroke_item);
            push(fill_item);
        } else {
            push(fill_item);
            push(stroke_item);
        }
        self.out.geoms.push(geom);
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
    let mut grid_aligned = false;
    for &(s, n) in &rings {
        for k in 0..n {
            let (a, b) = (pts[s + k], pts[s + (k + 1) % n]);
            grid_aligned |=
                (a[0] == b[0] && a[0] == a[0].floor()) || (a[1] == b[1] && a[1] == a[1].floor());
        }
    }
    Some(Item {
        grid_aligned,
        path,
        kind,
        pts,
        src,
        rings,
        evenodd,
        paint,
        bbox,
    })
}
