//! Glyph fitting: closed filled cubic curves with as few segments as an IoU goal needs.
//!
//! The target is a picture of ink (dark on light; transparent pixels count as paper). Its
//! ink coverage `1 − mean(R, G, B)` over white is traced at the level ½ with marching
//! squares (sub-pixel, by linear interpolation between pixel centers), which gives closed
//! contours oriented with the ink on their right (on screen, y down): outer boundaries run
//! clockwise, holes counter-clockwise, so one black path with the **nonzero** rule (or
//! even-odd) draws them all.
//!
//! Each contour starts with few cubic segments: joints at the corners of the traced
//! boundary (where it turns by more than [`GlyphOptions::corner_degrees`] within
//! `CORNER_REACH` pixels either side), at least [`GlyphOptions::initial_segments`]
//! stretches spread evenly by arc length between them, and each stretch fitted by
//! Schneider's method (handles along the boundary's tangents, lengths by least squares)
//! and split at its worst point while it strays more than
//! [`GlyphOptions::init_tolerance`] (3 px: deliberately loose, so that the start has
//! fewer segments than the goal needs). Then:
//!
//! 1. **Refine.** [`refine`] moves every control point (Adam, cosine schedule, exact
//!    gradients of the MSE between the path's coverage and the ink; the color stays
//!    black). Every `CHECK_EVERY` steps the **IoU** of the inked areas (coverage ≥ ½ in
//!    both) is measured, on the coordinates as the SVG file will hold them, and the round
//!    stops as soon as it reaches the goal.
//! 2. **Grow.** Short of the goal, each pixel's squared coverage error is charged to the
//!    nearest of 16 points on every segment; the contour charged most gets one segment
//!    more, by splitting its most-charged segment exactly (de Casteljau) where the charge
//!    peaks, and is refined again; until the goal or [`GlyphOptions::max_segments`].
//! 3. **Shrink.** At the goal, the joint whose two segments one least-squares cubic
//!    replaces best is removed and the fit refined again; kept if it still reaches the
//!    goal, else the next joint is tried, until [`GlyphOptions::merge_failures`] tries in
//!    a row fail.
//!
//! The count found is the fewest this greedy search reaches, not a proven minimum.
//! Everything is deterministic: the same target and options give the same bits.
//!
//! ```
//! use diffsvg::fit::glyph::{GlyphOptions, fit_glyph};
//! use diffsvg::{Scene, Sizing, raster};
//! let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="40">
//!   <rect width="40" height="40" fill="white"/><circle cx="20" cy="20" r="12"/></svg>"#;
//! let img = raster::render(&Scene::from_svg_str(svg, "o.svg", Sizing::Natural)?, &Default::default());
//! let out = fit_glyph(&img, &GlyphOptions::default());
//! assert!(out.reached && out.iou >= 0.99);
//! assert!(out.segments <= 8, "{} segments for a disc", out.segments);
//! # Ok::<(), diffsvg::Error>(())
//! ```

use std::time::{Duration, Instant};

use super::refine::{Control, FitOptions, refine};
use super::{LearningRates, Objective};
use crate::image_io::Image;
use crate::loss::Loss;
use crate::metrics::iou;
use crate::optim::Schedule;
use crate::raster::{RenderOptions, render};
use crate::scene::geom::{Cubic, dist, eval, lerp, split, sub};
use crate::scene::{Fill, FillRule, Node, Paint, Path, Point, Scene, SegmentKind};

/// Settings of a glyph fit.
#[derive(Clone, Debug)]
pub struct GlyphOptions {
    /// Stop once the IoU of the inked areas reaches this.
    pub iou_goal: f64,
    /// Most cubic segments in all (contours never get fewer than one each, nor fewer than
    /// their corners).
    pub max_segments: usize,
    /// Fewest segments a contour starts with.
    pub initial_segments: usize,
    /// A boundary point is a corner when the boundary turns by more than this many
    /// degrees within `CORNER_REACH` pixels on either side.
    pub corner_degrees: f64,
    /// Largest distance, pixels, of the initial cubics from the traced boundary: a
    /// stretch that does not fit within it is split at its worst point.
    pub init_tolerance: f64,
    /// Optimizer steps per round (after the start and after each added segment); a round
    /// stops early once the goal is reached.
    pub iters: usize,
    /// Once the goal is reached, joints are removed one at a time (the one whose two
    /// segments one cubic replaces best first) and the fit refined again, kept when it
    /// still reaches the goal; the search stops after this many merges in a row fail (0:
    /// no merging).
    pub merge_failures: usize,
    /// Learning rate of the control points, pixels per step (cosine schedule per round).
    pub lr: f64,
    /// Fill rule of the fitted path.
    pub rule: FillRule,
    /// Rasterizer settings.
    pub render: RenderOptions,
}

impl Default for GlyphOptions {
    fn default() -> Self {
        GlyphOptions {
            iou_goal: 0.99,
            max_segments: 64,
            initial_segments: 2,
            corner_degrees: 40.0,
            init_tolerance: 3.0,
            iters: 150,
            merge_failures: 3,
            lr: 0.3,
            rule: FillRule::NonZero,
            render: RenderOptions::default(),
        }
    }
}

/// What a glyph fit produced.
#[derive(Clone, Debug)]
pub struct GlyphOutcome {
    /// The fitted scene: one black path, one closed cubic subpath per contour, on no
    /// background (composite it over white to compare with the target).
    pub scene: Scene,
    /// Cubic segments in all.
    pub segments: usize,
    /// Cubic segments per contour, in the order of [`GlyphOutcome::holes`].
    pub per_contour: Vec<usize>,
    /// Whether each contour is a hole (traced counter-clockwise on screen).
    pub holes: Vec<bool>,
    /// IoU of the inked areas (coverage ≥ ½) of fit and target.
    pub iou: f64,
    /// Mean squared error of the fit over white against the target's ink over white
    /// (RGB, values in `[0, 1]`).
    pub mse: f64,
    /// Whether the IoU goal was reached.
    pub reached: bool,
    /// Refinement rounds run.
    pub rounds: usize,
    /// Optimizer steps in all.
    pub steps: usize,
    /// Wall time.
    pub elapsed: Duration,
}

