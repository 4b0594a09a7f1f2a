//! Line plots (speed against error) drawn with diffsvg's own rasterizer.
//!
//! One chart is laid out once ([`Series`] and a [`PlotSpec`] in, a list of lines, dots and
//! text runs out) and then written two ways: [`plot_svg`] emits a standalone SVG with
//! `<text>` labels, and [`plot_image`] builds a [`Scene`] and renders it with
//! [`raster::render`](fn@crate::raster::render). diffsvg draws no SVG text, so the raster
//! labels use a small built-in stroked font (digits, `a–z`, `A–Z` and a little
//! punctuation; other characters draw as `?`).
//!
//! Points whose coordinates are NaN or infinite, or not positive on a logarithmic axis,
//! are skipped. Axes snap to "nice" ticks (1, 2 or 5 times a power of ten) that cover the
//! data; an empty chart gets a default range, and a single value a range around it.

use crate::scene::svg_out::escape;
use crate::scene::{
    FRAME_IDENTITY, Fill, FillRule, LineCap, LineJoin, Node, Paint, Path as ScenePath, Point,
    Stroke,
};
use crate::{Image, Scene};

/// One named curve: points `(x, y)` joined in the order given.
#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    /// Legend label.
    pub name: String,
    /// Points `(x, y)`, drawn in this order; non-finite points are skipped.
    pub points: Vec<(f64, f64)>,
}

impl Series {
    /// A series from a name and its points.
    pub fn new(name: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Series {
            name: name.into(),
            points,
        }
    }
}

/// Titles, axis kinds and size of a chart.
#[derive(Clone, Debug, PartialEq)]
pub struct PlotSpec {
    /// Title above the chart (may be empty).
    pub title: String,
    /// Label under the x axis (may be empty).
    pub x_label: String,
    /// Label left of the y axis, written bottom to top (may be empty).
    pub y_label: String,
    /// Logarithmic x axis (points with `x ≤ 0` are skipped).
    pub log_x: bool,
    /// Logarithmic y axis (points with `y ≤ 0` are skipped), e.g. for a loss.
    pub log_y: bool,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl PlotSpec {
    /// An 800 × 500 chart with linear axes.
    pub fn new(
        title: impl Into<String>,
        x_label: impl Into<String>,
        y_label: impl Into<String>,
    ) -> Self {
        PlotSpec {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            log_x: false,
            log_y: false,
            width: 800,
            height: 500,
        }
    }
}

impl Default for PlotSpec {
    fn default() -> Self {
        PlotSpec::new("", "", "")
    }
}

/// Series colors (straight sRGB), used in order and repeated after the twelfth series.
pub const PALETTE: [[f64; 3]; 12] = [
    [0.122, 0.467, 0.706], // blue
    [1.000, 0.498, 0.055], // orange
    [0.173, 0.627, 0.173], // green
    [0.839, 0.153, 0.157], // red
    [0.580, 0.404, 0.741], // purple
    [0.549, 0.337, 0.294], // brown
    [0.890, 0.467, 0.761], // pink
    [0.498, 0.498, 0.498], // gray
    [0.737, 0.741, 0.133], // olive
    [0.090, 0.745, 0.812], // cyan
    [0.000, 0.000, 0.000], // black
    [0.100, 0.100, 0.450], // navy
];

/// The color of series number `i`.
pub fn series_color(i: usize) -> [f64; 3] {
    PALETTE[i % PALETTE.len()]
}

/// The chart as an SVG document (white background, `<text>` labels, one
/// `<polyline class="series">` per series with at least one drawable point).
pub fn plot_svg(spec: &PlotSpec, series: &[Series]) -> String {
    let chart = layout(spec, series);
    let mut out = String::new();
    let (w, h) = (spec.width, spec.height);
    out.push_str(&format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" \
         viewBox=\"0 0 {w} {h}\">\n"
    ));
    if !spec.title.is_empty() {
        out.push_str(&format!("<title>{}</title>\n", escape(&spec.title)));
    }
    out.push_str(&format!(
        "<rect x=\"0\" y=\"0\" width=\"{w}\" height=\"{h}\" fill=\"#ffffff\"/>\n"
    ));
    for p in &chart.prims {
        match p {
            Prim::Line(l) => {
                let cap = match l.cap {
                    LineCap::Round => "round",
                    _ => "butt",
                };
                let common = format!(
                    "fill=\"none\" stroke=\"{}\" stroke-width=\"{}\" stroke-linecap=\"{cap}\" \
                     stroke-linejoin=\"round\"",
                    hex(l.color),
                    num(l.width)
                );
                if l.series.is_some() || l.closed || l.pts.len() != 2 {
                    let tag = if l.closed { "polygon" } else { "polyline" };
                    let class = if l.series.is_some() {
                        " class=\"series\""
                    } else {
                        ""
                    };
                    let pts: Vec<String> = l
                        .pts
                        .iter()
                        .map(|p| format!("{},{}", num(p[0]), num(p[1])))
                        .collect();
                    out.push_str(&format!(
                        "<{tag}{class} points=\"{}\" {common}/>\n",
                        pts.join(" ")
                    ));
                } else {
                    let (a, b) = (l.pts[0], l.pts[1]);
                    out.push_str(&format!(
                        "<line x1=\"{}\" y1=\"{}\" x2=\"{}\" y2=\"{}\" {common}/>\n",
                        num(a[0]),
                        num(a[1]),
                        num(b[0]),
                        num(b[1])
                    ));
                }
            }
            Prim::Dot { c, r, color } => {
                out.push_str(&format!(
                    "<circle cx=\"{}\" cy=\"{}\" r=\"{}\" fill=\"{}\" stroke=\"#ffffff\" \
                     stroke-width=\"1\"/>\n",
                    num(c[0]),
                    num(c[1]),
                    num(*r),
                    hex(*color)
                ));
            }
            Prim::Text(t) => {
                let anchor = match t.anchor {
                    Anchor::Start => "start",
                    Anchor::Middle => "middle",
                    Anchor::End => "end",
                };
                let rotate = if t.vertical {
                    format!(
                        " transform=\"rotate(-90 {} {})\"",
                        num(t.at[0]),
                        num(t.at[1])
                    )
                } else {
                    String::new()
                };
                // Sans-serif capitals are about 0.7 em tall.
                out.push_str(&format!(
                    "<text x=\"{}\" y=\"{}\" font-family=\"DejaVu Sans, Helvetica, Arial, \
                     sans-serif\" font-size=\"{}\"{} fill=\"{}\" text-anchor=\"{anchor}\"{rotate}>{}</text>\n",
                    num(t.at[0]),
                    num(t.at[1]),
                    num(t.size / 0.7),
                    if t.bold { " font-weight=\"bold\"" } else { "" },
                    hex(t.color),
                    escape(&t.text)
                ));
            }
        }
    }
    out.push_str("</svg>\n");
    out
}

