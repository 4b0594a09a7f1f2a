//! Point and cubic Bézier helpers shared by the rasterizer, the SVG writer and the fitters:
//! one copy of each, so that every caller gets the same floating-point operations.
//!
//! A cubic is the four points `[p0, c1, c2, p3]` of [`Path::segment_points`]
//! (device pixels).
//!
//! [`Path::segment_points`]: super::Path::segment_points

use super::Point;

// ---- rounding without library calls --------------------------------------------------

/// `x.floor()` for any `x`, without the library call that baseline x86-64 makes of it
/// (truncating casts are single instructions; huge and non-finite values take `floor`).
#[inline]
pub(crate) fn floor_f64(x: f64) -> f64 {
    if x.abs() < 4.5e15 {
        let t = (x as i64) as f64;
        if t > x { t - 1.0 } else { t }
    } else {
        x.floor()
    }
}

/// `x.ceil()` for any `x`, as `−floor(−x)` (exact), without a library call.
#[inline]
pub(crate) fn ceil_f64(x: f64) -> f64 {
    -floor_f64(-x)
}

// ---- how finely the rasterizer flattens and strokes (also counted at load) ----------

/// The rasterizer's default flattening tolerance, device pixels
/// (`raster::RenderOptions::default`); the load-time chord limit counts at it.
pub(crate) const DEFAULT_TOLERANCE: f64 = 0.02;

/// Chord count for one cubic under `tolerance` (pixels). `visible` is the canvas grown by
/// any stroke margin, `[xmin, ymin, xmax, ymax]`: a cubic wholly to its left, right, top or
/// bottom only needs one chord (its net crossing of each row is set by its end points).
pub(crate) fn chord_count(p: &[Point; 4], tolerance: f64, visible: [f64; 4]) -> u32 {
    let all = |f: &dyn Fn(&Point) -> bool| p.iter().all(f);
    if all(&|q| q[0] <= visible[0])
        || all(&|q| q[0] >= visible[2])
        || all(&|q| q[1] <= visible[1])
        || all(&|q| q[1] >= visible[3])
    {
        return 1;
    }
    // The second differences' larger length, through its square: `hypot` and `ceil` are
    // library calls on baseline x86-64, and this runs for every cubic of every render
    // (a twentieth of a line of text's). A square that overflows takes `hypot`.
    let second =
        |a: &Point, b: &Point, c: &Point| [a[0] - 2.0 * b[0] + c[0], a[1] - 2.0 * b[1] + c[1]];
    let (u, v) = (second(&p[0], &p[1], &p[2]), second(&p[1], &p[2], &p[3]));
    let dd = (u[0] * u[0] + u[1] * u[1]).max(v[0] * v[0] + v[1] * v[1]);
    let d = if dd < 1e300 {
        dd.sqrt()
    } else {
        u[0].hypot(u[1]).max(v[0].hypot(v[1]))
    };
    let n = ceil_f64((0.75 * d / tolerance.max(1e-6)).sqrt());
    if n.is_finite() {
        (n as u32).clamp(1, crate::limits::MAX_CHORDS)
    } else {
        1
    }
}

/// The region where `path` is flattened finely: the canvas grown by the stroke's reach.
pub(crate) fn flatten_rect(path: &super::Path, width: u32, height: u32) -> [f64; 4] {
    let (w, h) = (width as f64, height as f64);
    // Strokes reach beyond the centerline; flatten generously near the canvas.
    let margin = path.stroke.as_ref().map_or(1.0, |s| {
        let [a, b, c, d] = s.frame;
        let norm = a.hypot(b).max(c.hypot(d));
        1.0 + 0.5 * s.width.abs() * s.miter_limit.max(1.0) * norm
    });
    [-margin, -margin, w + margin, h + margin]
}

/// The flattening tolerance in a stroke's own frame: `tolerance` device pixels divided by
/// the square root of the frame's area scale.
pub(crate) fn frame_tolerance(s: &super::Stroke, tolerance: f64) -> f64 {
    let [a, b, c, d] = s.frame;
    let det = a * d - b * c;
    tolerance / det.abs().sqrt()
}

/// Chords of a round join or cap of half width `h` sweeping `angle` radians at `tolerance`
/// (both in the stroke's frame): 1 to 256.
pub(crate) fn arc_steps(h: f64, tolerance: f64, angle: f64) -> usize {
    if h <= tolerance {
        return 1;
    }
    let step = 2.0 * (1.0 - tolerance / h).clamp(-1.0, 1.0).acos();
    ((angle.abs() / step.max(1e-3)).ceil() as usize).clamp(1, 256)
}

