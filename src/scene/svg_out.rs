//! SVG out: a clean, valid SVG with absolute path data in device pixels.
//!
//! The canvas becomes `width`, `height` and `viewBox="0 0 width height"`. Paths keep their
//! ids; gradients are written to `<defs>` in `userSpaceOnUse` units with their transform.
//! A stroke with a non-identity frame (drawn under a non-uniform scale) is written with a
//! `transform` on its path so that the pen keeps its shape. Coordinates are written with
//! four decimals, colors as `#rrggbb`. The glyph outlines of a `<text>` are written as
//! paths after a comment holding the text (`<!-- text: Hello -->`). An image-filled path is written as an
//! `<image>` with its pixels embedded as a base64 PNG. A circle, ellipse or rectangle
//! ([`Path::primitive`]) is written as its own element, rotated by a `rotate` transform.

use std::collections::HashSet;
use std::fmt::Write as _;
use std::path::Path as FsPath;

use super::geom::lerp;
use super::{
    Affine, BlendMode, Clip, FRAME_IDENTITY, Fill, FillRule, GradientKind, Group, ImagePaint,
    ImageQuality, LineCap, LineJoin, Mask, MaskKind, Node, Paint, Path, Point, Scene, SegmentKind,
    Spread, apply, concat, invert,
};
use crate::error::{Error, Result};
use crate::limits::MAX_COORDINATE;

/// Formats a number with at most four decimals and no trailing zeros.
pub(crate) fn num(v: f64) -> String {
    let mut s = format!("{:.4}", v);
    if s.contains('.') {
        while s.ends_with('0') {
            s.pop();
        }
        if s.ends_with('.') {
            s.pop();
        }
    }
    if s == "-0" { "0".to_string() } else { s }
}

/// A color in 8 bits; [`exact_color`](super::exact_color) writes what they miss beside it.
pub(crate) fn hex(c: &[f64; 3]) -> String {
    let q = super::exact_color::byte;
    format!("#{:02x}{:02x}{:02x}", q(c[0]), q(c[1]), q(c[2]))
}

struct Writer {
    defs: String,
    body: String,
    ids: HashSet<String>,
    next_id: usize,
    /// Writing a clip path's shapes.
    in_clip: bool,
    /// While writing a clip path's shapes, the clip path (and its id) of the group they
    /// are in, which each shape carries.
    clip_ref: Option<(String, Box<Clip>)>,
    /// The pattern the next shape written is painted with (its fill, or its stroke when it
    /// has no fill): the tiling and tile 0's content, written in device pixels.
    pattern: Option<(String, super::Tiling, String)>,
    /// The `transform` attribute of a shape whose own transform is a parameter
    /// ([`Writer::shape_transform`]), for the next shape written.
    element_transform: Option<String>,
}

/// A group transform as a `transform` attribute: `matrix(…)` in `f32`, the precision it
/// is read with, in full.
fn matrix_attr(t: &super::transform::GroupTransform) -> String {
    let m = t.affine().map(|v| format!("{}", v as f32));
    format!(" transform=\"matrix({})\"", m.join(" "))
}

/// The device-space rectangle `[x0, y0, x1, y1]` a clip content is, when it is one
/// axis-aligned rectangle path (a mask region as the reader makes it).
fn rectangle(content: &Group) -> Option<[f64; 4]> {
    let [Node::Path(p)] = content.children.as_slice() else {
        return None;
    };
    if content.clip.is_some() || p.subpaths.len() != 1 {
        return None;
    }
    let sp = &p.subpaths[0];
    if sp.kinds.len() != 3 || sp.kinds.iter().any(|k| *k != SegmentKind::Line) {
        return None;
    }
    let c: Vec<Point> = (0..4).map(|k| p.points[sp.start + 3 * k]).collect();
    let b = p.control_bounds()?;
    let axis = (0..4).all(|k| {
        let (a, n) = (c[k], c[(k + 1) % 4]);
        (a[0] == n[0]) != (a[1] == n[1])
    });
    axis.then_some(b)
}

impl Writer {
    fn unique_id(&mut self, want: &str) -> String {
        let base = if want.is_empty() { "grad" } else { want };
        if !want.is_empty() && self.ids.insert(base.to_string()) {
            return base.to_string();
        }
        loop {
            self.next_id += 1;
            let id = format!("{base}-{}", self.next_id);
            if self.ids.insert(id.clone()) {
                return id;
            }
        }
    }