/// The chart rendered by diffsvg, opaque on a white background, `width × height` pixels.
pub fn plot_image(spec: &PlotSpec, series: &[Series]) -> Image {
    let mut img = crate::raster::render(
        &plot_scene(spec, series),
        &crate::raster::RenderOptions::default(),
    );
    img.over_background([1.0; 4]);
    img
}

/// The chart as a diffsvg [`Scene`] on a transparent canvas (labels are stroked glyphs).
pub fn plot_scene(spec: &PlotSpec, series: &[Series]) -> Scene {
    let chart = layout(spec, series);
    let mut scene = Scene::new(spec.width, spec.height);
    for p in &chart.prims {
        match p {
            Prim::Line(l) => {
                if l.pts.len() < 2 {
                    continue;
                }
                let mut path = ScenePath::new("");
                path.move_to(l.pts[0]);
                for &q in &l.pts[1..] {
                    path.line_to(q);
                }
                if l.closed {
                    path.close();
                }
                path.stroke = Some(solid_stroke(l.color, l.width, l.cap));
                scene.nodes.push(Node::Path(path));
            }
            Prim::Dot { c, r, color } => {
                let mut ring = circle(*c, r + 1.0);
                ring.fill = Some(solid_fill([1.0; 3]));
                scene.nodes.push(Node::Path(ring));
                let mut dot = circle(*c, *r);
                dot.fill = Some(solid_fill(*color));
                scene.nodes.push(Node::Path(dot));
            }
            Prim::Text(t) => glyph_paths(t, &mut scene.nodes),
        }
    }
    scene
}

/// Writes the chart as a PNG (rendered by diffsvg) and as an SVG.
pub fn write_plot(
    spec: &PlotSpec,
    series: &[Series],
    png: impl AsRef<std::path::Path>,
    svg: impl AsRef<std::path::Path>,
) -> crate::Result<()> {
    plot_image(spec, series).save_png(png)?;
    crate::image_io::write_atomic(svg.as_ref(), plot_svg(spec, series).as_bytes())
}

// ---------------------------------------------------------------------------------------
// Layout.

const INK: [f64; 3] = [0.12, 0.12, 0.12];
const FRAME: [f64; 3] = [0.35, 0.35, 0.35];
const GRID: [f64; 3] = [0.88, 0.88, 0.88];

#[derive(Clone, Copy, Debug, PartialEq)]
enum Anchor {
    Start,
    Middle,
    End,
}

#[derive(Clone, Debug)]
struct Line {
    pts: Vec<Point>,
    color: [f64; 3],
    width: f64,
    cap: LineCap,
    closed: bool,
    /// The series index for data curves.
    series: Option<usize>,
}

#[derive(Clone, Debug)]
struct Text {
    /// Anchor point on the baseline.
    at: Point,
    text: String,
    /// Capital height in pixels.
    size: f64,
    color: [f64; 3],
    anchor: Anchor,
    bold: bool,
    /// Rotated −90°: read bottom to top.
    vertical: bool,
}

#[derive(Clone, Debug)]
enum Prim {
    Line(Line),
    Dot { c: Point, r: f64, color: [f64; 3] },
    Text(Text),
}

/// A laid-out axis: its range (snapped to ticks) and the ticks with their labels.
#[derive(Clone, Debug)]
struct Axis {
    lo: f64,
    hi: f64,
    log: bool,
    ticks: Vec<(f64, String)>,
    /// Unlabeled ticks (2–9 × 10ᵏ on a logarithmic axis spanning decades).
    minor: Vec<f64>,
}

impl Axis {
    fn new(values: &[f64], log: bool, target: usize) -> Axis {
        let mut lo = f64::INFINITY;
        let mut hi = f64::NEG_INFINITY;
        for &v in values {
            lo = lo.min(v);
            hi = hi.max(v);
        }
        if lo > hi {
            (lo, hi) = if log { (1.0, 10.0) } else { (0.0, 1.0) };
        }
        let (lo, hi, ticks, minor) = if log {
            log_ticks(lo, hi, target)
        } else {
            let (lo, hi, t) = linear_ticks(lo, hi, target);
            let step = if t.len() > 1 { t[1] - t[0] } else { hi - lo };
            let labeled = t.iter().map(|&v| (v, tick_label(v, step))).collect();
            (lo, hi, labeled, Vec::new())
        };
        Axis {
            lo,
            hi,
            log,
            ticks,
            minor,
        }
    }

    /// Where `v` falls in the range, 0 at `lo` and 1 at `hi`.
    fn frac(&self, v: f64) -> f64 {
        let f = if self.log {
            (v.ln() - self.lo.ln()) / (self.hi.ln() - self.lo.ln())
        } else {
            // Halves keep spans near f64::MAX finite.
            (v / 2.0 - self.lo / 2.0) / (self.hi / 2.0 - self.lo / 2.0)
        };
        if f.is_finite() { f } else { 0.5 }
    }
}

/// Ticks at a 1-2-5 step covering `[lo, hi]` with about `target` intervals; returns the
/// snapped range and the ticks. A zero-width range is widened around its value first.
fn linear_ticks(lo: f64, hi: f64, target: usize) -> (f64, f64, Vec<f64>) {
    let (mut lo, mut hi) = (lo, hi);
    if hi / 2.0 - lo / 2.0 <= 1e-12 * lo.abs().max(hi.abs()) {
        let c = lo / 2.0 + hi / 2.0;
        let d = if c == 0.0 { 1.0 } else { c.abs() * 0.1 };
        (lo, hi) = (c - d, c + d);
    }
    let fallback = (lo, hi, vec![lo, hi]);
    let raw = (hi / 2.0 - lo / 2.0) / target.max(1) as f64 * 2.0;
    if !raw.is_finite() || raw <= 0.0 {
        return fallback;
    }
    let mag = 10f64.powf(raw.log10().floor());
    let Some(step) = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|&s| s >= raw * (1.0 - 1e-9))
    else {
        return fallback;
    };
    let a = (lo / step + 1e-9).floor();
    let b = (hi / step - 1e-9).ceil();
    if !(b - a).is_finite() || b - a > 100.0 || b <= a {
        return fallback;
    }
    let ticks: Vec<f64> = (0..=(b - a) as i64)
        .map(|k| {
            let v = (a + k as f64) * step;
            if v == 0.0 { 0.0 } else { v }
        })
        .collect();
    if ticks.iter().any(|v| !v.is_finite()) {
        return fallback;
    }
    (ticks[0], ticks[ticks.len() - 1], ticks)
}

