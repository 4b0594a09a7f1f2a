//! SVG in: usvg parses and simplifies, this module bakes transforms into device space.

use std::path::Path as FsPath;

use super::transform::GroupTransform;
use super::{
    Affine, BlendMode, Clip, FRAME_IDENTITY, Fill, FillRule, Fonts, Gradient, GradientKind, Group,
    IDENTITY, ImagePaint, ImageQuality, LineCap, LineJoin, Mask, MaskKind, Node, Paint, Path,
    Point, Role, Scene, Spread, Stop, Stroke, apply, concat, invert,
};
use crate::error::{Error, Result};

use crate::image_io::{gunzip_bounded, is_gzip, read_bounded};
use crate::limits::MAX_GROUP_DEPTH;
pub(crate) use crate::limits::MAX_SIDE;
use crate::limits::{
    MAX_ARC_RADIUS, MAX_DECOMPRESSED_BYTES, MAX_FILE_BYTES, MAX_MARKER_NODES, MAX_PATTERN_SHAPES,
    MAX_PATTERN_TILES, MAX_PIXELS, MAX_SCENE_IMAGE_PIXELS, MAX_SELECTOR_WORK,
};

/// How to size the canvas when loading an SVG.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Sizing {
    /// The SVG's own size (its `width`/`height`, else its viewBox).
    #[default]
    Natural,
    /// Scale uniformly so that the canvas is this many pixels wide.
    Width(u32),
    /// Scale uniformly by this factor.
    Scale(f64),
    /// Scale non-uniformly to exactly this size (used to match a target image).
    Exact(u32, u32),
}

impl Sizing {
    /// The sizing asked for by a `width` (height by the aspect ratio), a `width` and a
    /// `height` (exactly), or a `scale`; none of them: the natural size. The one reading of
    /// these options for every front end: errors ([`Error::Setting`]) name the option.
    pub fn from_options(
        width: Option<u32>,
        height: Option<u32>,
        scale: Option<f64>,
    ) -> Result<Sizing> {
        let positive = |name: &str, v: Option<u32>| -> Result<()> {
            match v {
                Some(v) => crate::limits::check_count(name, v as usize, 1..=usize::MAX),
                None => Ok(()),
            }
        };
        positive("width", width)?;
        positive("height", height)?;
        Ok(match (width, height, scale) {
            (None, None, None) => Sizing::Natural,
            (Some(w), None, None) => Sizing::Width(w),
            (Some(w), Some(h), None) => Sizing::Exact(w, h),
            (None, None, Some(s)) if s.is_finite() && s > 0.0 => Sizing::Scale(s),
            (None, None, Some(s)) => {
                return Err(Error::Setting {
                    name: "scale".into(),
                    message: format!("{s} must be a positive number"),
                });
            }
            _ => {
                return Err(Error::Setting {
                    name: "height".into(),
                    message: "alone or with scale is ambiguous: give width, width and \
                              height, or scale"
                        .into(),
                });
            }
        })
    }
}

impl Scene {
    /// Loads an SVG file (plain or gzip-compressed, `.svgz`), of at most
    /// [`MAX_FILE_BYTES`] bytes, with the bundled fonts ([`Fonts::default`]). Errors name
    /// the file.
    pub fn load(path: impl AsRef<FsPath>, sizing: Sizing) -> Result<Scene> {
        Scene::load_with(path, sizing, super::fonts::bundled())
    }

    /// [`Scene::load`] with these fonts for `<text>`.
    pub fn load_with(path: impl AsRef<FsPath>, sizing: Sizing, fonts: &Fonts) -> Result<Scene> {
        let path = path.as_ref();
        let data = read_bounded(path, MAX_FILE_BYTES)?;
        Scene::from_svg_data_with(&data, path, sizing, fonts)
    }

    /// Parses SVG text; `name` is used in error messages.
    pub fn from_svg_str(text: &str, name: impl AsRef<FsPath>, sizing: Sizing) -> Result<Scene> {
        Scene::from_svg_data(text.as_bytes(), name.as_ref(), sizing)
    }

    /// [`Scene::from_svg_str`] with these fonts for `<text>`.
    pub fn from_svg_str_with(
        text: &str,
        name: impl AsRef<FsPath>,
        sizing: Sizing,
        fonts: &Fonts,
    ) -> Result<Scene> {
        Scene::from_svg_data_with(text.as_bytes(), name.as_ref(), sizing, fonts)
    }

    /// Parses SVG bytes (plain or gzip-compressed); `name` is used in error messages.
    pub fn from_svg_data(data: &[u8], name: &FsPath, sizing: Sizing) -> Result<Scene> {
        Scene::from_svg_data_with(data, name, sizing, super::fonts::bundled())
    }

    /// [`Scene::from_svg_data`] with these fonts for `<text>`.
    pub fn from_svg_data_with(
        data: &[u8],
        name: &FsPath,
        sizing: Sizing,
        fonts: &Fonts,
    ) -> Result<Scene> {
        let unzipped;
        let data = if is_gzip(data) {
            unzipped = gunzip_bounded(data, MAX_DECOMPRESSED_BYTES, name)?;
            &unzipped[..]
        } else {
            data
        };
        let mut scene = from_tree(&parse_tree_with(data, name, fonts)?, name, sizing)?;
        if let Ok(text) = std::str::from_utf8(data) {
            super::exact_color::restore(&mut scene, text);
        }
        Ok(scene)
    }
}

/// [`parse_tree_with`] the bundled fonts ([`Fonts::default`]).
pub fn parse_tree(data: &[u8], name: &FsPath) -> Result<usvg::Tree> {
    parse_tree_with(data, name, super::fonts::bundled())
}

/// Parses SVG bytes with usvg, refusing elements usvg would silently drop. Gzip-compressed
/// bytes (`.svgz`) are decompressed first, to at most [`MAX_DECOMPRESSED_BYTES`]. A panic
/// inside usvg is caught and reported as an [`Error::Svg`] naming the file.
///
/// `<text>` is laid out into glyph outlines with `fonts`; a `font-family` no loaded font
/// has is an [`Error::Unsupported`] naming the file and the families, unless the fonts
/// allow fallback. Give the same tree to [`from_tree`] and to the reference renderer
/// (`reference::render_resvg`), and both draw the same glyphs.
pub fn parse_tree_with(data: &[u8], name: &FsPath, fonts: &Fonts) -> Result<usvg::Tree> {
    let unzipped;
    let data = if is_gzip(data) {
        unzipped = gunzip_bounded(data, MAX_DECOMPRESSED_BYTES, name)?;
        &unzipped[..]
    } else {
        data
    };
    if let Ok(text) = std::str::from_utf8(data) {
        reject_unsupported_xml(text, name)?;
    }
    let (font_opt, missing) = fonts.usvg_options()?;
    // Images usvg cannot load it skips without a word: the resolvers note each failure,
    // and the first one refuses the file.
    let failures = std::sync::Mutex::new(Vec::new());
    let opt = usvg::Options {
        fontdb: font_opt.fontdb,
        font_family: font_opt.font_family,
        font_resolver: font_opt.font_resolver,
        ..image_options(name, &failures)
    };
    // usvg's geometry unwraps rectangles it cannot build (a filter or image region of
    // width 3.4e38): behind the guard such a panic is one more parse error.
    let parsed =
        crate::guard::quietly(|| usvg::Tree::from_data(data, &opt)).map_err(|why| Error::Svg {
            path: name.to_path_buf(),
            message: format!("the SVG parser (usvg) failed on this file: {why}"),
        })?;
    let tree = parsed.map_err(|e| Error::Svg {
        path: name.to_path_buf(),
        message: e.to_string(),
    })?;
    drop(opt);
    fonts.check_missing(&missing, name)?;
    let failures = failures.into_inner().unwrap_or_else(|e| e.into_inner());
    match failures.into_iter().next() {
        Some(message) => Err(Error::Image {
            path: name.to_path_buf(),
            message,
        }),
        None => Ok(tree),
    }
}

/// usvg's options for `name`: images referenced by a relative path resolve against the
/// SVG's folder; an image file is read with the bound [`MAX_FILE_BYTES`]; an SVG image
/// (file or data URL) passes the checks an SVG file passes (`reject_unsupported_xml`)
/// before usvg parses it. Every image that cannot be loaded adds a sentence naming it to
/// `failures` (usvg would drop the element silently).
fn image_options<'a>(
    name: &FsPath,
    failures: &'a std::sync::Mutex<Vec<String>>,
) -> usvg::Options<'a> {
    use std::sync::Arc;
    let fail = move |what: String| {
        if let Ok(mut f) = failures.lock() {
            f.push(what);
        }
        None
    };
    // Raster data is recognized by its signature; anything else is taken for SVG text.
    let is_raster = |d: &[u8]| {
        d.starts_with(b"\x89PNG")
            || d.starts_with(&[0xff, 0xd8, 0xff])
            || d.starts_with(b"GIF8")
            || (d.len() >= 12 && &d[..4] == b"RIFF" && &d[8..12] == b"WEBP")
    };
    // An SVG image passes the checks of an SVG file; a compressed one (`.svgz`) is
    // inflated here (usvg is built without its own gzip support). Returns the bytes for
    // usvg, or the sentence that refuses them.
    let svg_name = name.to_path_buf();
    let vet = move |data: Arc<Vec<u8>>, what: &str| -> std::result::Result<Arc<Vec<u8>>, String> {
        if is_raster(&data) {
            return Ok(data);
        }
        let data = if is_gzip(&data) {
            Arc::new(
                gunzip_bounded(&data, MAX_DECOMPRESSED_BYTES, &svg_name)
                    .map_err(|e| format!("{what}: {}", inner_message(&e)))?,
            )
        } else {
            data
        };
        match std::str::from_utf8(&data) {
            Ok(text) => reject_unsupported_xml(text, &svg_name)
                .map_err(|e| format!("{what}, an SVG image: {}", inner_message(&e)))?,
            Err(_) => {
                return Err(format!("{what} is not a PNG, JPEG, GIF, WebP or SVG image"));
            }
        }
        Ok(data)
    };
    // What usvg made of the bytes: nothing, or a raster image whose header gives no size
    // (usvg then drops it, `ImageKind::actual_size`), is a failure.
    let resolved = move |kind: Option<usvg::ImageKind>, what: &str| {
        use usvg::ImageKind as K;
        match kind {
            None => fail(format!("{what} cannot be decoded")),
            Some(K::PNG(ref d) | K::JPEG(ref d) | K::GIF(ref d) | K::WEBP(ref d)) => {
                match imagesize::blob_size(d) {
                    Ok(s) if s.width > 0 && s.height > 0 => kind,
                    Ok(s) => fail(format!("{what} is empty ({}x{})", s.width, s.height)),
                    Err(e) => fail(format!("{what} cannot be decoded: {e}")),
                }
            }
            Some(K::SVG(_)) => kind,
        }
    };
    let resolved_data = resolved;
    let vet_data = vet.clone();
    let resolve_data: usvg::ImageHrefDataResolverFn<'a> = Box::new(move |mime, data, opts| {
        let what = format!("an image in a data URL ({mime})");
        let data = match vet_data(data, &what) {
            Ok(d) => d,
            Err(e) => return fail(e),
        };
        resolved_data(
            (usvg::ImageHrefResolver::default_data_resolver())(mime, data, opts),
            &what,
        )
    });
    let resolve_string: usvg::ImageHrefStringResolverFn<'a> = Box::new(move |href, opts| {
        let what = format!("image \"{href}\"");
        if href.contains("://") {
            return fail(format!("{what} is a URL: diffsvg reads no remote images"));
        }
        let path = opts.get_abs_path(FsPath::new(href));
        let data = match read_bounded(&path, MAX_FILE_BYTES) {
            Ok(d) => d,
            Err(e) => return fail(format!("{what} cannot be read: {e}")),
        };
        let data = match vet(Arc::new(data), &what) {
            Ok(d) => d,
            Err(e) => return fail(e),
        };
        resolved(
            (usvg::ImageHrefResolver::default_data_resolver())("text/plain", data, opts),
            &format!("{what} ({})", path.display()),
        )
    });
    usvg::Options {
        resources_dir: name
            .parent()
            .filter(|d| !d.as_os_str().is_empty())
            .map(FsPath::to_path_buf),
        image_href_resolver: usvg::ImageHrefResolver {
            resolve_data,
            resolve_string,
        },
        ..usvg::Options::default()
    }
}

