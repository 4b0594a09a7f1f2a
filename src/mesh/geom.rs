//! Convex polygons in screen space whose vertices remember how they were made, so that
//! the area of a clipped piece can be differentiated exactly with respect to the
//! projected triangle vertices.
//!
//! Every piece vertex is a projected vertex, a pixel corner, or the intersection of two
//! lines; every line is a triangle edge (two projected vertices) or a pixel border
//! (`x = c` or `y = c`). Areas come from the shoelace formula; the backward pass runs
//! reverse-mode through the shoelace formula and the line intersections.

/// A line in screen space (pixels, x right, y down).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Line {
    /// Through screen vertices `a` then `b` (indices into the view's screen vertices).
    Edge(u32, u32),
    /// The vertical line `x = c` (a pixel border).
    X(f64),
    /// The horizontal line `y = c` (a pixel border).
    Y(f64),
}

/// Where a polygon vertex comes from (a projected triangle vertex inside a pixel is the
/// crossing of its two edges).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Origin {
    /// A fixed point (pixel corner): no gradient.
    Fixed,
    /// The intersection of two lines.
    Cross(Line, Line),
}

/// A polygon vertex: its position, its origin, and the line of the edge that leaves it
/// (towards the next vertex).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Vertex {
    pub(crate) p: [f64; 2],
    pub(crate) origin: Origin,
    pub(crate) next: Line,
}

/// A convex polygon, counter-clockwise in the sense of a positive shoelace area.
pub(crate) type Poly = Vec<Vertex>;

/// The implicit form `n · p = c` of a line.
#[inline]
fn implicit(line: Line, sv: &[[f64; 2]]) -> ([f64; 2], f64) {
    match line {
        Line::X(c) => ([1.0, 0.0], c),
        Line::Y(c) => ([0.0, 1.0], c),
        Line::Edge(a, b) => {
            let (a, b) = (sv[a as usize], sv[b as usize]);
            // n = perp(b − a), c = n · a = bx·ay − ax·by.
            ([a[1] - b[1], b[0] - a[0]], b[0] * a[1] - a[0] * b[1])
        }
    }
}

/// Signed distance-like value of `p` against a line, positive on the inside: for an
/// edge `a → b` the cross product `(b − a) × (p − a)`; for a border, `side · (p − c)`.
#[inline]
fn side_value(line: Line, side: f64, p: [f64; 2], sv: &[[f64; 2]]) -> f64 {
    side * match line {
        Line::X(c) => p[0] - c,
        Line::Y(c) => p[1] - c,
        Line::Edge(a, b) => {
            let (a, b) = (sv[a as usize], sv[b as usize]);
            (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])
        }
    }
}

/// The intersection of two lines; `None` when they are parallel.
#[inline]
pub(crate) fn cross_point(l1: Line, l2: Line, sv: &[[f64; 2]]) -> Option<[f64; 2]> {
    let (n1, c1) = implicit(l1, sv);
    let (n2, c2) = implicit(l2, sv);
    let det = n1[0] * n2[1] - n1[1] * n2[0];
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    Some([
        (c1 * n2[1] - c2 * n1[1]) / det,
        (n1[0] * c2 - n2[0] * c1) / det,
    ])
}

/// The part of `poly` on the inside (`side · value ≥ 0`) of `line` (Sutherland–Hodgman,
/// keeping each output vertex's origin and outgoing line). An intersection that cannot
/// be computed (parallel lines: a crossing that round-off invented) is skipped.
pub(crate) fn clip(poly: &[Vertex], line: Line, side: f64, sv: &[[f64; 2]], out: &mut Poly) {
    out.clear();
    let n = poly.len();
    if n == 0 {
        return;
    }
    let mut d_prev = side_value(line, side, poly[n - 1].p, sv);
    let mut prev = poly[n - 1];
    for &cur in poly {
        let d_cur = side_value(line, side, cur.p, sv);
        // The edge prev → cur, on the line `prev.next`.
        if d_prev >= 0.0 {
            if d_cur < 0.0 {
                if d_prev > 0.0 {
                    out.push(prev);
                    if let Some(p) = cross_point(prev.next, line, sv) {
                        out.push(Vertex {
                            p,
                            origin: Origin::Cross(prev.next, line),
                            next: line,
                        });
                    }
                } else {
                    out.push(Vertex { next: line, ..prev });
                }
            } else {
                out.push(prev);
            }
        } else if d_cur > 0.0
            && let Some(p) = cross_point(prev.next, line, sv)
        {
            out.push(Vertex {
                p,
                origin: Origin::Cross(prev.next, line),
                next: prev.next,
            });
        }
        d_prev = d_cur;
        prev = cur;
    }
    // `out` was built starting from the last input vertex; the order is still cyclic.
}

