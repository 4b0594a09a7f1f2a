//! Flattening cubic Béziers to polylines at fixed parameters.
//!
//! A cubic is cut into `n` chords at `t_k = k / n`. `n` comes from the control polygon's
//! second differences: with `dd = max |P0 − 2P1 + P2|, |P1 − 2P2 + P3|` the second derivative
//! is bounded by `6·dd`, so the chord error is at most `6·dd / (8 n²)`, and
//! `n = ceil(sqrt(0.75 · dd / tolerance))` keeps it below `tolerance` (pixels).
//!
//! Within one evaluation `n` is fixed, so every flattened vertex is a fixed Bernstein
//! combination of four control points, and the backward pass maps vertex gradients back
//! to control points exactly ([`FlatSource`]).

use crate::scene::geom::{bernstein, eval};
use crate::scene::{Path, Point};

pub(crate) use crate::scene::geom::chord_count;

/// Where a flattened vertex comes from: `Σ B_k(t) · points[first + k]`, `k = 0..4`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct FlatSource {
    /// Index of the segment's first control point in [`Path::points`].
    pub(crate) first: u32,
    /// Curve parameter in `[0, 1]`.
    pub(crate) t: f64,
}

impl FlatSource {
    /// Bernstein weights of the four control points.
    #[inline]
    pub(crate) fn weights(&self) -> [f64; 4] {
        bernstein(self.t)
    }
}

/// One flattened subpath: `len` vertices starting at `start` in [`Flattened::pts`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Contour {
    /// First vertex.
    pub(crate) start: usize,
    /// Number of vertices (≥ 1).
    pub(crate) len: usize,
    /// Whether the contour closes back to its first vertex.
    pub(crate) closed: bool,
    /// Whether the subpath has at least one segment or is closed (a lone `M` draws no cap).
    pub(crate) drawn: bool,
}

/// A path flattened to polylines.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Flattened {
    /// Vertices in device pixels.
    pub(crate) pts: Vec<Point>,
    /// Provenance of each vertex (empty when not asked for, see [`flatten`]).
    pub(crate) src: Vec<FlatSource>,
    /// Whether vertex `i` ends an original segment (a corner where a join is drawn) rather
    /// than lying inside a flattened curve.
    pub(crate) corner: Vec<bool>,
    /// Subpaths.
    pub(crate) contours: Vec<Contour>,
}

/// Chord counts of every segment of a path, in order; fixed counts make the rendering a
/// smooth function of the control points (used by gradient checks).
pub(crate) type ChordCounts = Vec<u32>;

/// Flattens `path`. With `counts`, uses those chord counts (one per segment, as returned
/// in the second value) instead of computing them. Without `sources`, [`Flattened::src`]
/// stays empty (a forward render never reads it).
pub(crate) fn flatten(
    path: &Path,
    tolerance: f64,
    visible: [f64; 4],
    counts: Option<&[u32]>,
    sources: bool,
) -> (Flattened, ChordCounts) {
    // Chord counts first, so that the vertex lists are allocated once.
    let mut used = Vec::with_capacity(path.subpaths.iter().map(|sp| sp.segments()).sum());
    for sp in &path.subpaths {
        for k in 0..sp.segments() {
            used.push(match counts {
                Some(c) => c.get(used.len()).copied().unwrap_or(1).max(1),
                None => chord_count(&path.segment_points(sp, k), tolerance, visible),
            });
        }
    }
    let verts = path.subpaths.len() + used.iter().map(|&n| n as usize).sum::<usize>();
    let mut out = Flattened {
        pts: Vec::with_capacity(verts),
        src: Vec::with_capacity(if sources { verts } else { 0 }),
        corner: Vec::with_capacity(verts),
        contours: Vec::with_capacity(path.subpaths.len()),
    };
    let mut seg_ix = 0usize;
    for sp in &path.subpaths {
        let start = out.pts.len();
        out.pts.push(path.points[sp.start]);
        if sources {
            out.src.push(FlatSource {
                first: sp.start as u32,
                t: 0.0,
            });
        }
        out.corner.push(true);
        for k in 0..sp.segments() {
            let first = sp.start + 3 * k;
            let p = path.segment_points(sp, k);
            let n = used[seg_ix];
            seg_ix += 1;
            for j in 1..=n {
                let t = j as f64 / n as f64;
                out.pts.push(if j == n { p[3] } else { eval(&p, t) });
                if sources {
                    out.src.push(FlatSource {
                        first: first as u32,
                        t,
                    });
                }
                out.corner.push(j == n);
            }
        }
        out.contours.push(Contour {
            start,
            len: out.pts.len() - start,
            closed: sp.closed,
            drawn: sp.segments() > 0 || sp.closed,
        });
    }
    (out, used)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::geom::{dist, lerp};

    const CANVAS: [f64; 4] = [0.0, 0.0, 100.0, 100.0];

    #[test]
    fn chord_error_is_below_tolerance() {
        let p = [[10.0, 10.0], [90.0, 0.0], [0.0, 90.0], [90.0, 90.0]];
        for tol in [0.5, 0.1, 0.02] {
            let n = chord_count(&p, tol, CANVAS);
            // Check the distance of curve samples to their chord.
            let mut worst: f64 = 0.0;
            for k in 0..n {
                let (t0, t1) = (k as f64 / n as f64, (k + 1) as f64 / n as f64);
                let (a, b) = (eval(&p, t0), eval(&p, t1));
                for s in 1..20 {
                    let t = t0 + (t1 - t0) * s as f64 / 20.0;
                    let q = eval(&p, t);
                    let u = s as f64 / 20.0;
                    worst = worst.max(dist(q, lerp(a, b, u)));
                }
            }
            assert!(worst <= tol, "tol {tol}: n {n} error {worst}");
        }
    }

    #[test]
    fn lines_and_offscreen_curves_need_one_chord() {
        let line = [[0.0, 0.0], [1.0, 1.0], [2.0, 2.0], [3.0, 3.0]];
        assert_eq!(chord_count(&line, 0.02, CANVAS), 1);
        let left = [[-50.0, 0.0], [-10.0, 80.0], [-90.0, 10.0], [-5.0, 50.0]];
        assert_eq!(chord_count(&left, 0.02, CANVAS), 1);
        let huge = [[0.0, 0.0], [1e9, 0.0], [0.0, 1e9], [50.0, 50.0]];
        assert_eq!(chord_count(&huge, 0.02, CANVAS), crate::limits::MAX_CHORDS);
    }

    #[test]
    fn flatten_keeps_provenance() {
        let mut path = Path::new("p");
        path.move_to([0.0, 0.0]);
        path.cubic_to([30.0, 0.0], [30.0, 30.0], [0.0, 30.0]);
        path.line_to([0.0, 10.0]);
        path.close();
        let (f, counts) = flatten(&path, 0.1, CANVAS, None, true);
        assert_eq!(counts.len(), 2);
        assert_eq!(counts[1], 1);
        assert_eq!(f.pts.len(), 1 + counts[0] as usize + 1);
        for (q, s) in f.pts.iter().zip(&f.src) {
            let i = s.first as usize;
            let p = [
                path.points[i],
                path.points[i + 1],
                path.points[i + 2],
                path.points[i + 3],
            ];
            let e = eval(&p, s.t);
            assert!((e[0] - q[0]).abs() < 1e-9 && (e[1] - q[1]).abs() < 1e-9);
        }
        assert!(f.contours[0].closed);
        let (g, _) = flatten(&path, 0.1, CANVAS, Some(&[3, 1]), true);
        assert_eq!(g.pts.len(), 5);
    }
}
