//! The per-shape view of the parameter vector: where each path's points, paints, opacities
//! and width and each group's opacity lie in [`Scene::params`], with the segment kinds as
//! written, and the gradient read the same way (`diffsvg grad --json`). One layout for
//! every front end: the command line's JSON and Python's `Scene.structure()` are both made
//! from [`Structure`].

use serde_json::{Value, json};

use super::params::{PaintOffsets, written_point_gradient};
use super::{GradientKind, Node, Paint, ParamLayout, Scene, SegmentKind};

/// Where one paint's values lie: `len` slots from `offset` hold its values then its
/// opacity (solid: `r, g, b`; a gradient: `geometry` values, then 5 per stop
/// (`offset, r, g, b, opacity`) from `stops_offset`; an image: none), the opacity at
/// `opacity`.
#[derive(Clone, Debug, PartialEq)]
pub struct PaintSlots {
    /// `"solid"`, `"linear"`, `"radial"` or `"image"`.
    pub kind: &'static str,
    /// First slot.
    pub offset: usize,
    /// Slots from `offset` through the opacity.
    pub len: usize,
    /// Geometry values of a gradient (4 linear, 6 radial; 0 solid).
    pub geometry: usize,
    /// Stops of a gradient (0 solid).
    pub stops: usize,
    /// First slot of the stops (gradients).
    pub stops_offset: usize,
    /// The opacity's slot.
    pub opacity: usize,
}

/// Where a circle's, ellipse's or rectangle's own parameters lie.
#[derive(Clone, Debug, PartialEq)]
pub struct PrimitiveSlots {
    /// `"circle"`, `"ellipse"` or `"rect"`.
    pub kind: &'static str,
    /// First slot.
    pub offset: usize,
    /// Names and lengths in slot order ([`Primitive::fields`](super::Primitive::fields)).
    pub fields: Vec<(&'static str, usize)>,
}

/// One path's slots.
#[derive(Clone, Debug, PartialEq)]
pub struct ShapeSlots {
    /// The path's id.
    pub id: String,
    /// First slot of the control points and their count (`2k`, `2k + 1`: point `k`); the
    /// count is 0 for a primitive, whose outline is built from its own parameters.
    pub points: (usize, usize),
    /// The circle's, ellipse's or rectangle's parameters, if the path is one.
    pub primitive: Option<PrimitiveSlots>,
    /// Segments per subpath.
    pub segments: Vec<usize>,
    /// Whether each subpath is closed.
    pub closed: Vec<bool>,
    /// The written kind of each segment, per subpath (`"L"`, `"Q"`, `"C"`).
    pub kinds: Vec<String>,
    /// The fill's paint.
    pub fill: Option<PaintSlots>,
    /// The stroke's paint.
    pub stroke: Option<PaintSlots>,
    /// The stroke width's slot.
    pub stroke_width: Option<usize>,
}

/// One group's opacity slot, or its transform's slots.
#[derive(Clone, Debug, PartialEq)]
pub struct GroupSlots {
    /// The group's id.
    pub id: String,
    /// The opacity's slot, or the transform's first.
    pub offset: usize,
    /// How many slots: 1 for an opacity; 4 for a similarity transform (`tx, ty, angle,
    /// scale`), 6 for a general affine one (`tx, ty, a, b, c, d`).
    pub len: usize,
}

/// Every shape's and group's slots, paths in paint order, groups in document order.
#[derive(Clone, Debug, PartialEq)]
pub struct Structure {
    /// Per path.
    pub shapes: Vec<ShapeSlots>,
    /// Per group drawn as a layer: its opacity.
    pub groups: Vec<GroupSlots>,
    /// Per group with a transform parameter: its slots (`tx, ty, angle, scale`, or
    /// `tx, ty, a, b, c, d`; [`transform`](super::transform)).
    pub transforms: Vec<GroupSlots>,
    /// Per filtered group whose filters have parameters: their slots
    /// ([`FilterPrimitive::slots_mut`](super::filter::FilterPrimitive::slots_mut), filter by
    /// filter, primitive by primitive).
    pub filters: Vec<FilterSlots>,
}

/// A filtered group's filter parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct FilterSlots {
    /// The group's id.
    pub id: String,
    /// The first slot.
    pub offset: usize,
    /// The number of slots.
    pub len: usize,
}