/// Shoelace area (positive for counter-clockwise polygons).
#[inline]
pub(crate) fn area(poly: &[Vertex]) -> f64 {
    let n = poly.len();
    if n < 3 {
        return 0.0;
    }
    let mut s = 0.0;
    for i in 0..n {
        let (p, q) = (poly[i].p, poly[(i + 1) % n].p);
        s += p[0] * q[1] - q[0] * p[1];
    }
    0.5 * s
}

/// Area-weighted centroid; `None` for an empty or degenerate polygon.
pub(crate) fn centroid(poly: &[Vertex]) -> Option<[f64; 2]> {
    let n = poly.len();
    let a = area(poly);
    if n < 3 || !(a > 0.0) {
        return None;
    }
    let (mut cx, mut cy) = (0.0, 0.0);
    for i in 0..n {
        let (p, q) = (poly[i].p, poly[(i + 1) % n].p);
        let w = p[0] * q[1] - q[0] * p[1];
        cx += (p[0] + q[0]) * w;
        cy += (p[1] + q[1]) * w;
    }
    Some([cx / (6.0 * a), cy / (6.0 * a)])
}

/// Adds `g · ∂area/∂(screen vertices)` into `grad` (two entries per screen vertex).
pub(crate) fn area_backward(poly: &[Vertex], g: f64, sv: &[[f64; 2]], grad: &mut impl GradSink) {
    let n = poly.len();
    if n < 3 || g == 0.0 {
        return;
    }
    for i in 0..n {
        let prev = poly[(i + n - 1) % n].p;
        let next = poly[(i + 1) % n].p;
        // ∂A/∂x_i = ½ (y_{i+1} − y_{i−1}), ∂A/∂y_i = ½ (x_{i−1} − x_{i+1}).
        let gp = [0.5 * g * (next[1] - prev[1]), 0.5 * g * (prev[0] - next[0])];
        point_backward(poly[i].origin, poly[i].p, gp, sv, grad);
    }
}

/// Receives gradients with respect to screen vertex coordinates.
pub(crate) trait GradSink {
    /// Adds `g` to the gradient of screen vertex `i`'s `(x, y)`.
    fn add(&mut self, i: u32, g: [f64; 2]);
}

/// Back-propagates `gp = ∂L/∂p` of a vertex at `p` with origin `origin`.
#[inline]
fn point_backward(
    origin: Origin,
    p: [f64; 2],
    gp: [f64; 2],
    sv: &[[f64; 2]],
    grad: &mut impl GradSink,
) {
    match origin {
        Origin::Fixed => {}
        Origin::Cross(l1, l2) => {
            // p solves M p = c with M = [n1; n2]: dp = M⁻¹ (dc − dM p), so with
            // λ = M⁻ᵀ gp: ∂L/∂c_k = λ_k and ∂L/∂n_k = −λ_k p.
            let (n1, _) = implicit(l1, sv);
            let (n2, _) = implicit(l2, sv);
            let det = n1[0] * n2[1] - n1[1] * n2[0];
            if det == 0.0 || !det.is_finite() {
                return;
            }
            // M⁻ᵀ = (1/det) [[n2y, −n2x], [−n1y, n1x]].
            let l1g = (n2[1] * gp[0] - n2[0] * gp[1]) / det;
            let l2g = (-n1[1] * gp[0] + n1[0] * gp[1]) / det;
            line_backward(l1, l1g, p, sv, grad);
            line_backward(l2, l2g, p, sv, grad);
        }
    }
}