    /// Writes `paint` as an attribute value; gradients go to defs. `to_local` maps device
    /// space to the coordinate system of the element the paint is used on.
    fn paint(&mut self, paint: &Paint, to_local: &Affine) -> String {
        match paint {
            Paint::Solid(c) => hex(c),
            // An image is written as an `<image>` element (`Writer::image`), never as a
            // paint of a path; `check_numbers` refuses an image anywhere else.
            Paint::Image(_) => "none".to_string(),
            Paint::Gradient(g) => {
                let id = self.unique_id(&g.id);
                let t = concat(to_local, &g.transform);
                let tf = format!(
                    "matrix({} {} {} {} {} {})",
                    num(t[0]),
                    num(t[1]),
                    num(t[2]),
                    num(t[3]),
                    num(t[4]),
                    num(t[5])
                );
                let spread = match g.spread {
                    Spread::Pad => "pad",
                    Spread::Reflect => "reflect",
                    Spread::Repeat => "repeat",
                };
                let d = &mut self.defs;
                match &g.kind {
                    GradientKind::Linear { p1, p2 } => {
                        let _ = write!(
                            d,
                            "    <linearGradient id=\"{id}\" gradientUnits=\"userSpaceOnUse\" x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\"",
                            num(p1[0]),
                            num(p1[1]),
                            num(p2[0]),
                            num(p2[1])
                        );
                    }
                    GradientKind::Radial { c, r, f, fr } => {
                        let _ = write!(
                            d,
                            "    <radialGradient id=\"{id}\" gradientUnits=\"userSpaceOnUse\" cx=\"{}\" cy=\"{}\" r=\"{}\" fx=\"{}\" fy=\"{}\" fr=\"{}\"",
                            num(c[0]),
                            num(c[1]),
                            num(r.max(0.0)),
                            num(f[0]),
                            num(f[1]),
                            num(fr.max(0.0))
                        );
                    }
                }
                let _ = writeln!(d, " gradientTransform=\"{tf}\" spreadMethod=\"{spread}\">");
                for s in &g.stops {
                    let _ = write!(
                        d,
                        "      <stop offset=\"{}\" stop-color=\"{}\"",
                        num(s.offset.clamp(0.0, 1.0)),
                        hex(&s.color)
                    );
                    d.push_str(&super::exact_color::attribute(
                        super::exact_color::STOP,
                        &s.color,
                    ));
                    if s.opacity < 1.0 {
                        let _ = write!(d, " stop-opacity=\"{}\"", num(s.opacity.clamp(0.0, 1.0)));
                    }
                    d.push_str("/>\n");
                }
                let tag = match g.kind {
                    GradientKind::Linear { .. } => "linearGradient",
                    GradientKind::Radial { .. } => "radialGradient",
                };
                let _ = writeln!(d, "    </{tag}>");
                format!("url(#{id})")
            }
        }
    }

    fn nodes(&mut self, nodes: &[Node], indent: usize) {
        for n in nodes {
            match n {
                // A `<clipPath>` holds shapes, not groups: a group's clip path goes on
                // each of its shapes (the union of clipped shapes is the clipped union).
                Node::Group(g) if self.in_clip => {
                    let outer = self.clip_ref.take();
                    if let Some(c) = &g.clip {
                        let mut c = (**c).clone();
                        if let Some((_, outer)) = &outer {
                            // Both clip the shapes: chain the outer one after this one's.
                            fn chain(c: &mut Clip, outer: Box<Clip>) {
                                match &mut c.content.clip {
                                    Some(next) => chain(next, outer),
                                    None => c.content.clip = Some(outer),
                                }
                            }
                            chain(&mut c, outer.clone());
                        }
                        let id = self.clip(&c);
                        self.clip_ref = Some((id, Box::new(c)));
                    } else {
                        self.clip_ref = outer.clone();
                    }
                    self.nodes(&g.children, indent);
                    self.clip_ref = outer;
                }
                Node::Group(g) if self.pattern_layer(g, indent) => {}
                Node::Group(g) if Self::shape_transform(g) => {
                    // A shape's own transform, written on the shape: it reads back as
                    // the same group around it.
                    self.element_transform = g.transform.as_ref().map(matrix_attr);
                    self.nodes(&g.children, indent);
                    self.element_transform = None;
                }
                Node::Group(g) => {
                    let pad = "  ".repeat(indent);
                    let mut attrs = String::new();
                    if !g.id.is_empty() {
                        let _ = write!(attrs, " id=\"{}\"", escape(&g.id));
                    }
                    if let Some(t) = &g.transform {
                        attrs.push_str(&matrix_attr(t));
                    }
                    if !self.in_clip && g.layer {
                        let _ = write!(attrs, " opacity=\"{}\"", num(g.opacity.clamp(0.0, 1.0)));
                    }
                    attrs.push_str(&self.layer_attrs(g));
                    let _ = writeln!(self.body, "{pad}<g{attrs}>");
                    self.nodes(&g.children, indent + 1);
                    let _ = writeln!(self.body, "{pad}</g>");
                }
                Node::Path(p) => match &p.fill {
                    Some(Fill {
                        paint: Paint::Image(img),
                        opacity,
                        ..
                    }) => self.image(p, img, *opacity, indent),
                    _ => self.path(p, indent),
                },
            }
        }
    }

    /// Whether `g` is a shape's own transform parameter, which is written on the shape: a
    /// group with no id, no layer and a transform around one shape that writes no
    /// `transform` of its own (no rotated primitive, no stroke frame, no image). (usvg
    /// reads `<rect transform="…">` as such a group around the rectangle.)
    fn shape_transform(g: &Group) -> bool {
        let [Node::Path(p)] = g.children.as_slice() else {
            return false;
        };
        let own = p.stroke.as_ref().is_some_and(|s| s.frame != FRAME_IDENTITY)
            || p.primitive.as_ref().is_some_and(|q| q.angle != 0.0)
            || matches!(p.fill.as_ref().map(|f| &f.paint), Some(Paint::Image(_)));
        g.transform.is_some()
            && g.id.is_empty()
            && !g.layer
            && g.clip.is_none()
            && g.mask.is_none()
            && g.blend == BlendMode::Normal
            && !g.isolate
            && g.filters.is_empty()
            && g.tiling.is_none()
            && !own
    }