/// usvg silently drops some elements; refuse them instead of rendering something else
/// than the file says. (Images it cannot load are caught by the resolvers of
/// `image_options`, text without fonts by the font selector of [`Fonts`].)
fn reject_unsupported_xml(text: &str, name: &FsPath) -> Result<()> {
    let Ok(doc) = usvg::roxmltree::Document::parse_with_options(
        text,
        usvg::roxmltree::ParsingOptions {
            allow_dtd: true,
            ..Default::default()
        },
    ) else {
        return Ok(()); // usvg reports the parse error with more detail
    };
    check_selector_work(&doc, name)?;
    check_marker_work(&doc, name)?;
    check_reference_depth(&doc, name)?;
    for n in doc.descendants().filter(|n| n.is_element()) {
        let tag = n.tag_name().name();
        if matches!(tag, "foreignObject") {
            return Err(Error::Unsupported {
                path: name.to_path_buf(),
                what: describe(tag, n.attribute("id")),
            });
        }
        for a in n.attributes() {
            let bad = if a.name() == "style" {
                css_bad_number(a.value())
            } else if GEOMETRY_ATTRIBUTES.contains(&a.name()) {
                bad_number(a.value())
                    .or_else(|| (a.name() == "d").then(|| huge_arc(a.value())).flatten())
                    .map(|bad| (a.name().to_string(), bad))
            } else {
                None
            };
            if let Some((property, bad)) = bad {
                let place = if a.name() == "style" {
                    format!("property {property} in the style of")
                } else {
                    format!("attribute {property} of")
                };
                return Err(Error::InvalidValue {
                    path: name.to_path_buf(),
                    what: format!("{bad} in {place} {}", describe(tag, n.attribute("id"))),
                });
            }
        }
        if tag == "style" {
            let css: String = n.children().filter_map(|c| c.text()).collect();
            if let Some((property, bad)) = css_bad_number(&css) {
                return Err(Error::InvalidValue {
                    path: name.to_path_buf(),
                    what: format!("{bad} in property {property} of a <style> rule"),
                });
            }
        }
    }
    Ok(())
}

/// Refuses clip paths, masks, patterns and markers that refer to each other (`clip-path`
/// on a `<clipPath>`, a pattern filling a pattern's shape, …) in a chain longer than
/// [`MAX_GROUP_DEPTH`]: each link is a layer inside a layer, and usvg follows the chain
/// recursively before anything else can count it (20,000 links overflowed the stack).
/// Cycles are usvg's to report; they add nothing here.
fn check_reference_depth(doc: &usvg::roxmltree::Document, name: &FsPath) -> Result<()> {
    use std::collections::HashMap;
    const KINDS: [&str; 4] = ["clipPath", "mask", "pattern", "marker"];
    let urls = |n: usvg::roxmltree::Node| -> Vec<String> {
        let mut out = Vec::new();
        for d in n.descendants().filter(|d| d.is_element()) {
            for a in d.attributes() {
                let mut rest = a.value();
                while let Some(at) = rest.find("url(") {
                    rest = &rest[at + 4..];
                    let end = rest.find(')').unwrap_or(rest.len());
                    let id = rest[..end]
                        .trim()
                        .trim_matches(['\'', '"'])
                        .trim_start_matches('#');
                    out.push(id.to_string());
                    rest = &rest[end..];
                }
            }
        }
        out
    };
    let mut links: HashMap<&str, Vec<String>> = HashMap::new();
    for n in doc
        .descendants()
        .filter(|n| KINDS.contains(&n.tag_name().name()))
    {
        if let Some(id) = n.attribute("id") {
            links.insert(id, urls(n));
        }
    }
    // Longest chain from each element, without recursion: 0 while being explored (a
    // cycle counts nothing more).
    let mut depth: HashMap<&str, usize> = HashMap::new();
    for &start in links.keys() {
        let mut stack: Vec<(&str, usize)> = vec![(start, 0)];
        while let Some(&(id, next)) = stack.last() {
            if next == 0 && depth.contains_key(id) {
                stack.pop();
                continue;
            }
            depth.entry(id).or_insert(0);
            let targets = &links[id];
            match targets.get(next) {
                Some(t) => {
                    stack.last_mut().expect("on the stack").1 += 1;
                    if let Some((key, _)) = links.get_key_value(t.as_str())
                        && !depth.contains_key(key)
                    {
                        stack.push((key, 0));
                    }
                }
                None => {
                    let d = 1 + targets
                        .iter()
                        .filter_map(|t| depth.get(t.as_str()))
                        .max()
                        .copied()
                        .unwrap_or(0);
                    depth.insert(id, d);
                    stack.pop();
                    if d > MAX_GROUP_DEPTH {
                        return Err(Error::Unsupported {
                            path: name.to_path_buf(),
                            what: format!(
                                "clip paths, masks, patterns or markers referring to each \
                                 other more than {MAX_GROUP_DEPTH} deep (the layer limit)"
                            ),
                        });
                    }
                }
            }
        }
    }
    Ok(())
}

/// Refuses a file whose markers would make more than [`MAX_MARKER_NODES`] elements:
/// usvg copies a marker's content at every vertex of every path that uses it, so a
/// marker of `m` elements on paths of `v` vertices in all makes up to `m × v` of them,
/// allocated before anything can be checked. Estimated from the text: the numbers in the
/// path data and point lists of the shapes that name a marker (of every shape when a
/// stylesheet or a container may give them one), at least one per vertex, times the
/// largest marker.
fn check_marker_work(doc: &usvg::roxmltree::Document, name: &FsPath) -> Result<()> {
    let markers = doc.descendants().filter(|n| n.has_tag_name("marker"));
    let largest = markers.map(|m| m.descendants().count()).max().unwrap_or(0) as f64;
    if largest == 0.0 {
        return Ok(());
    }
    // The shapes that can carry markers: those naming one, unless a stylesheet or a
    // container (inherited) may give them to any shape.
    let names_marker = |n: &usvg::roxmltree::Node| {
        n.attributes().any(|a| {
            a.name().starts_with("marker") || (a.name() == "style" && a.value().contains("marker"))
        })
    };
    let shapes = ["path", "line", "polyline", "polygon"];
    let inherited = doc.descendants().any(|n| {
        (n.has_tag_name("style") && n.text().is_some_and(|t| t.contains("marker")))
            || (n.is_element() && !shapes.contains(&n.tag_name().name()) && names_marker(&n))
    });
    let numbers: f64 = doc
        .descendants()
        .filter(|n| inherited || names_marker(n))
        .flat_map(|n| {
            // A line's four numbers make two vertices.
            let line = n.has_tag_name("line").then_some("0 0 0 0");
            [n.attribute("d"), n.attribute("points"), line]
        })
        .flatten()
        .map(|v| {
            v.split(|c: char| !c.is_ascii_digit())
                .filter(|t| !t.is_empty())
                .count() as f64
        })
        .sum();
    // Every vertex has at least one number; a few more for the start and end markers.
    let work = largest * (numbers + 3.0);
    if work > MAX_MARKER_NODES as f64 {
        return Err(Error::Unsupported {
            path: name.to_path_buf(),
            what: format!(
                "markers would be copied into about {work:.0} elements (a marker of {largest} \
                 elements on paths of up to {numbers} vertices; the limit is \
                 {MAX_MARKER_NODES})"
            ),
        });
    }
    Ok(())
}

/// Refuses a stylesheet whose selectors would take too long to match: usvg matches a
/// selector of `k` compound parts joined by descendant combinators by backtracking over
/// ancestors, up to `depth^(k−1)` steps per element. 300 nested groups under a rule like
/// `g#a * g * * rect` ran for minutes; [`MAX_SELECTOR_WORK`] bounds that product before
/// usvg sees the text.
fn check_selector_work(doc: &usvg::roxmltree::Document, name: &FsPath) -> Result<()> {
    // Depth of every node, in document order (a parent comes before its children).
    let mut depth = vec![0u32; doc.descendants().count()];
    let (mut max_depth, mut elements, mut sheets) = (0u64, 0u64, Vec::new());
    for n in doc.descendants() {
        let d = n.parent().map_or(0, |p| depth[p.id().get_usize()] + 1);
        depth[n.id().get_usize()] = d;
        if n.is_element() {
            elements += 1;
            max_depth = max_depth.max(d as u64);
            if n.tag_name().name() == "style" {
                sheets.push(n);
            }
        }
    }
    let parts = sheets
        .iter()
        .flat_map(|s| s.descendants().filter_map(|t| t.text()))
        .map(most_selector_parts)
        .max()
        .unwrap_or(0);
    if parts < 2 {
        return Ok(());
    }
    let work = (elements as f64) * (max_depth as f64).powi(parts as i32 - 1);
    if work > MAX_SELECTOR_WORK {
        return Err(Error::Unsupported {
            path: name.to_path_buf(),
            what: format!(
                "a stylesheet selector of {parts} parts over {elements} elements nested \
                 {max_depth} deep (about {work:.1e} matching steps; the limit is \
                 {MAX_SELECTOR_WORK:.0e})"
            ),
        });
    }
    Ok(())
}