/// Back-propagates `∂L/∂c = lambda`, `∂L/∂n = −lambda · p` of a line into its points.
#[inline]
fn line_backward(line: Line, lambda: f64, p: [f64; 2], sv: &[[f64; 2]], grad: &mut impl GradSink) {
    if let Line::Edge(a, b) = line {
        let (pa, pb) = (sv[a as usize], sv[b as usize]);
        let (gnx, gny, gc) = (-lambda * p[0], -lambda * p[1], lambda);
        // n = (ay − by, bx − ax), c = bx·ay − ax·by.
        grad.add(a, [-gny - gc * pb[1], gnx + gc * pb[0]]);
        grad.add(b, [gny + gc * pa[1], -gnx - gc * pa[0]]);
    }
}

/// The pixel square `[x, x+1] × [y, y+1]` as a counter-clockwise polygon.
#[cfg(test)]
pub(crate) fn pixel_box(x: f64, y: f64) -> Poly {
    let mut b = Poly::with_capacity(8);
    set_pixel_box(x, y, &mut b);
    b
}

/// Sets `out` to the pixel square `[x, x+1] × [y, y+1]` (counter-clockwise).
#[inline]
pub(crate) fn set_pixel_box(x: f64, y: f64, out: &mut Poly) {
    let (x1, y1) = (x + 1.0, y + 1.0);
    let v = |p, next| Vertex {
        p,
        origin: Origin::Fixed,
        next,
    };
    out.clear();
    out.extend_from_slice(&[
        v([x, y], Line::Y(y)),
        v([x1, y], Line::X(x1)),
        v([x1, y1], Line::Y(y1)),
        v([x, y1], Line::X(x)),
    ]);
}

/// A list of polygons whose buffers are kept and reused: the first `len` are in use, so
/// that the per-pixel loop allocates nothing once the buffers have grown.
#[derive(Default)]
pub(crate) struct Polys {
    polys: Vec<Poly>,
    len: usize,
}

impl Polys {
    /// Empties the list (keeping the buffers).
    #[inline]
    pub(crate) fn clear(&mut self) {
        self.len = 0;
    }

    /// Number of polygons in use.
    #[inline]
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// The polygons in use.
    #[inline]
    pub(crate) fn as_slice(&self) -> &[Poly] {
        &self.polys[..self.len]
    }

    /// Appends an empty polygon and returns it.
    #[inline]
    pub(crate) fn push_new(&mut self) -> &mut Poly {
        if self.len == self.polys.len() {
            self.polys.push(Poly::new());
        }
        let p = &mut self.polys[self.len];
        p.clear();
        self.len += 1;
        p
    }

    /// Appends a copy of `poly`.
    #[inline]
    pub(crate) fn push_copy(&mut self, poly: &[Vertex]) {
        self.push_new().extend_from_slice(poly);
    }

    /// Removes the last polygon.
    #[inline]
    pub(crate) fn pop(&mut self) {
        self.len -= 1;
    }
}