    /// Writes a tiled group ([`Tiling`](super::Tiling)) back as its shape painted with a
    /// `<pattern>` made of tile 0, and returns `true`; `false` (nothing written) for any
    /// other group.
    fn pattern_layer(&mut self, g: &Group, indent: usize) -> bool {
        let (Some(t), Some(c)) = (&g.tiling, &g.clip) else {
            return false;
        };
        let [Node::Path(shape)] = c.content.children.as_slice() else {
            return false;
        };
        let plain = g.mask.is_none()
            && g.blend == BlendMode::Normal
            && g.filters.is_empty()
            && c.content.clip.is_none()
            && g.transform.is_none();
        if !plain || t.per_tile == 0 || g.children.len() != t.per_tile * t.cells.len() {
            return false;
        }
        // Tile 0's content without its cell's clip (the pattern clips each tile).
        let mut content: Vec<Node> = Vec::new();
        for n in &g.children[..t.per_tile] {
            match n {
                Node::Group(tile) if t.clipped => content.extend(tile.children.iter().cloned()),
                _ => content.push(n.clone()),
            }
        }
        let body = self.detached(&content, 4, false);
        let id = self.unique_id(if g.id.is_empty() { "pattern" } else { &g.id });
        let mut shape = shape.clone();
        let opacity = g.opacity.clamp(0.0, 1.0);
        match (&mut shape.fill, &mut shape.stroke) {
            (Some(f), _) => f.opacity = opacity,
            (None, Some(s)) => s.opacity = opacity,
            (None, None) => return false,
        }
        self.pattern = Some((id, (**t).clone(), body));
        self.path(&shape, indent);
        self.pattern = None;
        true
    }

    /// Writes the pending pattern ([`Writer::pattern`]) to the defs for a shape whose
    /// user space `to_local` maps device pixels to; returns the paint's value.
    fn pattern_paint(&mut self, to_local: &Affine) -> String {
        let Some((id, t, body)) = self.pattern.take() else {
            return "none".to_string();
        };
        let matrix = |m: &Affine| {
            format!(
                "matrix({} {} {} {} {} {})",
                m[0], m[1], m[2], m[3], m[4], m[5]
            )
        };
        // The content is in device pixels: the tile at `cells[0]` maps it back into its
        // cell's frame.
        let to_tile = invert(&t.tile_transform(t.cells[0])).unwrap_or(super::IDENTITY);
        let [x, y, w, h] = t.cell;
        let _ = write!(
            self.defs,
            "    <pattern id=\"{id}\" patternUnits=\"userSpaceOnUse\" x=\"{x}\" y=\"{y}\" width=\"{w}\" height=\"{h}\" patternTransform=\"{}\">\n      <g transform=\"{}\">\n{body}      </g>\n    </pattern>\n",
            matrix(&concat(to_local, &t.transform)),
            matrix(&to_tile),
        );
        format!("url(#{id})")
    }

    /// The `clip-path`, `mask` and blend attributes of a layer (its clip path and mask
    /// written to the defs).
    fn layer_attrs(&mut self, g: &Group) -> String {
        let mut attrs = String::new();
        if let Some(c) = &g.clip {
            let id = self.clip(c);
            let _ = write!(attrs, " clip-path=\"url(#{id})\"");
        }
        if let Some(m) = &g.mask {
            let id = self.mask(m);
            let _ = write!(attrs, " mask=\"url(#{id})\"");
        }
        let mut style = Vec::new();
        if g.blend != BlendMode::Normal {
            style.push(format!("mix-blend-mode:{}", g.blend.name()));
        }
        if g.isolate {
            style.push("isolation:isolate".to_string());
        }
        if !style.is_empty() {
            let _ = write!(attrs, " style=\"{}\"", style.join(";"));
        }
        if !g.filters.is_empty() {
            let mut refs = Vec::new();
            for f in &g.filters {
                let id = self.unique_id(if f.id.is_empty() { "filter" } else { &f.id });
                // An feImage's content: a group in the defs, moved so that its origin
                // is the corner resvg draws it from.
                let mut image = |nodes: &[Node], [x, y]: [i64; 2]| {
                    let id = self.unique_id("fe-image");
                    let body = self.detached(nodes, 3, false);
                    let _ = write!(
                        self.defs,
                        "    <g id=\"{id}\" transform=\"translate({} {})\">\n{body}    </g>\n",
                        -x, -y
                    );
                    id
                };
                let element = super::svg_out_filter::filter_element(f, &id, &mut image);
                self.defs.push_str(&element);
                refs.push(format!("url(#{id})"));
            }
            let _ = write!(attrs, " filter=\"{}\"", refs.join(" "));
        }
        attrs
    }

    /// Writes `nodes` into a string of their own (for the defs), at `indent`, with
    /// paths written as clip shapes when `in_clip`.
    fn detached(&mut self, nodes: &[Node], indent: usize, in_clip: bool) -> String {
        let body = std::mem::take(&mut self.body);
        let was = std::mem::replace(&mut self.in_clip, in_clip);
        let clip_ref = self.clip_ref.take();
        self.nodes(nodes, indent);
        self.in_clip = was;
        self.clip_ref = clip_ref;
        std::mem::replace(&mut self.body, body)
    }

    /// Writes a clip path to the defs; returns its id. A clip path of the clip path
    /// becomes the `clip-path` of the `<clipPath>` element.
    fn clip(&mut self, c: &Clip) -> String {
        let id = self.unique_id(if c.id.is_empty() { "clip" } else { &c.id });
        let mut attrs = String::new();
        if let Some(inner) = &c.content.clip {
            let inner = self.clip(inner);
            let _ = write!(attrs, " clip-path=\"url(#{inner})\"");
        }
        let content = self.detached(&c.content.children, 3, true);
        let _ = write!(
            self.defs,
            "    <clipPath id=\"{id}\" clipPathUnits=\"userSpaceOnUse\"{attrs}>\n{content}    </clipPath>\n"
        );
        id
    }