/// A closed polyline traced from a picture, device pixels, y down.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Contour {
    /// The vertices; the last connects back to the first.
    pub(crate) points: Vec<Point>,
    /// Whether the contour bounds a hole (it runs counter-clockwise on screen; outer
    /// boundaries run clockwise).
    pub(crate) hole: bool,
}

#[cfg(test)]
impl Contour {
    /// Signed area (shoelace, y down): positive for outer boundaries, negative for holes.
    pub(crate) fn area(&self) -> f64 {
        signed_area(&self.points)
    }
}

/// How far either side of a boundary point its turning angle is measured, pixels.
pub(crate) const CORNER_REACH: f64 = 2.5;

/// Contours smaller than this many square pixels are dropped as specks.
const MIN_AREA: f64 = 2.0;

/// Ink coverage of every pixel of `img` (premultiplied, row-major): `1 − mean(R, G, B)` of
/// the image composited over white, in `[0, 1]`.
pub(crate) fn ink(img: &Image) -> Vec<f32> {
    img.data
        .iter()
        .map(|p| {
            let t = 1.0 - p[3];
            let light = (p[0] + p[1] + p[2] + 3.0 * t) / 3.0;
            (1.0 - light).clamp(0.0, 1.0)
        })
        .collect()
}

/// Traces the boundaries where `values` (`width × height`, row-major, one per pixel
/// center) crosses `level`, by marching squares: the crossing points lie on the segments
/// between neighboring pixel centers, placed by linear interpolation. Outside the image
/// counts as below the level, so every contour is closed. Contours run with the side at
/// or above the level on their right (on screen): outer boundaries clockwise, holes
/// counter-clockwise. Saddles are resolved by the mean of the four corners. Contours
/// enclosing less than 2 px² are dropped. Order: by the first crossing in row-major
/// scan order, deterministic.
pub(crate) fn trace_contours(
    values: &[f32],
    width: usize,
    height: usize,
    level: f32,
) -> Vec<Contour> {
    assert_eq!(
        values.len(),
        width * height,
        "values must be width × height"
    );
    // Padded grid: sample (i, j) is pixel (i − 1, j − 1), center (i − ½, j − ½).
    let (gw, gh) = (width + 2, height + 2);
    let v = |i: usize, j: usize| -> f32 {
        if i == 0 || j == 0 || i > width || j > height {
            0.0
        } else {
            values[(j - 1) * width + (i - 1)]
        }
    };
    let inside = |i: usize, j: usize| v(i, j) >= level;
    // Edge ids: horizontal edge from sample (i, j) to (i + 1, j) is 2(jW + i), vertical
    // edge from (i, j) to (i, j + 1) is 2(jW + i) + 1.
    let h_edge = |i: usize, j: usize| 2 * (j * gw + i);
    let v_edge = |i: usize, j: usize| 2 * (j * gw + i) + 1;
    let crossing = |e: usize| -> Point {
        let (k, horizontal) = (e / 2, e & 1 == 0);
        let (i, j) = (k % gw, k / gw);
        let (a, b) = if horizontal {
            (v(i, j), v(i + 1, j))
        } else {
            (v(i, j), v(i, j + 1))
        };
        let t = if a == b {
            0.5
        } else {
            ((level - a) / (b - a)).clamp(0.0, 1.0) as f64
        };
        if horizontal {
            [i as f64 + t - 0.5, j as f64 - 0.5]
        } else {
            [i as f64 - 0.5, j as f64 + t - 0.5]
        }
    };
    let mut next = vec![usize::MAX; 2 * gw * gh];
    for j in 0..gh - 1 {
        for i in 0..gw - 1 {
            // Corners a (top left), b (top right), c (bottom right), d (bottom left).
            let corners = [(i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)];
            let ins = corners.map(|(x, y)| inside(x, y));
            let n_in = ins.iter().filter(|&&x| x).count();
            if n_in == 0 || n_in == 4 {
                continue;
            }
            // Cell edges: top (a–b), right (b–c), bottom (d–c), left (a–d), and the
            // midpoints used to orient segments (cell coordinates, y down).
            let edges = [
                h_edge(i, j),
                v_edge(i + 1, j),
                h_edge(i, j + 1),
                v_edge(i, j),
            ];
            let mids: [Point; 4] = [[0.5, 0.0], [1.0, 0.5], [0.5, 1.0], [0.0, 0.5]];
            let pos: [Point; 4] = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
            // Edge k joins corners k and k + 1.
            let crosses: Vec<usize> = (0..4).filter(|&k| ins[k] != ins[(k + 1) % 4]).collect();
            let mut link = |e0: usize, e1: usize, corner: usize| {
                // Orient e0 → e1 so that `corner` is on the right if inside, left if not.
                let (p, q, x) = (mids[e0], mids[e1], pos[corner]);
                let cross = (q[0] - p[0]) * (x[1] - p[1]) - (q[1] - p[1]) * (x[0] - p[0]);
                let right = cross > 0.0;
                let (from, to) = if right == ins[corner] {
                    (e0, e1)
                } else {
                    (e1, e0)
                };
                next[edges[from]] = edges[to];
            };
            if crosses.len() == 2 {
                let corner = (0..4).find(|&k| ins[k]).expect("some corner is inside");
                link(crosses[0], crosses[1], corner);
            } else {
                // Saddle: a and c on one side, b and d on the other.
                let mean = corners.iter().map(|&(x, y)| v(x, y)).sum::<f32>() / 4.0;
                let center_in = mean >= level;
                // Cut off the corners on the other side than the center: corner k lies
                // between edges k − 1 and k.
                for (k, &is_in) in ins.iter().enumerate() {
                    if is_in != center_in {
                        link((k + 3) % 4, k, k);
                    }
                }
            }
        }
    }
    let mut out = Vec::new();
    let mut seen = vec![false; next.len()];
    for start in 0..next.len() {
        if next[start] == usize::MAX || seen[start] {
            continue;
        }
        let mut pts = Vec::new();
        let mut e = start;
        while !seen[e] {
            seen[e] = true;
            pts.push(crossing(e));
            e = next[e];
            debug_assert!(e != usize::MAX, "marching-squares contours are closed");
            if e == usize::MAX {
                break;
            }
        }
        dedup(&mut pts);
        let area = signed_area(&pts);
        if pts.len() >= 3 && area.abs() >= MIN_AREA {
            out.push(Contour {
                points: pts,
                hole: area < 0.0,
            });
        }
    }
    out
}

