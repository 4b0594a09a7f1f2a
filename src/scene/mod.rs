//! The 2D scene model.
//!
//! # Contract
//!
//! * **Device space.** Every coordinate stored in a [`Scene`] is in device pixels of the
//!   canvas `width × height`: x to the right, **y down**, the origin at the top-left corner
//!   of the top-left pixel. Pixel `(i, j)` covers `[i, i+1] × [j, j+1]`; its center is
//!   `(i + 0.5, j + 0.5)`. SVG transforms and the viewBox are baked in when the scene is
//!   loaded; only stroke frames and paint transforms keep a matrix (see [`Stroke::frame`],
//!   [`Gradient::transform`], [`ImagePaint::transform`]), and a group whose transform is
//!   a parameter ([`transform`]) keeps it too, its content still stored in device pixels.
//! * **Geometry.** A path is a list of subpaths; each subpath is a start point followed by
//!   cubic Bézier segments (three points each). Lines and quadratics are elevated to cubics
//!   exactly and remember their original kind only to be written back compactly.
//! * **Colors** are straight (not premultiplied) sRGB values in `[0, 1]`, stored as `f64`
//!   (an image's pixels: straight 8-bit RGBA, [`ImagePaint`]). Opacities are separate
//!   scalars in `[0, 1]`. Rendering premultiplies.
//! * **Images.** An SVG `<image>` is a path (its rectangle) filled with
//!   [`Paint::Image`]; its pixels have no parameters, and fits keep its rectangle where
//!   it is (its point slots get a learning rate of 0).
//! * **Paint order.** [`Scene::nodes`] is in paint order (first drawn first); a [`Group`]
//!   with opacity < 1 is composited as one layer, like resvg.
//!
//! The flat parameter vector that the optimizer moves is described in [`params`].
//!
//! ```
//! use diffsvg::{Scene, Sizing};
//! let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="16" height="16">
//!   <rect x="4" y="4" width="8" height="8" fill="crimson"/></svg>"#;
//! let scene = Scene::from_svg_str(svg, "square.svg", Sizing::Natural)?;
//! assert_eq!((scene.width, scene.height, scene.path_count()), (16, 16, 1));
//! // A <rect> keeps its own parameters: x, y, width, height, rotation, then the fill's
//! // color and opacity.
//! let mut params = scene.params();
//! assert_eq!(params[..5], [4.0, 4.0, 8.0, 8.0, 0.0]);
//! params[0] += 1.0; // move it right by a pixel
//! let mut moved = scene.clone();
//! moved.set_params(&params);
//! assert!(moved.to_svg_string().contains(r#"<rect x="5" y="4" width="8" height="8""#));
//! # Ok::<(), diffsvg::Error>(())
//! ```

mod check;
mod exact_color;
pub mod filter;
pub mod fonts;
pub(crate) mod geom;
pub mod params;
mod project;
pub mod random;
pub mod shape;
pub mod structure;
pub(crate) mod svg_in;
pub(crate) mod svg_out;
mod svg_out_filter;
pub mod tiling;
pub mod transform;

pub use fonts::Fonts;
pub use params::{ParamGroup, ParamLayout, ParamSlot};
pub use project::project;
pub use shape::{Primitive, Shape};
pub use structure::Structure;
pub use svg_in::{Sizing, from_tree, parse_tree, parse_tree_with};
pub use svg_out::escape;
pub use tiling::Tiling;

/// A 2D point or vector in device pixels.
pub type Point = [f64; 2];

/// An affine transform `[a, b, c, d, e, f]` mapping `(x, y)` to
/// `(a·x + c·y + e, b·x + d·y + f)`, as in SVG's `matrix(a b c d e f)`.
pub type Affine = [f64; 6];

/// The identity [`Affine`].
pub(crate) const IDENTITY: Affine = [1.0, 0.0, 0.0, 1.0, 0.0, 0.0];