/// The most compound parts (runs between combinators) of any selector in a CSS text.
fn most_selector_parts(css: &str) -> u32 {
    let mut most = 0;
    let mut rest = css;
    // Selectors are what precedes each `{`; declarations run to the matching `}`.
    while let Some(open) = rest.find('{') {
        let selectors = &rest[..open];
        for sel in selectors.split(',') {
            let n = sel
                .split(|c: char| c.is_whitespace() || matches!(c, '>' | '+' | '~'))
                .filter(|p| !p.is_empty())
                .count() as u32;
            most = most.max(n);
        }
        rest = match rest[open..].find('}') {
            Some(close) => &rest[open + close + 1..],
            None => "",
        };
    }
    most
}

/// Describes the first elliptical arc in path data whose radius exceeds [`MAX_ARC_RADIUS`]:
/// the radius as written or, where the endpoint lies beyond the ellipse's reach, the radius
/// SVG scales it up to (the implementation notes, F.6.6). usvg turns an arc into cubics at
/// a fixed tolerance, about `(radius / 0.1)^(1/6)` of them, and takes them one by one from
/// the front of a list: quadratic in their number. An arc of radius 1e30 spent 12 s there,
/// and `a48 48 0 0 0 7.1 1e38`, whose radius grows to 5e37, ran past 20 s.
fn huge_arc(d: &str) -> Option<String> {
    if !d.contains(['a', 'A']) {
        return None;
    }
    use svgtypes::PathSegment as S;
    // The current point and the start of the subpath, in the path's absolute units.
    let (mut cur, mut start) = ([0.0f64; 2], [0.0f64; 2]);
    for seg in svgtypes::PathParser::from(d) {
        let Ok(seg) = seg else {
            break; // usvg reports (or drops) malformed data itself
        };
        let abs = match seg {
            S::MoveTo { abs, .. }
            | S::LineTo { abs, .. }
            | S::HorizontalLineTo { abs, .. }
            | S::VerticalLineTo { abs, .. }
            | S::CurveTo { abs, .. }
            | S::SmoothCurveTo { abs, .. }
            | S::Quadratic { abs, .. }
            | S::SmoothQuadratic { abs, .. }
            | S::EllipticalArc { abs, .. }
            | S::ClosePath { abs } => abs,
        };
        let base = if abs { [0.0; 2] } else { cur };
        let to = |x: f64, y: f64| [base[0] + x, base[1] + y];
        let end = match seg {
            S::MoveTo { x, y, .. } => {
                start = to(x, y);
                start
            }
            S::LineTo { x, y, .. }
            | S::CurveTo { x, y, .. }
            | S::SmoothCurveTo { x, y, .. }
            | S::Quadratic { x, y, .. }
            | S::SmoothQuadratic { x, y, .. } => to(x, y),
            S::HorizontalLineTo { x, .. } => [base[0] + x, cur[1]],
            S::VerticalLineTo { y, .. } => [cur[0], base[1] + y],
            S::ClosePath { .. } => start,
            S::EllipticalArc {
                rx,
                ry,
                x_axis_rotation,
                x,
                y,
                ..
            } => {
                let end = to(x, y);
                let r = arc_radius(cur, end, rx, ry, x_axis_rotation);
                if !(r <= MAX_ARC_RADIUS) {
                    return Some(format!(
                        "arc radius {r:e} above the limit of {MAX_ARC_RADIUS:e}"
                    ));
                }
                end
            }
        };
        cur = end;
    }
    None
}

/// The larger radius an SVG arc from `from` to `to` is drawn with: `max(|rx|, |ry|)`, scaled
/// up by `√Λ` when the radii are too small to reach the endpoint (SVG 1.1, F.6.6). Zero
/// where either radius is zero (the arc is a straight line); NaN where an input is NaN.
fn arc_radius(from: [f64; 2], to: [f64; 2], rx: f64, ry: f64, rotation_deg: f64) -> f64 {
    let (rx, ry) = (rx.abs(), ry.abs());
    if rx == 0.0 || ry == 0.0 {
        return 0.0;
    }
    let (sin, cos) = rotation_deg.to_radians().sin_cos();
    let (dx, dy) = (0.5 * (from[0] - to[0]), 0.5 * (from[1] - to[1]));
    let (x1, y1) = (cos * dx + sin * dy, -sin * dx + cos * dy);
    let lambda = (x1 / rx).powi(2) + (y1 / ry).powi(2);
    // `max` would turn a NaN into 1.
    let scale = if lambda.is_nan() {
        f64::NAN
    } else {
        lambda.sqrt().max(1.0)
    };
    rx.max(ry) * scale
}

/// Attributes holding numbers that usvg would silently drop a shape (or a property) for
/// when they are not finite in `f32`: NaN, infinities and magnitudes above `f32::MAX`
/// never reach the resolved tree, so this raw scan stays only to report them.
///
/// Every other range check (|v| ≤ [`MAX_COORDINATE`](crate::limits::MAX_COORDINATE),
/// wherever the value came from: attribute, `style`, `<style>` rule, inheritance) is made
/// once on the resolved values, by [`check_numbers`](super::svg_out::check_numbers) in
/// [`from_tree`].
const GEOMETRY_ATTRIBUTES: &[&str] = &[
    "d",
    "points",
    "x",
    "y",
    "width",
    "height",
    "cx",
    "cy",
    "r",
    "rx",
    "ry",
    "x1",
    "y1",
    "x2",
    "y2",
    "fx",
    "fy",
    "fr",
    "transform",
    "gradientTransform",
    "stroke-width",
    "stroke-dasharray",
    "stroke-dashoffset",
    "stroke-miterlimit",
    "viewBox",
];

/// The first CSS declaration (`name: value`, in a `style` attribute or a `<style>` sheet)
/// of a [`GEOMETRY_ATTRIBUTES`] property whose value holds a number usvg cannot represent:
/// the property and [`bad_number`]'s description.
fn css_bad_number(css: &str) -> Option<(String, String)> {
    css.split([';', '{', '}'])
        .filter_map(|decl| decl.split_once(':'))
        .map(|(k, v)| (k.trim(), v.trim().trim_end_matches("!important")))
        .filter(|(k, _)| GEOMETRY_ATTRIBUTES.contains(k))
        .find_map(|(k, v)| bad_number(v).map(|b| (k.to_string(), b)))
}

/// Describes the first NaN, infinity or number beyond `f32` in an attribute value.
fn bad_number(value: &str) -> Option<String> {
    let lower = value.to_ascii_lowercase();
    if lower.contains("nan") {
        return Some("NaN".into());
    }
    if lower.contains("inf") {
        return Some("an infinite number".into());
    }
    // Scan numbers: sign, digits, fraction, exponent.
    let b = value.as_bytes();
    let mut i = 0;
    while i < b.len() {
        let start = i;
        if b[i] == b'+' || b[i] == b'-' {
            i += 1;
        }
        let digits = i;
        while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'.') {
            i += 1;
        }
        if i == digits {
            i = start + 1;
            continue;
        }
        if i < b.len() && (b[i] == b'e' || b[i] == b'E') {
            let mut j = i + 1;
            if j < b.len() && (b[j] == b'+' || b[j] == b'-') {
                j += 1;
            }
            if j < b.len() && b[j].is_ascii_digit() {
                i = j;
                while i < b.len() && b[i].is_ascii_digit() {
                    i += 1;
                }
            }
        }
        if let Ok(v) = value[start..i].parse::<f64>()
            && !(v.abs() <= f32::MAX as f64)
        {
            return Some(format!("number {} out of range", &value[start..i]));
        }
    }
    None
}

/// An error's sentence without the file name it starts with (for an error about an image
/// inside the file that is named already).
fn inner_message(e: &Error) -> String {
    match e {
        Error::Svg { message, .. } => format!("malformed SVG: {message}"),
        Error::Unsupported { what, .. } => format!("unsupported: {what}"),
        Error::InvalidValue { what, .. } => format!("invalid value: {what}"),
        Error::Image { message, .. } => message.clone(),
        e => e.to_string(),
    }
}

fn describe(tag: &str, id: Option<&str>) -> String {
    match id {
        Some(id) if !id.is_empty() => format!("<{tag}> element (id \"{id}\")"),
        _ => format!("<{tag}> element"),
    }
}

fn to_affine(t: usvg::Transform) -> Affine {
    [
        t.sx as f64,
        t.ky as f64,
        t.kx as f64,
        t.sy as f64,
        t.tx as f64,
        t.ty as f64,
    ]
}

struct Ctx<'a> {
    name: &'a FsPath,
    root: Affine,
    /// Pixels of the raster images decoded so far ([`MAX_SCENE_IMAGE_PIXELS`]).
    image_pixels: std::cell::Cell<u64>,
    /// Pattern tiles made so far, nested patterns' included ([`MAX_PATTERN_TILES`]).
    pattern_tiles: std::cell::Cell<usize>,
    /// Shapes copied into pattern tiles so far ([`MAX_PATTERN_SHAPES`]).
    pattern_shapes: std::cell::Cell<usize>,
    /// The map from the frame of the innermost group with a transform parameter to device
    /// pixels (the identity outside any): a group's parameter is its transform relative
    /// to it ([`GroupTransform`]).
    frame: std::cell::Cell<Affine>,
    /// Converting a pattern's content: its groups' transforms stay baked (a tile's copies
    /// are moved by translation, and a written pattern's content is read back the same).
    in_pattern: std::cell::Cell<bool>,
}

impl Ctx<'_> {
    fn unsupported(&self, what: String) -> Error {
        Error::Unsupported {
            path: self.name.to_path_buf(),
            what,
        }
    }
    fn image(&self, message: String) -> Error {
        Error::Image {
            path: self.name.to_path_buf(),
            message,
        }
    }
    fn invalid(&self, what: String) -> Error {
        Error::InvalidValue {
            path: self.name.to_path_buf(),
            what,
        }
    }
}

