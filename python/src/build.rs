//! Building scenes in code: paints and paths from Python values (`Scene.add_*`).

use diffsvg::scene::{
    Fill, FillRule, Gradient, GradientKind, Node, Paint, Path, Primitive, Spread, Stop, Stroke,
};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::error::bad;

/// Largest coordinate a shape built in code may have (the primitives' projection bound).
const BOUND: f64 = diffsvg::limits::MAX_COORDINATE / 8.0;

fn finite(v: f64, what: &str) -> PyResult<f64> {
    if v.abs() <= BOUND {
        Ok(v)
    } else {
        Err(bad(format!(
            "{what}: {v} is not a finite number within ±{BOUND:e}"
        )))
    }
}

fn unit(v: f64, what: &str) -> PyResult<f64> {
    if (0.0..=1.0).contains(&v) {
        Ok(v)
    } else {
        Err(bad(format!("{what}: {v} must be in [0, 1]")))
    }
}

/// A paint and its opacity from Python: straight `(r, g, b, opacity)` in `[0, 1]`, or a
/// dict `{"kind": "linear"|"radial", "geometry": [x1, y1, x2, y2] | [cx, cy, r, fx, fy,
/// fr], "stops": [[offset, r, g, b, opacity], …], "opacity": 1.0}` in device pixels.
pub(crate) fn paint_in(v: &Bound<'_, PyAny>, what: &str) -> PyResult<(Paint, f64)> {
    if let Ok(d) = v.cast::<PyDict>() {
        for k in d.keys() {
            let k: String = k.extract()?;
            if !["kind", "geometry", "stops", "opacity", "spread"].contains(&k.as_str()) {
                return Err(bad(format!(
                    "{what}: unknown key {k:?}; expected kind, geometry, stops, opacity, spread"
                )));
            }
        }
        let get = |k: &str| -> PyResult<Bound<'_, PyAny>> {
            d.get_item(k)?
                .ok_or_else(|| bad(format!("{what}: the gradient needs {k:?}")))
        };
        let kind: String = get("kind")?.extract()?;
        let geo: Vec<f64> = get("geometry")?.extract()?;
        for g in &geo {
            finite(*g, what)?;
        }
        let kind = match (kind.as_str(), geo.len()) {
            ("linear", 4) => GradientKind::Linear {
                p1: [geo[0], geo[1]],
                p2: [geo[2], geo[3]],
            },
            ("radial", 6) if geo[2] >= 0.0 && geo[5] >= 0.0 => GradientKind::Radial {
                c: [geo[0], geo[1]],
                r: geo[2],
                f: [geo[3], geo[4]],
                fr: geo[5],
            },
            _ => {
                return Err(bad(format!(
                    "{what}: kind {kind:?} with {} geometry values; expected \"linear\" with \
                     x1, y1, x2, y2 or \"radial\" with cx, cy, r, fx, fy, fr (radii ≥ 0)",
                    geo.len()
                )));
            }
        };
        let rows: Vec<Vec<f64>> = get("stops")?.extract()?;
        if rows.is_empty() || rows.len() > 1024 {
            return Err(bad(format!("{what}: 1 to 1024 stops, got {}", rows.len())));
        }
        let mut stops = Vec::new();
        let mut last = 0.0;
        for row in &rows {
            let [offset, r, g, b, a] = row[..] else {
                return Err(bad(format!(
                    "{what}: a stop is [offset, r, g, b, opacity], got {row:?}"
                )));
            };
            for x in [offset, r, g, b, a] {
                unit(x, what)?;
            }
            if offset < last {
                return Err(bad(format!("{what}: stop offsets must not decrease")));
            }
            last = offset;
            stops.push(Stop {
                offset,
                color: [r, g, b],
                opacity: a,
            });
        }
        let spread = match d.get_item("spread")? {
            None => Spread::Pad,
            Some(s) => match s.extract::<String>()?.as_str() {
                "pad" => Spread::Pad,
                "reflect" => Spread::Reflect,
                "repeat" => Spread::Repeat,
                other => return Err(bad(format!("{what}: spread {other:?}"))),
            },
        };
        let opacity = match d.get_item("opacity")? {
            Some(o) => unit(o.extract()?, what)?,
            None => 1.0,
        };
        let g = Gradient {
            id: String::new(),
            kind,
            transform: [1.0, 0.0, 0.0, 1.0, 0.0, 0.0],
            spread,
            stops,
        };
        return Ok((Paint::Gradient(g), opacity));
    }
    let c: Vec<f64> = v
        .extract()
        .map_err(|_| bad(format!("{what}: expected (r, g, b, a) or a gradient dict")))?;
    let [r, g, b, a] = c[..] else {
        return Err(bad(format!("{what}: expected 4 values, got {}", c.len())));
    };
    for x in [r, g, b, a] {
        unit(x, what)?;
    }
    Ok((Paint::Solid([r, g, b]), a))
}