/// Drops consecutive (and closing) repeated points.
fn dedup(pts: &mut Vec<Point>) {
    pts.dedup_by(|a, b| (a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9);
    while pts.len() > 1 {
        let (f, l) = (pts[0], pts[pts.len() - 1]);
        if (f[0] - l[0]).abs() < 1e-9 && (f[1] - l[1]).abs() < 1e-9 {
            pts.pop();
        } else {
            break;
        }
    }
}

/// Shoelace area of a closed polyline, y down: positive when clockwise on screen.
fn signed_area(pts: &[Point]) -> f64 {
    let n = pts.len();
    let mut a = 0.0;
    for k in 0..n {
        let (p, q) = (pts[k], pts[(k + 1) % n]);
        a += p[0] * q[1] - q[0] * p[1];
    }
    0.5 * a
}

/// Cumulative arc length of a closed polyline: `s[k]` up to vertex `k`, `s[n]` the whole.
fn arc_lengths(pts: &[Point]) -> Vec<f64> {
    let n = pts.len();
    let mut s = Vec::with_capacity(n + 1);
    s.push(0.0);
    for k in 0..n {
        let d = dist(pts[k], pts[(k + 1) % n]);
        s.push(s[k] + d);
    }
    s
}

/// The point at arc length `at` (wrapped) of a closed polyline with lengths `s`.
fn point_at(pts: &[Point], s: &[f64], at: f64) -> Point {
    let total = s[pts.len()];
    let at = at.rem_euclid(total.max(1e-12));
    let k = s.partition_point(|&x| x <= at).clamp(1, pts.len()) - 1;
    let seg = s[k + 1] - s[k];
    let t = if seg > 0.0 { (at - s[k]) / seg } else { 0.0 };
    lerp(pts[k], pts[(k + 1) % pts.len()], t)
}

/// Vertices where the boundary turns by more than `degrees` within `reach` on either side
/// (local maxima of the turn, at least `reach` apart), sorted.
fn corners(pts: &[Point], degrees: f64, reach: f64) -> Vec<usize> {
    let n = pts.len();
    let s = arc_lengths(pts);
    let total = s[n];
    let reach = reach.min(total / 8.0);
    if n < 8 || reach <= 0.0 {
        return Vec::new();
    }
    let turn: Vec<f64> = (0..n)
        .map(|k| {
            let p = pts[k];
            let a = sub(p, point_at(pts, &s, s[k] - reach));
            let b = sub(point_at(pts, &s, s[k] + reach), p);
            let cross = a[0] * b[1] - a[1] * b[0];
            let dot = a[0] * b[0] + a[1] * b[1];
            cross.atan2(dot).abs()
        })
        .collect();
    let limit = degrees.to_radians();
    let mut out = Vec::new();
    for k in 0..n {
        if turn[k] <= limit {
            continue;
        }
        // A local maximum within `reach` (ties go to the first).
        let mut best = true;
        for (j, &tj) in turn.iter().enumerate() {
            if j == k {
                continue;
            }
            let d = (s[j] - s[k]).abs();
            let d = d.min(total - d);
            if d <= reach && (tj > turn[k] || (tj == turn[k] && j < k)) {
                best = false;
                break;
            }
        }
        if best {
            out.push(k);
        }
    }
    out
}

/// Reparametrization passes of the least-squares fits.
const NEWTON_PASSES: usize = 8;

/// Newton step of each parameter `u[k]` toward the point of `c` nearest `samples[k]`.
fn reparametrize(c: &Cubic, u: &mut [f64], samples: &[Point]) {
    for (t, q) in u.iter_mut().zip(samples) {
        let s = 1.0 - *t;
        let p = eval(c, *t);
        let d1: Point = [0, 1].map(|d| {
            3.0 * (s * s * (c[1][d] - c[0][d])
                + 2.0 * s * *t * (c[2][d] - c[1][d])
                + *t * *t * (c[3][d] - c[2][d]))
        });
        let d2: Point = [0, 1].map(|d| {
            6.0 * (s * (c[2][d] - 2.0 * c[1][d] + c[0][d])
                + *t * (c[3][d] - 2.0 * c[2][d] + c[1][d]))
        });
        let e = sub(p, *q);
        let num = e[0] * d1[0] + e[1] * d1[1];
        let den = d1[0] * d1[0] + d1[1] * d1[1] + e[0] * d2[0] + e[1] * d2[1];
        if den.abs() > 1e-12 {
            *t = (*t - num / den).clamp(0.0, 1.0);
        }
    }
}

/// Chord-length parameters in `[0, 1]` of `samples` on the polyline `p0, samples…, p3`;
/// `None` when it has no length.
fn chord_params(p0: Point, p3: Point, samples: &[Point]) -> Option<Vec<f64>> {
    let mut u = Vec::with_capacity(samples.len());
    let mut acc = 0.0;
    let mut prev = p0;
    for &q in samples {
        acc += dist(prev, q);
        u.push(acc);
        prev = q;
    }
    let total = acc + dist(prev, p3);
    if total <= 1e-9 {
        return None;
    }
    u.iter_mut().for_each(|x| *x /= total);
    Some(u)
}

/// Least-squares cubic from `p0` to `p3` through `samples` (in order, end points left
/// out), all four points free but the ends; chord-length parameters improved by Newton
/// passes. A straight cubic when there is too little to fit.
pub(crate) fn fit_cubic(p0: Point, p3: Point, samples: &[Point]) -> Cubic {
    let line = [p0, lerp(p0, p3, 1.0 / 3.0), lerp(p0, p3, 2.0 / 3.0), p3];
    if samples.len() < 2 {
        return line;
    }
    let Some(mut u) = chord_params(p0, p3, samples) else {
        return line;
    };
    let mut c = line;
    for pass in 0..=NEWTON_PASSES {
        let (mut a11, mut a12, mut a22) = (0.0, 0.0, 0.0);
        let (mut r1, mut r2) = ([0.0; 2], [0.0; 2]);
        for (&t, q) in u.iter().zip(samples) {
            let s = 1.0 - t;
            let (b0, b1, b2, b3) = (s * s * s, 3.0 * s * s * t, 3.0 * s * t * t, t * t * t);
            a11 += b1 * b1;
            a12 += b1 * b2;
            a22 += b2 * b2;
            for d in 0..2 {
                let r = q[d] - b0 * p0[d] - b3 * p3[d];
                r1[d] += b1 * r;
                r2[d] += b2 * r;
            }
        }
        let det = a11 * a22 - a12 * a12;
        if det.abs() < 1e-12 * (a11 * a22).max(1e-300) || !det.is_finite() {
            return if pass == 0 { line } else { c };
        }
        let c1 = [0, 1].map(|d| (a22 * r1[d] - a12 * r2[d]) / det);
        let c2 = [0, 1].map(|d| (a11 * r2[d] - a12 * r1[d]) / det);
        c = [p0, c1, c2, p3];
        if pass < NEWTON_PASSES {
            reparametrize(&c, &mut u, samples);
        }
    }
    c
}

/// Schneider's fit: the cubic from `p0` leaving along the unit tangent `t0` to `p3`
/// arriving along `t3` (pointing forward), handle lengths by least squares through
/// `samples` (end points left out), parameters improved by Newton passes. Handles that
/// come out negative, tiny or longer than twice the chord fall back to a third of the
/// chord. Returns the cubic and the largest distance of a sample from it, with the index
/// of that sample.
fn fit_tangent_cubic(
    p0: Point,
    t0: Point,
    p3: Point,
    t3: Point,
    samples: &[Point],
) -> (Cubic, f64, usize) {
    let chord = dist(p0, p3);
    let with = |a1: f64, a2: f64| -> Cubic {
        [
            p0,
            [p0[0] + a1 * t0[0], p0[1] + a1 * t0[1]],
            [p3[0] - a2 * t3[0], p3[1] - a2 * t3[1]],
            p3,
        ]
    };
    let fallback = with(chord / 3.0, chord / 3.0);
    let Some(mut u) = chord_params(p0, p3, samples).filter(|_| samples.len() >= 2) else {
        let err = samples
            .iter()
            .map(|q| nearest(&fallback, *q))
            .fold(0.0, f64::max);
        return (fallback, err, 0);
    };
    let mut c = fallback;
    for pass in 0..=NEWTON_PASSES {
        let (mut c11, mut c12, mut c22, mut x1, mut x2) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (&t, q) in u.iter().zip(samples) {
            let s = 1.0 - t;
            let (b0, b1, b2, b3) = (s * s * s, 3.0 * s * s * t, 3.0 * s * t * t, t * t * t);
            // B(t) = (b0 + b1) p0 + (b2 + b3) p3 + a1 b1 t0 − a2 b2 t3.
            let a1 = [b1 * t0[0], b1 * t0[1]];
            let a2 = [-b2 * t3[0], -b2 * t3[1]];
            let r = [
                q[0] - (b0 + b1) * p0[0] - (b2 + b3) * p3[0],
                q[1] - (b0 + b1) * p0[1] - (b2 + b3) * p3[1],
            ];
            c11 += a1[0] * a1[0] + a1[1] * a1[1];
            c12 += a1[0] * a2[0] + a1[1] * a2[1];
            c22 += a2[0] * a2[0] + a2[1] * a2[1];
            x1 += a1[0] * r[0] + a1[1] * r[1];
            x2 += a2[0] * r[0] + a2[1] * r[1];
        }
        let det = c11 * c22 - c12 * c12;
        let (mut h1, mut h2) = if det.abs() > 1e-12 * (c11 * c22).max(1e-300) {
            ((x1 * c22 - x2 * c12) / det, (c11 * x2 - c12 * x1) / det)
        } else {
            (chord / 3.0, chord / 3.0)
        };
        let ok = |h: f64| h.is_finite() && h > 1e-3 * chord && h < 2.0 * chord;
        if !ok(h1) || !ok(h2) {
            h1 = chord / 3.0;
            h2 = chord / 3.0;
        }
        c = with(h1, h2);
        if pass < NEWTON_PASSES {
            reparametrize(&c, &mut u, samples);
        }
    }
    let mut worst = (0.0, 0usize);
    for (k, (&t, q)) in u.iter().zip(samples).enumerate() {
        // The parameter found, and a check against the whole curve.
        let d = dist(eval(&c, t), *q).min(nearest(&c, *q));
        if d > worst.0 {
            worst = (d, k);
        }
    }
    (c, worst.0, worst.1)
}

/// Distance from `q` to the nearest of 64 points along `c`.
fn nearest(c: &Cubic, q: Point) -> f64 {
    (0..=64)
        .map(|k| dist(eval(c, k as f64 / 64.0), q))
        .fold(f64::INFINITY, f64::min)
}

fn unit(v: Point) -> Point {
    let n = v[0].hypot(v[1]);
    if n > 0.0 {
        [v[0] / n, v[1] / n]
    } else {
        [1.0, 0.0]
    }
}

/// A traced contour with its arc lengths, for the initial fit.
struct Trace<'a> {
    pts: &'a [Point],
    s: Vec<f64>,
    total: f64,
}

