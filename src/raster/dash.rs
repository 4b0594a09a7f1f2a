//! Dashing a flattened centerline (SVG `stroke-dasharray`).
//!
//! Dashes are cut from the polyline by arc length in the stroke frame; each subpath
//! restarts the pattern at `dash_offset`. A cut point lies on a chord, so it is a fixed
//! linear blend of the chord's two end vertices ([`DashSource`]); with the cut parameters
//! held fixed, the backward pass maps gradients through that blend.

use super::flatten::Contour;
use crate::scene::Point;
use crate::scene::geom::{dist, lerp};

/// Where a dashed vertex comes from: `(1 − u)·pts[a] + u·pts[b]` of the undashed polyline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct DashSource {
    /// First vertex.
    pub(crate) a: u32,
    /// Second vertex.
    pub(crate) b: u32,
    /// Blend factor in `[0, 1]`.
    pub(crate) u: f64,
}

/// A dashed polyline: open contours, with provenance of every vertex.
#[derive(Clone, Debug, Default)]
pub(crate) struct Dashed {
    /// Vertices.
    pub(crate) pts: Vec<Point>,
    /// Whether each vertex is a corner of the original path (joins are drawn there).
    pub(crate) corner: Vec<bool>,
    /// Provenance of each vertex.
    pub(crate) src: Vec<DashSource>,
    /// Open contours, one per dash.
    pub(crate) contours: Vec<Contour>,
}

/// Where dashes can be seen: device positions of the polyline's vertices and the visible
/// rectangle `[xmin, ymin, xmax, ymax]` (the canvas grown by the stroke's reach, so that a
/// cap or join drawn outside it cannot touch the canvas).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Visible<'a> {
    /// Device position of every vertex (the polyline mapped out of the stroke frame).
    pub(crate) device: &'a [Point],
    /// Visible rectangle in device pixels.
    pub(crate) rect: [f64; 4],
}

/// The part `[u0, u1]` of the chord `a → b` inside `rect` (Liang–Barsky), or `None`.
pub(crate) fn visible_span(a: Point, b: Point, rect: [f64; 4]) -> Option<(f64, f64)> {
    let (mut u0, mut u1) = (0.0f64, 1.0f64);
    let d = [b[0] - a[0], b[1] - a[1]];
    for (p, q) in [
        (-d[0], a[0] - rect[0]),
        (d[0], rect[2] - a[0]),
        (-d[1], a[1] - rect[1]),
        (d[1], rect[3] - a[1]),
    ] {
        if !(q.is_finite() && p.is_finite()) {
            return None;
        }
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                u0 = u0.max(r);
            } else {
                u1 = u1.min(r);
            }
        }
    }
    (u0 <= u1).then_some((u0.clamp(0.0, 1.0), u1.clamp(0.0, 1.0)))
}

/// Vertex order of a contour, with the closing chord back to the start when closed.
fn order(c: &Contour) -> impl Iterator<Item = (u32, u32)> {
    let n = c.len;
    let closing = c.closed && n > 1;
    (0..n.saturating_sub(1) + closing as usize).map(move |i| {
        let a = c.start + i;
        let b = if i + 1 == n { c.start } else { a + 1 };
        (a as u32, b as u32)
    })
}

/// An upper bound of the number of dashes [`dash`] cuts (before cutting anything):
/// for each run of consecutive visible chords, `(length / period + 1)` times the number
/// of dash entries of the pattern. Invisible chords cost nothing. Infinite when the
/// lengths overflow.
pub(crate) fn dash_count(
    pts: &[Point],
    contours: &[Contour],
    pattern: &[f64],
    visible: Option<Visible>,
) -> f64 {
    let period: f64 = pattern.iter().sum();
    if !(period > 0.0) || !period.is_finite() {
        return 0.0;
    }
    let on = pattern.len().div_ceil(2) as f64;
    let mut total = 0.0;
    for c in contours {
        if !c.drawn || c.len == 0 {
            continue;
        }
        // Length of the current run of visible chords, if one is open.
        let mut run: Option<f64> = None;
        for (a, b) in order(c) {
            let (pa, pb) = (pts[a as usize], pts[b as usize]);
            let len = dist(pa, pb);
            let span = match visible {
                Some(v) => visible_span(v.device[a as usize], v.device[b as usize], v.rect),
                None => Some((0.0, 1.0)),
            };
            match span {
                None => {
                    if let Some(l) = run.take() {
                        total += (l / period + 1.0) * on;
                    }
                }
                Some((u0, u1)) => {
                    if u0 > 0.0
                        && let Some(l) = run.take()
                    {
                        total += (l / period + 1.0) * on;
                    }
                    *run.get_or_insert(0.0) += (u1 - u0) * len;
                    if u1 < 1.0
                        && let Some(l) = run.take()
                    {
                        total += (l / period + 1.0) * on;
                    }
                }
            }
        }
        if let Some(l) = run.take() {
            total += (l / period + 1.0) * on;
        }
        // A lone point (zero-length subpath) is not dashed.
    }
    if total.is_finite() {
        total
    } else {
        f64::INFINITY
    }
}