/// Canvas size for `sizing` and the root transform from SVG user space to device pixels.
pub(crate) fn canvas_size(
    tree: &usvg::Tree,
    sizing: Sizing,
    name: &FsPath,
) -> Result<(u32, u32, Affine)> {
    let (w, h) = (tree.size().width() as f64, tree.size().height() as f64);
    let bad = |what: String| Error::InvalidValue {
        path: name.to_path_buf(),
        what,
    };
    let (sx, sy) = match sizing {
        Sizing::Natural => (1.0, 1.0),
        Sizing::Width(px) => {
            let s = px as f64 / w;
            (s, s)
        }
        Sizing::Scale(s) => {
            if !(s.is_finite() && s > 0.0) {
                return Err(bad(format!("scale {s} must be a positive number")));
            }
            (s, s)
        }
        Sizing::Exact(pw, ph) => (pw as f64 / w, ph as f64 / h),
    };
    let (cw, ch) = match sizing {
        Sizing::Exact(pw, ph) => (pw as f64, ph as f64),
        Sizing::Width(pw) => (pw as f64, (h * sy).round()),
        _ => ((w * sx).round(), (h * sy).round()),
    };
    if !(cw >= 1.0 && ch >= 1.0) {
        return Err(bad(format!("output size {cw}x{ch} is empty")));
    }
    if cw > MAX_SIDE as f64 || ch > MAX_SIDE as f64 {
        return Err(bad(format!(
            "output size {cw}x{ch} exceeds the limit of {MAX_SIDE} pixels per side"
        )));
    }
    if cw * ch > MAX_PIXELS as f64 {
        return Err(bad(format!(
            "output size {cw}x{ch} ({} pixels) exceeds the limit of {MAX_PIXELS} pixels",
            cw * ch
        )));
    }
    Ok((cw as u32, ch as u32, [sx, 0.0, 0.0, sy, 0.0, 0.0]))
}

/// Converts a parsed usvg tree into a [`Scene`] of the requested size.
///
/// Every converted number (resolved by usvg, so CSS and inheritance count) is checked
/// once, in device pixels, by `check_numbers`: finite and
/// within [`MAX_COORDINATE`](crate::limits::MAX_COORDINATE), the same rule the writer
/// applies.
pub fn from_tree(tree: &usvg::Tree, name: &FsPath, sizing: Sizing) -> Result<Scene> {
    let (w, h, root) = canvas_size(tree, sizing, name)?;
    let ctx = Ctx {
        name,
        root,
        image_pixels: std::cell::Cell::new(0),
        pattern_tiles: std::cell::Cell::new(0),
        pattern_shapes: std::cell::Cell::new(0),
        frame: std::cell::Cell::new(IDENTITY),
        in_pattern: std::cell::Cell::new(false),
    };
    let mut scene = Scene::new(w, h);
    let mut t = concat(&ctx.root, &to_affine(tree.root().transform()));
    // usvg wraps the drawing in a group of its own for the viewBox (and the root's
    // `transform`): that is the canvas's frame, not a group transform to fit. (A drawing
    // whose one element is a plain `<g>` without an id looks the same, and is baked too.)
    let mut top = tree.root();
    if let [usvg::Node::Group(w)] = top.children()
        && w.id().is_empty()
        && w.opacity().get() >= 1.0
        && w.clip_path().is_none()
        && w.mask().is_none()
        && w.filters().is_empty()
        && w.blend_mode() == usvg::BlendMode::Normal
    {
        t = concat(&t, &to_affine(w.transform()));
        top = w;
    }
    scene.nodes = convert_group_children(top, &ctx, &t, Role::Paint)?;

    super::svg_out::check_numbers_with(&scene, super::svg_out::READ_SLACK)
        .map_err(|what| ctx.invalid(what))?;
    scene.check_limits(name)?;
    Ok(scene)
}

/// Converts a group's children; `t` maps the group's user space to device pixels.
/// (resvg composes group transforms the same way while drawing.) In a clip path
/// (`role` [`Role::Clip`]) only shapes and their fill rules count, as resvg draws them.
fn convert_group_children(g: &usvg::Group, ctx: &Ctx, t: &Affine, role: Role) -> Result<Vec<Node>> {
    let mut out = Vec::new();
    for child in g.children() {
        match child {
            usvg::Node::Group(g) => {
                let what = |f: &str| describe("g", Some(g.id())).replace("element", f);
                let gt = concat(t, &to_affine(g.transform()));
                // Inside a clip path resvg draws shapes only: filters play no part.
                let filters = match role {
                    Role::Paint => {
                        // An feImage's content is no parameter: its transforms stay baked.
                        let image = |root: &usvg::Group, at: &Affine| {
                            let mut nodes = convert_group_children(root, ctx, at, Role::Paint)
                                .map_err(|e| e.to_string())?;
                            bake(&mut nodes);
                            Ok(nodes)
                        };
                        super::filter::from_usvg(g.filters(), &gt, convert_blend, &image)
                            .map_err(|fe| ctx.unsupported(what(&format!("element with {fe}"))))?
                    }
                    Role::Clip => Vec::new(),
                };
                // A transform that can be a parameter: the group's frame is the one its
                // children's parameters are in. usvg puts a shape's own `transform` on a
                // group of its own (no id; the shape keeps it): one shape is enough.
                let movable = role == Role::Paint
                    && !ctx.in_pattern.get()
                    && !g.transform().is_identity()
                    && shapes_in(g, 1) >= 1;
                let relative = invert(&ctx.frame.get()).map(|f| concat(&f, &gt));
                // Within the range a fit keeps it in, so that the first step does not
                // jump (a scale of 1e-6 stays baked).
                let in_range = |t: Option<GroupTransform>| {
                    t.is_some_and(|t| {
                        let mut kept = t;
                        kept.project();
                        kept == t
                    })
                };
                // A similarity where strokes stay round; else a general affine map over
                // content with no primitive (`transform::movable`);
                // `true` for the latter.
                let own = relative.filter(|_| movable).and_then(|r| {
                    if movable_group(g, false)
                        && is_uniform(&gt)
                        && in_range(GroupTransform::from_affine(&r, [0.0; 2]))
                    {
                        Some((r, false))
                    } else if movable_group(g, true)
                        && in_range(GroupTransform::from_affine_general(&r, [0.0; 2]))
                    {
                        Some((r, true))
                    } else {
                        None
                    }
                });
                let outer = ctx.frame.get();
                if own.is_some() {
                    ctx.frame.set(gt);
                }
                let converted = convert_group_children(g, ctx, &gt, role);
                ctx.frame.set(outer);
                let mut children = converted?;
                let transform = match own {
                    // A circle, ellipse or rectangle turned about its own center: that is
                    // its angle (as the writer writes it), not a transform of its own.
                    Some((r, false)) if turned_about_center(&r, &gt, &children) => {
                        bake(&mut children);
                        None
                    }
                    // The same under a general map above: the turn goes into the angle, the
                    // outline keeps the outer frame's map.
                    Some((r, true)) if turned_about_center(&r, &gt, &children) => {
                        turn_into_angle(&mut children, &r, &outer);
                        None
                    }
                    Some((r, general)) if super::transform::movable(&children, general) => {
                        // Rotate and scale about the content's center in the local frame
                        // (which a change of the transform leaves where it is, so a file
                        // written and read back gets the same parameters).
                        let pivot = invert(&gt)
                            .and_then(|i| local_center(&children, &i))
                            .unwrap_or([0.0; 2]);
                        if general {
                            GroupTransform::from_affine_general(&r, pivot)
                        } else {
                            GroupTransform::from_affine(&r, pivot)
                        }
                    }
                    Some(_) => {
                        bake(&mut children);
                        None
                    }
                    None => None,
                };
                let clip = match g.clip_path() {
                    Some(c) => Some(Box::new(convert_clip(c, ctx, &gt)?)),
                    None => None,
                };
                // Inside a clip path resvg draws a child group's shapes and its own clip
                // path only: no opacity, mask or blend mode.
                let (mask, opacity, blend) = match role {
                    Role::Clip => (None, 1.0, BlendMode::Normal),
                    Role::Paint => (
                        match g.mask() {
                            Some(m) => Some(Box::new(convert_mask(m, ctx, &gt)?)),
                            None => None,
                        },
                        g.opacity().get() as f64,
                        convert_blend(g.blend_mode()),
                    ),
                };
                let group = Group {
                    id: g.id().to_string(),
                    opacity,
                    children,
                    clip,
                    mask,
                    blend,
                    // Isolation matters only to children that blend.
                    isolate: g.isolate() && role == Role::Paint,
                    filters,
                    transform,
                    layer: true,
                    tiling: None,
                };
                // A layer composited source-over at full opacity, unclipped and
                // unmasked, changes nothing (`isolation: isolate` alone): no layer, and
                // without a transform parameter no group at all.
                if opacity < 1.0 || !group.is_plain() {
                    out.push(Node::Group(group));
                } else if group.transform.is_some() {
                    out.push(Node::Group(Group {
                        layer: false,
                        ..group
                    }));
                } else {
                    out.extend(group.children);
                }
            }
            usvg::Node::Path(p) => {
                let Some(path) = convert_path(p, ctx, t, role)? else {
                    continue;
                };
                let patterned = role == Role::Paint
                    && (p.fill().is_some_and(|f| is_pattern(f.paint()))
                        || p.stroke().is_some_and(|s| is_pattern(s.paint())));
                if patterned {
                    out.extend(convert_patterned(p, path, ctx, t)?);
                } else {
                    out.push(Node::Path(path));
                }
            }
            // A clip path draws shapes and text only (resvg skips its images).
            usvg::Node::Image(_) if role == Role::Clip => {}
            usvg::Node::Image(i) => {
                // usvg wraps each image in a group of its own, which holds the id.
                let id = if i.id().is_empty() && g.children().len() == 1 {
                    g.id()
                } else {
                    i.id()
                };
                if i.is_visible() {
                    out.extend(convert_image(i, id, ctx, t)?);
                }
            }
            usvg::Node::Text(text) => out.extend(convert_text(text, ctx, t, role)?),
        }
    }
    Ok(out)
}