/// Applies an affine transform to a point.
#[inline]
pub(crate) fn apply(t: &Affine, p: Point) -> Point {
    [
        t[0] * p[0] + t[2] * p[1] + t[4],
        t[1] * p[0] + t[3] * p[1] + t[5],
    ]
}

/// Composes two transforms: the result applies `b` first, then `a`.
pub(crate) fn concat(a: &Affine, b: &Affine) -> Affine {
    [
        a[0] * b[0] + a[2] * b[1],
        a[1] * b[0] + a[3] * b[1],
        a[0] * b[2] + a[2] * b[3],
        a[1] * b[2] + a[3] * b[3],
        a[0] * b[4] + a[2] * b[5] + a[4],
        a[1] * b[4] + a[3] * b[5] + a[5],
    ]
}

/// Inverts an affine transform; `None` when it is singular or not finite.
pub(crate) fn invert(t: &Affine) -> Option<Affine> {
    let det = t[0] * t[3] - t[1] * t[2];
    if !det.is_finite() || det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let a = t[3] * inv;
    let b = -t[1] * inv;
    let c = -t[2] * inv;
    let d = t[0] * inv;
    Some([a, b, c, d, -(a * t[4] + c * t[5]), -(b * t[4] + d * t[5])])
}

/// A whole drawing: canvas size and nodes in paint order.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// Canvas width in pixels.
    pub width: u32,
    /// Canvas height in pixels.
    pub height: u32,
    /// Top-level nodes, first drawn first.
    pub nodes: Vec<Node>,
}

/// One node of the scene tree.
#[derive(Clone, Debug, PartialEq)]
// Paths are the common node and are walked in every hot loop: kept inline, not boxed.
#[allow(clippy::large_enum_variant)]
pub enum Node {
    /// A filled and/or stroked path.
    Path(Path),
    /// A group composited as a layer with an opacity.
    Group(Group),
}

/// A group of nodes rendered into a transparent layer, then clipped, masked and
/// composited onto what lies below with `opacity` and `blend` (resvg's order).
#[derive(Clone, Debug, PartialEq)]
pub struct Group {
    /// The SVG id (may be empty).
    pub id: String,
    /// Layer opacity in `[0, 1]`.
    pub opacity: f64,
    /// Children in paint order.
    pub children: Vec<Node>,
    /// A clip path: the layer is multiplied by the clip's coverage.
    pub clip: Option<Box<Clip>>,
    /// A mask: the layer is multiplied by the mask's luminance or alpha.
    pub mask: Option<Box<Mask>>,
    /// How the layer is composited onto what lies below.
    pub blend: BlendMode,
    /// `isolation: isolate`: the children's blend modes see a transparent backdrop (the
    /// layer), not what lies below the group. A group with an opacity, clip path, mask or
    /// blend mode is isolated anyway.
    pub isolate: bool,
    /// Filters applied to the layer in order, before the clip path and the mask
    /// ([`filter`]); the layer then covers the filter region.
    pub filters: Vec<filter::Filter>,
    /// The group's own transform as parameters ([`transform`]), or `None` when it is
    /// baked into the children's points.
    pub transform: Option<transform::GroupTransform>,
    /// Whether the group is drawn as a layer, with an opacity parameter. `false` for a
    /// group that is only a transform (opacity 1, no clip, mask, blend mode, isolation or
    /// filter): its children are drawn as if they were its parent's, and it has no
    /// opacity slot.
    pub layer: bool,
    /// For a shape's pattern paint: how the children, the pattern's tiles, are laid out;
    /// they are copies of the first tile and share its parameters ([`tiling`]).
    pub tiling: Option<Box<Tiling>>,
}

impl Group {
    /// A plain group: opacity only, no clip, mask or blend mode.
    pub fn new(id: impl Into<String>, opacity: f64, children: Vec<Node>) -> Self {
        Group {
            id: id.into(),
            opacity,
            children,
            clip: None,
            mask: None,
            blend: BlendMode::Normal,
            isolate: false,
            filters: Vec::new(),
            transform: None,
            layer: true,
            tiling: None,
        }
    }