impl Trace<'_> {
    fn at(&self, arc: f64) -> Point {
        point_at(self.pts, &self.s, arc)
    }

    /// Unit tangent at `arc` looking `reach` back (`back`) and/or ahead (`ahead`).
    fn tangent(&self, arc: f64, back: bool, ahead: bool, reach: f64) -> Point {
        let a = if back {
            self.at(arc - reach)
        } else {
            self.at(arc)
        };
        let b = if ahead {
            self.at(arc + reach)
        } else {
            self.at(arc)
        };
        unit(sub(b, a))
    }

    /// Vertices whose unwrapped arc length lies strictly inside `(from, to)`, with it.
    fn inside(&self, from: f64, to: f64) -> Vec<(f64, Point)> {
        let n = self.pts.len();
        let mut out = Vec::new();
        let lap0 = (from / self.total).floor() as i64;
        for lap in lap0..=lap0 + 2 {
            for (i, &si) in self.s[..n].iter().enumerate() {
                let at = si + lap as f64 * self.total;
                if at > from + 1e-9 && at < to - 1e-9 {
                    out.push((at, self.pts[i]));
                }
            }
        }
        out
    }

    /// Schneider's recursive fit of the stretch `(from, to)`: one cubic when it stays
    /// within `tol` of the trace, else two fits split at the worst sample. `corner0` and
    /// `corner1` say whether the ends are corners (one-sided tangents) or not (centered).
    fn fit(
        &self,
        from: f64,
        to: f64,
        corner0: bool,
        corner1: bool,
        tol: f64,
        out: &mut Vec<Cubic>,
    ) {
        let reach = CORNER_REACH.min((to - from) / 3.0).max(1e-3);
        let p0 = self.at(from);
        let p3 = self.at(to);
        let t0 = self.tangent(from, !corner0, true, reach);
        let t3 = self.tangent(to, true, !corner1, reach);
        let inner = self.inside(from, to);
        let samples: Vec<Point> = inner.iter().map(|x| x.1).collect();
        let (c, err, k) = fit_tangent_cubic(p0, t0, p3, t3, &samples);
        // Split at the worst sample, keeping a pixel's worth of trace on either side.
        if err > tol && to - from > 4.0 {
            let mid = inner[k].0.clamp(from + 1.5, to - 1.5);
            self.fit(from, mid, corner0, false, tol, out);
            self.fit(mid, to, false, corner1, tol, out);
        } else {
            out.push(c);
        }
    }
}