/// Ticks for a logarithmic axis over `[lo, hi]` (both > 0): linear ticks inside a narrow
/// range, 1-2-5 mantissas over up to two decades, powers of ten beyond (every decade, or
/// every 2nd, 5th, 10th… decade when there are many, the others as minor ticks; 2–9 × 10ᵏ
/// are minor ticks when every decade is labeled). The range snaps to the enclosing ticks
/// or decades. Returns the range, labeled ticks and minor ticks.
#[allow(clippy::type_complexity)]
fn log_ticks(lo: f64, hi: f64, target: usize) -> (f64, f64, Vec<(f64, String)>, Vec<f64>) {
    let (mut lo, mut hi) = (lo, hi);
    if hi / lo < 1.0 + 1e-9 {
        (lo, hi) = (lo / 10f64.sqrt(), hi * 10f64.sqrt());
        if lo <= 0.0 || !hi.is_finite() {
            (lo, hi) = (f64::MIN_POSITIVE.max(lo), f64::MAX.min(hi));
        }
    }
    let decades = hi.log10() - lo.log10();
    if decades < 0.6 {
        let (a, b, t) = linear_ticks(lo, hi, target.min(5));
        if a > 0.0 && t.len() >= 3 {
            let step = t[1] - t[0];
            let labeled = t.iter().map(|&v| (v, tick_label(v, step))).collect();
            return (a, b, labeled, Vec::new());
        }
    }
    let k0 = lo.log10().floor() as i32;
    let k1 = hi.log10().ceil() as i32;
    let p = |k: i32| 10f64.powi(k);
    if decades <= 2.2 {
        let mut all = Vec::new();
        for k in k0 - 1..=k1 {
            for m in [1.0, 2.0, 5.0] {
                all.push(m * p(k));
            }
        }
        let first = all
            .iter()
            .rposition(|&v| v <= lo * (1.0 + 1e-9))
            .unwrap_or(0);
        let last = all
            .iter()
            .position(|&v| v >= hi * (1.0 - 1e-9))
            .unwrap_or(all.len() - 1);
        let t: Vec<(f64, String)> = all[first..=last]
            .iter()
            .map(|&v| (v, tick_label(v, v)))
            .collect();
        return (all[first], all[last], t, Vec::new());
    }
    let k1 = k1.max(k0 + 1);
    let raw = (k1 - k0) as f64 / target.max(2) as f64;
    let stride = [1, 2, 5, 10, 20, 50, 100, 200]
        .into_iter()
        .find(|&m| m as f64 >= raw)
        .unwrap_or(500);
    let mut ticks = Vec::new();
    let mut minor = Vec::new();
    for k in k0..=k1 {
        if k.rem_euclid(stride) == 0 {
            ticks.push((p(k), tick_label(p(k), p(k))));
        } else {
            minor.push(p(k));
        }
        if stride == 1 && k < k1 {
            minor.extend((2..10).map(|m| m as f64 * p(k)));
        }
    }
    if ticks.len() < 2 {
        ticks = [k0, k1].map(|k| (p(k), tick_label(p(k), p(k)))).into();
    }
    (p(k0), p(k1), ticks, minor)
}

/// A tick label for `v` on a grid of spacing `step`: as many decimals as the step needs,
/// scientific notation (`2.5e-5`) for very small or large magnitudes, never `-0`.
fn tick_label(v: f64, step: f64) -> String {
    if !v.is_finite() {
        return String::new();
    }
    let step = if step.is_finite() && step > 0.0 {
        step
    } else {
        v.abs()
    };
    if v.abs() <= step * 1e-9 {
        return "0".into();
    }
    let step_exp = (step.log10() + 1e-9).floor();
    let a = v.abs();
    if !(1e-4..1e6).contains(&a) {
        let prec = ((a.log10() + 1e-9).floor() - step_exp).clamp(0.0, 15.0) as usize;
        let s = format!("{v:.prec$e}");
        let (mant, exp) = s.split_once('e').unwrap_or((&s, "0"));
        let mant = if mant.contains('.') {
            mant.trim_end_matches('0').trim_end_matches('.')
        } else {
            mant
        };
        return format!("{mant}e{exp}");
    }
    let decimals = (-step_exp).clamp(0.0, 15.0) as usize;
    let s = format!("{v:.decimals$}");
    if s.trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        "0".into()
    } else {
        s
    }
}

/// Pixel position of the center line of a 1-pixel line near `v`, so it draws crisply.
fn crisp(v: f64) -> f64 {
    v.floor() + 0.5
}