    /// Writes a mask to the defs; returns its id. The mask region (the content's clip
    /// path) is written as the mask's rectangle where it is one in device space, else
    /// as a clip path of the content inside a region around it; a mask of the mask
    /// becomes the `mask` of a group holding the content.
    fn mask(&mut self, m: &Mask) -> String {
        let id = self.unique_id(if m.id.is_empty() { "mask" } else { &m.id });
        let region = m.content.clip.as_ref().and_then(|c| rectangle(&c.content));
        let mut inner = m.content.clone();
        let rect = match region {
            Some(r) => {
                inner.clip = None;
                r
            }
            None => {
                // The content's bounds, and the region as a clip path inside them.
                let mut b = [
                    f64::INFINITY,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    f64::NEG_INFINITY,
                ];
                let mut probe = Scene::new(1, 1);
                probe.nodes = vec![Node::Group(inner.clone())];
                probe.for_each_path(|p| {
                    if let Some(c) = p.control_bounds() {
                        b = [
                            b[0].min(c[0]),
                            b[1].min(c[1]),
                            b[2].max(c[2]),
                            b[3].max(c[3]),
                        ];
                    }
                });
                if b[0] > b[2] {
                    b = [0.0, 0.0, 1.0, 1.0];
                }
                [b[0] - 1.0, b[1] - 1.0, b[2] + 1.0, b[3] + 1.0]
            }
        };
        let kind = match m.kind {
            MaskKind::Luminance => "",
            MaskKind::Alpha => " style=\"mask-type:alpha\"",
        };
        let content = if inner.is_plain() {
            self.detached(&inner.children, 3, false)
        } else {
            inner.opacity = 1.0;
            self.detached(&[Node::Group(inner)], 3, false)
        };
        let _ = write!(
            self.defs,
            "    <mask id=\"{id}\" maskUnits=\"userSpaceOnUse\" x=\"{}\" y=\"{}\" width=\"{}\" height=\"{}\"{kind}>\n{content}    </mask>\n",
            num(rect[0]),
            num(rect[1]),
            num(rect[2] - rect[0]),
            num(rect[3] - rect[1])
        );
        id
    }

    /// An image-filled path as `<image>`: its pixels as an embedded PNG at their own
    /// size, placed by the image's transform, so that diffsvg, resvg and browsers read it
    /// back as the same rectangle with the same pixels. The path's points are not written:
    /// they are the image's rectangle (fits keep them there; `check_numbers` refuses to
    /// save one moved off it).
    fn image(&mut self, p: &Path, img: &ImagePaint, opacity: f64, indent: usize) {
        let mut attrs = String::new();
        if !p.id.is_empty() {
            let _ = write!(attrs, " id=\"{}\"", escape(&p.id));
        }
        // Full precision: a rounded scale would move the far corner by its error times
        // the image's size.
        let t = img.transform;
        let _ = write!(
            attrs,
            " width=\"{}\" height=\"{}\" preserveAspectRatio=\"none\" transform=\"matrix({} {} {} {} {} {})\"",
            img.width, img.height, t[0], t[1], t[2], t[3], t[4], t[5]
        );
        match img.quality {
            ImageQuality::Nearest => attrs.push_str(" image-rendering=\"optimizeSpeed\""),
            ImageQuality::Bilinear => attrs.push_str(" style=\"image-rendering:smooth\""),
            ImageQuality::Bicubic => {}
        }
        if opacity < 1.0 {
            let _ = write!(attrs, " opacity=\"{}\"", num(opacity.clamp(0.0, 1.0)));
        }
        let png = crate::image_io::encode_png_rgba8(img.width, img.height, &img.pixels);
        use base64::Engine as _;
        let data = base64::engine::general_purpose::STANDARD.encode(png);
        let pad = "  ".repeat(indent);
        let _ = writeln!(
            self.body,
            "{pad}<image{attrs} href=\"data:image/png;base64,{data}\"/>"
        );
    }