/// Whether a usvg group's content can live in a frame of its own
/// ([`transform`](super::transform)): plain groups whose transforms keep strokes round,
/// paths with solid or gradient paints and undashed strokes; no text, image, pattern,
/// clip path, mask or filter. Under a general affine map (`general`): strokes dashed or
/// not (drawn in a frame that takes the map), and nested transforms of any kind.
fn movable_group(g: &usvg::Group, general: bool) -> bool {
    g.clip_path().is_none()
        && g.mask().is_none()
        && g.filters().is_empty()
        && g.children().iter().all(|n| match n {
            usvg::Node::Group(c) => {
                (general || is_uniform(&to_affine(c.transform()))) && movable_group(c, general)
            }
            usvg::Node::Path(p) => {
                let paint_ok = |paint: &usvg::Paint| match paint {
                    usvg::Paint::Color(_)
                    | usvg::Paint::LinearGradient(_)
                    | usvg::Paint::RadialGradient(_) => true,
                    usvg::Paint::Pattern(_) => false,
                };
                p.fill().is_none_or(|f| paint_ok(f.paint()))
                    && if general {
                        // A stroke's frame takes the map (dashes included).
                        p.stroke().is_none_or(|s| paint_ok(s.paint()))
                    } else {
                        p.stroke()
                            .is_none_or(|s| paint_ok(s.paint()) && s.dasharray().is_none())
                    }
            }
            usvg::Node::Image(_) | usvg::Node::Text(_) => false,
        })
}

/// The paths under a usvg group, counted up to `at_most` (so a big group is not walked
/// whole for every transformed group above it).
fn shapes_in(g: &usvg::Group, at_most: usize) -> usize {
    let mut n = 0;
    for c in g.children() {
        n += match c {
            usvg::Node::Group(c) => shapes_in(c, at_most - n),
            _ => 1,
        };
        if n >= at_most {
            break;
        }
    }
    n
}

/// Whether `t` scales uniformly (a similarity, possibly mirrored): a stroke under it stays
/// round, so it is drawn in device space.
fn is_uniform(t: &Affine) -> bool {
    let [a, b, c, d, _, _] = *t;
    let (sx, sy) = (a.hypot(b), c.hypot(d));
    sx > 0.0 && (sx - sy).abs() <= 1e-9 * sx && (a * c + b * d).abs() <= 1e-9 * sx * sy
}

/// Whether `nodes` is one circle, ellipse or rectangle and `r` (its group's transform
/// relative to the parent frame; `gt` the group's frame to device pixels) a rotation (no
/// scale, to `f32`'s precision) that keeps the shape's center where it is (within
/// `1e-4` px per pixel of distance from the origin): the shape's own angle.
fn turned_about_center(r: &Affine, gt: &Affine, nodes: &[Node]) -> bool {
    let [Node::Path(p)] = nodes else {
        return false;
    };
    let (Some(q), Some(to_local)) = (&p.primitive, invert(gt)) else {
        return false;
    };
    let [a, b, ..] = *r;
    let c = apply(&to_local, q.center());
    let moved = apply(r, c);
    let tol = 1e-4 * (1.0 + c[0].abs().max(c[1].abs()));
    (a.hypot(b) - 1.0).abs() <= 1e-6 && (moved[0] - c[0]).hypot(moved[1] - c[1]) <= tol
}

/// The one primitive of `nodes` (which [`turned_about_center`] accepted), its frame
/// `lin(gt)` (`gt = outer · r`, `r` a rotation about its center), held in the frame
/// `outer` maps to device pixels instead: the frame `lin(outer)`, the turn added to its
/// angle.
fn turn_into_angle(nodes: &mut [Node], r: &Affine, outer: &Affine) {
    let [Node::Path(p)] = nodes else {
        return;
    };
    if let Some(q) = &mut p.primitive {
        q.frame = [outer[0], outer[1], outer[2], outer[3]];
        q.angle += r[1].atan2(r[0]);
        // The stroke, drawn in the same frame, keeps its width (the turn keeps its pen).
        if let Some(s) = &mut p.stroke
            && s.frame != FRAME_IDENTITY
        {
            s.frame = q.frame;
            s.normalize_frame();
        }
        p.sync_primitive();
    }
}

/// The center of the bounds of every control point under `nodes` (device pixels) mapped
/// by `to_local`.
fn local_center(nodes: &[Node], to_local: &Affine) -> Option<Point> {
    let mut b: Option<[f64; 4]> = None;
    let mut add = |[x0, y0, x1, y1]: [f64; 4]| {
        let o = b.get_or_insert([x0, y0, x1, y1]);
        *o = [o[0].min(x0), o[1].min(y0), o[2].max(x1), o[3].max(y1)];
    };
    let k = (to_local[0] * to_local[3] - to_local[1] * to_local[2])
        .abs()
        .sqrt();
    super::paths_of(nodes, Role::Paint, &mut |p, _| match &p.primitive {
        // A circle's outline starts where its angle says, which turning the group does
        // not change: its bounds from its center and radius instead.
        Some(c) if matches!(c.shape, super::Shape::Circle { .. }) => {
            let [x, y] = apply(to_local, c.center());
            // The circle's image under the linear map `m`: its half extents are the
            // radius times the rows' lengths.
            let f = c.frame;
            let m = [
                to_local[0] * f[0] + to_local[2] * f[1],
                to_local[1] * f[0] + to_local[3] * f[1],
                to_local[0] * f[2] + to_local[2] * f[3],
                to_local[1] * f[2] + to_local[3] * f[3],
            ];
            let (rx, ry) = if f == FRAME_IDENTITY {
                (k * c.radius(), k * c.radius())
            } else {
                (c.radius() * m[0].hypot(m[2]), c.radius() * m[1].hypot(m[3]))
            };
            add([x - rx, y - ry, x + rx, y + ry]);
        }
        _ => {
            for q in &p.points {
                let [x, y] = apply(to_local, *q);
                add([x, y, x, y]);
            }
        }
    });
    b.map(|r| [0.5 * (r[0] + r[2]), 0.5 * (r[1] + r[3])])
}

/// Drops every transform parameter under `nodes` (their geometry is in device space
/// already): a group that was only a transform gives way to its children.
fn bake(nodes: &mut Vec<Node>) {
    let mut out = Vec::with_capacity(nodes.len());
    for n in nodes.drain(..) {
        match n {
            Node::Group(mut g) => {
                g.transform = None;
                bake(&mut g.children);
                if g.layer {
                    out.push(Node::Group(g));
                } else {
                    out.extend(g.children);
                }
            }
            Node::Path(mut p) => {
                // A primitive held in a general map's frame is no primitive in device
                // space: its outline, baked.
                if p.primitive
                    .as_ref()
                    .is_some_and(|q| q.frame != FRAME_IDENTITY)
                {
                    p.outline_primitive();
                }
                out.push(Node::Path(p));
            }
        }
    }
    *nodes = out;
}

/// A clip path applied to a group whose user space `t` maps to device pixels.
fn convert_clip(c: &usvg::ClipPath, ctx: &Ctx, t: &Affine) -> Result<Clip> {
    let ct = concat(t, &to_affine(c.transform()));
    let mut content = Group::new(
        "",
        1.0,
        convert_group_children(c.root(), ctx, &ct, Role::Clip)?,
    );
    // A clip path of the clip path multiplies the same layer (resvg applies it with the
    // group's transform, not the clip path's).
    if let Some(inner) = c.clip_path() {
        content.clip = Some(Box::new(convert_clip(inner, ctx, t)?));
    }
    Ok(Clip {
        id: c.id().to_string(),
        content,
    })
}

/// A mask applied to a group whose user space `t` maps to device pixels: its content,
/// clipped to the mask region, and a mask of the mask multiplying the same layer.
fn convert_mask(m: &usvg::Mask, ctx: &Ctx, t: &Affine) -> Result<Mask> {
    let mut content = Group::new(
        "",
        1.0,
        convert_group_children(m.root(), ctx, t, Role::Paint)?,
    );
    let r = m.rect();
    let (x0, y0, x1, y1) = (
        r.left() as f64,
        r.top() as f64,
        r.right() as f64,
        r.bottom() as f64,
    );
    content.clip = Some(rect_clip(t, [x0, y0, x1, y1]));
    if let Some(inner) = m.mask() {
        content.mask = Some(Box::new(convert_mask(inner, ctx, t)?));
    }
    Ok(Mask {
        id: m.id().to_string(),
        kind: match m.kind() {
            usvg::MaskType::Luminance => MaskKind::Luminance,
            usvg::MaskType::Alpha => MaskKind::Alpha,
        },
        content,
    })
}

fn convert_blend(b: usvg::BlendMode) -> BlendMode {
    use usvg::BlendMode as U;
    match b {
        U::Normal => BlendMode::Normal,
        U::Multiply => BlendMode::Multiply,
        U::Screen => BlendMode::Screen,
        U::Overlay => BlendMode::Overlay,
        U::Darken => BlendMode::Darken,
        U::Lighten => BlendMode::Lighten,
        U::ColorDodge => BlendMode::ColorDodge,
        U::ColorBurn => BlendMode::ColorBurn,
        U::HardLight => BlendMode::HardLight,
        U::SoftLight => BlendMode::SoftLight,
        U::Difference => BlendMode::Difference,
        U::Exclusion => BlendMode::Exclusion,
        U::Hue => BlendMode::Hue,
        U::Saturation => BlendMode::Saturation,
        U::Color => BlendMode::Color,
        U::Luminosity => BlendMode::Luminosity,
        U::PlusLighter => BlendMode::PlusLighter,
    }
}

/// A `<text>` as the glyph outlines usvg laid it out into (`flattened()`: a plain group of
/// ordinary paths, one per span and decoration, so paints and gradients reach glyphs as
/// they reach any path). The paths take the text's id (`id`, or `id-1`, `id-2`, … when
/// there are several), and the first carries the characters for SVG out's comment.
fn convert_text(text: &usvg::Text, ctx: &Ctx, t: &Affine, role: Role) -> Result<Vec<Node>> {
    let g = text.flattened();
    let mut nodes = convert_group_children(g, ctx, &concat(t, &to_affine(g.transform())), role)?;
    let mut paths = Vec::new();
    fn collect<'a>(nodes: &'a mut [Node], out: &mut Vec<&'a mut Path>) {
        for n in nodes {
            match n {
                Node::Path(p) => out.push(p),
                Node::Group(g) => collect(&mut g.children, out),
            }
        }
    }
    collect(&mut nodes, &mut paths);
    let several = paths.len() > 1;
    for (k, p) in paths.iter_mut().enumerate() {
        // Glyph outlines stay paths, even a glyph that is a rectangle.
        p.primitive = None;
        if p.id.is_empty() && !text.id().is_empty() {
            p.id = if several {
                format!("{}-{}", text.id(), k + 1)
            } else {
                text.id().to_string()
            };
        }
    }
    if let Some(first) = paths.first_mut() {
        let chars: String = text.chunks().iter().map(|c| c.text()).collect();
        first.text = Some(chars);
    }
    Ok(nodes)
}