fn layout(spec: &PlotSpec, series: &[Series]) -> Chart {
    let w = spec.width as f64;
    let h = spec.height as f64;
    let s = (w / 800.0).min(h / 500.0).clamp(0.7, 4.0);
    let pad = 10.0 * s;
    let title_size = 12.0 * s;
    let label_size = 10.0 * s;
    let tick_size = 8.5 * s;
    let legend_size = 9.0 * s;
    let tick_len = 4.0 * s;
    let thin = s.round().max(1.0);

    let valid: Vec<Vec<(f64, f64)>> = series
        .iter()
        .map(|se| {
            se.points
                .iter()
                .copied()
                .filter(|&(x, y)| {
                    x.is_finite()
                        && y.is_finite()
                        && (!spec.log_x || x > 0.0)
                        && (!spec.log_y || y > 0.0)
                })
                .collect()
        })
        .collect();
    let xs: Vec<f64> = valid.iter().flatten().map(|p| p.0).collect();
    let ys: Vec<f64> = valid.iter().flatten().map(|p| p.1).collect();

    // Vertical budget.
    let top = pad
        + if spec.title.is_empty() {
            0.0
        } else {
            title_size + pad
        };
    let bottom = tick_len
        + 0.6 * pad
        + tick_size
        + if spec.x_label.is_empty() {
            0.0
        } else {
            pad + label_size
        }
        + pad;
    let plot_h = (h - top - bottom).max(1.0);
    let y = Axis::new(
        &ys,
        spec.log_y,
        ((plot_h / (45.0 * s)) as usize).clamp(2, 10),
    );

    // Horizontal budget: y label, tick labels, legend.
    let y_tick_w = y
        .ticks
        .iter()
        .map(|t| text_width(&t.1, tick_size))
        .fold(0.0, f64::max);
    let left =
        pad + if spec.y_label.is_empty() {
            0.0
        } else {
            label_size + pad
        } + y_tick_w
            + 0.6 * pad
            + tick_len;
    let swatch = 22.0 * s;
    let max_name_w = (w * 0.3).max(40.0);
    let names: Vec<String> = series
        .iter()
        .map(|se| fit_text(&se.name, legend_size, max_name_w))
        .collect();
    let legend_w = if series.is_empty() {
        0.0
    } else {
        let nw = names
            .iter()
            .map(|n| text_width(n, legend_size))
            .fold(0.0, f64::max);
        0.8 * pad + swatch + 0.6 * pad + nw + 0.8 * pad
    };
    let right = pad + if legend_w > 0.0 { legend_w + pad } else { 0.0 };
    let x0 = crisp(left);
    let x1 = crisp((w - right).max(left + 1.0));
    let y0 = crisp(top);
    let y1 = crisp((h - bottom).max(top + 1.0));
    let x = Axis::new(
        &xs,
        spec.log_x,
        ((x1 - x0) / (70.0 * s) + 0.5).clamp(2.0, 10.0) as usize,
    );

    let mut chart = Chart {
        plot: [x0, y0, x1, y1],
        x,
        y,
        prims: Vec::new(),
    };
    let mut prims = Vec::new();
    let line = |pts: Vec<Point>, color, width, closed| {
        Prim::Line(Line {
            pts,
            color,
            width,
            cap: LineCap::Butt,
            closed,
            series: None,
        })
    };

    // Grid, minor ticks, frame.
    for (v, _) in &chart.x.ticks {
        let px = crisp(chart.px(*v));
        if px > x0 + 0.5 && px < x1 - 0.5 {
            prims.push(line(vec![[px, y0], [px, y1]], GRID, thin, false));
        }
    }
    for (v, _) in &chart.y.ticks {
        let py = crisp(chart.py(*v));
        if py > y0 + 0.5 && py < y1 - 0.5 {
            prims.push(line(vec![[x0, py], [x1, py]], GRID, thin, false));
        }
    }
    for &v in &chart.x.minor {
        let px = crisp(chart.px(v));
        prims.push(line(
            vec![[px, y1], [px, y1 + tick_len * 0.6]],
            FRAME,
            thin,
            false,
        ));
    }
    for &v in &chart.y.minor {
        let py = crisp(chart.py(v));
        prims.push(line(
            vec![[x0 - tick_len * 0.6, py], [x0, py]],
            FRAME,
            thin,
            false,
        ));
    }
    prims.push(line(
        vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]],
        FRAME,
        thin,
        true,
    ));

    // Ticks and tick labels.
    for (v, label) in &chart.x.ticks {
        let px = crisp(chart.px(*v));
        prims.push(line(
            vec![[px, y1], [px, y1 + tick_len]],
            FRAME,
            thin,
            false,
        ));
        prims.push(Prim::Text(Text {
            at: [px, y1 + tick_len + 0.6 * pad + tick_size],
            text: label.clone(),
            size: tick_size,
            color: INK,
            anchor: Anchor::Middle,
            bold: false,
            vertical: false,
        }));
    }
    for (v, label) in &chart.y.ticks {
        let py = crisp(chart.py(*v));
        prims.push(line(
            vec![[x0 - tick_len, py], [x0, py]],
            FRAME,
            thin,
            false,
        ));
        prims.push(Prim::Text(Text {
            at: [x0 - tick_len - 0.6 * pad, py + tick_size / 2.0],
            text: label.clone(),
            size: tick_size,
            color: INK,
            anchor: Anchor::End,
            bold: false,
            vertical: false,
        }));
    }

    // Titles.
    let text = |at, text: &str, size, anchor, bold, vertical| {
        Prim::Text(Text {
            at,
            text: text.to_string(),
            size,
            color: INK,
            anchor,
            bold,
            vertical,
        })
    };
    if !spec.title.is_empty() {
        prims.push(text(
            [(x0 + x1) / 2.0, pad + title_size],
            &spec.title,
            title_size,
            Anchor::Middle,
            true,
            false,
        ));
    }
    if !spec.x_label.is_empty() {
        prims.push(text(
            [(x0 + x1) / 2.0, h - pad],
            &spec.x_label,
            label_size,
            Anchor::Middle,
            false,
            false,
        ));
    }
    if !spec.y_label.is_empty() {
        prims.push(text(
            [pad + label_size, (y0 + y1) / 2.0],
            &spec.y_label,
            label_size,
            Anchor::Middle,
            false,
            true,
        ));
    }

    // Curves, then a dot on each curve's last point.
    let curve_w = 2.0 * s;
    let dot_r = 3.5 * s;
    for (i, pts) in valid.iter().enumerate() {
        let mut dev: Vec<Point> = Vec::with_capacity(pts.len());
        for &(vx, vy) in pts {
            let p = [chart.px(vx), chart.py(vy)];
            if dev.last().is_none_or(|q| q[0] != p[0] || q[1] != p[1]) {
                dev.push(p);
            }
        }
        if dev.is_empty() {
            continue;
        }
        prims.push(Prim::Line(Line {
            pts: dev,
            color: series_color(i),
            width: curve_w,
            cap: LineCap::Round,
            closed: false,
            series: Some(i),
        }));
    }
    for (i, pts) in valid.iter().enumerate() {
        if let Some(&(vx, vy)) = pts.last() {
            prims.push(Prim::Dot {
                c: [chart.px(vx), chart.py(vy)],
                r: dot_r,
                color: series_color(i),
            });
        }
    }

    // Legend, right of the plot, top-aligned.
    if !series.is_empty() {
        let lx0 = crisp(x1 + pad);
        let row = legend_size * 2.0;
        let ly0 = y0;
        let lh = (0.4 * pad + row * series.len() as f64 + 0.4 * pad).round();
        prims.push(line(
            vec![
                [lx0, ly0],
                [lx0 + legend_w.round(), ly0],
                [lx0 + legend_w.round(), ly0 + lh],
                [lx0, ly0 + lh],
            ],
            GRID,
            thin,
            true,
        ));
        for (i, name) in names.iter().enumerate() {
            let cy = ly0 + 0.4 * pad + row * (i as f64 + 0.5);
            let sx = lx0 + 0.8 * pad;
            prims.push(Prim::Line(Line {
                pts: vec![[sx, cy], [sx + swatch, cy]],
                color: series_color(i),
                width: curve_w,
                cap: LineCap::Round,
                closed: false,
                series: None,
            }));
            prims.push(Prim::Dot {
                c: [sx + swatch, cy],
                r: dot_r * 0.8,
                color: series_color(i),
            });
            prims.push(text(
                [sx + swatch + 0.6 * pad + dot_r, cy + legend_size / 2.0],
                name,
                legend_size,
                Anchor::Start,
                false,
                false,
            ));
        }
    }
    chart.prims = prims;
    chart
}