/// Vertices one end cap adds to an outline (0 for butt caps).
pub(crate) fn cap_vertices(cap: super::LineCap, h: f64, tolerance: f64) -> usize {
    match cap {
        super::LineCap::Butt => 0,
        super::LineCap::Square => 2,
        super::LineCap::Round => arc_steps(h, tolerance, std::f64::consts::PI).max(2) - 1,
    }
}

/// A cubic Bézier segment: start, two control points, end.
pub(crate) type Cubic = [Point; 4];

/// `a − b`.
#[inline]
pub(crate) fn sub(a: Point, b: Point) -> Point {
    [a[0] - b[0], a[1] - b[1]]
}

/// Euclidean distance from `a` to `b` (symmetric to the bit: `hypot` ignores signs).
#[inline]
pub(crate) fn dist(a: Point, b: Point) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// `a + w·b`.
#[inline]
pub(crate) fn add_scaled(a: Point, b: Point, w: f64) -> Point {
    [a[0] + w * b[0], a[1] + w * b[1]]
}

/// `w·a`.
#[inline]
pub(crate) fn scale(a: Point, w: f64) -> Point {
    [a[0] * w, a[1] * w]
}

/// The point `a + t·(b − a)`.
#[inline]
pub(crate) fn lerp(a: Point, b: Point, t: f64) -> Point {
    [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
}

/// The midpoint `(a + b) / 2` (which may differ from `lerp(a, b, 0.5)` in the last bit).
#[inline]
pub(crate) fn midpoint(a: Point, b: Point) -> Point {
    [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0]
}

/// Bernstein weights of the four control points of a cubic at `t`.
#[inline]
pub(crate) fn bernstein(t: f64) -> [f64; 4] {
    let s = 1.0 - t;
    [s * s * s, 3.0 * s * s * t, 3.0 * s * t * t, t * t * t]
}

/// The point of the cubic `c` at `t`: `Σ B_k(t) · c[k]` ([`bernstein`]).
#[inline]
pub(crate) fn eval(c: &Cubic, t: f64) -> Point {
    let w = bernstein(t);
    [
        w[0] * c[0][0] + w[1] * c[1][0] + w[2] * c[2][0] + w[3] * c[3][0],
        w[0] * c[0][1] + w[1] * c[1][1] + w[2] * c[2][1] + w[3] * c[3][1],
    ]
}

/// De Casteljau's construction with `between` as the interpolation of two points.
fn de_casteljau(c: &Cubic, between: impl Fn(Point, Point) -> Point) -> (Cubic, Cubic) {
    let ab = between(c[0], c[1]);
    let bc = between(c[1], c[2]);
    let cd = between(c[2], c[3]);
    let abc = between(ab, bc);
    let bcd = between(bc, cd);
    let m = between(abc, bcd);
    ([c[0], ab, abc, m], [m, bcd, cd, c[3]])
}

/// Splits `c` at `t` (de Casteljau with [`lerp`]); the two halves draw the same curve.
pub(crate) fn split(c: &Cubic, t: f64) -> (Cubic, Cubic) {
    de_casteljau(c, |a, b| lerp(a, b, t))
}

/// Splits `c` at `t = ½` (de Casteljau with [`midpoint`]).
pub(crate) fn split_half(c: &Cubic) -> (Cubic, Cubic) {
    de_casteljau(c, midpoint)
}

#[cfg(test)]
mod tests {
    use super::*;

    const C: Cubic = [[0.0, 0.0], [10.0, 20.0], [30.0, 20.0], [40.0, 0.0]];

    #[test]
    fn halves_meet_on_the_curve() {
        for t in [0.25, 0.5, 0.8] {
            let (a, b) = split(&C, t);
            assert_eq!((a[0], b[3], a[3]), (C[0], C[3], b[0]));
            assert!(dist(a[3], eval(&C, t)) < 1e-12);
            assert!(dist(eval(&a, 0.5), eval(&C, 0.5 * t)) < 1e-12);
            assert!(dist(eval(&b, 0.5), eval(&C, 0.5 + 0.5 * t)) < 1e-12);
        }
        let (a, b) = split_half(&C);
        assert_eq!(a[3], [20.0, 15.0]);
        assert_eq!(b[0], a[3]);
        assert_eq!(midpoint(C[0], C[3]), lerp(C[0], C[3], 0.5));
    }

    #[test]
    fn small_helpers() {
        assert_eq!(dist([1.0, 2.0], [4.0, 6.0]), 5.0);
        assert_eq!(dist([4.0, 6.0], [1.0, 2.0]), 5.0);
        assert_eq!(sub([4.0, 6.0], [1.0, 2.0]), [3.0, 4.0]);
        assert_eq!(bernstein(0.0), [1.0, 0.0, 0.0, 0.0]);
        assert_eq!(eval(&C, 1.0), C[3]);
    }
}
