//! Line charts for the reports (PSNR against time and the like), drawn with [`plotters`]
//! once into an RGB buffer, saved as a PNG, and once as an SVG.
//!
//! Points with a NaN or infinite coordinate, or one that is not positive on a logarithmic
//! axis, are skipped. Axes cover the data with round ends (a multiple of the tick step, or
//! a power of ten on a log axis); an empty chart gets a default range and a single value a
//! range around it. Text uses DejaVu Sans, bundled by the `dejavu` crate, so no system
//! font is needed.

use std::ops::Range;
use std::path::Path;
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};

use diffsvg::image_io::{Image, write_atomic};
use diffsvg::{Error, Result};

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

/// Series colors (matplotlib's "tab10", then black and navy), repeated after the twelfth.
const PALETTE: [RGBColor; 12] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
    RGBColor(0, 0, 0),
    RGBColor(26, 26, 115),
];

const FONT: &str = "sans-serif";
const INK: RGBColor = RGBColor(30, 30, 30);
const GRID: RGBColor = RGBColor(222, 222, 222);
const MINOR_GRID: RGBColor = RGBColor(240, 240, 240);

/// Writes the chart as a PNG and as an SVG (each atomically: a temporary file, then a
/// rename). The size is checked like any image size first.
pub fn write_plot(
    spec: &PlotSpec,
    series: &[Series],
    png: impl AsRef<Path>,
    svg: impl AsRef<Path>,
) -> Result<()> {
    let (png, svg) = (png.as_ref(), svg.as_ref());
    diffsvg::image_io::check_image_size(spec.width, spec.height, png)?;
    plot_image(spec, series)
        .map_err(|e| failed(png, e))?
        .save_png(png)?;
    let text = plot_svg(spec, series).map_err(|e| failed(svg, e))?;
    write_atomic(svg, text.as_bytes())
}

fn failed(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::Image {
        path: path.to_path_buf(),
        message: format!("cannot draw the plot: {e}"),
    }
}

/// The chart drawn into an opaque `width × height` image: drawn at twice the size and
/// halved (plotters' bitmap lines are not antialiased and it places glyphs on whole pixels).
fn plot_image(spec: &PlotSpec, series: &[Series]) -> Result<Image, String> {
    let (w, h) = (spec.width, spec.height);
    let s = if w.max(h) <= 4096 { 2 } else { 1 };
    let mut rgb = vec![255u8; (w * s) as usize * (h * s) as usize * 3];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, (w * s, h * s)).into_drawing_area();
        let big = PlotSpec {
            width: w * s,
            height: h * s,
            ..spec.clone()
        };
        draw(&root, &big, series, true)?;
        root.present().map_err(|e| e.to_string())?;
    }
    // Each output pixel is the mean of its s × s block.
    let mut rgba = Vec::with_capacity(w as usize * h as usize * 4);
    for (x, y) in (0..h).flat_map(|y| (0..w).map(move |x| (x, y))) {
        for c in 0..3 {
            let at = |k: u32| rgb[(((y * s + k / s) * w * s + x * s + k % s) * 3) as usize + c];
            let sum: u32 = (0..s * s).map(|k| at(k) as u32).sum();
            rgba.push(((sum + s * s / 2) / (s * s)) as u8);
        }
        rgba.push(255);
    }
    Ok(Image::from_rgba8(w, h, &rgba))
}

/// The chart as an SVG document whose `<title>` is the chart's title.
fn plot_svg(spec: &PlotSpec, series: &[Series]) -> Result<String, String> {
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, (spec.width, spec.height)).into_drawing_area();
        draw(&root, spec, series, false)?;
        root.present().map_err(|e| e.to_string())?;
    }
    if let Some(end) = out.find(">\n") {
        let title = format!("<title>{}</title>\n", diffsvg::scene::escape(&spec.title));
        out.insert_str(end + 2, &title);
    }
    Ok(out)
}

/// The drawable points of each series and the axis ranges that cover them.
struct Data {
    curves: Vec<(String, Vec<(f64, f64)>)>,
    /// Draw segments one by one (see [`draw`]).
    joinless: bool,
    x: Range<f64>,
    y: Range<f64>,
}

fn prepare(spec: &PlotSpec, series: &[Series]) -> Data {
    let ok = |v: f64, log: bool| v.is_finite() && (!log || v > 0.0);
    let curves: Vec<_> = series
        .iter()
        .map(|s| {
            let pts = s.points.iter().copied();
            let pts = pts.filter(|&(x, y)| ok(x, spec.log_x) && ok(y, spec.log_y));
            (label(&s.name), pts.collect::<Vec<_>>())
        })
        .collect();
    let all = || curves.iter().flat_map(|c| c.1.iter().copied());
    Data {
        x: nice_range(all().map(|p| p.0), spec.log_x),
        y: nice_range(all().map(|p| p.1), spec.log_y),
        curves,
        joinless: false,
    }
}