/// Cubics along a traced contour, before any refinement: joints at its corners (turning by
/// more than `corner_degrees`), at least `min_pieces` stretches spread evenly by arc
/// length between them, each fitted by [`Trace::fit`] within `tol` pixels.
fn initial_cubics(c: &Contour, min_pieces: usize, corner_degrees: f64, tol: f64) -> Vec<Cubic> {
    let pts = &c.points;
    let n = pts.len();
    let s = arc_lengths(pts);
    let total = s[n];
    let corner_at: Vec<f64> = corners(pts, corner_degrees, CORNER_REACH)
        .into_iter()
        .map(|i| s[i])
        .collect();
    let (joints, sharp) = if corner_at.is_empty() {
        (vec![0.0], false)
    } else {
        (corner_at, true)
    };
    let k = min_pieces.max(joints.len()).max(1);
    // Pieces per arc between corners: each extra piece goes to the arc whose pieces are
    // longest.
    let m = joints.len();
    let arc_len = |a: usize| {
        let (from, to) = (joints[a], joints[(a + 1) % m]);
        if m == 1 {
            total
        } else {
            (to - from).rem_euclid(total)
        }
    };
    let mut pieces = vec![1usize; m];
    for _ in m..k {
        let a = (0..m)
            .max_by(|&x, &y| {
                (arc_len(x) / pieces[x] as f64)
                    .total_cmp(&(arc_len(y) / pieces[y] as f64))
                    .then(y.cmp(&x))
            })
            .expect("at least one arc");
        pieces[a] += 1;
    }
    // Breaks in unwrapped arc length, each with whether it is a corner.
    let mut breaks: Vec<(f64, bool)> = Vec::with_capacity(k);
    for a in 0..m {
        let len = arc_len(a);
        for p in 0..pieces[a] {
            breaks.push((
                joints[a] + len * p as f64 / pieces[a] as f64,
                sharp && p == 0,
            ));
        }
    }
    let trace = Trace { pts, s, total };
    let mut out = Vec::new();
    for b in 0..breaks.len() {
        let (from, c0) = breaks[b];
        let (to, c1) = if b + 1 < breaks.len() {
            breaks[b + 1]
        } else {
            (breaks[0].0 + total, breaks[0].1)
        };
        trace.fit(from, to, c0, c1, tol, &mut out);
    }
    out
}

/// The scene of one black path with a closed subpath per contour of cubics.
fn build_scene(w: u32, h: u32, contours: &[Vec<Cubic>], rule: FillRule) -> Scene {
    let mut path = Path::new("glyph");
    for cubics in contours {
        let start = cubics[0][0];
        path.move_to(start);
        for (j, c) in cubics.iter().enumerate() {
            let end = if j + 1 == cubics.len() { start } else { c[3] };
            path.cubic_to(c[1], c[2], end);
        }
        path.close();
    }
    path.fill = Some(Fill {
        paint: Paint::Solid([0.0; 3]),
        opacity: 1.0,
        rule,
    });
    let mut scene = Scene::new(w, h);
    scene.nodes.push(Node::Path(path));
    scene
}

/// The cubics of every subpath of the scene's first path; a closed subpath's last end
/// point is set to its start (the average of the two, which the optimizer moves apart a
/// little).
fn read_cubics(scene: &Scene) -> Vec<Vec<Cubic>> {
    let mut out = Vec::new();
    let Some(Node::Path(p)) = scene.nodes.first() else {
        return out;
    };
    for sp in &p.subpaths {
        let mut cubics: Vec<Cubic> = (0..sp.segments())
            .map(|k| p.segment_points(sp, k))
            .collect();
        if let (Some(first), true) = (cubics.first().map(|c| c[0]), sp.closed) {
            let last = cubics.last().expect("not empty")[3];
            let mid = lerp(first, last, 0.5);
            cubics[0][0] = mid;
            let l = cubics.len() - 1;
            cubics[l][3] = mid;
        }
        out.push(cubics);
    }
    out
}

/// Samples per segment when charging errors to the curve.
const CHARGE_SAMPLES: usize = 16;