    fn path(&mut self, p: &Path, indent: usize) {
        // A stroke with a non-identity frame is written in its frame.
        let frame = p
            .stroke
            .as_ref()
            .map(|s| s.frame)
            .filter(|f| *f != FRAME_IDENTITY);
        // A circle, ellipse or rectangle is written as itself, its rotation as a
        // `rotate` about its center (its paints then in the rotated frame).
        // (One held in a general map's frame outside that map's group, in device space,
        // is no primitive there: its outline.)
        let primitive = p
            .primitive
            .as_ref()
            .filter(|q| frame.is_none() && q.frame == FRAME_IDENTITY);
        let (to_local, transform_attr) = match frame {
            None if primitive.is_some_and(|q| q.angle != 0.0) => {
                let q = primitive.expect("checked");
                let c = q.center();
                let deg = q.angle.to_degrees();
                let (s, co) = (-q.angle).sin_cos();
                let inv = [
                    co,
                    s,
                    -s,
                    co,
                    c[0] - co * c[0] + s * c[1],
                    c[1] - s * c[0] - co * c[1],
                ];
                (
                    inv,
                    format!(
                        " transform=\"rotate({} {} {})\"",
                        num(deg),
                        num(c[0]),
                        num(c[1])
                    ),
                )
            }
            Some([a, b, c, d]) => {
                let m = [a, b, c, d, 0.0, 0.0];
                match invert(&m) {
                    Some(inv) => (
                        inv,
                        format!(
                            " transform=\"matrix({} {} {} {} 0 0)\"",
                            num(a),
                            num(b),
                            num(c),
                            num(d)
                        ),
                    ),
                    None => (super::IDENTITY, String::new()),
                }
            }
            None => (super::IDENTITY, String::new()),
        };
        // Exact colors beside the 8-bit ones are found by the shape's id.
        use super::exact_color::{FILL, STROKE, attribute};
        // A patterned shape's black stand-in paint is not written.
        let patterned = self.pattern.is_some();
        let solid = |paint: Option<&Paint>| match paint {
            Some(Paint::Solid(c)) if !patterned => Some(*c),
            _ => None,
        };
        let exact = [
            (FILL, solid(p.fill.as_ref().map(|f| &f.paint))),
            (STROKE, solid(p.stroke.as_ref().map(|s| &s.paint))),
        ]
        .map(|(name, c)| c.map_or(String::new(), |c| attribute(name, &c)));
        let id = match p.id.is_empty() {
            true if exact.iter().any(|a| !a.is_empty()) => self.unique_id("shape"),
            _ => p.id.clone(),
        };
        let mut attrs = String::new();
        if !id.is_empty() {
            let _ = write!(attrs, " id=\"{}\"", escape(&id));
        }
        if let Some(t) = self.element_transform.take() {
            attrs.push_str(&t);
        }
        attrs.push_str(&transform_attr);
        match primitive {
            Some(q) => attrs.push_str(&primitive_attrs(q)),
            None => {
                let _ = write!(attrs, " d=\"{}\"", path_data(p, &to_local));
            }
        }
        match &p.fill {
            Some(f) => {
                let v = match patterned {
                    true => self.pattern_paint(&to_local),
                    false => self.paint(&f.paint, &to_local),
                };
                let _ = write!(attrs, " fill=\"{v}\"{}", exact[0]);
                if f.opacity < 1.0 {
                    let _ = write!(
                        attrs,
                        " fill-opacity=\"{}\"",
                        num(f.opacity.clamp(0.0, 1.0))
                    );
                }
                if let Some((id, _)) = &self.clip_ref {
                    let _ = write!(attrs, " clip-path=\"url(#{id})\"");
                }
                if f.rule == FillRule::EvenOdd {
                    // A clip path's shapes take their rule from `clip-rule`.
                    attrs.push_str(if self.in_clip {
                        " clip-rule=\"evenodd\""
                    } else {
                        " fill-rule=\"evenodd\""
                    });
                }
            }
            None => attrs.push_str(" fill=\"none\""),
        }
        if let Some(s) = &p.stroke {
            let v = match patterned && p.fill.is_none() {
                true => self.pattern_paint(&to_local),
                false => self.paint(&s.paint, &to_local),
            };
            let _ = write!(
                attrs,
                " stroke=\"{v}\"{} stroke-width=\"{}\"",
                exact[1],
                num(s.width.max(0.0))
            );
            if s.opacity < 1.0 {
                let _ = write!(
                    attrs,
                    " stroke-opacity=\"{}\"",
                    num(s.opacity.clamp(0.0, 1.0))
                );
            }
            let join = match s.join {
                LineJoin::Miter => None,
                LineJoin::MiterClip => Some("miter-clip"),
                LineJoin::Round => Some("round"),
                LineJoin::Bevel => Some("bevel"),
            };
            if let Some(j) = join {
                let _ = write!(attrs, " stroke-linejoin=\"{j}\"");
            }
            let cap = match s.cap {
                LineCap::Butt => None,
                LineCap::Round => Some("round"),
                LineCap::Square => Some("square"),
            };
            if let Some(c) = cap {
                let _ = write!(attrs, " stroke-linecap=\"{c}\"");
            }
            if s.miter_limit != 4.0 {
                let _ = write!(attrs, " stroke-miterlimit=\"{}\"", num(s.miter_limit));
            }
            if let Some(d) = &s.dash {
                let list: Vec<String> = d.iter().map(|v| num(*v)).collect();
                let _ = write!(attrs, " stroke-dasharray=\"{}\"", list.join(" "));
                if s.dash_offset != 0.0 {
                    let _ = write!(attrs, " stroke-dashoffset=\"{}\"", num(s.dash_offset));
                }
            }
            if p.stroke_first {
                attrs.push_str(" paint-order=\"stroke\"");
            }
        }
        if p.crisp {
            attrs.push_str(" shape-rendering=\"crispEdges\"");
        }
        let pad = "  ".repeat(indent);
        if let Some(text) = &p.text {
            let _ = writeln!(self.body, "{pad}<!-- text: {} -->", comment_text(text));
        }
        let tag = primitive.map_or("path", |q| q.element());
        let _ = writeln!(self.body, "{pad}<{tag}{attrs}/>");
    }
}

/// The geometry attributes of a primitive's element, before its rotation.
fn primitive_attrs(q: &super::Primitive) -> String {
    use super::Shape;
    let attrs: Vec<(&str, f64)> = match q.shape {
        Shape::Circle { center, r } => vec![("cx", center[0]), ("cy", center[1]), ("r", r)],
        Shape::Ellipse { center, rx, ry } => {
            vec![("cx", center[0]), ("cy", center[1]), ("rx", rx), ("ry", ry)]
        }
        Shape::Rect {
            x,
            y,
            width,
            height,
            radii,
        } => {
            let mut v = vec![("x", x), ("y", y), ("width", width), ("height", height)];
            if let Some([rx, ry]) = radii {
                v.extend([("rx", rx), ("ry", ry)]);
            }
            v
        }
    };
    let mut out = String::new();
    for (name, v) in attrs {
        let _ = write!(out, " {name}=\"{}\"", num(v));
    }
    out
}