/// Text as one line without the control characters that XML refuses.
fn label(s: &str) -> String {
    s.chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect()
}

/// A range with round ends that covers `values`.
fn nice_range(values: impl Iterator<Item = f64>, log: bool) -> Range<f64> {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if log {
        let (lo, hi) = if lo > hi { (1.0, 10.0) } else { (lo, hi) };
        let a = lo.log10().floor().clamp(-300.0, 299.0);
        let b = hi.log10().ceil().clamp(a + 1.0, 300.0);
        // Nudged outwards so that rounding keeps both ends among the ticks.
        return 10f64.powf(a) * (1.0 - 1e-12)..10f64.powf(b) * (1.0 + 1e-12);
    }
    let (lo, hi) = match (lo.max(-f64::MAX / 4.0), hi.min(f64::MAX / 4.0)) {
        (lo, hi) if lo > hi => (0.0, 1.0),
        (v, _) if lo == hi => (v - v.abs().max(1e-300) * 0.1, v + v.abs().max(1e-300) * 0.1),
        r => r,
    };
    let rough = (hi - lo) / 8.0;
    let mag = 10f64.powf(rough.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * mag)
        .find(|&s| s >= rough)
        .unwrap_or(10.0 * mag);
    (lo / step).floor() * step..(hi / step).ceil() * step
}

/// A tick label: six significant digits at most, without trailing zeros, and in
/// scientific notation when very large or small.
fn tick(v: &f64) -> String {
    let v: f64 = format!("{v:.5e}").parse().unwrap_or(*v);
    if v != 0.0 && !(1e-4..1e6).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{}", v + 0.0)
    }
}

/// Registers the bundled font with plotters once per process.
fn register_font() -> Result<(), String> {
    static LOADED: OnceLock<bool> = OnceLock::new();
    let font = dejavu::sans::regular();
    let ok = LOADED
        .get_or_init(|| plotters::style::register_font(FONT, FontStyle::Normal, font).is_ok());
    ok.then_some(())
        .ok_or_else(|| "the bundled font does not load".into())
}

/// Draws the chart, choosing linear or logarithmic coordinates for each axis. With
/// `joinless`, each segment of a curve is drawn on its own: plotters' bitmap backend joins
/// thick lines with unlimited miters, which shoot out of the chart where a curve turns
/// back sharply (an SVG viewer limits miters itself, so the SVG keeps one polyline).
fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    spec: &PlotSpec,
    series: &[Series],
    joinless: bool,
) -> Result<(), String> {
    register_font()?;
    let mut data = prepare(spec, series);
    data.joinless = joinless;
    let (x, y) = (data.x.clone(), data.y.clone());
    match (spec.log_x, spec.log_y) {
        (false, false) => chart(root, spec, &data, x, y),
        (true, false) => chart(root, spec, &data, x.log_scale(), y),
        (false, true) => chart(root, spec, &data, x, y.log_scale()),
        (true, true) => chart(root, spec, &data, x.log_scale(), y.log_scale()),
    }
    .map_err(|e| e.to_string())
}