/// Where to add a segment: charges every pixel's squared coverage error to the nearest of
/// [`CHARGE_SAMPLES`] points on each segment; returns (contour, segment, split parameter):
/// the most-charged segment of the most-charged contour, split at its most-charged sample
/// (kept within [0.2, 0.8]). `None` when nothing is charged.
fn worst_segment(
    contours: &[Vec<Cubic>],
    coverage: &[f32],
    target: &[f32],
    width: usize,
) -> Option<(usize, usize, f64)> {
    let mut samples = Vec::new(); // (contour, segment, bin, point)
    for (ci, cubics) in contours.iter().enumerate() {
        for (si, c) in cubics.iter().enumerate() {
            for b in 0..CHARGE_SAMPLES {
                let t = (b as f64 + 0.5) / CHARGE_SAMPLES as f64;
                samples.push((ci, si, b, eval(c, t)));
            }
        }
    }
    if samples.is_empty() {
        return None;
    }
    let mut charge = vec![0.0f64; samples.len()];
    for (i, (&a, &b)) in coverage.iter().zip(target).enumerate() {
        let e = (a - b) as f64;
        let e2 = e * e;
        if e2 < 1e-4 {
            continue;
        }
        let p = [(i % width) as f64 + 0.5, (i / width) as f64 + 0.5];
        let mut best = (f64::INFINITY, 0usize);
        for (k, s) in samples.iter().enumerate() {
            let d = (s.3[0] - p[0]).powi(2) + (s.3[1] - p[1]).powi(2);
            if d < best.0 {
                best = (d, k);
            }
        }
        charge[best.1] += e2;
    }
    let mut per_contour = vec![0.0f64; contours.len()];
    for (k, s) in samples.iter().enumerate() {
        per_contour[s.0] += charge[k];
    }
    let ci = argmax(&per_contour)?;
    if per_contour[ci] <= 0.0 {
        return None;
    }
    let offset: usize = contours[..ci]
        .iter()
        .map(|c| c.len() * CHARGE_SAMPLES)
        .sum();
    let n = contours[ci].len();
    let per_segment: Vec<f64> = (0..n)
        .map(|si| {
            charge[offset + si * CHARGE_SAMPLES..offset + (si + 1) * CHARGE_SAMPLES]
                .iter()
                .sum()
        })
        .collect();
    let si = argmax(&per_segment)?;
    let bins = &charge[offset + si * CHARGE_SAMPLES..offset + (si + 1) * CHARGE_SAMPLES];
    // Smooth over neighbors so that one stray pixel does not decide.
    let smooth: Vec<f64> = (0..CHARGE_SAMPLES)
        .map(|b| {
            let l = if b > 0 { bins[b - 1] } else { 0.0 };
            let r = if b + 1 < CHARGE_SAMPLES {
                bins[b + 1]
            } else {
                0.0
            };
            l + 2.0 * bins[b] + r
        })
        .collect();
    let b = argmax(&smooth)?;
    let t = ((b as f64 + 0.5) / CHARGE_SAMPLES as f64).clamp(0.2, 0.8);
    Some((ci, si, t))
}

/// Index of the largest value (the first among equals).
fn argmax(v: &[f64]) -> Option<usize> {
    let mut best: Option<usize> = None;
    for (i, &x) in v.iter().enumerate() {
        if best.is_none_or(|b| x > v[b]) {
            best = Some(i);
        }
    }
    best
}

/// Coverage of every pixel of a rendering (its alpha).
fn coverage(img: &Image) -> Vec<f32> {
    img.data.iter().map(|p| p[3].clamp(0.0, 1.0)).collect()
}

/// Fits closed cubic curves to the ink of `target` with as few segments as reach
/// `opts.iou_goal` (see the [module documentation](self)). The fitted scene has the
/// target's size. A blank target gives an empty path with IoU 1.
pub fn fit_glyph(target: &Image, opts: &GlyphOptions) -> GlyphOutcome {
    let start = Instant::now();
    let (w, h) = (target.width, target.height);
    let ink = ink(target);
    // The target as the objective sees it: the ink, black on white.
    let mut goal = Image::new(w, h);
    for (p, &c) in goal.data.iter_mut().zip(&ink) {
        let l = 1.0 - c;
        *p = [l, l, l, 1.0];
    }
    let objective = Objective::new(&goal, Loss::Mse, Some([1.0; 4]), 1);
    let traced = trace_contours(&ink, w as usize, h as usize, 0.5);
    let holes: Vec<bool> = traced.iter().map(|c| c.hole).collect();
    let initial: Vec<Vec<Cubic>> = traced
        .iter()
        .map(|c| {
            initial_cubics(
                c,
                opts.initial_segments.max(1),
                opts.corner_degrees,
                opts.init_tolerance,
            )
        })
        .collect();
    let fit = FitOptions {
        iters: opts.iters,
        rates: LearningRates {
            points: opts.lr,
            color: 0.0,
            opacity: 0.0,
            width: 0.0,
            paint: 0.0,
            stops: 0.0,
            transform: 0.0,
            filter: 0.0,
        },
        schedule: Schedule::Cosine,
        render: opts.render,
        ..FitOptions::default()
    };
    let measure = |scene: &Scene| {
        let img = render(scene, &opts.render);
        let cov = coverage(&img);
        (iou(&cov, &ink, 0.5), img, cov)
    };
    let mut rounds = 0;
    let mut steps = 0;
    // One round: refine the contours (stopping as soon as the written form of the scene
    // reaches the goal) and measure the result.
    let mut round = |contours: Vec<Vec<Cubic>>| -> Round {
        let mut contours = contours;
        if !contours.is_empty() {
            let scene = build_scene(w, h, &contours, opts.rule);
            let mut hit: Option<Vec<Vec<Cubic>>> = None;
            let run = refine(scene, &objective, &fit, &mut |step, sc| {
                if step.iter % CHECK_EVERY == 0 {
                    let (cubics, written) = canonical(sc, opts.rule);
                    if measure(&written).0 >= opts.iou_goal {
                        hit = Some(cubics);
                        return Control::Stop;
                    }
                }
                Control::Continue
            });
            steps += run.steps;
            rounds += 1;
            contours = hit.unwrap_or_else(|| canonical(&run.best, opts.rule).0);
        }
        let scene = build_scene(w, h, &contours, opts.rule);
        let (iou, img, coverage) = measure(&scene);
        Round {
            mse: objective.mse(&img),
            contours,
            scene,
            iou,
            coverage,
        }
    };
    // Grow: one segment more per round where the error is, until the goal.
    let mut best = round(initial);
    let mut last = best.clone();
    while best.iou < opts.iou_goal && last.segments() < opts.max_segments {
        let Some((ci, si, t)) = worst_segment(&last.contours, &last.coverage, &ink, w as usize)
        else {
            break;
        };
        let mut contours = last.contours.clone();
        let (a, b) = split(&contours[ci][si], t);
        contours[ci][si] = a;
        contours[ci].insert(si + 1, b);
        last = round(contours);
        if last.iou >= opts.iou_goal
            || last.iou > best.iou
            || (last.iou == best.iou && last.mse < best.mse)
        {
            best = last.clone();
        }
    }
    // Shrink: remove joints while the goal holds.
    if best.iou >= opts.iou_goal && opts.merge_failures > 0 {
        let mut failures = 0;
        let mut tried: Vec<(usize, usize)> = Vec::new();
        while failures < opts.merge_failures {
            let Some((ci, j, merged)) = cheapest_merge(&best.contours, &tried) else {
                break;
            };
            let trial = round(merged);
            if trial.iou >= opts.iou_goal {
                best = trial;
                tried.clear();
                failures = 0;
            } else {
                tried.push((ci, j));
                failures += 1;
            }
        }
    }
    let per_contour: Vec<usize> = best.contours.iter().map(Vec::len).collect();
    GlyphOutcome {
        segments: per_contour.iter().sum(),
        per_contour,
        holes,
        iou: best.iou,
        mse: best.mse,
        reached: best.iou >= opts.iou_goal,
        rounds,
        steps,
        elapsed: start.elapsed(),
        scene: best.scene,
    }
}