    /// Whether the group is only a layer with an opacity (no clip, mask, blend mode,
    /// isolation or filter).
    pub fn is_plain(&self) -> bool {
        self.clip.is_none()
            && self.mask.is_none()
            && self.blend == BlendMode::Normal
            && !self.isolate
            && self.filters.is_empty()
    }
}

/// An SVG `clipPath`: the union of its shapes' coverage, each shape filled with its own
/// fill rule (`clip-rule`); paints, opacities and strokes play no part. A clip's shapes
/// are parameters through their control points only.
///
/// `content` holds the shapes in device pixels (as every node of a scene). A clip path of
/// the clip path (`clip-path` on `<clipPath>`) is `content.clip`: multiplying the clip's
/// coverage by it is multiplying the clipped layer by both, as resvg does.
#[derive(Clone, Debug, PartialEq)]
pub struct Clip {
    /// The SVG id of the `clipPath` element (may be empty).
    pub id: String,
    /// The shapes; [`Path::fill`] carries only the fill rule (drawn opaque black).
    pub content: Group,
}

impl Clip {
    /// The clip path of one shape (drawn as a clip shape: its coverage only), without id.
    pub fn of_shape(shape: Path) -> Clip {
        Clip {
            id: String::new(),
            content: Group::new("", 1.0, vec![Node::Path(shape)]),
        }
    }
}

/// How a mask's rendered content becomes a per-pixel factor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MaskKind {
    /// `0.2125·r + 0.7154·g + 0.0721·b` of the premultiplied sRGB color (resvg's
    /// coefficients), the default `mask-type`.
    Luminance,
    /// The alpha (`mask-type: alpha`).
    Alpha,
}

/// An SVG `mask`: its content rendered into a layer, then reduced to one factor per
/// pixel by `kind`. The mask region is `content.clip`; a mask of the mask (`mask` on
/// `<mask>`) is `content.mask` (the product is the same either way: both factors are
/// linear in the content's premultiplied color).
#[derive(Clone, Debug, PartialEq)]
pub struct Mask {
    /// The SVG id of the `mask` element (may be empty).
    pub id: String,
    /// Luminance or alpha.
    pub kind: MaskKind,
    /// The content, device pixels.
    pub content: Group,
}

/// How a layer is composited onto the one below: SVG's `mix-blend-mode`, on
/// premultiplied colors as resvg (tiny-skia) computes them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BlendMode {
    /// Source-over.
    Normal,
    /// `s·d`.
    Multiply,
    /// `s + d − s·d`.
    Screen,
    /// Hard light with the layers swapped.
    Overlay,
    /// The darker of the two.
    Darken,
    /// The lighter of the two.
    Lighten,
    /// Brightens the backdrop.
    ColorDodge,
    /// Darkens the backdrop.
    ColorBurn,
    /// Multiply or screen by the source.
    HardLight,
    /// A softer hard light.
    SoftLight,
    /// `|s − d|`.
    Difference,
    /// `s + d − 2·s·d`.
    Exclusion,
    /// The source's hue with the backdrop's saturation and luminosity.
    Hue,
    /// The source's saturation.
    Saturation,
    /// The source's hue and saturation.
    Color,
    /// The source's luminosity.
    Luminosity,
    /// `min(s + d, 1)` on every channel (`plus-lighter`).
    PlusLighter,
}

impl BlendMode {
    /// Every mode, in SVG's order.
    pub const ALL: [BlendMode; 17] = [
        BlendMode::Normal,
        BlendMode::Multiply,
        BlendMode::Screen,
        BlendMode::Overlay,
        BlendMode::Darken,
        BlendMode::Lighten,
        BlendMode::ColorDodge,
        BlendMode::ColorBurn,
        BlendMode::HardLight,
        BlendMode::SoftLight,
        BlendMode::Difference,
        BlendMode::Exclusion,
        BlendMode::Hue,
        BlendMode::Saturation,
        BlendMode::Color,
        BlendMode::Luminosity,
        BlendMode::PlusLighter,
    ];