/// Gives `path` its fill and stroke; one of them at least.
pub(crate) fn paint_path(
    mut path: Path,
    fill: Option<&Bound<'_, PyAny>>,
    stroke: Option<&Bound<'_, PyAny>>,
    stroke_width: f64,
    evenodd: bool,
) -> PyResult<Node> {
    if !(stroke_width.is_finite() && (0.0..=BOUND).contains(&stroke_width)) {
        return Err(bad(format!("stroke_width {stroke_width} must be ≥ 0")));
    }
    if let Some(f) = fill.filter(|f| !f.is_none()) {
        let (paint, opacity) = paint_in(f, "fill")?;
        path.fill = Some(Fill {
            paint,
            opacity,
            rule: if evenodd {
                FillRule::EvenOdd
            } else {
                FillRule::NonZero
            },
        });
    }
    if let Some(s) = stroke.filter(|s| !s.is_none()) {
        let (paint, opacity) = paint_in(s, "stroke")?;
        let mut st = Stroke::new(paint, stroke_width);
        st.opacity = opacity;
        path.stroke = Some(st);
    }
    if path.fill.is_none() && path.stroke.is_none() {
        return Err(bad("give a fill, a stroke or both"));
    }
    Ok(Node::Path(path))
}

/// A circle, ellipse or rectangle from its values in slot order.
pub(crate) fn primitive(kind: &str, values: &[f64]) -> PyResult<Primitive> {
    let want = match (kind, values.len()) {
        ("circle", 3) | ("ellipse", 5) | ("rect", 5) | ("rect", 7) => values.len(),
        ("circle", _) => 3,
        ("ellipse", _) => 5,
        ("rect", _) => 5,
        _ => {
            return Err(bad(format!(
                "add_shape: unknown kind {kind:?}; expected \"circle\", \"ellipse\" or \"rect\""
            )));
        }
    };
    if values.len() != want {
        return Err(bad(format!(
            "add_shape: a {kind} takes {want} values{}, got {}",
            if kind == "rect" {
                " (or 7 with corner radii)"
            } else {
                ""
            },
            values.len()
        )));
    }
    for v in values {
        finite(*v, "add_shape")?;
    }
    let v = values;
    let sizes = if kind == "circle" {
        2..3
    } else {
        2..v.len() - 1
    };
    if v[sizes].iter().any(|x| *x < 0.0) {
        return Err(bad(format!(
            "add_shape: a {kind}'s sizes must be ≥ 0, got {v:?}"
        )));
    }
    Ok(match kind {
        "circle" => Primitive::circle([v[0], v[1]], v[2]),
        "ellipse" => Primitive::ellipse([v[0], v[1]], v[2], v[3], v[4]),
        _ if v.len() == 7 => Primitive::rect(v[0], v[1], v[2], v[3], Some([v[4], v[5]]), v[6]),
        _ => Primitive::rect(v[0], v[1], v[2], v[3], None, v[4]),
    })
}

/// A path of cubic segments: `segments[k]` cubics in subpath `k` (`1 + 3·segments[k]`
/// points, start first), closed where `closed[k]`.
pub(crate) fn cubic_path(
    points: &[[f64; 2]],
    segments: &[usize],
    closed: &[bool],
    id: String,
) -> PyResult<Path> {
    if segments.len() != closed.len() || segments.is_empty() {
        return Err(bad(format!(
            "add_path: {} segment counts and {} closed flags; give one of each per subpath",
            segments.len(),
            closed.len()
        )));
    }
    let want: usize = segments.iter().map(|n| 1 + 3 * n).sum();
    if points.len() != want {
        return Err(bad(format!(
            "add_path: {} points for {segments:?} cubic segments; expected {want} \
             (a start, then 3 per segment, per subpath)",
            points.len()
        )));
    }
    for p in points {
        finite(p[0], "add_path")?;
        finite(p[1], "add_path")?;
    }
    let mut path = Path::new(id);
    let mut at = 0;
    for (&n, &c) in segments.iter().zip(closed) {
        path.move_to(points[at]);
        for k in 0..n {
            let q = &points[at + 1 + 3 * k..at + 4 + 3 * k];
            path.cubic_to(q[0], q[1], q[2]);
        }
        if c {
            path.close();
        }
        at += 1 + 3 * n;
    }
    Ok(path)
}