/// The laid-out chart: plot area `[x0, y0, x1, y1]` in pixels, axes, and what to draw in
/// paint order.
struct Chart {
    plot: [f64; 4],
    x: Axis,
    y: Axis,
    prims: Vec<Prim>,
}

impl Chart {
    fn px(&self, v: f64) -> f64 {
        let [x0, _, x1, _] = self.plot;
        x0 + self.x.frac(v).clamp(-1.0, 2.0) * (x1 - x0)
    }

    fn py(&self, v: f64) -> f64 {
        let [_, y0, _, y1] = self.plot;
        y1 - self.y.frac(v).clamp(-1.0, 2.0) * (y1 - y0)
    }
}

// ---------------------------------------------------------------------------------------
// Output helpers.

fn num(v: f64) -> String {
    let s = format!("{v:.2}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

fn hex(c: [f64; 3]) -> String {
    let b = |v: f64| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    format!("#{:02x}{:02x}{:02x}", b(c[0]), b(c[1]), b(c[2]))
}

fn solid_stroke(color: [f64; 3], width: f64, cap: LineCap) -> Stroke {
    Stroke {
        paint: Paint::Solid(color),
        opacity: 1.0,
        width,
        join: LineJoin::Round,
        cap,
        miter_limit: 4.0,
        dash: None,
        dash_offset: 0.0,
        frame: FRAME_IDENTITY,
    }
}

fn solid_fill(color: [f64; 3]) -> Fill {
    Fill {
        paint: Paint::Solid(color),
        opacity: 1.0,
        rule: FillRule::NonZero,
    }
}

/// A circle as four cubics.
fn circle(c: Point, r: f64) -> ScenePath {
    const K: f64 = 0.552_284_749_8;
    let [x, y] = c;
    let k = K * r;
    let mut p = ScenePath::new("");
    p.move_to([x + r, y]);
    p.cubic_to([x + r, y + k], [x + k, y + r], [x, y + r]);
    p.cubic_to([x - k, y + r], [x - r, y + k], [x - r, y]);
    p.cubic_to([x - r, y - k], [x - k, y - r], [x, y - r]);
    p.cubic_to([x + k, y - r], [x + r, y - k], [x + r, y]);
    p.close();
    p
}

// ---------------------------------------------------------------------------------------
// The built-in stroked font.
//
// Glyphs live on a grid in font units: x to the right from 0 to the glyph width, y down
// with capitals from 0 (top) to 6 (baseline), lowercase x-height at 2 and descenders to
// 8. A glyph is a list of strokes separated by `|`; a stroke is a list of points written
// as two digits `xy`; a one-point stroke is a dot.

/// Font units from the top of a capital to the baseline.
const CAP: f64 = 6.0;
/// Font units between neighboring glyphs.
const GAP: f64 = 1.6;

/// Width in font units and strokes of `c`, `None` where the font has no glyph.
fn glyph(c: char) -> Option<(f64, &'static str)> {
    Some(match c {
        ' ' => (1.4, ""),
        '0' => (4.0, "10 30 41 45 36 16 05 01 10 | 34 12"),
        '1' => (3.0, "02 20 26 | 06 36"),
        '2' => (4.0, "01 10 30 41 42 06 46"),
        '3' => (4.0, "01 10 30 41 42 33 44 45 36 16 05 | 13 33"),
        '4' => (4.0, "36 30 04 44"),
        '5' => (4.0, "40 00 02 32 43 45 36 16 05"),
        '6' => (4.0, "03 33 44 45 36 16 05 01 10 30 41"),
        '7' => (4.0, "00 40 41 16"),
        '8' => (4.0, "10 30 41 42 33 13 02 01 10 | 13 04 05 16 36 45 44 33"),
        '9' => (4.0, "43 13 02 01 10 30 41 45 36 16 05"),
        'A' => (4.0, "06 01 10 30 41 46 | 03 43"),
        'B' => (4.0, "06 00 30 41 42 33 03 | 33 44 45 36 06"),
        'C' => (4.0, "41 30 10 01 05 16 36 45"),
        'D' => (4.0, "00 30 41 45 36 06 00"),
        'E' => (4.0, "40 00 06 46 | 03 33"),
        'F' => (4.0, "40 00 06 | 03 33"),
        'G' => (4.0, "41 30 10 01 05 16 36 45 43 23"),
        'H' => (4.0, "00 06 | 40 46 | 03 43"),
        'I' => (2.0, "00 20 | 10 16 | 06 26"),
        'J' => (4.0, "20 40 45 36 16 05"),
        'K' => (4.0, "00 06 | 40 03 46"),
        'L' => (4.0, "00 06 46"),
        'M' => (4.0, "06 00 23 40 46"),
        'N' => (4.0, "06 00 46 40"),
        'O' => (4.0, "10 30 41 45 36 16 05 01 10"),
        'P' => (4.0, "06 00 30 41 42 33 03"),
        'Q' => (4.0, "10 30 41 45 36 16 05 01 10 | 24 46"),
        'R' => (4.0, "06 00 30 41 42 33 03 | 23 46"),
        'S' => (4.0, "41 30 10 01 02 13 33 44 45 36 16 05"),
        'T' => (4.0, "00 40 | 20 26"),
        'U' => (4.0, "00 05 16 36 45 40"),
        'V' => (4.0, "00 26 40"),
        'W' => (4.0, "00 16 23 36 40"),
        'X' => (4.0, "00 46 | 40 06"),
        'Y' => (4.0, "00 23 40 | 23 26"),
        'Z' => (4.0, "00 40 06 46"),
        'a' => (4.0, "12 32 43 46 | 44 14 05 16 36 45"),
        'b' => (4.0, "00 06 36 45 43 32 02"),
        'c' => (4.0, "42 12 03 05 16 46"),
        'd' => (4.0, "40 46 16 05 03 12 42"),
        'e' => (4.0, "04 44 43 32 12 03 05 16 46"),
        'f' => (3.0, "30 20 11 16 | 02 32"),
        'g' => (4.0, "46 16 05 03 12 42 47 38 08"),
        'h' => (4.0, "00 06 | 02 32 43 46"),
        'i' => (0.0, "02 06 | 00"),
        'j' => (2.0, "22 27 18 08 | 20"),
        'k' => (3.0, "00 06 | 32 04 36"),
        'l' => (1.0, "00 05 16"),
        'm' => (6.0, "02 06 | 03 12 22 33 36 | 33 42 52 63 66"),
        'n' => (4.0, "02 06 | 03 12 32 43 46"),
        'o' => (4.0, "12 32 43 45 36 16 05 03 12"),
        'p' => (4.0, "08 02 32 43 45 36 06"),
        'q' => (4.0, "48 42 12 03 05 16 46"),
        'r' => (3.0, "02 06 | 03 12 32"),
        's' => (4.0, "42 12 03 14 34 45 36 06"),
        't' => (3.0, "11 15 26 36 | 02 32"),
        'u' => (4.0, "02 05 16 36 45 | 42 46"),
        'v' => (4.0, "02 26 42"),
        'w' => (4.0, "02 16 23 36 42"),
        'x' => (4.0, "02 46 | 42 06"),
        'y' => (4.0, "02 26 | 42 18"),
        'z' => (4.0, "02 42 06 46"),
        '.' => (0.0, "06"),
        ',' => (1.0, "16 07"),
        ':' => (0.0, "02 | 06"),
        '-' => (3.0, "03 33"),
        '+' => (4.0, "03 43 | 21 25"),
        '=' => (4.0, "02 42 | 04 44"),
        '×' => (4.0, "12 34 | 32 14"),
        '(' => (1.0, "10 02 05 17"),
        ')' => (1.0, "00 12 15 07"),
        '[' => (1.0, "10 00 07 17"),
        ']' => (1.0, "00 10 17 07"),
        '/' => (3.0, "06 30"),
        '%' => (4.0, "06 40 | 00 10 11 01 00 | 35 45 46 36 35"),
        '_' => (4.0, "07 47"),
        '\'' => (0.0, "00 01"),
        '?' => (4.0, "01 10 30 41 42 23 24 | 26"),
        _ => return None,
    })
}

fn glyph_or_fallback(c: char) -> (f64, &'static str) {
    glyph(c).or_else(|| glyph('?')).unwrap_or((0.0, ""))
}

/// Width in pixels of `text` at capital height `size`.
fn text_width(text: &str, size: f64) -> f64 {
    let mut units = 0.0;
    for (i, c) in text.chars().enumerate() {
        if i > 0 {
            units += GAP;
        }
        units += glyph_or_fallback(c).0;
    }
    units * size / CAP
}

/// `text`, shortened with a trailing `..` until it is at most `max_w` pixels wide.
fn fit_text(text: &str, size: f64, max_w: f64) -> String {
    if text_width(text, size) <= max_w {
        return text.to_string();
    }
    let mut chars: Vec<char> = text.chars().collect();
    while !chars.is_empty() {
        chars.pop();
        let t: String = chars.iter().collect::<String>() + "..";
        if text_width(&t, size) <= max_w {
            return t;
        }
    }
    "..".into()
}

/// Appends the strokes (one path) and dots (one filled path) of a text run.
fn glyph_paths(t: &Text, nodes: &mut Vec<Node>) {
    let u = t.size / CAP;
    let sw = (u * if t.bold { 0.95 } else { 0.72 }).max(0.9);
    let w = text_width(&t.text, t.size);
    let mut pen = match t.anchor {
        Anchor::Start => 0.0,
        Anchor::Middle => -w / 2.0,
        Anchor::End => -w,
    };
    // (along the text, below the baseline) → device.
    let place = |a: f64, b: f64| -> Point {
        if t.vertical {
            [t.at[0] + b, t.at[1] - a]
        } else {
            [t.at[0] + a, t.at[1] + b]
        }
    };
    let mut strokes = ScenePath::new("");
    let mut dots = ScenePath::new("");
    for c in t.text.chars() {
        let (gw, spec) = glyph_or_fallback(c);
        for stroke in spec.split('|') {
            let pts: Vec<Point> = stroke
                .split_whitespace()
                .filter_map(|xy| {
                    let mut d = xy.chars().filter_map(|c| c.to_digit(10));
                    let (gx, gy) = (d.next()? as f64, d.next()? as f64);
                    Some(place(pen + gx * u, (gy - CAP) * u))
                })
                .collect();
            match pts.len() {
                0 => {}
                1 => {
                    let r = sw * 0.75;
                    let [x, y] = pts[0];
                    dots.move_to([x - r, y - r]);
                    dots.line_to([x + r, y - r]);
                    dots.line_to([x + r, y + r]);
                    dots.line_to([x - r, y + r]);
                    dots.close();
                }
                _ => {
                    strokes.move_to(pts[0]);
                    for &p in &pts[1..] {
                        strokes.line_to(p);
                    }
                }
            }
        }
        pen += (gw + GAP) * u;
    }
    if !strokes.subpaths.is_empty() {
        strokes.stroke = Some(solid_stroke(t.color, sw, LineCap::Round));
        nodes.push(Node::Path(strokes));
    }
    if !dots.subpaths.is_empty() {
        dots.fill = Some(solid_fill(t.color));
        nodes.push(Node::Path(dots));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn demo_series() -> Vec<Series> {
        let mut out = Vec::new();
        for (k, name) in ["01-curves", "05-translucent-overlap", "11-landscape"]
            .iter()
            .enumerate()
        {
            let pts = (0..40)
                .map(|i| {
                    let t = 0.05 * (1.0 + k as f64) * 1.25f64.powi(i);
                    (t, 18.0 + 6.0 * k as f64 + 4.0 * (1.0 + t).ln())
                })
                .collect();
            out.push(Series::new(*name, pts));
        }
        out
    }

    #[test]
    fn image_has_requested_size_and_white_background() {
        let mut spec = PlotSpec::new("t", "x", "y");
        spec.width = 321;
        spec.height = 207;
        let img = plot_image(&spec, &demo_series());
        assert_eq!((img.width, img.height), (321, 207));
        assert_eq!(img.get(0, 0), [1.0; 4]);
        assert!(img.data.iter().all(|p| (p[3] - 1.0).abs() < 1e-6));
    }

    fn dist(a: [f32; 4], c: [f64; 3]) -> f32 {
        (0..3)
            .map(|i| (a[i] - c[i] as f32).abs())
            .fold(0.0, f32::max)
    }

    fn near(a: [f32; 4], c: [f64; 3], tol: f32) -> bool {
        (0..3).all(|i| (a[i] - c[i] as f32).abs() <= tol)
    }

    #[test]
    fn curve_pixels_carry_series_color() {
        let spec = PlotSpec::new("colors", "x", "y");
        let series = vec![
            Series::new("flat", vec![(1.0, 2.0), (3.0, 2.0)]),
            Series::new("rising", vec![(1.0, 0.0), (3.0, 4.0)]),
        ];
        let chart = layout(&spec, &series);
        let img = plot_image(&spec, &series);
        for (i, (x, y)) in [(1.5, 2.0), (2.5, 3.0), (1.25, 0.5)]
            .into_iter()
            .enumerate()
        {
            let want = series_color(if i == 0 { 0 } else { 1 });
            let (px, py) = (chart.px(x), chart.py(y));
            // The pixel whose center lies closest to the curve's center line.
            let p = (0..9)
                .map(|k| img.get(px as u32 + k % 3 - 1, py as u32 + k / 3 - 1))
                .min_by(|a, b| dist(*a, want).total_cmp(&dist(*b, want)))
                .unwrap();
            assert!(
                near(p, want, 0.02),
                "({x}, {y}) → ({px}, {py}): {p:?} vs {want:?}"
            );
        }
        // Off the curves, inside the plot, the background is white or grid gray.
        let p = img.get(chart.px(2.5) as u32 + 3, chart.py(1.0) as u32);
        assert!(p[0] > 0.8 && p[1] > 0.8 && p[2] > 0.8, "{p:?}");
    }

    #[test]
    fn last_point_is_marked() {
        let spec = PlotSpec::default();
        let series = vec![Series::new("a", vec![(0.0, 0.0), (2.0, 1.0), (1.0, 0.5)])];
        let chart = layout(&spec, &series);
        let img = plot_image(&spec, &series);
        let (px, py) = (chart.px(1.0), chart.py(0.5));
        // Below the last point, away from the curve (which arrives from the upper right),
        // only the marker paints.
        let p = img.get(px as u32, (py + 2.0) as u32);
        assert!(near(p, series_color(0), 0.02), "{p:?}");
        let p = img.get(px as u32, (py + 8.0) as u32);
        assert!(p[0] > 0.8 && p[1] > 0.8 && p[2] > 0.8, "{p:?}");
    }

    #[test]
    fn degenerate_inputs_do_not_panic() {
        let cases: Vec<Vec<Series>> = vec![
            vec![],
            vec![Series::new("empty", vec![])],
            vec![Series::new("one", vec![(3.0, 4.0)])],
            vec![Series::new("zero", vec![(0.0, 0.0)])],
            vec![Series::new(
                "nan",
                vec![
                    (f64::NAN, 1.0),
                    (1.0, f64::INFINITY),
                    (2.0, 3.0),
                    (f64::NEG_INFINITY, 0.0),
                ],
            )],
            vec![Series::new("all nan", vec![(f64::NAN, f64::NAN)])],
            vec![Series::new(
                "flat",
                vec![(0.0, 7.0), (1.0, 7.0), (2.0, 7.0)],
            )],
            vec![Series::new("vertical", vec![(1.0, 0.0), (1.0, 5.0)])],
            vec![Series::new("dup", vec![(1.0, 1.0), (1.0, 1.0)])],
            vec![Series::new("neg", vec![(-5.0, -1e-7), (-1.0, -2e-7)])],
            vec![Series::new("huge", vec![(-1e308, -1e308), (1e308, 1e308)])],
            vec![Series::new(
                "tiny",
                vec![(1e-300, 1e-300), (2e-300, 3e-300)],
            )],
            vec![Series::new(
                "close",
                vec![(1.0, 1.0), (1.0 + 1e-15, 1.0 + 1e-15)],
            )],
            vec![Series::new(
                "<&\"weird\u{1}\u{263a}>",
                vec![(0.0, 1.0), (1.0, 0.0)],
            )],
            (0..30)
                .map(|k| Series::new(format!("s{k}"), vec![(k as f64, 1.0)]))
                .collect(),
        ];
        for (w, h) in [(800, 500), (40, 30), (1, 1), (0, 0), (3000, 120)] {
            for log_x in [false, true] {
                for log_y in [false, true] {
                    for series in &cases {
                        let spec = PlotSpec {
                            title: "T".into(),
                            x_label: "x".into(),
                            y_label: "y".into(),
                            log_x,
                            log_y,
                            width: w,
                            height: h,
                        };
                        let img = plot_image(&spec, series);
                        assert_eq!((img.width, img.height), (w, h));
                        assert!(img.data.iter().all(|p| p.iter().all(|v| v.is_finite())));
                        let svg = plot_svg(&spec, series);
                        assert!(!svg.contains("NaN") && !svg.contains("inf"), "{svg}");
                        if w > 0 && h > 0 {
                            usvg::Tree::from_str(&svg, &usvg::Options::default())
                                .unwrap_or_else(|e| panic!("{e}: {svg}"));
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn svg_parses_and_has_one_polyline_per_drawable_series() {
        let mut series = demo_series();
        series.push(Series::new("nothing to draw", vec![(f64::NAN, 1.0)]));
        series.push(Series::new("a & <b>", vec![(1.0, 20.0)]));
        let mut spec = PlotSpec::new("Speed & error", "time (s)", "PSNR (dB)");
        spec.log_x = true;
        let svg = plot_svg(&spec, &series);
        usvg::Tree::from_str(&svg, &usvg::Options::default()).unwrap();
        assert_eq!(
            svg.matches("<polyline class=\"series\"").count(),
            series.len() - 1
        );
        assert!(svg.contains(">Speed &amp; error</text>"));
        assert!(svg.contains(">a &amp; &lt;b&gt;</text>"));
        assert!(svg.contains(">PSNR (dB)</text>") && svg.contains("rotate(-90"));
        for (i, _) in series.iter().enumerate() {
            assert!(svg.contains(&hex(series_color(i))));
        }
        // Tick labels on the log axis are powers of ten or 1-2-5 values.
        assert!(svg.contains(">10</text>") || svg.contains(">100</text>"));
    }

    /// `step` snapped to the 1-2-5 value it is within 1e-6 of, if any.
    fn snap_125(step: f64) -> Option<f64> {
        let e = 10f64.powf(step.log10().floor());
        [1.0, 2.0, 5.0, 10.0]
            .iter()
            .map(|&m| m * e)
            .find(|&c| (step - c).abs() < 1e-6 * c)
    }

    fn is_125(step: f64) -> bool {
        snap_125(step).is_some()
    }

    #[test]
    fn linear_ticks_are_125_and_cover() {
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        for _ in 0..2000 {
            let scale = 10f64.powf(rnd() * 16.0 - 8.0);
            let a = (rnd() - 0.5) * scale * 10.0;
            let b = a + rnd() * scale;
            let target = 2 + (rnd() * 8.0) as usize;
            let (lo, hi, t) = linear_ticks(a, b, target);
            assert!(t.len() >= 2 && t.len() <= 2 * target + 3, "{a} {b} {t:?}");
            assert_eq!((lo, hi), (t[0], t[t.len() - 1]));
            assert!(lo <= a && hi >= b, "{a} {b} {t:?}");
            let step = snap_125(t[1] - t[0]).unwrap_or_else(|| panic!("{t:?}"));
            for w in t.windows(2) {
                assert!(((w[1] - w[0]) - step).abs() <= 1e-6 * step, "{t:?}");
            }
            for &v in &t {
                let k = v / step;
                assert!((k - k.round()).abs() < 1e-6, "{v} / {step}");
            }
        }
        assert_eq!(
            linear_ticks(0.13, 0.87, 5).2,
            vec![0.0, 0.2, 0.4, 0.6000000000000001, 0.8, 1.0]
        );
        assert_eq!(
            linear_ticks(0.0, 10.0, 5).2,
            vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
        );
        let (lo, hi, t) = linear_ticks(7.0, 7.0, 5);
        assert!(lo < 7.0 && hi > 7.0 && t.len() >= 3);
        let (lo, hi, _) = linear_ticks(0.0, 0.0, 5);
        assert!(lo < 0.0 && hi > 0.0);
    }

    #[test]
    fn log_ticks_cover_and_use_125_or_decades() {
        let (lo, hi, t, minor) = log_ticks(0.3, 40.0, 6);
        assert!(lo <= 0.3 && hi >= 40.0);
        let v: Vec<f64> = t.iter().map(|p| p.0).collect();
        assert!(v.iter().all(|&x| is_125(x)), "{v:?}");
        assert!(
            v.iter().any(|&x| (x - 1.0).abs() < 1e-12)
                && v.iter().any(|&x| (x - 10.0).abs() < 1e-9)
        );
        assert!(minor.is_empty());
        let (lo, hi, t, minor) = log_ticks(0.003, 2e4, 8);
        assert_eq!((lo, hi), (1e-3, 1e5));
        assert_eq!(t.len(), 9);
        assert!(
            t.iter()
                .all(|p| (p.0.log10() - p.0.log10().round()).abs() < 1e-9)
        );
        assert_eq!(minor.len(), 8 * 8);
        // Many decades: every other decade labeled, the range not stretched past the data.
        let (lo, hi, t, minor) = log_ticks(0.05, 900.0, 3);
        assert_eq!((lo, hi), (0.01, 1000.0));
        let labels: Vec<&str> = t.iter().map(|p| p.1.as_str()).collect();
        assert_eq!(labels, ["0.01", "1", "100"]);
        assert_eq!(minor, [0.1, 10.0, 1000.0]);
        let (lo, hi, t, _) = log_ticks(1e-30, 1e30, 6);
        assert!(lo <= 1e-30 && hi >= 1e30 && t.len() <= 8, "{t:?}");
        let (lo, hi, t, _) = log_ticks(2.0, 3.0, 6);
        assert!(lo <= 2.0 && hi >= 3.0 && t.len() >= 3, "{t:?}");
        let (lo, hi, t, _) = log_ticks(5.0, 5.0, 6);
        assert!(lo < 5.0 && hi > 5.0 && t.len() >= 3, "{t:?}");
    }

    #[test]
    fn tick_labels_are_short_and_clean() {
        assert_eq!(tick_label(0.30000000000000004, 0.1), "0.3");
        assert_eq!(tick_label(-0.0, 0.1), "0");
        assert_eq!(tick_label(1e-17, 0.1), "0");
        assert_eq!(tick_label(25.0, 5.0), "25");
        assert_eq!(tick_label(2.5, 0.5), "2.5");
        assert_eq!(tick_label(0.02, 0.02), "0.02");
        assert_eq!(tick_label(1e-5, 1e-5), "1e-5");
        assert_eq!(tick_label(2.5e-5, 5e-6), "2.5e-5");
        assert_eq!(tick_label(3e7, 1e7), "3e7");
        assert_eq!(tick_label(1000.0, 1000.0), "1000");
    }

    #[test]
    fn font_covers_the_needed_characters() {
        let needed = "0123456789abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ.-()/% ×";
        for c in needed.chars() {
            let (w, strokes) = glyph(c).unwrap_or_else(|| panic!("no glyph for {c:?}"));
            for stroke in strokes.split('|') {
                for xy in stroke.split_whitespace() {
                    let d: Vec<u32> = xy.chars().map(|c| c.to_digit(10).unwrap()).collect();
                    assert_eq!(d.len(), 2, "{c:?}: {xy}");
                    assert!(
                        d[0] as f64 <= w && d[1] <= 8,
                        "{c:?}: {xy} outside width {w}"
                    );
                }
            }
        }
        assert_eq!(glyph_or_fallback('€'), glyph('?').unwrap());
    }

    #[test]
    fn text_draws_ink_inside_its_box() {
        let t = Text {
            at: [10.0, 30.0],
            text: "Hello 42".into(),
            size: 12.0,
            color: [0.0; 3],
            anchor: Anchor::Start,
            bold: false,
            vertical: false,
        };
        let mut scene = Scene::new(120, 40);
        glyph_paths(&t, &mut scene.nodes);
        let img = crate::raster::render(&scene, &crate::raster::RenderOptions::default());
        let w = text_width(&t.text, t.size);
        let mut inside = 0.0;
        let mut outside = 0.0;
        for y in 0..40 {
            for x in 0..120 {
                let a = img.get(x, y)[3] as f64;
                let (cx, cy) = (x as f64 + 0.5, y as f64 + 0.5);
                if cx > 8.0 && cx < 12.0 + w && cy > 16.0 && cy < 32.0 {
                    inside += a;
                } else {
                    outside += a;
                }
            }
        }
        assert!(inside > 60.0, "{inside}");
        assert!(outside < 1e-3, "{outside}");
    }
}