    /// The CSS name (`mix-blend-mode` value).
    pub fn name(self) -> &'static str {
        match self {
            BlendMode::Normal => "normal",
            BlendMode::Multiply => "multiply",
            BlendMode::Screen => "screen",
            BlendMode::Overlay => "overlay",
            BlendMode::Darken => "darken",
            BlendMode::Lighten => "lighten",
            BlendMode::ColorDodge => "color-dodge",
            BlendMode::ColorBurn => "color-burn",
            BlendMode::HardLight => "hard-light",
            BlendMode::SoftLight => "soft-light",
            BlendMode::Difference => "difference",
            BlendMode::Exclusion => "exclusion",
            BlendMode::Hue => "hue",
            BlendMode::Saturation => "saturation",
            BlendMode::Color => "color",
            BlendMode::Luminosity => "luminosity",
            BlendMode::PlusLighter => "plus-lighter",
        }
    }
}

/// What a path is drawn for: painted, or as a shape of a clip path (coverage only).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// Painted with its fill and stroke.
    Paint,
    /// A clip path's shape: its fill rule and coverage count, nothing else.
    Clip,
}

/// How a segment was written in the source, so SVG out can write it back compactly.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SegmentKind {
    /// A straight line (control points at 1/3 and 2/3).
    Line,
    /// A quadratic elevated to a cubic.
    Quad,
    /// A cubic.
    Cubic,
}

/// A run of connected cubic segments.
#[derive(Clone, Debug, PartialEq)]
pub struct Subpath {
    /// Index of the start point in [`Path::points`]; segment `k` uses the points
    /// `start + 3k + 1 ..= start + 3k + 3` with the previous end point as its first point.
    pub start: usize,
    /// How each segment was written; its length is the number of segments.
    pub kinds: Vec<SegmentKind>,
    /// Whether the subpath is closed by a straight line back to its start.
    pub closed: bool,
    /// Whether it is closed and its last segment ends on its start point: then the two are
    /// one point, one parameter (the start's; see [`params`](crate::scene::ParamLayout)),
    /// so that optimization cannot open a gap that the closing line would bridge with a
    /// straight chord. Set by [`Path::close`].
    pub ends_at_start: bool,
}

impl Subpath {
    /// Number of cubic segments (not counting the closing line).
    pub fn segments(&self) -> usize {
        self.kinds.len()
    }

    /// Index one past the last point of this subpath.
    pub fn end(&self) -> usize {
        self.start + 1 + 3 * self.kinds.len()
    }
}

/// Fill rule.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FillRule {
    /// Nonzero winding.
    NonZero,
    /// Even-odd.
    EvenOdd,
}

/// Spread method of a gradient outside `[0, 1]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Spread {
    /// Clamp to the end stops.
    Pad,
    /// Mirror back and forth.
    Reflect,
    /// Repeat.
    Repeat,
}

/// A gradient stop.
#[derive(Clone, Debug, PartialEq)]
pub struct Stop {
    /// Offset in `[0, 1]`; offsets are non-decreasing along a gradient.
    pub offset: f64,
    /// Straight sRGB color in `[0, 1]`.
    pub color: [f64; 3],
    /// Stop opacity in `[0, 1]`.
    pub opacity: f64,
}

/// Geometry of a gradient paint, in gradient space.
#[derive(Clone, Debug, PartialEq)]
pub enum GradientKind {
    /// `t` is the projection onto `p1 → p2`.
    Linear {
        /// Start point.
        p1: Point,
        /// End point.
        p2: Point,
    },
    /// Two-point conical gradient from the focal circle `(f, fr)` (t = 0) to the circle
    /// `(c, r)` (t = 1), as SVG's `radialGradient`.
    Radial {
        /// Center of the end circle.
        c: Point,
        /// Radius of the end circle.
        r: f64,
        /// Focal point.
        f: Point,
        /// Focal radius.
        fr: f64,
    },
}