/// The result of one refinement round.
#[derive(Clone)]
struct Round {
    contours: Vec<Vec<Cubic>>,
    scene: Scene,
    iou: f64,
    mse: f64,
    coverage: Vec<f32>,
}

impl Round {
    fn segments(&self) -> usize {
        self.contours.iter().map(Vec::len).sum()
    }
}

/// The contours with one joint removed: of all joints not in `tried` (contour, index of
/// the segment that starts there), the one where a single least-squares cubic through
/// both neighboring segments strays least from them. `None` when there is none.
fn cheapest_merge(
    contours: &[Vec<Cubic>],
    tried: &[(usize, usize)],
) -> Option<(usize, usize, Vec<Vec<Cubic>>)> {
    let mut best: Option<(f64, usize, usize, Cubic)> = None;
    for (ci, cubics) in contours.iter().enumerate() {
        let n = cubics.len();
        if n < 2 {
            continue;
        }
        for j in 0..n {
            if tried.contains(&(ci, j)) {
                continue;
            }
            let (a, b) = (&cubics[(j + n - 1) % n], &cubics[j]);
            let samples: Vec<Point> = (1..MERGE_SAMPLES)
                .map(|k| eval(a, k as f64 / MERGE_SAMPLES as f64))
                .chain(std::iter::once(a[3]))
                .chain((1..MERGE_SAMPLES).map(|k| eval(b, k as f64 / MERGE_SAMPLES as f64)))
                .collect();
            let c = fit_cubic(a[0], b[3], &samples);
            let cost = samples.iter().map(|q| nearest(&c, *q)).fold(0.0, f64::max);
            if best.as_ref().is_none_or(|b| cost < b.0) {
                best = Some((cost, ci, j, c));
            }
        }
    }
    let (_, ci, j, c) = best?;
    let mut out = contours.to_vec();
    let cubics = &mut out[ci];
    if j == 0 {
        // The last segment and the first become one, starting where the last did.
        cubics.pop();
        cubics[0] = c;
    } else {
        cubics[j - 1] = c;
        cubics.remove(j);
    }
    Some((ci, j, out))
}

/// Samples per segment when two are fitted by one.
const MERGE_SAMPLES: usize = 24;

/// Steps between IoU checks during a round.
pub(crate) const CHECK_EVERY: usize = 10;

/// A coordinate as an SVG file written by [`Scene::save_svg`] holds it and a reader
/// gets it back (four decimals, then single precision).
fn as_written(v: f64) -> f64 {
    format!("{v:.4}").parse::<f32>().map_or(v, f64::from)
}

/// The cubics of an optimized scene (each closed subpath ending exactly on its start) with
/// every coordinate as written to SVG, and the scene built from them: what is measured is
/// what is saved.
fn canonical(scene: &Scene, rule: FillRule) -> (Vec<Vec<Cubic>>, Scene) {
    let mut cubics = read_cubics(scene);
    for c in cubics.iter_mut().flatten() {
        for p in c.iter_mut() {
            *p = p.map(as_written);
        }
    }
    let built = build_scene(scene.width, scene.height, &cubics, rule);
    (cubics, built)
}