/// `poly` minus the convex polygon whose counter-clockwise edges are `edges`: the
/// pieces (convex, disjoint) are appended to `out`. `rest` and `inside` are scratch.
pub(crate) fn subtract(
    poly: &[Vertex],
    edges: &[Line],
    sv: &[[f64; 2]],
    out: &mut Polys,
    min_area: f64,
    rest: &mut Poly,
    inside: &mut Poly,
) {
    rest.clear();
    rest.extend_from_slice(poly);
    for &e in edges {
        let piece = out.push_new();
        clip(rest, e, -1.0, sv, piece);
        if !(area(piece) > min_area) {
            out.pop();
        }
        clip(rest, e, 1.0, sv, inside);
        std::mem::swap(rest, inside);
        if area(rest) <= min_area {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Dense(Vec<[f64; 2]>);
    impl GradSink for Dense {
        fn add(&mut self, i: u32, g: [f64; 2]) {
            self.0[i as usize][0] += g[0];
            self.0[i as usize][1] += g[1];
        }
    }

    /// The pieces of (triangle 0 ∩ pixel) minus triangle 1.
    fn visible_pieces(sv: &[[f64; 2]]) -> Vec<Poly> {
        let b = pixel_box(0.0, 0.0);
        let mut t = b.clone();
        let mut tmp = Poly::new();
        for k in 0..3u32 {
            clip(&t, Line::Edge(k, (k + 1) % 3), 1.0, sv, &mut tmp);
            std::mem::swap(&mut t, &mut tmp);
        }
        let mut pieces = Polys::default();
        subtract(
            &t,
            &[Line::Edge(3, 4), Line::Edge(4, 5), Line::Edge(5, 3)],
            sv,
            &mut pieces,
            0.0,
            &mut Poly::new(),
            &mut Poly::new(),
        );
        pieces.as_slice().to_vec()
    }

    /// Area of (triangle 0 ∩ pixel) minus triangle 1, as a function of the vertices.
    fn visible(sv: &[[f64; 2]]) -> f64 {
        visible_pieces(sv).iter().map(|p| area(p)).sum()
    }

    fn visible_grad(sv: &[[f64; 2]]) -> Vec<[f64; 2]> {
        let pieces = visible_pieces(sv);
        let mut g = Dense(vec![[0.0; 2]; sv.len()]);
        for p in &pieces {
            area_backward(p, 1.0, sv, &mut g);
        }
        g.0
    }

    #[test]
    fn clipped_area_matches_known_values() {
        // A right triangle covering the lower-left half of the unit pixel (CCW).
        let sv = [[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]];
        let b = pixel_box(0.0, 0.0);
        let mut t = b.clone();
        let mut tmp = Poly::new();
        for k in 0..3u32 {
            clip(&t, Line::Edge(k, (k + 1) % 3), 1.0, &sv, &mut tmp);
            std::mem::swap(&mut t, &mut tmp);
        }
        assert!((area(&t) - 0.5).abs() < 1e-15, "{}", area(&t));
        // The box minus that triangle: the other half.
        let mut pieces = Polys::default();
        subtract(
            &b,
            &[Line::Edge(0, 1), Line::Edge(1, 2), Line::Edge(2, 0)],
            &sv,
            &mut pieces,
            0.0,
            &mut Poly::new(),
            &mut Poly::new(),
        );
        let rest: f64 = pieces.as_slice().iter().map(|p| area(p)).sum();
        assert!((rest - 0.5).abs() < 1e-15, "{rest}");
    }

    #[test]
    fn area_gradient_through_clipping_and_subtraction_matches_differences() {
        // Triangle 0 crosses the pixel; triangle 1 covers part of it.
        let sv0 = [
            [-0.3, -0.2],
            [1.4, 0.35],
            [0.2, 1.3],
            [0.45, -0.5],
            [1.3, 0.9],
            [0.6, 1.5],
        ];
        // Orient both counter-clockwise (positive shoelace).
        let orient = |sv: &mut [[f64; 2]; 6]| {
            for t in 0..2 {
                let (a, b, c) = (sv[3 * t], sv[3 * t + 1], sv[3 * t + 2]);
                let s = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
                if s < 0.0 {
                    sv.swap(3 * t + 1, 3 * t + 2);
                }
            }
        };
        let mut sv = sv0;
        orient(&mut sv);
        let a0 = visible(&sv);
        assert!(a0 > 0.05 && a0 < 0.95, "{a0}");
        let g = visible_grad(&sv);
        let h = 1e-6;
        for i in 0..6 {
            for k in 0..2 {
                let (mut p, mut m) = (sv, sv);
                p[i][k] += h;
                m[i][k] -= h;
                let fd = (visible(&p) - visible(&m)) / (2.0 * h);
                assert!(
                    (fd - g[i][k]).abs() < 1e-6,
                    "vertex {i} coord {k}: analytic {} vs fd {fd}",
                    g[i][k]
                );
            }
        }
    }
}