/// A linear or radial gradient.
#[derive(Clone, Debug, PartialEq)]
pub struct Gradient {
    /// The SVG id of the gradient element (may be empty).
    pub id: String,
    /// Geometry in gradient space.
    pub kind: GradientKind,
    /// Gradient space → device space.
    pub transform: Affine,
    /// Spread method.
    pub spread: Spread,
    /// At least one stop, offsets non-decreasing.
    pub stops: Vec<Stop>,
}

/// What a fill or stroke is painted with.
#[derive(Clone, Debug, PartialEq)]
pub enum Paint {
    /// One straight sRGB color in `[0, 1]`.
    Solid([f64; 3]),
    /// A linear or radial gradient.
    Gradient(Gradient),
    /// A raster image (an SVG `<image>`): its pixels are fixed, so it has no parameters.
    Image(ImagePaint),
}

/// How an [`ImagePaint`] is sampled between its pixels: tiny-skia's filters, which resvg
/// picks from `image-rendering`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImageQuality {
    /// The pixel under the sample point (`optimizeSpeed`, `pixelated`, `crisp-edges`).
    Nearest,
    /// Bilinear between the four nearest pixels (`smooth`).
    Bilinear,
    /// Bicubic over the sixteen nearest pixels, with tiny-skia's cubic (B = C = 1/3,
    /// Mitchell–Netravali); the default (`optimizeQuality`, `high-quality`).
    Bicubic,
}

/// A raster image used as a paint: the pixels of an SVG `<image>`, drawn through
/// [`transform`](Self::transform) onto the path it fills (its rectangle, when loaded).
///
/// Pixel `(i, j)` of the image covers `[i, i+1] × [j, j+1]` in image space. Outside the
/// image the edge pixels extend (resvg's pad spread). Sampling follows tiny-skia: a
/// pixel's premultiplied value (8 bits, rounded as tiny-skia premultiplies) is filtered as
/// [`quality`](Self::quality) says; a transform that is a pure translation samples the
/// nearest pixel, whatever the quality, as tiny-skia does.
#[derive(Clone, Debug, PartialEq)]
pub struct ImagePaint {
    /// Width in pixels, at least 1.
    pub width: u32,
    /// Height in pixels, at least 1.
    pub height: u32,
    /// **Straight** (not premultiplied) sRGB RGBA, 8 bits a channel, rows from the top,
    /// `4 · width · height` bytes; shared between clones of a scene.
    pub pixels: std::sync::Arc<Vec<u8>>,
    /// Image space → device space.
    pub transform: Affine,
    /// Sampling filter.
    pub quality: ImageQuality,
}

impl ImagePaint {
    /// The image's own rectangle in device space: the corners of `[0, width] × [0, height]`
    /// through the transform, clockwise from the origin in image space.
    pub fn corners(&self) -> [Point; 4] {
        let (w, h) = (self.width as f64, self.height as f64);
        [[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]].map(|q| apply(&self.transform, q))
    }

    /// Whether `path` is this image's rectangle as [`ImagePaint::rectangle`] builds it
    /// (within a millionth of a pixel per coordinate, relative to the corners' size).
    pub fn is_rectangle_of(&self, path: &Path) -> bool {
        let want = Self::rectangle_points(self);
        let scale = want.iter().flatten().fold(1.0f64, |m, v| m.max(v.abs()));
        path.subpaths.len() == 1
            && path.subpaths[0].closed
            && path.points.len() == want.len()
            && path.points.iter().zip(&want).all(|(a, b)| {
                (a[0] - b[0]).abs() <= 1e-6 * scale && (a[1] - b[1]).abs() <= 1e-6 * scale
            })
    }

    fn rectangle_points(&self) -> Vec<Point> {
        let mut p = Path::new("");
        self.trace(&mut p);
        p.points
    }

    fn trace(&self, p: &mut Path) {
        let c = self.corners();
        p.move_to(c[0]);
        for q in &c[1..] {
            p.line_to(*q);
        }
        p.close();
    }