/// Cuts the contours of `pts` into dashes. `pattern` has an even number of non-negative
/// lengths whose sum is positive; `offset` shifts the pattern's start along each subpath.
///
/// With `visible`, dashes are cut only where chords cross the visible rectangle: the
/// pattern is advanced over the rest in closed form, and a dash leaving the rectangle
/// ends where its chord leaves it (such ends lie outside the rectangle, so their caps do
/// not reach the canvas). The work and the output are then bounded by
/// [`dash_count`] with the same arguments, which callers check first.
pub(crate) fn dash(
    pts: &[Point],
    corner: &[bool],
    contours: &[Contour],
    pattern: &[f64],
    offset: f64,
    visible: Option<Visible>,
) -> Dashed {
    let mut out = Dashed::default();
    let period: f64 = pattern.iter().sum();
    if !(period > 0.0) || !period.is_finite() {
        return out;
    }
    for c in contours {
        if !c.drawn || c.len == 0 {
            continue;
        }
        // Zero-length subpaths draw nothing when dashed (as in Skia).
        let length: f64 = order(c)
            .map(|(a, b)| dist(pts[a as usize], pts[b as usize]))
            .sum();
        if !(length > 0.0) {
            continue;
        }
        // Position in the pattern at the start of the subpath.
        let mut phase = offset.rem_euclid(period);
        let mut k = 0usize;
        while phase > 0.0 && phase >= pattern[k] {
            phase -= pattern[k];
            k = (k + 1) % pattern.len();
        }
        // `left`: length remaining in the current pattern entry; even `k` = dash on.
        let mut left = pattern[k] - phase;
        let mut on = k.is_multiple_of(2);
        let mut open: Option<usize> = None;
        let push = |out: &mut Dashed, s: DashSource, is_corner: bool| {
            let p0 = pts[s.a as usize];
            let p1 = pts[s.b as usize];
            out.pts.push(lerp(p0, p1, s.u));
            out.corner.push(is_corner);
            out.src.push(s);
        };
        let finish = |out: &mut Dashed, start: usize| {
            let len = out.pts.len() - start;
            out.contours.push(Contour {
                start,
                len,
                closed: false,
                drawn: true,
            });
        };
        // Moves the pattern `d` further along without cutting (over invisible parts).
        let advance = |k: &mut usize, left: &mut f64, on: &mut bool, d: f64| {
            let mut d = d;
            if d > *left {
                d -= *left;
                *k = (*k + 1) % pattern.len();
                *on = !*on;
                *left = pattern[*k];
                d %= period;
                // Less than one period remains; rounding may leave a hair more.
                for _ in 0..2 * pattern.len() {
                    if d <= *left {
                        break;
                    }
                    d -= *left;
                    *k = (*k + 1) % pattern.len();
                    *on = !*on;
                    *left = pattern[*k];
                }
            }
            *left = (*left - d).max(0.0);
        };
        let first_dash = out.contours.len();
        let started_on = on;
        let mut first = true;
        for (a, b) in order(c) {
            let pa = pts[a as usize];
            let pb = pts[b as usize];
            let len = dist(pa, pb);
            let span = match visible {
                Some(v) => visible_span(v.device[a as usize], v.device[b as usize], v.rect),
                None => Some((0.0, 1.0)),
            };
            let Some((u0, u1)) = span else {
                // Invisible chord: end the open dash at its start and skip it.
                if let Some(s) = open.take() {
                    finish(&mut out, s);
                }
                advance(&mut k, &mut left, &mut on, len);
                first = false;
                continue;
            };
            let mut pos = 0.0;
            if u0 > 0.0 {
                if let Some(s) = open.take() {
                    finish(&mut out, s);
                }
                pos = u0 * len;
                advance(&mut k, &mut left, &mut on, pos);
                if on {
                    open = Some(out.pts.len());
                    push(&mut out, DashSource { a, b, u: u0 }, false);
                }
            } else if on && open.is_none() {
                // The subpath's start, or a return into the visible rectangle.
                open = Some(out.pts.len());
                push(
                    &mut out,
                    DashSource { a, b: a, u: 0.0 },
                    first || corner[a as usize],
                );
            }
            first = false;
            let end = if u1 < 1.0 { u1 * len } else { len };
            // Cut the chord wherever the pattern switches (zero-length entries included).
            while left < end - pos {
                pos += left;
                let u = if len > 0.0 {
                    (pos / len).clamp(0.0, 1.0)
                } else {
                    1.0
                };
                if on {
                    push(&mut out, DashSource { a, b, u }, false);
                    if let Some(s) = open.take() {
                        finish(&mut out, s);
                    }
                } else {
                    open = Some(out.pts.len());
                    push(&mut out, DashSource { a, b, u }, false);
                }
                on = !on;
                k = (k + 1) % pattern.len();
                left = pattern[k];
                if len == 0.0 && left > 0.0 {
                    break;
                }
            }
            left -= end - pos;
            if u1 < 1.0 {
                // Leaving the visible rectangle inside this chord.
                if on {
                    push(&mut out, DashSource { a, b, u: u1 }, false);
                    if let Some(s) = open.take() {
                        finish(&mut out, s);
                    }
                }
                advance(&mut k, &mut left, &mut on, len - end);
            } else if on {
                push(&mut out, DashSource { a: b, b, u: 0.0 }, corner[b as usize]);
            }
        }
        let ended_on = open.is_some();
        if let Some(s) = open.take() {
            finish(&mut out, s);
        }
        // A closed contour that is dashed at both its start and its end is one dash
        // through the start point (joined there), as in Skia.
        let here = &out.contours[first_dash..];
        let starts_at_start = here.first().is_some_and(|d| {
            out.src[d.start]
                == DashSource {
                    a: c.start as u32,
                    b: c.start as u32,
                    u: 0.0,
                }
        });
        if c.closed && started_on && ended_on && starts_at_start && here.len() >= 2 {
            let first = here[0];
            let last = here[here.len() - 1];
            let start = out.pts.len();
            for i in
                (last.start..last.start + last.len).chain(first.start + 1..first.start + first.len)
            {
                out.pts.push(out.pts[i]);
                out.corner.push(out.corner[i]);
                out.src.push(out.src[i]);
            }
            let n = out.contours.len();
            out.contours[n - 1] = Contour {
                start,
                len: out.pts.len() - start,
                closed: false,
                drawn: true,
            };
            out.contours.remove(first_dash);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn line(len: f64) -> (Vec<Point>, Vec<bool>, Vec<Contour>) {
        (
            vec![[0.0, 0.0], [len, 0.0]],
            vec![true, true],
            vec![Contour {
                start: 0,
                len: 2,
                closed: false,
                drawn: true,
            }],
        )
    }

    fn lengths(d: &Dashed) -> Vec<f64> {
        d.contours
            .iter()
            .map(|c| {
                (c.start + 1..c.start + c.len)
                    .map(|i| dist(d.pts[i - 1], d.pts[i]))
                    .sum()
            })
            .collect()
    }

    #[test]
    fn even_pattern_cuts_equal_dashes() {
        let (p, c, k) = line(100.0);
        let d = dash(&p, &c, &k, &[10.0, 10.0], 0.0, None);
        assert_eq!(d.contours.len(), 5);
        for l in lengths(&d) {
            assert!((l - 10.0).abs() < 1e-9, "{l}");
        }
        assert!((d.pts[d.contours[1].start][0] - 20.0).abs() < 1e-9);
    }

    #[test]
    fn offset_shifts_the_pattern() {
        let (p, c, k) = line(30.0);
        let d = dash(&p, &c, &k, &[10.0, 10.0], 5.0, None);
        // on 5 (0–5), off 10, on 10 (15–25), off 5.
        let l = lengths(&d);
        assert_eq!(l.len(), 2);
        assert!(
            (l[0] - 5.0).abs() < 1e-9 && (l[1] - 10.0).abs() < 1e-9,
            "{l:?}"
        );
        assert!((d.pts[d.contours[1].start][0] - 15.0).abs() < 1e-9);
        // Negative offsets wrap.
        let d = dash(&p, &c, &k, &[10.0, 10.0], -5.0, None);
        assert!((d.pts[d.contours[0].start][0] - 5.0).abs() < 1e-9);
    }

    #[test]
    fn dash_spans_corners_and_closing_chord() {
        // A closed 10×10 square, dashes of 15 on / 5 off.
        let p = vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];
        let c = vec![true; 4];
        let k = vec![Contour {
            start: 0,
            len: 4,
            closed: true,
            drawn: true,
        }];
        let d = dash(&p, &c, &k, &[15.0, 5.0], 0.0, None);
        let l = lengths(&d);
        assert_eq!(l.len(), 2);
        assert!(l.iter().all(|x| (x - 15.0).abs() < 1e-9), "{l:?}");
        // With 12 on / 2 off (dashes 0–12, 14–26, 28–40) the dash over the start point
        // is one piece, 28–40 then 0–12.
        let d = dash(&p, &c, &k, &[12.0, 2.0], 0.0, None);
        let l = lengths(&d);
        assert_eq!(l.len(), 2, "{l:?}");
        assert!(
            (l[0] - 12.0).abs() < 1e-9 && (l[1] - 24.0).abs() < 1e-9,
            "{l:?}"
        );
        // The first dash turns the corner at (10, 0), which stays a corner.
        let first = d.contours[0];
        assert_eq!(first.len, 3);
        assert!(d.corner[first.start + 1]);
    }

    #[test]
    fn zero_length_dash_makes_a_dot() {
        let (p, c, k) = line(20.0);
        let d = dash(&p, &c, &k, &[0.0, 10.0], 0.0, None);
        assert_eq!(
            d.contours.len(),
            2,
            "dots at 0 and 10; the pattern ends at 20"
        );
        assert!(lengths(&d).iter().all(|&l| l == 0.0));
    }

    #[test]
    fn only_the_visible_part_of_a_line_to_1e20_is_cut() {
        let pts = vec![[10.0, 0.0], [10.0, 1e20]];
        let corner = vec![true, true];
        let k = vec![Contour {
            start: 0,
            len: 2,
            closed: false,
            drawn: true,
        }];
        let vis = Visible {
            device: &pts,
            rect: [-5.0, -5.0, 105.0, 105.0],
        };
        assert!(dash_count(&pts, &k, &[5.0, 5.0], None) > 1e18);
        let n = dash_count(&pts, &k, &[5.0, 5.0], Some(vis));
        assert!((11.0..=12.0).contains(&n), "{n}");
        let d = dash(&pts, &corner, &k, &[5.0, 5.0], 0.0, Some(vis));
        // On 0–5, 10–15, …, 100–105 (where the rectangle ends).
        assert_eq!(d.contours.len(), 11);
        for l in lengths(&d) {
            assert!((l - 5.0).abs() < 1e-6, "{l}");
        }
        assert!(d.pts.iter().all(|q| q[1] <= 105.0 + 1e-9));
    }

    #[test]
    fn clipping_changes_nothing_when_all_is_visible() {
        let p = vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]];
        let c = vec![true; 4];
        let k = vec![Contour {
            start: 0,
            len: 4,
            closed: true,
            drawn: true,
        }];
        let vis = Visible {
            device: &p,
            rect: [-100.0, -100.0, 100.0, 100.0],
        };
        for (pattern, offset) in [(&[12.0, 2.0][..], 0.0), (&[3.0, 1.0, 0.0, 2.0][..], 1.5)] {
            let a = dash(&p, &c, &k, pattern, offset, None);
            let b = dash(&p, &c, &k, pattern, offset, Some(vis));
            assert_eq!((a.pts, a.src, a.contours), (b.pts, b.src, b.contours));
        }
    }

    #[test]
    fn a_dash_leaving_the_rectangle_ends_at_its_edge() {
        // A square half outside the rectangle: the dashes are cut where it leaves.
        let p = vec![[-50.0, 0.0], [50.0, 0.0], [50.0, 10.0], [-50.0, 10.0]];
        let c = vec![true; 4];
        let k = vec![Contour {
            start: 0,
            len: 4,
            closed: true,
            drawn: true,
        }];
        let vis = Visible {
            device: &p,
            rect: [0.0, -1.0, 100.0, 11.0],
        };
        let d = dash(&p, &c, &k, &[30.0, 10.0], 0.0, Some(vis));
        assert!(d.pts.iter().all(|q| q[0] >= -1e-9), "{:?}", d.pts);
        // The top edge: on −50…−20, off, on −10…20, off, on 30…60 (turning the corner).
        assert!((d.pts[d.contours[0].start][0] - 0.0).abs() < 1e-9);
        assert!((d.pts[d.contours[0].start + 1][0] - 20.0).abs() < 1e-9);
    }
}