/// An image: a raster one becomes its rectangle filled with [`Paint::Image`] (decoded
/// here, its size checked against [`MAX_SCENE_IMAGE_PIXELS`] first); an SVG one becomes
/// its paths, converted as the file's own (what that conversion refuses, it refuses).
/// `t` maps the image's pixel space (usvg resolved `preserveAspectRatio` into it) to
/// device pixels.
fn convert_image(i: &usvg::Image, id: &str, ctx: &Ctx, t: &Affine) -> Result<Vec<Node>> {
    let what = describe("image", Some(id));
    let data = match i.kind() {
        usvg::ImageKind::SVG(tree) => {
            let t = concat(t, &to_affine(tree.root().transform()));
            return convert_group_children(tree.root(), ctx, &t, Role::Paint).map_err(
                |e| match e {
                    Error::Unsupported { path, what: inner } => Error::Unsupported {
                        path,
                        what: format!("{inner} inside the SVG of {what}"),
                    },
                    e => e,
                },
            );
        }
        usvg::ImageKind::PNG(d)
        | usvg::ImageKind::JPEG(d)
        | usvg::ImageKind::GIF(d)
        | usvg::ImageKind::WEBP(d) => d,
    };
    let left = MAX_SCENE_IMAGE_PIXELS - ctx.image_pixels.get();
    // The size usvg read from the header (a malformed rest is not looked at).
    let (hw, hh) = (i.size().width() as f64, i.size().height() as f64);
    if hw * hh > left as f64 || hw > MAX_SIDE as f64 || hh > MAX_SIDE as f64 {
        return Err(ctx.image(format!(
            "{what} is {hw}x{hh} pixels, past the limit of {MAX_SIDE} a side and {left} \
             pixels (limits::MAX_SCENE_IMAGE_PIXELS, for all the images of a drawing)"
        )));
    }
    let (width, height, pixels) = crate::image_io::decode_embedded(data, left)
        .map_err(|why| ctx.image(format!("{what} {why}")))?;
    ctx.image_pixels
        .set(ctx.image_pixels.get() + width as u64 * height as u64);
    let quality = match i.rendering_mode() {
        usvg::ImageRendering::OptimizeSpeed
        | usvg::ImageRendering::CrispEdges
        | usvg::ImageRendering::Pixelated => ImageQuality::Nearest,
        usvg::ImageRendering::Smooth => ImageQuality::Bilinear,
        usvg::ImageRendering::OptimizeQuality | usvg::ImageRendering::HighQuality => {
            ImageQuality::Bicubic
        }
    };
    let paint = ImagePaint {
        width,
        height,
        pixels: std::sync::Arc::new(pixels),
        transform: *t,
        quality,
    };
    if paint.corners().iter().flatten().any(|v| !v.is_finite()) {
        return Err(ctx.invalid(format!("{what} has a non-finite transform")));
    }
    Ok(vec![Node::Path(paint.rectangle(id))])
}

fn convert_path(p: &usvg::Path, ctx: &Ctx, t: &Affine, role: Role) -> Result<Option<Path>> {
    if !p.is_visible() {
        return Ok(None);
    }
    let t = *t;
    let mut out = Path::new(p.id());
    out.crisp = !p.rendering_mode().use_shape_antialiasing();
    let tp = |q: usvg::tiny_skia_path::Point| -> Result<[f64; 2]> {
        let d = apply(&t, [q.x as f64, q.y as f64]);
        if d[0].is_finite() && d[1].is_finite() {
            Ok(d)
        } else {
            Err(ctx.invalid(format!(
                "path \"{}\" has a non-finite coordinate ({}, {})",
                p.id(),
                q.x,
                q.y
            )))
        }
    };
    let mut open = false;
    for seg in p.data().segments() {
        use usvg::tiny_skia_path::PathSegment as S;
        match seg {
            S::MoveTo(a) => {
                out.move_to(tp(a)?);
                open = true;
            }
            S::LineTo(a) => {
                ensure_open(&mut out, &mut open);
                out.line_to(tp(a)?);
            }
            S::QuadTo(a, b) => {
                ensure_open(&mut out, &mut open);
                out.quad_to(tp(a)?, tp(b)?);
            }
            S::CubicTo(a, b, c) => {
                ensure_open(&mut out, &mut open);
                out.cubic_to(tp(a)?, tp(b)?, tp(c)?);
            }
            S::Close => {
                out.close();
                open = false;
            }
        }
    }
    if out.points.is_empty() {
        return Ok(None);
    }
    if role == Role::Clip {
        // A clip path's shape: its coverage under its fill rule (`clip-rule`) only.
        out.fill = p.fill().map(|f| Fill {
            paint: Paint::Solid([0.0; 3]),
            opacity: 1.0,
            rule: match f.rule() {
                usvg::FillRule::NonZero => FillRule::NonZero,
                usvg::FillRule::EvenOdd => FillRule::EvenOdd,
            },
        });
        return Ok(out.fill.is_some().then_some(out));
    }
    if let Some(f) = p.fill() {
        out.fill = Some(Fill {
            paint: convert_paint(f.paint(), &t),
            opacity: f.opacity().get() as f64,
            rule: match f.rule() {
                usvg::FillRule::NonZero => FillRule::NonZero,
                usvg::FillRule::EvenOdd => FillRule::EvenOdd,
            },
        });
    }
    if let Some(s) = p.stroke() {
        let mut stroke = Stroke {
            paint: convert_paint(s.paint(), &t),
            opacity: s.opacity().get() as f64,
            width: s.width().get() as f64,
            join: match s.linejoin() {
                usvg::LineJoin::Miter => LineJoin::Miter,
                usvg::LineJoin::MiterClip => LineJoin::MiterClip,
                usvg::LineJoin::Round => LineJoin::Round,
                usvg::LineJoin::Bevel => LineJoin::Bevel,
            },
            cap: match s.linecap() {
                usvg::LineCap::Butt => LineCap::Butt,
                usvg::LineCap::Round => LineCap::Round,
                usvg::LineCap::Square => LineCap::Square,
            },
            miter_limit: s.miterlimit().get() as f64,
            dash: s.dasharray().map(|d| d.iter().map(|&v| v as f64).collect()),
            dash_offset: s.dashoffset() as f64,
            frame: [t[0], t[1], t[2], t[3]],
        };
        stroke.normalize_frame();
        if stroke.frame != FRAME_IDENTITY {
            let [a, b, c, d] = stroke.frame;
            if (a * d - b * c).abs() < 1e-12 {
                return Ok(if out.fill.is_some() { Some(out) } else { None });
            }
        }
        out.stroke = Some(stroke);
    }
    if out.fill.is_none() && out.stroke.is_none() {
        return Ok(None);
    }
    out.stroke_first = p.paint_order() == usvg::PaintOrder::StrokeAndFill;
    recognize_primitive(p, &mut out, &t, &ctx.frame.get());
    Ok(Some(out))
}

/// Makes `out` a circle, ellipse or rectangle with its own parameters when its outline is
/// one (as usvg builds `<circle>`, `<ellipse>` and `<rect>`) under a transform that keeps
/// it one, and the outline the primitive builds is the one loaded. Under a general
/// affine group transform (`frame`, the map from its frame to device pixels, no
/// similarity), the transform relative to that frame must keep it one: the primitive is
/// then held in that frame, its outline mapped ([`Primitive::frame`](super::Primitive::frame)),
/// and a stroke's pen must be round in that frame (its width then in the frame's units).
fn recognize_primitive(p: &usvg::Path, out: &mut Path, t: &Affine, frame: &Affine) {
    let general = GroupTransform::from_affine(frame, [0.0; 2]).is_none();
    if !general && !out.stroke_in_device_space() {
        return;
    }
    let mut local = Path::new("");
    for seg in p.data().segments() {
        use usvg::tiny_skia_path::PathSegment as S;
        let q = |a: usvg::tiny_skia_path::Point| [a.x as f64, a.y as f64];
        match seg {
            S::MoveTo(a) => local.move_to(q(a)),
            S::LineTo(a) if !local.subpaths.is_empty() => local.line_to(q(a)),
            S::CubicTo(a, b, c) if !local.subpaths.is_empty() => local.cubic_to(q(a), q(b), q(c)),
            S::Close => local.close(),
            _ => return,
        }
    }
    let mut stroke = out.stroke.clone();
    let prim = if general {
        let Some(rel) = invert(frame).map(|i| concat(&i, t)) else {
            return;
        };
        let Some(mut prim) = super::Primitive::recognize(&local, &rel, out.stroke.is_some()) else {
            return;
        };
        // `rel` is the identity's linear part but for rounding when the shape is drawn
        // in the frame itself: no turn (which SVG out would write as a `rotate(0 …)`).
        if prim.angle.abs() <= 1e-9 {
            prim.angle = 0.0;
        }
        let l = [frame[0], frame[1], frame[2], frame[3]];
        if let Some(s) = &mut stroke {
            // The stroke's frame relative to the group's, a similarity there (recognize
            // refuses a stroked shape otherwise): its scale goes into the width.
            let Some(li) = invert(&[l[0], l[1], l[2], l[3], 0.0, 0.0]) else {
                return;
            };
            let f = s.frame;
            s.frame = [
                li[0] * f[0] + li[2] * f[1],
                li[1] * f[0] + li[3] * f[1],
                li[0] * f[2] + li[2] * f[3],
                li[1] * f[2] + li[3] * f[3],
            ];
            s.normalize_frame();
            if s.frame != FRAME_IDENTITY {
                return;
            }
            s.frame = l;
        }
        let c = apply(frame, prim.center());
        let now = prim.center();
        prim.translate([c[0] - now[0], c[1] - now[1]]);
        prim.frame = l;
        prim
    } else {
        let Some(prim) = super::Primitive::recognize(&local, t, out.stroke.is_some()) else {
            return;
        };
        prim
    };
    let (built, _) = prim.outline();
    let scale = out
        .points
        .iter()
        .fold(1.0f64, |m, q| m.max(q[0].abs()).max(q[1].abs()));
    let same = built.len() == out.points.len()
        && built
            .iter()
            .zip(&out.points)
            .all(|(a, b)| (a[0] - b[0]).abs().max((a[1] - b[1]).abs()) <= 1e-6 * scale);
    if same {
        out.primitive = Some(prim);
        out.stroke = stroke;
        out.sync_primitive();
    }
}