    /// A path filling this image's rectangle with the image (fill opacity 1, no stroke):
    /// how an SVG `<image>` is loaded.
    pub fn rectangle(self, id: impl Into<String>) -> Path {
        let mut p = Path::new(id);
        self.trace(&mut p);
        p.fill = Some(Fill {
            paint: Paint::Image(self),
            opacity: 1.0,
            rule: FillRule::NonZero,
        });
        p
    }
}

/// Fill of a path.
#[derive(Clone, Debug, PartialEq)]
pub struct Fill {
    /// Paint.
    pub paint: Paint,
    /// Fill opacity in `[0, 1]`.
    pub opacity: f64,
    /// Fill rule.
    pub rule: FillRule,
}

/// Stroke line join.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineJoin {
    /// Miter, falling back to bevel past the miter limit.
    Miter,
    /// Miter clipped at the miter limit (SVG 2 `miter-clip`).
    MiterClip,
    /// Round.
    Round,
    /// Bevel.
    Bevel,
}

/// Stroke line cap.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineCap {
    /// Flat at the end point.
    Butt,
    /// Half disc.
    Round,
    /// Half square.
    Square,
}

/// Stroke of a path.
#[derive(Clone, Debug, PartialEq)]
pub struct Stroke {
    /// Paint.
    pub paint: Paint,
    /// Stroke opacity in `[0, 1]`.
    pub opacity: f64,
    /// Width in stroke-frame units (device pixels when `frame` is the identity).
    pub width: f64,
    /// Line join.
    pub join: LineJoin,
    /// Line cap.
    pub cap: LineCap,
    /// Miter limit (ratio of miter length to width), ≥ 1.
    pub miter_limit: f64,
    /// Dash lengths in stroke-frame units, even count, all ≥ 0 and not all zero.
    pub dash: Option<Vec<f64>>,
    /// Dash offset in stroke-frame units.
    pub dash_offset: f64,
    /// Linear map `[a, b, c, d]` from stroke frame to device space. The identity unless
    /// the path was drawn under a non-uniform scale or skew: then the outline is built in
    /// the frame (where the pen is round) and mapped to device space.
    pub frame: [f64; 4],
}

/// Linear identity for [`Stroke::frame`].
pub const FRAME_IDENTITY: [f64; 4] = [1.0, 0.0, 0.0, 1.0];

/// A filled and/or stroked path. Fill is painted before the stroke unless
/// `stroke_first` is set (SVG `paint-order: stroke`).
#[derive(Clone, Debug, PartialEq)]
pub struct Path {
    /// The SVG id (may be empty; SVG out invents none).
    pub id: String,
    /// All control points of all subpaths, device pixels.
    pub points: Vec<Point>,
    /// Subpaths indexing into `points`.
    pub subpaths: Vec<Subpath>,
    /// Fill, if any.
    pub fill: Option<Fill>,
    /// Stroke, if any.
    pub stroke: Option<Stroke>,
    /// Paint the stroke before the fill.
    pub stroke_first: bool,
    /// The characters of the `<text>` element this path is the outline of (on the first
    /// path of each text only): SVG out writes them back as a comment, so that the text
    /// stays recognisable once it is outlines.
    pub text: Option<String>,
    /// The circle, ellipse or rectangle this path is drawn as, if any: then its
    /// parameters are the primitive's, and `points` and `subpaths` are its outline, built
    /// by [`Path::sync_primitive`] (see [`shape`]).
    pub primitive: Option<Primitive>,
    /// Drawn without anti-aliasing (`shape-rendering: crispEdges` or `optimizeSpeed`): a
    /// pixel is covered, wholly, when its center is inside. Its coverage is then
    /// piecewise constant in the points, so they get no gradient from it (its paint
    /// still does).
    pub crisp: bool,
}

impl Path {
    /// The four control points of segment `k` of `sub` (device pixels).
    pub fn segment_points(&self, sub: &Subpath, k: usize) -> [Point; 4] {
        let first = sub.start + 3 * k;
        [
            self.points[first],
            self.points[first + 1],
            self.points[first + 2],
            self.points[first + 3],
        ]
    }