/// Absolute path data (`M`, `L`, `Q`, `C`, `Z`) for a path, after mapping by `t`.
/// A segment is written as `L` (or `Q`) only when its control points still sit where an
/// elevated line (or quadratic) puts them.
pub(crate) fn path_data(p: &Path, t: &Affine) -> String {
    let mut d = String::new();
    let pt = |q: [f64; 2]| {
        let q = apply(t, q);
        format!("{} {}", num(q[0]), num(q[1]))
    };
    for sp in &p.subpaths {
        if !d.is_empty() {
            d.push(' ');
        }
        let _ = write!(d, "M{}", pt(p.points[sp.start]));
        for (k, kind) in sp.kinds.iter().enumerate() {
            let [a, c1, c2, b] = p.segment_points(sp, k);
            let near = |u: [f64; 2], v: [f64; 2]| (u[0] - v[0]).abs() + (u[1] - v[1]).abs() < 1e-6;
            match kind {
                SegmentKind::Line
                    if near(c1, lerp(a, b, 1.0 / 3.0)) && near(c2, lerp(a, b, 2.0 / 3.0)) =>
                {
                    let _ = write!(d, " L{}", pt(b));
                }
                SegmentKind::Quad | SegmentKind::Line => {
                    // q = a + 1.5 (c1 - a) = b + 1.5 (c2 - b) for an elevated quadratic.
                    let q1 = lerp(a, c1, 1.5);
                    let q2 = lerp(b, c2, 1.5);
                    if *kind == SegmentKind::Quad && near(q1, q2) {
                        let _ = write!(d, " Q{} {}", pt(q1), pt(b));
                    } else {
                        let _ = write!(d, " C{} {} {}", pt(c1), pt(c2), pt(b));
                    }
                }
                SegmentKind::Cubic => {
                    let _ = write!(d, " C{} {} {}", pt(c1), pt(c2), pt(b));
                }
            }
        }
        if sp.closed {
            d.push_str(" Z");
        }
    }
    d
}

/// Escapes text for XML or HTML content and quoted attribute values: `& < > " '` become
/// entities, and control characters other than tab (not allowed in XML 1.0, or unwanted in
/// one-line labels) become spaces. Shared by the SVG writer, the plots and the batch report.
pub fn escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c if (c as u32) < 0x20 && c != '\t' => out.push(' '),
            c => out.push(c),
        }
    }
    out
}

/// Text made safe inside an XML comment, kept readable: `--` may not occur in a comment,
/// so a space follows every `-` that another `-` follows (the writer puts a space before
/// `-->`, so a `-` at the end is safe);
/// control characters, which XML 1.0 does not allow, become spaces as in [`escape`].
/// Entities mean nothing in a comment: `<` and `&` stay as they are.
pub(crate) fn comment_text(s: &str) -> String {
    let mut out = String::with_capacity(s.len() + 2);
    let mut chars = s.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '-' => {
                out.push('-');
                if chars.peek() == Some(&'-') {
                    out.push(' ');
                }
            }
            c if (c as u32) < 0x20 && c != '\t' => out.push(' '),
            c => out.push(c),
        }
    }
    out
}

impl Scene {
    /// The scene as SVG text.
    pub fn to_svg_string(&self) -> String {
        let mut w = Writer {
            defs: String::new(),
            body: String::new(),
            ids: HashSet::new(),
            next_id: 0,
            in_clip: false,
            clip_ref: None,
            pattern: None,
            element_transform: None,
        };
        // Reserve path and group ids so that gradient ids do not collide with them.
        fn reserve(nodes: &[Node], ids: &mut HashSet<String>) {
            for n in nodes {
                match n {
                    Node::Group(g) => {
                        ids.insert(g.id.clone());
                        reserve_layer(g, ids);
                    }
                    Node::Path(p) => {
                        ids.insert(p.id.clone());
                    }
                }
            }
        }
        fn reserve_layer(g: &Group, ids: &mut HashSet<String>) {
            reserve(&g.children, ids);
            if let Some(c) = &g.clip {
                ids.insert(c.id.clone());
                reserve_layer(&c.content, ids);
            }
            if let Some(m) = &g.mask {
                ids.insert(m.id.clone());
                reserve_layer(&m.content, ids);
            }
        }
        reserve(&self.nodes, &mut w.ids);
        // A transformed group's content is written in its own frame, under its transform.
        let mut nodes = self.nodes.clone();
        super::transform::localize(&mut nodes);
        w.nodes(&nodes, 1);
        let mut out = String::new();
        let _ = writeln!(
            out,
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{0}\" height=\"{1}\" viewBox=\"0 0 {0} {1}\">",
            self.width, self.height
        );
        if !w.defs.is_empty() {
            let _ = write!(out, "  <defs>\n{}  </defs>\n", w.defs);
        }
        out.push_str(&w.body);
        out.push_str("</svg>\n");
        out
    }

    /// Writes the scene as an SVG file, atomically (temporary file, then rename).
    ///
    /// A scene holding a number that is not finite or beyond [`MAX_COORDINATE`] (see
    /// `check_numbers`) is refused with an error naming `path` and the value, and nothing
    /// is written: diffsvg never writes an SVG that it refuses to read.
    pub fn save_svg(&self, path: impl AsRef<FsPath>) -> Result<()> {
        let path = path.as_ref();
        check_numbers(self).map_err(|what| Error::InvalidValue {
            path: path.to_path_buf(),
            what: format!("refusing to write {what}"),
        })?;
        crate::image_io::write_atomic(path, self.to_svg_string().as_bytes())
    }
}