/// usvg may emit a segment right after a close without a MoveTo: SVG starts the next
/// subpath at the previous subpath's start.
fn ensure_open(out: &mut Path, open: &mut bool) {
    if !*open {
        let start = out
            .subpaths
            .last()
            .map(|s| out.points[s.start])
            .unwrap_or([0.0, 0.0]);
        out.move_to(start);
        *open = true;
    }
}

fn convert_paint(paint: &usvg::Paint, t: &Affine) -> Paint {
    let color = |c: usvg::Color| {
        [
            c.red as f64 / 255.0,
            c.green as f64 / 255.0,
            c.blue as f64 / 255.0,
        ]
    };
    let base = |g: &usvg::BaseGradient, kind: GradientKind| Gradient {
        id: g.id().to_string(),
        kind,
        transform: concat(t, &to_affine(g.transform())),
        spread: match g.spread_method() {
            usvg::SpreadMethod::Pad => Spread::Pad,
            usvg::SpreadMethod::Reflect => Spread::Reflect,
            usvg::SpreadMethod::Repeat => Spread::Repeat,
        },
        stops: g
            .stops()
            .iter()
            .map(|s| Stop {
                offset: s.offset().get() as f64,
                color: color(s.color()),
                opacity: s.opacity().get() as f64,
            })
            .collect(),
    };
    match paint {
        usvg::Paint::Color(c) => Paint::Solid(color(*c)),
        usvg::Paint::LinearGradient(g) => Paint::Gradient(base(
            g,
            GradientKind::Linear {
                p1: [g.x1() as f64, g.y1() as f64],
                p2: [g.x2() as f64, g.y2() as f64],
            },
        )),
        usvg::Paint::RadialGradient(g) => Paint::Gradient(base(
            g,
            GradientKind::Radial {
                c: [g.cx() as f64, g.cy() as f64],
                r: g.r().get() as f64,
                f: [g.fx() as f64, g.fy() as f64],
                fr: g.fr().get() as f64,
            },
        )),
        // A stand-in: `convert_patterned` replaces the paint by the tiles themselves.
        usvg::Paint::Pattern(_) => Paint::Solid([0.0; 3]),
    }
}

fn is_pattern(paint: &usvg::Paint) -> bool {
    matches!(paint, usvg::Paint::Pattern(_))
}

/// A path painted with a pattern, as resvg draws it: for each patterned part (fill or
/// stroke, in paint order) a layer with the part's opacity holding the pattern's tile
/// content repeated over the part's bounds, clipped by the part's coverage (the fill
/// under its rule, or the stroke outline). The tiles are ordinary shapes, so gradients
/// reach their points and paints (each tile's copy on its own).
fn convert_patterned(p: &usvg::Path, base: Path, ctx: &Ctx, t: &Affine) -> Result<Vec<Node>> {
    let mut fill_part = base.clone();
    fill_part.stroke = None;
    let mut stroke_part = base.clone();
    stroke_part.fill = None;
    let bounds = base.control_bounds().unwrap_or([0.0; 4]);
    let mut parts = Vec::new();
    if let (Some(f), Some(uf)) = (fill_part.fill.clone(), p.fill()) {
        parts.push(match uf.paint() {
            usvg::Paint::Pattern(pat) => {
                let mut shape = fill_part;
                shape.fill = Some(Fill {
                    paint: Paint::Solid([0.0; 3]),
                    opacity: 1.0,
                    rule: f.rule,
                });
                Some(patterned_layer(pat, shape, bounds, f.opacity, ctx, t)?)
            }
            _ => Some(Node::Path(fill_part)),
        });
    }
    if let (Some(st), Some(us)) = (stroke_part.stroke.clone(), p.stroke()) {
        let part = match us.paint() {
            usvg::Paint::Pattern(pat) => {
                let [a, b, c, d] = st.frame;
                let reach = 0.5
                    * st.width.abs()
                    * st.miter_limit.max(2.0)
                    * (a * a + b * b + c * c + d * d).sqrt()
                    + 1.0;
                let grown = [
                    bounds[0] - reach,
                    bounds[1] - reach,
                    bounds[2] + reach,
                    bounds[3] + reach,
                ];
                let mut shape = stroke_part;
                if let Some(s) = &mut shape.stroke {
                    s.paint = Paint::Solid([0.0; 3]);
                    s.opacity = 1.0;
                }
                patterned_layer(pat, shape, grown, st.opacity, ctx, t)?
            }
            _ => Node::Path(stroke_part),
        };
        if base.stroke_first {
            parts.insert(0, Some(part));
        } else {
            parts.push(Some(part));
        }
    }
    Ok(parts.into_iter().flatten().collect())
}

/// One patterned part: the tiles covering `bounds` (device pixels), clipped by `shape`
/// (drawn as a clip shape), composited with `opacity`.
fn patterned_layer(
    pat: &usvg::Pattern,
    shape: Path,
    bounds: [f64; 4],
    opacity: f64,
    ctx: &Ctx,
    t: &Affine,
) -> Result<Node> {
    let (tiles, tiling) = pattern_tiles(pat, bounds, ctx, t)?;
    let mut layer = Group::new(pat.id(), opacity, tiles);
    layer.clip = Some(Box::new(Clip::of_shape(shape)));
    layer.tiling = tiling.map(Box::new);
    Ok(Node::Group(layer))
}

/// The clip path of the rectangle `[x0, y0, x1, y1]` of the user space `t` maps to device
/// pixels (a mask region, a pattern's cell).
fn rect_clip(t: &Affine, [x0, y0, x1, y1]: [f64; 4]) -> Box<Clip> {
    let mut rect = Path::new("");
    rect.move_to(apply(t, [x0, y0]));
    rect.line_to(apply(t, [x1, y0]));
    rect.line_to(apply(t, [x1, y1]));
    rect.line_to(apply(t, [x0, y1]));
    rect.close();
    rect.fill = Some(Fill {
        paint: Paint::Solid([0.0; 3]),
        opacity: 1.0,
        rule: FillRule::NonZero,
    });
    Box::new(Clip::of_shape(rect))
}