    /// An empty path with no paint.
    pub fn new(id: impl Into<String>) -> Self {
        Path {
            id: id.into(),
            points: Vec::new(),
            subpaths: Vec::new(),
            fill: None,
            stroke: None,
            stroke_first: false,
            text: None,
            primitive: None,
            crisp: false,
        }
    }

    /// Starts a new subpath at `p`.
    pub fn move_to(&mut self, p: Point) {
        self.subpaths.push(Subpath {
            start: self.points.len(),
            kinds: Vec::new(),
            closed: false,
            ends_at_start: false,
        });
        self.points.push(p);
    }

    fn last_point(&self) -> Point {
        *self.points.last().expect("move_to must come first")
    }

    /// Appends a cubic segment to the current subpath.
    pub fn cubic_to(&mut self, c1: Point, c2: Point, p: Point) {
        self.push_segment([c1, c2, p], SegmentKind::Cubic);
    }

    /// Appends a straight segment, elevated to a cubic with control points at 1/3 and 2/3.
    pub fn line_to(&mut self, p: Point) {
        let a = self.last_point();
        let c1 = [a[0] + (p[0] - a[0]) / 3.0, a[1] + (p[1] - a[1]) / 3.0];
        let c2 = [
            a[0] + 2.0 * (p[0] - a[0]) / 3.0,
            a[1] + 2.0 * (p[1] - a[1]) / 3.0,
        ];
        self.push_segment([c1, c2, p], SegmentKind::Line);
    }

    /// Appends a quadratic segment, elevated exactly to a cubic.
    pub fn quad_to(&mut self, q: Point, p: Point) {
        let a = self.last_point();
        let c1 = [
            a[0] + 2.0 / 3.0 * (q[0] - a[0]),
            a[1] + 2.0 / 3.0 * (q[1] - a[1]),
        ];
        let c2 = [
            p[0] + 2.0 / 3.0 * (q[0] - p[0]),
            p[1] + 2.0 / 3.0 * (q[1] - p[1]),
        ];
        self.push_segment([c1, c2, p], SegmentKind::Quad);
    }

    fn push_segment(&mut self, pts: [Point; 3], kind: SegmentKind) {
        let sp = self.subpaths.last_mut().expect("move_to must come first");
        sp.kinds.push(kind);
        self.points.extend_from_slice(&pts);
    }

    /// Closes the current subpath. When its last segment already ends on its start point,
    /// the two become one parameter ([`Subpath::ends_at_start`]).
    pub fn close(&mut self) {
        if let Some(sp) = self.subpaths.last_mut() {
            sp.closed = true;
            sp.ends_at_start =
                sp.segments() > 0 && self.points[sp.end() - 1] == self.points[sp.start];
        }
    }

    /// Gives each closed subpath that ends at its start its start point's value again
    /// (after parameters were written one slot at a time).
    pub(crate) fn join_closing_points(&mut self) {
        for sp in &self.subpaths {
            if sp.ends_at_start {
                self.points[sp.end() - 1] = self.points[sp.start];
            }
        }
    }

    /// Axis-aligned bounds of the control points, `[xmin, ymin, xmax, ymax]`; the curve lies
    /// inside. `None` for a path without points.
    pub fn control_bounds(&self) -> Option<[f64; 4]> {
        let mut it = self.points.iter();
        let first = it.next()?;
        let mut b = [first[0], first[1], first[0], first[1]];
        for p in it {
            b[0] = b[0].min(p[0]);
            b[1] = b[1].min(p[1]);
            b[2] = b[2].max(p[0]);
            b[3] = b[3].max(p[1]);
        }
        Some(b)
    }
}