fn paint_slots(paint: &Paint, po: Option<PaintOffsets>, opacity: usize) -> Option<PaintSlots> {
    let po = po?;
    let (kind, geometry, stops) = match paint {
        Paint::Solid(_) => ("solid", 0, 0),
        Paint::Image(_) => ("image", 0, 0),
        Paint::Gradient(g) => match g.kind {
            GradientKind::Linear { .. } => ("linear", 4, g.stops.len()),
            GradientKind::Radial { .. } => ("radial", 6, g.stops.len()),
        },
    };
    Some(PaintSlots {
        kind,
        offset: po.base,
        len: opacity + 1 - po.base,
        geometry,
        stops,
        stops_offset: po.stops,
        opacity,
    })
}

/// The ids of the groups that `keep` selects, in document order.
fn group_ids(nodes: &[Node], keep: fn(&super::Group) -> bool, out: &mut Vec<String>) {
    for n in nodes {
        if let Node::Group(g) = n {
            if keep(g) {
                // A shape's own transform (a group with no id, no layer, around the shape)
                // goes by the shape's id.
                let id = match g.children.as_slice() {
                    [Node::Path(p)] if g.id.is_empty() && !g.layer && g.transform.is_some() => {
                        p.id.clone()
                    }
                    _ => g.id.clone(),
                };
                out.push(id);
            }
            group_ids(&g.children, keep, out);
        }
    }
}

impl Structure {
    /// The structure of `scene`'s parameter vector.
    pub fn of(scene: &Scene) -> Structure {
        let layout = ParamLayout::new(scene);
        let mut shapes = Vec::new();
        scene.for_each_path(|p| {
            let off = layout.paths[shapes.len()];
            let kinds = p
                .subpaths
                .iter()
                .map(|s| {
                    s.kinds
                        .iter()
                        .map(|k| match k {
                            SegmentKind::Line => 'L',
                            SegmentKind::Quad => 'Q',
                            SegmentKind::Cubic => 'C',
                        })
                        .collect()
                })
                .collect();
            let primitive = p.primitive.as_ref().map(|q| PrimitiveSlots {
                kind: q.element(),
                offset: off.points,
                fields: q.fields(),
            });
            let n = if primitive.is_some() {
                0
            } else {
                p.points.len()
            };
            shapes.push(ShapeSlots {
                id: p.id.clone(),
                points: (off.points, n),
                primitive,
                segments: p.subpaths.iter().map(|s| s.kinds.len()).collect(),
                closed: p.subpaths.iter().map(|s| s.closed).collect(),
                kinds,
                fill: p
                    .fill
                    .as_ref()
                    .and_then(|f| paint_slots(&f.paint, off.fill, off.fill_opacity)),
                stroke: p
                    .stroke
                    .as_ref()
                    .and_then(|s| paint_slots(&s.paint, off.stroke, off.stroke_opacity)),
                stroke_width: p.stroke.as_ref().map(|_| off.stroke_width),
            });
        });
        let slots = |keep: fn(&super::Group) -> bool, offsets: &[usize], lens: &[usize]| {
            let mut ids = Vec::new();
            group_ids(&scene.nodes, keep, &mut ids);
            ids.into_iter()
                .zip(offsets)
                .enumerate()
                .map(|(i, (id, &offset))| GroupSlots {
                    id,
                    offset,
                    len: lens.get(i).copied().unwrap_or(1),
                })
                .collect()
        };
        let lens: Vec<usize> = super::transform::reaches(&scene.nodes)
            .into_iter()
            .map(|(_, _, n)| n)
            .collect();
        Structure {
            shapes,
            groups: slots(|g| g.layer, &layout.groups, &[]),
            transforms: slots(|g| g.transform.is_some(), &layout.transforms, &lens),
            filters: layout
                .filters
                .iter()
                .map(|r| FilterSlots {
                    id: layout.owners[layout.slots[r.start].owner].id.clone(),
                    offset: r.start,
                    len: r.len(),
                })
                .collect(),
        }
    }