fn chart<DB, X, Y>(
    root: &DrawingArea<DB, Shift>,
    spec: &PlotSpec,
    data: &Data,
    x: X,
    y: Y,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend,
    X: AsRangedCoord<Value = f64>,
    Y: AsRangedCoord<Value = f64>,
    X::CoordDescType: ValueFormatter<f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    root.fill(&WHITE)?;
    let size = |s: f64| s * (spec.width.min(spec.height * 8 / 5) as f64 / 800.0).max(0.5);
    let text = |s: f64| (FONT, size(s)).into_font().color(&INK);
    // The legend goes right of the chart, as wide as its longest name.
    let legend_w = data
        .curves
        .iter()
        .map(|c| {
            root.estimate_text_size(&c.0, &text(14.0))
                .map_or(0, |s| s.0)
        })
        .max()
        .map_or(0, |w| (w as f64 + size(56.0)) as u32)
        .min(spec.width * 2 / 5);
    let (area, legend) = root.split_horizontally(spec.width - legend_w);
    let mut chart = ChartBuilder::on(&area)
        .caption(label(&spec.title), text(20.0))
        .margin(size(12.0) as u32)
        .x_label_area_size(size(40.0) as u32)
        .y_label_area_size(size(56.0) as u32)
        .build_cartesian_2d(x, y)?;
    let thin = size(1.0).round().max(1.0) as u32;
    chart
        .configure_mesh()
        .x_desc(label(&spec.x_label))
        .y_desc(label(&spec.y_label))
        .axis_desc_style(text(15.0))
        .label_style(text(13.0))
        .bold_line_style(GRID.stroke_width(thin))
        .light_line_style(MINOR_GRID.stroke_width(thin))
        .axis_style(INK.mix(0.7).stroke_width(thin))
        .set_all_tick_mark_size(size(5.0) as u32)
        .x_max_light_lines(if spec.log_x { 10 } else { 0 })
        .y_max_light_lines(if spec.log_y { 10 } else { 0 })
        .x_labels(10)
        .y_labels(10)
        .x_label_formatter(&tick)
        .y_label_formatter(&tick)
        .draw()?;
    let stroke = size(2.0).round().max(1.0) as u32;
    let dot = size(4.0).round().max(2.0) as i32;
    for (i, (_, pts)) in data.curves.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        // One point per device pixel: thousands of steps share each pixel of a log-time
        // axis, and what cannot be seen need not be drawn or written.
        let mut last_px = None;
        let kept: Vec<(f64, f64)> = pts
            .iter()
            .enumerate()
            .filter(|&(k, p)| {
                let px = chart.backend_coord(p);
                let keep = last_px != Some(px) || k + 1 == pts.len();
                last_px = Some(px);
                keep
            })
            .map(|(_, &p)| p)
            .collect();
        let style = color.stroke_width(stroke);
        if data.joinless {
            let segments = kept
                .windows(2)
                .map(|w| PathElement::new(vec![w[0], w[1]], style));
            chart.draw_series(segments)?;
        } else {
            chart.draw_series(LineSeries::new(kept, style))?;
        }
        // A dot on the last point, where the eye looks for the final value.
        let last = pts.last().map(|&p| Circle::new(p, dot, color.filled()));
        chart.draw_series(last)?;
    }
    let (x0, y0) = (size(8.0) as i32, chart.plotting_area().get_base_pixel().1);
    let row = size(22.0) as i32;
    for (i, (name, _)) in data.curves.iter().enumerate() {
        let color = PALETTE[i % PALETTE.len()];
        let y = y0 + row / 2 + row * i as i32;
        let (x1, x2) = (x0 + size(28.0) as i32, x0 + size(36.0) as i32);
        legend.draw(&PathElement::new(
            [(x0, y), (x1, y)],
            color.stroke_width(stroke),
        ))?;
        legend.draw(&Circle::new((x1, y), dot, color.filled()))?;
        let anchor = Pos::new(HPos::Left, VPos::Center);
        legend.draw(&Text::new(name.as_str(), (x2, y), text(14.0).pos(anchor)))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether the pixel at `(x, y)` is `color`, give or take the edge blending.
    fn is(img: &Image, x: u32, y: u32, color: RGBColor) -> bool {
        let p = img.get(x, y);
        let want = [color.0, color.1, color.2];
        (0..3)
            .map(|c| (p[c] * 255.0 - want[c] as f32).abs())
            .sum::<f32>()
            < 60.0
    }

    fn count(img: &Image, color: RGBColor) -> usize {
        (0..img.height)
            .flat_map(|y| (0..img.width).map(move |x| (x, y)))
            .filter(|&(x, y)| is(img, x, y, color))
            .count()
    }

    /// Curves shaped like the refinement report: PSNR climbing over a log time axis.
    pub(super) fn refine_like() -> Vec<Series> {
        let names = [
            "01-curves",
            "02-strokes",
            "03-linear-gradient",
            "04-radial-gradient",
            "05-translucent-overlap",
            "06-evenodd-star",
            "07-glyph",
            "08-dashes",
            "09-transforms",
            "10-logo",
            "11-landscape",
            "12-hairlines",
        ];
        names
            .iter()
            .enumerate()
            .map(|(i, n)| {
                let top = 20.0 + 4.5 * i as f64;
                let end = 2.0 + 0.8 * i as f64;
                let pts = (0..300)
                    .map(|k| {
                        let t = 0.005 * (end / 0.005f64).powf(k as f64 / 299.0);
                        let s = 1.0 / (1.0 + (-(t.ln() + 1.0 - 0.1 * i as f64) * 1.3).exp());
                        let wobble = 0.8 * ((k * (i + 3)) as f64 * 0.7).sin() * s;
                        (t, 13.0 + (top - 13.0 + 10.0 * (i % 3) as f64) * s + wobble)
                    })
                    .collect();
                Series::new(*n, pts)
            })
            .collect()
    }

    /// Regression: a run of thousands of steps packs many points into each pixel column of
    /// a log-time axis, and plotters' thick bitmap lines drew spikes out of the chart (to
    /// the top of the image) at the zero-length segments between them.
    #[test]
    fn dense_oscillating_series_stay_inside_the_chart() {
        let pts: Vec<(f64, f64)> = (0..4000)
            .map(|i| {
                let t = 1.0 + 4.0 * i as f64 / 4000.0;
                let y = 20.0 + 8.0 * ((i % 7) as f64 / 6.0) - if i % 50 == 0 { 9.0 } else { 0.0 };
                (t, y.min(30.0))
            })
            .collect();
        let spec = PlotSpec {
            log_x: true,
            ..PlotSpec::new("dense", "time (s)", "PSNR (dB)")
        };
        let img = plot_image(&spec, &[Series::new("a", pts)]).unwrap();
        // Rows above the chart's top edge (the title's band) hold no series color.
        for y in 0..30 {
            for x in 0..img.width {
                assert!(!is(&img, x, y, PALETTE[0]), "series color at ({x}, {y})");
            }
        }
    }

    #[test]
    fn png_has_the_size_and_shows_the_series_colors() {
        let spec = PlotSpec {
            width: 640,
            height: 400,
            ..PlotSpec::new("Two lines", "x", "y")
        };
        let series = [
            Series::new("rising", vec![(0.0, 0.0), (10.0, 10.0)]),
            Series::new("flat", vec![(0.0, 5.0), (10.0, 5.0)]),
        ];
        let img = plot_image(&spec, &series).unwrap();
        assert_eq!((img.width, img.height), (640, 400));
        // Not blank: text, axes and lines ink over 1 % of the pixels.
        let ink = img
            .data
            .iter()
            .filter(|p| p[..3].iter().any(|&c| c < 0.8))
            .count();
        assert!(ink > img.data.len() / 100, "{ink} inked pixels");
        img.save_png(std::env::temp_dir().join("diffsvg-plot-two-lines.png"))
            .unwrap();
        // Each series' color is drawn, and more of it than the legend alone would draw.
        for c in &PALETTE[..2] {
            assert!(count(&img, *c) > 300, "{c:?}: {}", count(&img, *c));
        }
        // The flat series at y = 5 crosses the middle of the plotting area: scanning down
        // the chart's middle column finds orange between the top and bottom quarters.
        let x = 640 * 2 / 5;
        let orange: Vec<u32> = (0..400).filter(|&y| is(&img, x, y, PALETTE[1])).collect();
        assert!(!orange.is_empty());
        assert!(
            orange.iter().all(|&y| (100..300).contains(&y)),
            "{orange:?}"
        );
        // The rising blue line is below the flat one left of the middle, above it right.
        let blue_at = |x: u32| (0..400).find(|&y| is(&img, x, y, PALETTE[0]));
        let (left, right) = (blue_at(640 / 6).unwrap(), blue_at(640 * 3 / 5).unwrap());
        assert!(
            left > orange[0] && right < orange[0],
            "{left} {right} {orange:?}"
        );
    }

    #[test]
    fn log_axes_skip_zero_negative_and_nan_points() {
        let spec = PlotSpec {
            log_x: true,
            log_y: true,
            ..PlotSpec::new("loss", "step", "loss")
        };
        let series = [Series::new(
            "loss",
            vec![
                (0.0, 1.0),
                (1.0, 0.5),
                (f64::NAN, 0.2),
                (10.0, 0.0),
                (100.0, -1.0),
                (1000.0, 0.01),
            ],
        )];
        let data = prepare(&spec, &series);
        assert_eq!(data.curves[0].1, vec![(1.0, 0.5), (1000.0, 0.01)]);
        let near = |r: &Range<f64>, a: f64, b: f64| {
            (r.start / a - 1.0).abs() < 1e-9 && (r.end / b - 1.0).abs() < 1e-9
        };
        assert!(
            near(&data.x, 1.0, 1000.0) && near(&data.y, 0.01, 1.0),
            "{:?} {:?}",
            data.x,
            data.y
        );
        let img = plot_image(&spec, &series).unwrap();
        assert!(count(&img, PALETTE[0]) > 100);
    }

    #[test]
    fn empty_and_degenerate_charts_do_not_panic() {
        let spec = PlotSpec::new("", "", "");
        let log = PlotSpec {
            log_x: true,
            log_y: true,
            ..spec.clone()
        };
        let cases: Vec<Vec<Series>> = vec![
            vec![],
            vec![Series::new("empty", vec![])],
            vec![Series::new("one", vec![(3.0, 30.0)])],
            vec![Series::new("nan", vec![(f64::NAN, f64::INFINITY)])],
            vec![Series::new(
                "huge",
                vec![(-f64::MAX, 0.0), (f64::MAX, 1e-300)],
            )],
            (0..40)
                .map(|i| Series::new("a long name ".repeat(i), vec![(i as f64, 1.0)]))
                .collect(),
        ];
        for s in &cases {
            for spec in [&spec, &log] {
                plot_image(spec, s).unwrap();
                plot_svg(spec, s).unwrap();
            }
        }
        let tiny = PlotSpec {
            width: 8,
            height: 8,
            ..spec.clone()
        };
        let _ = plot_image(&tiny, &cases[2]);
        assert_eq!(nice_range(std::iter::empty(), false), 0.0..1.0);
        let log = nice_range(std::iter::empty(), true);
        assert!((log.start - 1.0).abs() < 1e-9 && (log.end - 10.0).abs() < 1e-9);
        assert_eq!(nice_range([12.7, 71.2].into_iter(), false), 10.0..80.0);
        let one = nice_range([30.0].into_iter(), false);
        assert!(one.start < 30.0 && one.end > 30.0);
    }

    #[test]
    fn svg_parses_and_names_the_title() {
        let spec = PlotSpec {
            log_x: true,
            ..PlotSpec::new("Refining <perturbed> & samples", "time (s)", "PSNR (dB)")
        };
        let series = [Series::new("a\u{1}b", vec![(0.01, 10.0), (1.0, 40.0)])];
        let svg = plot_svg(&spec, &series).unwrap();
        let tree = usvg::Tree::from_str(&svg, &usvg::Options::default()).unwrap();
        assert_eq!((tree.size().width(), tree.size().height()), (800.0, 500.0));
        assert!(svg.contains("<title>Refining &lt;perturbed&gt; &amp; samples</title>"));
        assert!(svg.contains(">\nRefining &lt;perturbed&gt; &amp; samples\n</text>"));
        assert!(svg.contains("time (s)") && svg.contains("PSNR (dB)") && svg.contains("a b"));
    }

    #[test]
    fn write_plot_writes_both_files() {
        let dir = std::env::temp_dir().join(format!("diffsvg-plot-{}", std::process::id()));
        let (png, svg) = (dir.join("p.png"), dir.join("p.svg"));
        let spec = PlotSpec {
            log_x: true,
            ..PlotSpec::new("Refining perturbed samples", "time (s)", "PSNR (dB)")
        };
        write_plot(&spec, &refine_like(), &png, &svg).unwrap();
        let img = Image::load(&png).unwrap();
        assert_eq!((img.width, img.height), (800, 500));
        assert!(std::fs::read_to_string(&svg).unwrap().starts_with("<svg"));
        let zero = PlotSpec { width: 0, ..spec };
        assert!(write_plot(&zero, &[], dir.join("z.png"), dir.join("z.svg")).is_err());
        assert!(!dir.join("z.png").exists() && !dir.join("z.svg").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Writes sample charts for eyes into the folder named by `DIFFSVG_PLOT_SAMPLE`.
    #[test]
    fn samples() {
        let Some(out) = std::env::var_os("DIFFSVG_PLOT_SAMPLE") else {
            return;
        };
        let out = Path::new(&out);
        let spec = PlotSpec {
            log_x: true,
            ..PlotSpec::new("Refining perturbed samples", "time (s)", "PSNR (dB)")
        };
        let (png, svg) = (out.join("refine-like.png"), out.join("refine-like.svg"));
        write_plot(&spec, &refine_like(), png, svg).unwrap();
        let curve = |a: f64, b: f64, n: usize, noise: f64| -> Vec<(f64, f64)> {
            (1..=n)
                .map(|k| {
                    let t = 490.0 * k as f64 / n as f64;
                    (
                        t,
                        a + b * (1.0 - (-t / 150.0).exp()) + noise * (k as f64 * 2.3).sin(),
                    )
                })
                .collect()
        };
        let series = [
            Series::new("test views", curve(24.0, 6.5, 12, 0.0)),
            Series::new("training batches", curve(23.0, 10.0, 60, 0.5)),
        ];
        let spec = PlotSpec::new(
            "lego: PSNR against training time",
            "training seconds",
            "PSNR (dB)",
        );
        write_plot(
            &spec,
            &series,
            out.join("lego-like.png"),
            out.join("lego-like.svg"),
        )
        .unwrap();
    }
}