/// Reader slack for `f32` rounding: a number written at exactly [`MAX_COORDINATE`] may read
/// back a few `f32` ulps above it.
pub(crate) const READ_SLACK: f64 = 1.0 + 1e-6;

/// Checks every number the SVG of `scene` holds, as [`Scene::to_svg_string`] writes it and
/// as [`Scene::load`] reads it back in device pixels: control points (in device space and,
/// for a stroke drawn in a frame, in the frame's space too), stroke widths, miter limits,
/// dash arrays and offsets, stroke frames, gradient geometry and transforms, stop offsets,
/// opacities. Each must be finite with magnitude at most [`MAX_COORDINATE`].
///
/// The reader runs this on every scene it loads and the writer before it writes, so what
/// one accepts the other accepts. The error describes the first bad value and its element:
/// `path "id": stroke width 1e38 is out of range (at most 1e30 in magnitude)`. Paths and
/// groups without an id are named by their position (`path #3`, 1-based, document order).
pub(crate) fn check_numbers(scene: &Scene) -> std::result::Result<(), String> {
    check_numbers_with(scene, 1.0)
}

/// [`check_numbers`] with the limit scaled by `slack` (the reader allows `f32` rounding).
pub(crate) fn check_numbers_with(scene: &Scene, slack: f64) -> std::result::Result<(), String> {
    let mut c = Checker {
        limit: MAX_COORDINATE * slack,
        paths: 0,
        groups: 0,
    };
    c.nodes(&scene.nodes)
}

struct Checker {
    limit: f64,
    paths: usize,
    groups: usize,
}

impl Checker {
    fn value(
        &self,
        owner: &dyn Fn() -> String,
        what: &str,
        v: f64,
    ) -> std::result::Result<(), String> {
        if v.is_finite() && v.abs() <= self.limit {
            Ok(())
        } else if v.is_finite() {
            // Lengths are in device pixels; shown as the nearest `f32`, the precision they
            // were read with.
            let unitless = ["opacity", "stop offset", "miter", "entry"];
            let unit = if unitless.iter().any(|u| what.contains(u)) {
                ""
            } else {
                " px"
            };
            Err(format!(
                "{}: {what} {:e}{unit} is out of range (at most {MAX_COORDINATE:e} in magnitude)",
                owner(),
                v as f32
            ))
        } else {
            Err(format!("{}: {what} is {v} (not a finite number)", owner()))
        }
    }

    fn nodes(&mut self, nodes: &[Node]) -> std::result::Result<(), String> {
        for n in nodes {
            match n {
                Node::Group(g) => {
                    self.groups += 1;
                    let k = self.groups;
                    let owner = || name("group", &g.id, k);
                    self.value(&owner, "opacity", g.opacity)?;
                    self.layer(g)?;
                }
                Node::Path(p) => {
                    self.paths += 1;
                    self.path(p)?;
                }
            }
        }
        Ok(())
    }

    /// A layer's children, then its clip path's and mask's content.
    fn layer(&mut self, g: &Group) -> std::result::Result<(), String> {
        self.nodes(&g.children)?;
        if let Some(c) = &g.clip {
            self.layer(&c.content)?;
        }
        if let Some(m) = &g.mask {
            self.layer(&m.content)?;
        }
        Ok(())
    }

    fn path(&self, p: &Path) -> std::result::Result<(), String> {
        let k = self.paths;
        let owner = || name("path", &p.id, k);
        // As the writer: a stroke frame other than the identity puts the path in it.
        let mut to_local = None;
        if let Some(s) = &p.stroke
            && s.frame != FRAME_IDENTITY
        {
            for v in s.frame {
                self.value(&owner, "stroke frame entry", v)?;
            }
            let [a, b, c, d] = s.frame;
            to_local = invert(&[a, b, c, d, 0.0, 0.0]);
        }
        // End points first, so that the value reported is one the file shows (a line's
        // control points sit a third of the way along it).
        let ends = p
            .subpaths
            .iter()
            .flat_map(|sp| (0..=sp.kinds.len()).map(move |k| sp.start + 3 * k))
            .filter_map(|i| p.points.get(i));
        for q in ends.chain(&p.points) {
            self.value(&owner, "coordinate", q[0])?;
            self.value(&owner, "coordinate", q[1])?;
            if let Some(t) = &to_local {
                let l = apply(t, *q);
                self.value(&owner, "coordinate in the stroke's frame", l[0])?;
                self.value(&owner, "coordinate in the stroke's frame", l[1])?;
            }
        }
        let to_local = to_local.unwrap_or(super::IDENTITY);
        if let Some(Paint::Image(_)) = p.stroke.as_ref().map(|s| &s.paint) {
            return Err(format!(
                "{}: an image as a stroke's paint cannot be written (SVG has none)",
                owner()
            ));
        }
        if let Some(Fill {
            paint: Paint::Image(img),
            ..
        }) = &p.fill
        {
            for v in img.transform {
                self.value(&owner, "image transform entry", v)?;
            }
            if p.stroke.is_some() || !img.is_rectangle_of(p) {
                return Err(format!(
                    "{}: an image is written only as its own rectangle without a stroke, \
                     and this one was moved or stroked",
                    owner()
                ));
            }
        }
        if let Some(f) = &p.fill {
            self.value(&owner, "fill opacity", f.opacity)?;
            self.paint(&owner, &f.paint, &to_local)?;
        }
        if let Some(s) = &p.stroke {
            self.value(&owner, "stroke opacity", s.opacity)?;
            self.value(&owner, "stroke width", s.width)?;
            self.value(&owner, "stroke miter limit", s.miter_limit)?;
            for &v in s.dash.iter().flatten() {
                self.value(&owner, "stroke dash length", v)?;
            }
            self.value(&owner, "stroke dash offset", s.dash_offset)?;
            self.paint(&owner, &s.paint, &to_local)?;
        }
        Ok(())
    }