/// Calls `f` on every path under `nodes` in paint order (depth first: a group's children,
/// then its clip path's shapes, then its mask's content), with its role; `role` is that
/// of `nodes`.
pub(crate) fn paths_of<'a>(nodes: &'a [Node], role: Role, f: &mut impl FnMut(&'a Path, Role)) {
    fn group<'a>(g: &'a Group, role: Role, f: &mut impl FnMut(&'a Path, Role)) {
        paths_of(&g.children, role, f);
        if let Some(c) = &g.clip {
            group(&c.content, Role::Clip, f);
        }
        if let Some(m) = &g.mask {
            group(&m.content, role, f);
        }
    }
    for n in nodes {
        match n {
            Node::Path(p) => f(p, role),
            Node::Group(g) => group(g, role, f),
        }
    }
}

/// Calls `f` on every path under `nodes` in paint order (as [`paths_of`]), mutably.
pub(crate) fn paths_of_mut(nodes: &mut [Node], f: &mut impl FnMut(&mut Path)) {
    fn group(g: &mut Group, f: &mut impl FnMut(&mut Path)) {
        paths_of_mut(&mut g.children, f);
        if let Some(c) = &mut g.clip {
            group(&mut c.content, f);
        }
        if let Some(m) = &mut g.mask {
            group(&mut m.content, f);
        }
    }
    for n in nodes {
        match n {
            Node::Path(p) => f(p),
            Node::Group(g) => group(g, f),
        }
    }
}

impl Scene {
    /// An empty scene of the given size.
    pub fn new(width: u32, height: u32) -> Self {
        Scene {
            width,
            height,
            nodes: Vec::new(),
        }
    }

    /// Calls `f` on every path in paint order (depth first): a group's children, then
    /// its clip path's shapes, then its mask's content.
    pub fn for_each_path<'a>(&'a self, mut f: impl FnMut(&'a Path)) {
        self.for_each_path_role(|p, _| f(p));
    }

    /// Like [`for_each_path`](Self::for_each_path), telling which paths are clip shapes.
    pub fn for_each_path_role<'a>(&'a self, mut f: impl FnMut(&'a Path, Role)) {
        paths_of(&self.nodes, Role::Paint, &mut f);
    }

    /// Calls `f` on every path in paint order (depth first), mutably.
    pub fn for_each_path_mut(&mut self, mut f: impl FnMut(&mut Path)) {
        paths_of_mut(&mut self.nodes, &mut f);
    }

    /// Number of paths in the scene.
    pub fn path_count(&self) -> usize {
        let mut n = 0;
        self.for_each_path(|_| n += 1);
        n
    }

    /// Scales the whole scene (geometry, widths, paint transforms) by `s` about the origin
    /// and sets the canvas to `width × height`.
    pub fn scale_to(&mut self, s: f64, width: u32, height: u32) {
        self.width = width;
        self.height = height;
        tiling::map_nodes(&mut self.nodes, s, [0.0; 2]);
    }
}

impl Stroke {
    /// An SVG-default stroke (opacity 1, miter join with limit 4, butt cap, no dashes, no
    /// frame) with the given paint and width in device pixels.
    pub fn new(paint: Paint, width: f64) -> Self {
        Stroke {
            paint,
            opacity: 1.0,
            width,
            join: LineJoin::Miter,
            cap: LineCap::Butt,
            miter_limit: 4.0,
            dash: None,
            dash_offset: 0.0,
            frame: FRAME_IDENTITY,
        }
    }

    /// If the frame is a similarity (uniform scale times a rotation or reflection), folds
    /// its scale into the width and resets it to the identity, so that the stroke is
    /// described in device pixels. Rotations do not change a round pen.
    pub fn normalize_frame(&mut self) {
        let [a, b, c, d] = self.frame;
        let sx = a.hypot(b);
        let sy = c.hypot(d);
        let dot = a * c + b * d;
        if sx > 0.0 && (sx - sy).abs() <= 1e-9 * sx && dot.abs() <= 1e-9 * sx * sy {
            self.width *= sx;
            if let Some(d) = &mut self.dash {
                for v in d.iter_mut() {
                    *v *= sx;
                }
            }
            self.dash_offset *= sx;
            // A reflection flips the pen's sides but a round pen does not care; the
            // outline orientation is fixed later by the nonzero fill.
            self.frame = FRAME_IDENTITY;
        }
    }
}