/// Counts the segments of the dark-filled paths of a scene, as a font would: every line,
/// quadratic and cubic, plus a closing line where a closed subpath does not end on its
/// start. Returns (contours, segments). Paths whose fill is light (mean of RGB ≥ ½, such
/// as a white background) or missing are left out.
pub fn count_ink_segments(scene: &Scene) -> (usize, usize) {
    let (mut contours, mut segments) = (0, 0);
    scene.for_each_path(|p| {
        let dark = match &p.fill {
            Some(Fill {
                paint: Paint::Solid(c),
                opacity,
                ..
            }) => *opacity > 0.0 && (c[0] + c[1] + c[2]) / 3.0 < 0.5,
            Some(Fill {
                paint: Paint::Gradient(_) | Paint::Image(_),
                ..
            }) => true,
            None => false,
        };
        if !dark {
            return;
        }
        for sp in &p.subpaths {
            if sp.kinds.is_empty() {
                continue;
            }
            contours += 1;
            segments += sp
                .kinds
                .iter()
                .filter(|k| {
                    matches!(
                        k,
                        SegmentKind::Line | SegmentKind::Quad | SegmentKind::Cubic
                    )
                })
                .count();
            let (first, last) = (p.points[sp.start], p.points[sp.end() - 1]);
            if sp.closed && dist(first, last) > 1e-6 {
                segments += 1;
            }
        }
    });
    (contours, segments)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A ring (annulus) rasterized by distance: one outer contour, clockwise on screen,
    /// and one hole, counter-clockwise, near the right radii.
    #[test]
    fn a_ring_gives_an_outer_contour_and_a_hole() {
        let (w, h) = (40usize, 40usize);
        let c = [20.0, 20.0];
        let values: Vec<f32> = (0..w * h)
            .map(|i| {
                let p = [(i % w) as f64 + 0.5, (i / w) as f64 + 0.5];
                let r = dist(p, c);
                // Anti-aliased: 1 inside 8 ≤ r ≤ 15, ramps of one pixel.
                ((r - 7.5).min(15.5 - r)).clamp(0.0, 1.0) as f32
            })
            .collect();
        let contours = trace_contours(&values, w, h, 0.5);
        assert_eq!(contours.len(), 2, "{contours:?}");
        let outer: Vec<_> = contours.iter().filter(|c| !c.hole).collect();
        let holes: Vec<_> = contours.iter().filter(|c| c.hole).collect();
        assert_eq!((outer.len(), holes.len()), (1, 1));
        let (o, i) = (outer[0], holes[0]);
        assert!(o.area() > 0.0 && i.area() < 0.0);
        // Areas of circles of radius 15 and 8 (the ½ level), within a few percent.
        let pi = std::f64::consts::PI;
        assert!((o.area() / (pi * 225.0) - 1.0).abs() < 0.03, "{}", o.area());
        assert!((-i.area() / (pi * 64.0) - 1.0).abs() < 0.05, "{}", i.area());
        for p in &o.points {
            assert!((dist(*p, c) - 15.0).abs() < 0.3, "{p:?}");
        }
        for p in &i.points {
            assert!((dist(*p, c) - 8.0).abs() < 0.3, "{p:?}");
        }
        // Clockwise on screen: from the top (y small) the outer contour heads right.
        let top = o
            .points
            .iter()
            .enumerate()
            .min_by(|a, b| a.1[1].total_cmp(&b.1[1]))
            .unwrap()
            .0;
        let next = o.points[(top + 1) % o.points.len()];
        assert!(next[0] >= o.points[top][0], "outer runs clockwise");
    }

    /// Ink at the image border still gives closed contours; two touching squares
    /// diagonally (a saddle) are kept apart or joined consistently; tiny specks go.
    #[test]
    fn borders_saddles_and_specks() {
        let (w, h) = (10usize, 10usize);
        let mut v = vec![0.0f32; w * h];
        for y in 0..4 {
            for x in 0..4 {
                v[y * w + x] = 1.0;
            }
        }
        // Diagonal neighbor square, touching at a corner.
        for y in 4..8 {
            for x in 4..8 {
                v[y * w + x] = 1.0;
            }
        }
        v[9 * w + 9] = 1.0; // a 1-pixel speck (area ½ at the ½ level): dropped
        let c = trace_contours(&v, w, h, 0.5);
        // The saddle's mean is ½ (≥ level): the squares join into one outer contour.
        assert_eq!(c.len(), 1, "{c:?}");
        assert!(!c[0].hole);
        // Two 4×4 squares whose ½ levels sit half a pixel inside the pixel grid's
        // centers: 2 × 4² minus the cut corners.
        assert!((c[0].area() - 32.0).abs() < 1.0, "{}", c[0].area());
    }

    #[test]
    fn least_squares_cubic_reproduces_a_cubic() {
        let c: Cubic = [[0.0, 0.0], [10.0, 20.0], [30.0, 20.0], [40.0, 0.0]];
        let samples: Vec<Point> = (1..40).map(|k| eval(&c, k as f64 / 40.0)).collect();
        let f = fit_cubic(c[0], c[3], &samples);
        for k in 0..=20 {
            let t = k as f64 / 20.0;
            let p = eval(&f, t);
            let best = (0..=400)
                .map(|j| dist(p, eval(&c, j as f64 / 400.0)))
                .fold(f64::INFINITY, f64::min);
            assert!(best < 0.1, "{t}: {best}");
        }
        let (a, b) = split(&c, 0.3);
        assert!(dist(a[3], eval(&c, 0.3)) < 1e-12);
        assert!(dist(eval(&b, 0.5), eval(&c, 0.65)) < 1e-12);
    }

    #[test]
    fn corners_of_a_square_are_found() {
        let mut pts = Vec::new();
        for k in 0..20 {
            pts.push([k as f64, 0.0]);
        }
        for k in 0..20 {
            pts.push([20.0, k as f64]);
        }
        for k in 0..20 {
            pts.push([20.0 - k as f64, 20.0]);
        }
        for k in 0..20 {
            pts.push([0.0, 20.0 - k as f64]);
        }
        assert_eq!(corners(&pts, 50.0, CORNER_REACH), vec![0, 20, 40, 60]);
    }

    /// A filled disc is fitted with a handful of segments to the IoU goal, and the fit
    /// is deterministic.
    #[test]
    fn fits_a_disc_with_few_segments() {
        let mut s = Scene::new(64, 64);
        s.nodes.push(Node::Path(super::super::shapes::circle(
            "c",
            [30.0, 33.0],
            20.0,
            8,
            [0.0; 3],
        )));
        let mut img = render(&s, &RenderOptions::default());
        img.over_background([1.0; 4]);
        let opts = GlyphOptions::default();
        let a = fit_glyph(&img, &opts);
        assert!(a.reached, "IoU {}", a.iou);
        assert!(a.segments <= 4, "{} segments", a.segments);
        assert_eq!(a.holes, vec![false]);
        let b = fit_glyph(&img, &opts);
        assert_eq!(a.scene, b.scene);
        // Nothing to fit: no segments, and the goal holds.
        let blank = fit_glyph(&Image::filled(16, 16, [1.0; 4]), &opts);
        assert_eq!((blank.segments, blank.reached), (0, true));
    }
}