    fn paint(
        &self,
        owner: &dyn Fn() -> String,
        paint: &Paint,
        to_local: &Affine,
    ) -> std::result::Result<(), String> {
        let Paint::Gradient(g) = paint else {
            return Ok(());
        };
        let geometry: Vec<f64> = match g.kind {
            GradientKind::Linear { p1, p2 } => vec![p1[0], p1[1], p2[0], p2[1]],
            GradientKind::Radial { c, r, f, fr } => vec![c[0], c[1], r, f[0], f[1], fr],
        };
        for v in geometry {
            self.value(owner, "gradient coordinate", v)?;
        }
        for v in g
            .transform
            .into_iter()
            .chain(concat(to_local, &g.transform))
        {
            self.value(owner, "gradient transform entry", v)?;
        }
        for s in &g.stops {
            self.value(owner, "gradient stop offset", s.offset)?;
            self.value(owner, "gradient stop opacity", s.opacity)?;
        }
        Ok(())
    }
}

fn name(kind: &str, id: &str, k: usize) -> String {
    if id.is_empty() {
        format!("{kind} #{k}")
    } else {
        format!("{kind} \"{id}\"")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn comment_text_never_holds_a_double_dash() {
        assert_eq!(comment_text("a--b"), "a- -b");
        assert_eq!(comment_text("---"), "- - -");
        assert_eq!(comment_text("end-"), "end-");
        assert_eq!(comment_text("<&>\n\tx"), "<&> \tx");
        for s in ["--", "x---y-", "-->", "<!-- -->"] {
            let c = comment_text(s);
            assert!(!c.contains("--"), "{c}");
            let doc = format!("<a><!-- text: {c} --></a>");
            assert!(usvg::roxmltree::Document::parse(&doc).is_ok(), "{doc}");
        }
    }
    use crate::scene::svg_in::Sizing;

    #[test]
    fn markup_is_escaped_and_control_characters_dropped() {
        assert_eq!(
            escape("a<b & \"c\" 'd'>\n\te"),
            "a&lt;b &amp; &quot;c&quot; &#39;d&#39;&gt; \te"
        );
        assert_eq!(escape("plain ünïcode"), "plain ünïcode");
    }

    #[test]
    fn numbers_are_compact() {
        assert_eq!(num(1.0), "1");
        assert_eq!(num(-0.00001), "0");
        assert_eq!(num(2.50004), "2.5");
        assert_eq!(num(-1.23456), "-1.2346");
    }

    #[test]
    fn lines_and_quads_are_written_back_as_such() {
        let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10">
            <path id="p" d="M1 1 L5 1 Q9 1 9 5 C9 7 7 9 5 9 Z" fill="#ff0000"/></svg>"##;
        let s = Scene::from_svg_str(svg, "t.svg", Sizing::Natural).unwrap();
        let out = s.to_svg_string();
        assert!(
            out.contains(r#"d="M1 1 L5 1 Q9 1 9 5 C9 7 7 9 5 9 Z""#),
            "{out}"
        );
        assert!(out.contains(r#"id="p""#));
        let back = Scene::from_svg_str(&out, "out.svg", Sizing::Natural).unwrap();
        assert_eq!(back.params().len(), s.params().len());
    }

    /// `fit --lr-points 1e308` and `perturb --points 1e300` wrote coordinates near 1e306
    /// that the reader refuses: the writer now refuses them, and writes nothing.
    #[test]
    fn writer_refuses_what_the_reader_refuses() {
        let dir = std::env::temp_dir().join(format!("diffsvg-out-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10">
            <path id="p" d="M1 1 L5 1 L5 5 Z" fill="#ff0000" stroke="#000000"/></svg>"##;
        let good = Scene::from_svg_str(svg, "t.svg", Sizing::Natural).unwrap();
        let f = dir.join("out.svg");
        type Break = fn(&mut Path);
        let cases: [(&str, Break); 4] = [
            ("coordinate 1e306 px", |p| p.points[1][0] = 1e306),
            ("coordinate is NaN", |p| p.points[0][1] = f64::NAN),
            ("stroke width 1e31 px", |p| {
                p.stroke.as_mut().unwrap().width = 1e31
            }),
            ("dash length inf", |p| {
                p.stroke.as_mut().unwrap().dash = Some(vec![1.0, f64::INFINITY])
            }),
        ];
        for (want, spoil) in cases {
            let mut bad = good.clone();
            let Node::Path(p) = &mut bad.nodes[0] else {
                unreachable!()
            };
            spoil(p);
            let e = bad.save_svg(&f).unwrap_err().to_string();
            assert!(e.contains("out.svg") && e.contains("path \"p\""), "{e}");
            assert!(e.contains(want.split(' ').next().unwrap()), "{want}: {e}");
            assert!(!f.exists());
            // And the reader refuses the same scene's text.
            let back = Scene::from_svg_str(&bad.to_svg_string(), "back.svg", Sizing::Natural);
            assert!(back.is_err() || want.contains("NaN"), "{want}");
        }
        // At the limit, a written scene reads back.
        let mut edge = good.clone();
        let Node::Path(p) = &mut edge.nodes[0] else {
            unreachable!()
        };
        p.points[1] = [MAX_COORDINATE, -MAX_COORDINATE];
        edge.save_svg(&f).unwrap();
        Scene::load(&f, Sizing::Natural).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