    /// A gradient (in [`Scene::params`] order) per shape, as `diffsvg grad --json` prints
    /// it: `{"loss", "shapes", "groups"}`, each shape with `id`, `points` (one `[x, y]`
    /// per written point, chained from the cubics; none for a primitive, which has
    /// `shape`: its `kind` and one entry per [`PrimitiveSlots::fields`]), `fill`/`stroke` (solid:
    /// `[r, g, b, opacity]`; gradient: `kind`, `geometry`, `stops`, `opacity`) and
    /// `stroke_width`; each group with `id` and `opacity`; each group transform with `id`,
    /// `translate`, `angle`, `scale`; each filtered group with `id` and its filters'
    /// `values` ([`Structure::filters`]).
    pub fn gradient_json(&self, scene: &Scene, loss: f64, grad: &[f64]) -> Value {
        let paint = |ps: &Option<PaintSlots>| -> Value {
            let Some(ps) = ps else { return Value::Null };
            if ps.kind == "solid" {
                let o = ps.offset;
                return json!([grad[o], grad[o + 1], grad[o + 2], grad[ps.opacity]]);
            }
            let stops: Vec<Vec<f64>> = (0..ps.stops)
                .map(|s| grad[ps.stops_offset + 5 * s..ps.stops_offset + 5 * s + 5].to_vec())
                .collect();
            json!({
                "kind": ps.kind,
                "geometry": grad[ps.offset..ps.offset + ps.geometry].to_vec(),
                "stops": stops,
                "opacity": grad[ps.opacity],
            })
        };
        let mut paths = Vec::new();
        scene.for_each_path(|p| paths.push(p));
        let shapes: Vec<Value> = self
            .shapes
            .iter()
            .zip(paths)
            .map(|(s, p)| {
                let (o, n) = s.points;
                let points = match &s.primitive {
                    Some(_) => Vec::new(),
                    None => written_point_gradient(p, &grad[o..o + 2 * n]),
                };
                let mut v = json!({"id": s.id, "points": points});
                if let Some(ps) = &s.primitive {
                    let mut shape = json!({"kind": ps.kind});
                    let mut at = ps.offset;
                    for &(name, len) in &ps.fields {
                        shape[name] = if len == 1 {
                            json!(grad[at])
                        } else {
                            json!(grad[at..at + len].to_vec())
                        };
                        at += len;
                    }
                    v["shape"] = shape;
                }
                if p.fill.is_some() {
                    v["fill"] = paint(&s.fill);
                }
                if let (Some(_), Some(w)) = (&p.stroke, s.stroke_width) {
                    v["stroke"] = paint(&s.stroke);
                    v["stroke_width"] = json!(grad[w]);
                }
                v
            })
            .collect();
        let groups: Vec<Value> = self
            .groups
            .iter()
            .map(|g| json!({"id": g.id, "opacity": grad[g.offset]}))
            .collect();
        let transforms: Vec<Value> = self
            .transforms
            .iter()
            .map(|g| {
                let v = &grad[g.offset..g.offset + g.len];
                if g.len == 6 {
                    json!({"id": g.id, "translate": [v[0], v[1]], "linear": v[2..6]})
                } else {
                    json!({"id": g.id, "translate": [v[0], v[1]], "angle": v[2], "scale": v[3]})
                }
            })
            .collect();
        let filters: Vec<Value> = self
            .filters
            .iter()
            .map(|f| json!({"id": f.id, "values": grad[f.offset..f.offset + f.len].to_vec()}))
            .collect();
        json!({"loss": loss, "shapes": shapes, "groups": groups, "transforms": transforms,
            "filters": filters})
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Sizing;

    /// Every parameter slot belongs to exactly one entry of the structure, and the entries
    /// say what the scene holds.
    #[test]
    fn the_structure_covers_every_slot_once() {
        let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="40">
            <linearGradient id="g" x2="1"><stop offset="0" stop-color="red"/>
              <stop offset="1" stop-color="blue"/></linearGradient>
            <g id="grp" opacity="0.5">
              <path id="a" d="M1 1 L30 2 Q35 20 20 30 Z" fill="#336699"/>
            </g>
            <path id="b" d="M2 38 C10 20 20 20 38 38" fill="none" stroke="url(#g)"
                  stroke-width="3"/></svg>"##;
        let scene = Scene::from_svg_str(svg, "s.svg", Sizing::Natural).unwrap();
        let st = Structure::of(&scene);
        let n = scene.params().len();
        let mut owner = vec![0u32; n];
        let mut mark = |from: usize, len: usize| {
            for o in &mut owner[from..from + len] {
                *o += 1;
            }
        };
        assert_eq!(st.shapes.len(), 2);
        assert_eq!(
            (st.shapes[0].id.as_str(), st.shapes[1].id.as_str()),
            ("a", "b")
        );
        assert_eq!(st.shapes[0].kinds, ["LQ"]); // `Z` closes with a chord, not a segment
        assert_eq!(st.shapes[0].closed, [true]);
        for s in &st.shapes {
            mark(s.points.0, 2 * s.points.1);
            for p in s.fill.iter().chain(&s.stroke) {
                mark(p.offset, p.len);
            }
            if let Some(w) = s.stroke_width {
                mark(w, 1);
            }
        }
        let fill = st.shapes[0].fill.as_ref().unwrap();
        assert_eq!((fill.kind, fill.len), ("solid", 4));
        let stroke = st.shapes[1].stroke.as_ref().unwrap();
        assert_eq!(
            (stroke.kind, stroke.geometry, stroke.stops),
            ("linear", 4, 2)
        );
        assert_eq!(stroke.len, 4 + 5 * 2 + 1);
        assert_eq!(st.groups.len(), 1);
        mark(st.groups[0].offset, 1);
        assert!(owner.iter().all(|&o| o == 1), "{owner:?}");
        // The gradient read through it: a vector of slot indices shows each value's place.
        let grad: Vec<f64> = (0..n).map(|i| i as f64).collect();
        let v = st.gradient_json(&scene, 0.5, &grad);
        assert_eq!(v["groups"][0]["opacity"], json!(st.groups[0].offset as f64));
        assert_eq!(v["shapes"][0]["fill"][3], json!(fill.opacity as f64));
        assert_eq!(v["shapes"][1]["stroke"]["kind"], "linear");
        assert_eq!(
            v["shapes"][1]["stroke_width"],
            json!(st.shapes[1].stroke_width.unwrap() as f64)
        );
        assert!(v["shapes"][1].get("fill").is_none());
    }

    /// A circle's and a rounded rectangle's own parameters: their fields cover their slots,
    /// and `grad --json` reads them by name.
    #[test]
    fn primitives_are_read_by_field() {
        let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="40">
            <circle id="c" cx="10" cy="12" r="6" fill="red"/>
            <rect id="r" x="4" y="20" width="30" height="12" rx="3" fill="blue"
                  transform="rotate(10 19 26)"/></svg>"##;
        let scene = Scene::from_svg_str(svg, "p.svg", Sizing::Natural).unwrap();
        let st = Structure::of(&scene);
        let n = scene.params().len();
        let (c, r) = (&st.shapes[0], &st.shapes[1]);
        let (cp, rp) = (c.primitive.as_ref().unwrap(), r.primitive.as_ref().unwrap());
        assert_eq!(
            (cp.kind, rp.kind, c.points.1, r.points.1),
            ("circle", "rect", 0, 0)
        );
        let len = |p: &PrimitiveSlots| p.fields.iter().map(|f| f.1).sum::<usize>();
        assert_eq!((len(cp), len(rp)), (3, 7));
        assert_eq!(cp.offset + 3, c.fill.as_ref().unwrap().offset);
        let grad: Vec<f64> = (0..n).map(|i| i as f64).collect();
        let v = st.gradient_json(&scene, 0.0, &grad);
        let shape = &v["shapes"][1]["shape"];
        assert_eq!(shape["kind"], "rect");
        let at = rp.offset as f64;
        assert_eq!(shape["corner"], json!([at, at + 1.0]));
        assert_eq!(shape["radii"], json!([at + 4.0, at + 5.0]));
        assert_eq!(shape["angle"], json!(at + 6.0));
        assert_eq!(
            v["shapes"][0]["shape"]["radius"],
            json!(cp.offset as f64 + 2.0)
        );
        assert_eq!(v["shapes"][0]["points"], json!([]));
    }
}