/// The tiles of `pat` (drawn in the user space `t` maps to device pixels) that cover the
/// device box `bounds`, each its content placed at its cell and clipped to it unless the
/// content stays inside. Like resvg, a tile smaller than half a device pixel draws
/// nothing; more than [`MAX_PATTERN_TILES`] tiles in the drawing are refused. When the
/// content translates exactly, the tiles are copies of the first and the layout is
/// returned ([`Tiling`](super::Tiling)); otherwise each tile is converted on its own.
fn pattern_tiles(
    pat: &usvg::Pattern,
    bounds: [f64; 4],
    ctx: &Ctx,
    t: &Affine,
) -> Result<(Vec<Node>, Option<super::Tiling>)> {
    let pt = concat(t, &to_affine(pat.transform()));
    let Some(inv) = super::invert(&pt) else {
        return Ok((Vec::new(), None));
    };
    let r = pat.rect();
    let (rx, ry, rw, rh) = (
        r.x() as f64,
        r.y() as f64,
        r.width() as f64,
        r.height() as f64,
    );
    let (sx, sy) = (pt[0].hypot(pt[1]), pt[2].hypot(pt[3]));
    let (pw, ph) = ((rw * sx).round(), (rh * sy).round());
    if pw < 1.0 || ph < 1.0 {
        return Ok((Vec::new(), None));
    }
    // resvg draws a tile into a pixmap of whole device pixels and repeats that: the
    // period (and the cell the content is clipped to) is the tile's size rounded to
    // pixels. Done the same way here, so that both draw the same picture.
    let (rw, rh) = (pw / sx, ph / sy);
    // The bounds in pattern space.
    let corners = [
        [bounds[0], bounds[1]],
        [bounds[2], bounds[1]],
        [bounds[0], bounds[3]],
        [bounds[2], bounds[3]],
    ]
    .map(|c| apply(&inv, c));
    let (mut u0, mut v0, mut u1, mut v1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for c in corners {
        u0 = u0.min(c[0]);
        v0 = v0.min(c[1]);
        u1 = u1.max(c[0]);
        v1 = v1.max(c[1]);
    }
    let (i0, i1) = (((u0 - rx) / rw).floor(), ((u1 - rx) / rw).ceil());
    let (j0, j1) = (((v0 - ry) / rh).floor(), ((v1 - ry) / rh).ceil());
    let count = (i1 - i0).max(0.0) * (j1 - j0).max(0.0);
    // Counted over the whole drawing: a pattern inside a pattern's tile multiplies.
    let total = count + ctx.pattern_tiles.get() as f64;
    if !(total <= MAX_PATTERN_TILES as f64) {
        return Err(ctx.unsupported(format!(
            "pattern \"{}\" would repeat {count:.0} tiles over its shape, {total:.0} in the \
             drawing with the patterns before and around it (the limit is {MAX_PATTERN_TILES})",
            pat.id()
        )));
    }
    ctx.pattern_tiles.set(total as usize);
    // Whether the content stays inside its cell (then no tile needs a clip).
    let local = convert_group_children(pat.root(), ctx, &super::IDENTITY, Role::Paint)?;
    let mut probe = Scene::new(1, 1);
    probe.nodes = local;
    // The shapes the tiles copy, counted over the drawing before any copy is made.
    let shapes = count * probe.path_count() as f64 + ctx.pattern_shapes.get() as f64;
    if !(shapes <= MAX_PATTERN_SHAPES as f64) {
        return Err(ctx.unsupported(format!(
            "pattern \"{}\" would copy its {} shapes into {count:.0} tiles, {shapes:.0} shapes \
             in the drawing (the limit is {MAX_PATTERN_SHAPES})",
            pat.id(),
            probe.path_count()
        )));
    }
    ctx.pattern_shapes.set(shapes as usize);
    let mut inside = true;
    probe.for_each_path(|q| {
        let b = q.control_bounds().unwrap_or([0.0; 4]);
        let reach = q
            .stroke
            .as_ref()
            .map_or(0.0, |s| s.width.abs() * s.miter_limit.max(1.0));
        // Within `f32` noise of the cell's sides (usvg's object-bounding-box units give
        // `0.2 · 160 = 32.000004` for a cell 32 wide): clipping there would only add seams.
        let eps = 1e-5 * rw.max(rh);
        inside &= b[0] - reach >= -eps
            && b[1] - reach >= -eps
            && b[2] + reach <= rw + eps
            && b[3] + reach <= rh + eps;
    });
    let mut tiling = super::Tiling {
        transform: pt,
        cell: [rx, ry, rw, rh],
        cells: ((j0 as i64)..(j1 as i64))
            .flat_map(|j| ((i0 as i64)..(i1 as i64)).map(move |i| [i, j]))
            .collect(),
        per_tile: 0,
        clipped: !inside,
    };
    // One tile: the content placed at its cell, clipped to it unless it stays inside.
    let tile = |tiling: &super::Tiling, cell: [i64; 2]| -> Result<Vec<Node>> {
        let tt = tiling.tile_transform(cell);
        let outer = ctx.in_pattern.replace(true);
        let children = convert_group_children(pat.root(), ctx, &tt, Role::Paint);
        ctx.in_pattern.set(outer);
        let children = children?;
        if inside || children.is_empty() {
            return Ok(children);
        }
        let mut tile = Group::new("", 1.0, children);
        tile.clip = Some(rect_clip(&tt, [0.0, 0.0, rw, rh]));
        Ok(vec![Node::Group(tile)])
    };
    let Some(&first) = tiling.cells.first() else {
        return Ok((Vec::new(), None));
    };
    let first = tile(&tiling, first)?;
    if first.is_empty() {
        return Ok((Vec::new(), None));
    }
    if super::tiling::translatable(&first) {
        // Copies of the first tile, moved: `Scene::set_params` keeps them so.
        tiling.per_tile = first.len();
        let tiles = super::tiling::copies(&first, &tiling);
        return Ok((tiles, Some(tiling)));
    }
    let mut tiles = first;
    for &cell in &tiling.cells[1..] {
        tiles.extend(tile(&tiling, cell)?);
    }
    Ok((tiles, None))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn non_finite_numbers_are_reported() {
        assert_eq!(bad_number("M 0 0 L 10 20.5e3 Z"), None);
        assert_eq!(bad_number("matrix(1 0 0 1 -5 .5)"), None);
        assert!(bad_number("M NaN 0").unwrap().contains("NaN"));
        assert!(bad_number("M 0 0 L 1e39 5").unwrap().contains("1e39"));
        assert!(bad_number("-Infinity").is_some());
        let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10">
            <rect id="r" x="NaN" width="5" height="5"/></svg>"#;
        let e = Scene::from_svg_str(svg, "nan.svg", Sizing::Natural)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("nan.svg") && e.contains("NaN") && e.contains("\"r\""),
            "{e}"
        );
    }

    #[test]
    fn css_numbers_beyond_f32_are_reported() {
        assert_eq!(css_bad_number("fill:#1e40af; stroke-width: 2"), None);
        let (k, b) = css_bad_number(".a { fill: red } .b{stroke-width:1e39 !important}").unwrap();
        assert_eq!(k, "stroke-width");
        assert!(b.contains("1e39"), "{b}");
        assert!(css_bad_number("stroke-dasharray: 1 NaN").is_some());
    }

    fn load(s: &str) -> Result<Scene> {
        Scene::from_svg_str(s, "t.svg", Sizing::Natural)
    }

    #[test]
    fn rect_becomes_closed_lines_in_device_space() {
        let s = load(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="20" height="10" viewBox="0 0 10 5">
               <rect id="r" x="1" y="1" width="2" height="3" fill="red"/></svg>"#,
        )
        .unwrap();
        assert_eq!((s.width, s.height), (20, 10));
        let Node::Path(p) = &s.nodes[0] else { panic!() };
        assert_eq!(p.id, "r");
        assert_eq!(p.points[0], [2.0, 2.0]);
        let b = p.control_bounds().unwrap();
        assert_eq!(b, [2.0, 2.0, 6.0, 8.0]);
        assert!(p.subpaths[0].closed);
        assert_eq!(
            p.fill.as_ref().unwrap().paint,
            Paint::Solid([1.0, 0.0, 0.0])
        );
    }

    #[test]
    fn group_opacity_becomes_layer() {
        let s = load(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10">
               <g opacity="0.5"><rect width="5" height="5"/><rect x="2" width="5" height="5"/></g></svg>"#,
        )
        .unwrap();
        let Node::Group(g) = &s.nodes[0] else {
            panic!()
        };
        assert_eq!(g.opacity, 0.5);
        assert_eq!(g.children.len(), 2);
    }

    #[test]
    fn malformed_and_unsupported_are_errors() {
        let e = load("<svg").unwrap_err().to_string();
        assert!(e.contains("t.svg") && e.contains("malformed"), "{e}");
        let e = load(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10"><foreignObject id="x"/></svg>"#,
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("unsupported") && e.contains("foreignObject"),
            "{e}"
        );
    }

    /// An `<image>` is its rectangle filled with the image, in device pixels: the transform
    /// maps image pixels there, `preserveAspectRatio` (meet) included, and sizing and
    /// `scale_to` scale it with the rest; the id usvg moves to a wrapper group is kept.
    #[test]
    fn image_becomes_its_rectangle_in_device_space() {
        // A 2 × 1 PNG drawn into a 10 × 10 box: meet scales it by 5 and centers it.
        let png = crate::image_io::encode_png_rgba8(2, 1, &[255, 0, 0, 255, 0, 0, 255, 100]);
        use base64::Engine as _;
        let url = base64::engine::general_purpose::STANDARD.encode(png);
        let svg = format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="20" height="20">
               <image id="pic" x="4" y="4" width="10" height="10" style="image-rendering:pixelated"
                 href="data:image/png;base64,{url}"/></svg>"#
        );
        let s = Scene::from_svg_str(&svg, "t.svg", Sizing::Width(40)).unwrap();
        let Node::Path(p) = &s.nodes[0] else { panic!() };
        assert_eq!(p.id, "pic");
        let Some(Fill {
            paint: Paint::Image(img),
            ..
        }) = &p.fill
        else {
            panic!("{:?}", p.fill)
        };
        assert_eq!(
            (img.width, img.height, img.quality),
            (2, 1, ImageQuality::Nearest)
        );
        assert_eq!(&img.pixels[..], &[255, 0, 0, 255, 0, 0, 255, 100]);
        // User space: x 4..14, y 6.5..11.5; device: twice that.
        assert_eq!(p.control_bounds().unwrap(), [8.0, 13.0, 28.0, 23.0]);
        assert!(img.is_rectangle_of(p));
        let mut scaled = s.clone();
        scaled.scale_to(0.5, 20, 20);
        let Node::Path(q) = &scaled.nodes[0] else {
            panic!()
        };
        let Some(Fill {
            paint: Paint::Image(half),
            ..
        }) = &q.fill
        else {
            panic!()
        };
        assert!(half.is_rectangle_of(q));
        assert_eq!(q.control_bounds().unwrap(), [4.0, 6.5, 14.0, 11.5]);
    }

    #[test]
    fn sizing_scales_everything() {
        let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="20">
               <path d="M1 1 L9 1" stroke="black" stroke-width="2"/></svg>"#;
        let s = Scene::from_svg_str(svg, "t.svg", Sizing::Width(30)).unwrap();
        assert_eq!((s.width, s.height), (30, 60));
        let Node::Path(p) = &s.nodes[0] else { panic!() };
        assert_eq!(p.points[0], [3.0, 3.0]);
        assert!((p.stroke.as_ref().unwrap().width - 6.0).abs() < 1e-9);
        assert!(Scene::from_svg_str(svg, "t.svg", Sizing::Scale(f64::NAN)).is_err());
        assert!(Scene::from_svg_str(svg, "t.svg", Sizing::Width(0)).is_err());
        assert!(Scene::from_svg_str(svg, "t.svg", Sizing::Width(100_000)).is_err());
    }

    #[test]
    fn nested_groups_300_under_a_descendant_selector_are_refused_quickly() {
        let mut svg = String::from(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10">
               <style>g#g1 * g * * rect { fill: red }</style><g id="g1">"#,
        );
        svg += &"<g>".repeat(300);
        svg += r#"<rect width="5" height="5"/>"#;
        svg += &"</g>".repeat(301);
        svg += "</svg>";
        let e = load(&svg).unwrap_err().to_string();
        assert!(
            e.contains("t.svg") && e.contains("stylesheet selector"),
            "{e}"
        );
        // The same rule over a shallow drawing is fine.
        let shallow = r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10">
               <style>g#g1 * g * * rect { fill: red }</style>
               <g id="g1"><g><g><g><rect width="5" height="5"/></g></g></g></g></svg>"#;
        assert!(load(shallow).is_ok());
        assert_eq!(most_selector_parts("a b, c > d e { x: y } f{}"), 3);
    }

    #[test]
    fn arc_of_radius_1e30_is_refused_before_usvg_converts_it() {
        let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 200 200">
            <path id="p" d="M 100 100 h -25 a 25 -1e30 0 1 1 25 25 z" fill="red"/></svg>"#;
        let e = load(svg).unwrap_err().to_string();
        assert!(e.contains("t.svg") && e.contains("arc radius"), "{e}");
        let ok = r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 200 200">
            <path d="M 100 100 h -25 a 25 25 0 1 1 25 25 z" fill="red"/></svg>"#;
        assert!(load(ok).is_ok());
    }

    #[test]
    fn arc_radius_is_scaled_up_to_reach_the_endpoint() {
        // Reachable: the radius as written, whatever the rotation.
        assert_eq!(arc_radius([0.0; 2], [10.0, 0.0], 48.0, 20.0, 30.0), 48.0);
        // A circle of radius 1 to a point 10 away: scaled to half the chord.
        let r = arc_radius([0.0; 2], [10.0, 0.0], 1.0, 1.0, 0.0);
        assert!((r - 5.0).abs() < 1e-12, "{r}");
        // An ellipse 2:1 rotated 90°: the chord along x meets the short axis.
        let r = arc_radius([0.0; 2], [8.0, 0.0], 2.0, 1.0, 90.0);
        assert!((r - 8.0).abs() < 1e-9, "{r}");
        assert_eq!(arc_radius([0.0; 2], [1e38, 0.0], 0.0, 5.0, 0.0), 0.0);
        assert!(arc_radius([0.0; 2], [f64::NAN, 0.0], 1.0, 1.0, 0.0).is_nan());
        // Relative segments, H/V and Z move the current point: each of these ends far.
        for d in [
            "M10 10 a48 48 0 0 0 7.1 1e38z",
            "M0 0 h1e30 A1 1 0 0 0 0 1",
            "M0 0 V1e30 Z a1 1 0 0 0 0 1e30",
            "M0 0 m1e25 0 A1 1 0 0 0 0 0",
        ] {
            assert!(huge_arc(d).is_some(), "{d}");
        }
        for d in ["M0 0 h1e30 Z a1 1 0 0 0 3 4", "M0 0 A1e19 1e19 0 0 0 5 5"] {
            assert_eq!(huge_arc(d), None, "{d}");
        }
    }
}
