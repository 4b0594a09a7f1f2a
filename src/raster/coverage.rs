//! Exact-area coverage accumulation and its boundary-gradient backward pass.
//!
//! **Forward.** Each line segment adds, for every pixel it crosses, its signed trapezoid
//! area to that cell and carries the rest of its height (the "cover") to the next cell;
//! a prefix sum along each row then gives, per pixel, the integral of the winding number
//! over the pixel square: the exact box-filtered coverage of the polygon wherever edges do
//! not overlap inside a pixel (where they do, [`overlap`](super::overlap) can integrate
//! the pixel exactly instead). A segment going down (y increasing) counts +1.
//!
//! **Backward.** Let `G(p) = ∂L/∂w(p)` be the loss gradient with respect to the winding
//! integral of pixel `p`. Moving the boundary by a velocity field `v` changes `Σ G·w` by
//! `∫ G (v · n) ds` (Reynolds transport), with `n ds = (−dy, dx)` along the segment. For a
//! segment `P(t) = P0 + t (P1 − P0)` the velocity is `(1 − t) δP0 + t δP1`, so
//! `∂L/∂P0 = Σ_cells G · ∫(1 − t) dt · N` and `∂L/∂P1 = Σ_cells G · ∫ t dt · N` with
//! `N = (−(y1 − y0), x1 − x0)`, integrating over the piece of the segment inside each cell.
//! No suffix sums, no sampling: exact and deterministic.
//!
//! Coordinates are device pixels (pixel `(i, j)` covers `[i, i+1] × [j, j+1]`).

use crate::scene::Point;

/// A rectangle of cells, `w × h`, whose first cell is device pixel `(x0, y0)`.
#[derive(Clone, Debug, Default)]
pub(crate) struct Cells<T> {
    /// Device column of the first cell.
    pub(crate) x0: i64,
    /// Device row of the first cell.
    pub(crate) y0: i64,
    /// Columns.
    pub(crate) w: usize,
    /// Rows.
    pub(crate) h: usize,
    /// Row-major values.
    pub(crate) data: Vec<T>,
}

impl<T: Copy + Default> Cells<T> {
    /// Resizes to `w × h` at `(x0, y0)` and zeroes.
    pub(crate) fn reset(&mut self, x0: i64, y0: i64, w: usize, h: usize) {
        self.x0 = x0;
        self.y0 = y0;
        self.w = w;
        self.h = h;
        self.data.clear();
        self.data.resize(w * h, T::default());
    }

    /// Resizes to `w × h` at `(x0, y0)` when every value is already zero: only cells
    /// beyond the current length are written.
    pub(crate) fn reshape_zeroed(&mut self, x0: i64, y0: i64, w: usize, h: usize) {
        self.x0 = x0;
        self.y0 = y0;
        self.w = w;
        self.h = h;
        self.data.resize(w * h, T::default());
    }
}

/// Accumulates line segments into `acc`, whose columns must span the segments' clamped
/// x range plus one guard column. Points are clamped to `0 ≤ x ≤ x_max` first (a segment
/// left of the canvas still carries its cover into the row; right of it nothing shows),
/// and rows outside `acc` are skipped.
pub(crate) fn accumulate_line(acc: &mut Cells<f32>, p0: Point, p1: Point, x_max: f64) {
    accumulate_line_visiting(acc, p0, p1, x_max, &mut ());
}

/// What [`accumulate_line_visiting`] tells about the cells a segment crosses.
pub(crate) trait CellVisitor {
    /// The piece of the segment in row `row` (local) crosses the interiors of columns
    /// `c0..=c1` (local; a piece on a vertical grid line is given the cell on its right).
    fn piece(&mut self, row: usize, c0: usize, c1: usize);
}

impl CellVisitor for () {
    #[inline(always)]
    fn piece(&mut self, _: usize, _: usize, _: usize) {}
}

/// [`accumulate_line`], telling `v` which cells the segment's pieces cross (those inside
/// the canvas's columns; pieces clamped onto `x = 0` or `x = x_max` cross none).
#[inline]
pub(crate) fn accumulate_line_visiting<V: CellVisitor>(
    acc: &mut Cells<f32>,
    p0: Point,
    p1: Point,
    x_max: f64,
    v: &mut V,
) {
    if p0[0] >= 0.0 && p0[0] <= x_max && p1[0] >= 0.0 && p1[0] <= x_max {
        // Inside the canvas's columns (the common case): nothing to split or clamp.
        return line_local(acc, p0, p1, v);
    }
    // Split at x = 0 and x = x_max so that the clamped pieces stay exact.
    let mut pieces = [(p0, p1); 3];
    let mut n = 0;
    split_x(p0, p1, 0.0, x_max, &mut |a, b| {
        pieces[n] = (a, b);
        n += 1;
    });
    for &(a, b) in &pieces[..n] {
        let inside = (0.0..=x_max).contains(&(0.5 * (a[0] + b[0])));
        let a = [a[0].clamp(0.0, x_max), a[1]];
        let b = [b[0].clamp(0.0, x_max), b[1]];
        if inside {
            line_local(acc, a, b, v);
        } else {
            line_local(acc, a, b, &mut ());
        }
    }
}

/// Accumulates segment `p0 → p1` of a shape drawn without anti-aliasing
/// (`shape-rendering: crispEdges`): its running sums are then the winding number at each
/// pixel's center, so a pixel is covered (0 or 1) by whether its center is inside.
///
/// Where the segment crosses the center line `y = r + ½` of row `r` at `x`, its
/// direction (+1 going down) is added to the first column whose center lies right of
/// `x`, `⌊x − ½⌋ + 1`; `x` is clamped to `0 ..= x_max` first, as [`accumulate_line`]
/// does. A center exactly on an edge counts as inside below or right of it and outside
/// above or left of it (`min(y) < r + ½ ≤ max(y)`, so a vertex shared by two edges counts
/// once), which is tiny-skia's rounding of the ends to the nearest pixel line, halves
/// up. Rows and columns outside `acc` are skipped.
pub(crate) fn accumulate_centers(acc: &mut Cells<f32>, p0: Point, p1: Point, x_max: f64) {
    if p0[1] == p1[1] {
        return;
    }
    let (dir, a, b) = if p0[1] < p1[1] {
        (1.0f32, p0, p1)
    } else {
        (-1.0, p1, p0)
    };
    let (ox, oy) = (acc.x0 as f64, acc.y0 as f64);
    // Rows whose center lies in (a.y, b.y], within the buffer.
    let first = (floor_f64(a[1] - 0.5) + 1.0).max(oy);
    let end = (floor_f64(b[1] - 0.5) + 1.0).min(oy + acc.h as f64);
    if first >= end {
        return;
    }
    let slope = (b[0] - a[0]) / (b[1] - a[1]);
    let mut y = first;
    while y < end {
        let x = (a[0] + (y + 0.5 - a[1]) * slope).clamp(0.0, x_max);
        let col = floor_f64(x - 0.5) + 1.0 - ox;
        if col >= 0.0 && col < acc.w as f64 {
            acc.data[to_index(y - oy) * acc.w + to_index(col)] += dir;
        }
        y += 1.0;
    }
}

/// Calls `f` with the pieces of `p0 → p1` cut at `x = lo` and `x = hi`, in order.
fn split_x(p0: Point, p1: Point, lo: f64, hi: f64, f: &mut dyn FnMut(Point, Point)) {
    let mut ts = [0.0f64, 1.0, 1.0, 1.0];
    let mut k = 1;
    let dx = p1[0] - p0[0];
    if dx != 0.0 {
        let mut cut = |x: f64| {
            let t = (x - p0[0]) / dx;
            if t > 0.0 && t < 1.0 {
                ts[k] = t;
                k += 1;
            }
        };
        cut(lo);
        cut(hi);
    }
    ts[k] = 1.0;
    ts[1..k].sort_by(|a, b| a.total_cmp(b));
    let at = |t: f64| {
        if t == 0.0 {
            p0
        } else if t == 1.0 {
            p1
        } else {
            [p0[0] + dx * t, p0[1] + (p1[1] - p0[1]) * t]
        }
    };
    for i in 0..k {
        f(at(ts[i]), at(ts[i + 1]));
    }
}

/// Exact-area accumulation of one segment already clamped to the buffer's columns.
#[inline(always)]
fn line_local<V: CellVisitor>(acc: &mut Cells<f32>, p0: Point, p1: Point, v: &mut V) {
    let Some(([ax, ay], [bx, by], dir)) = downward_local(acc, p0, p1) else {
        return;
    };
    let w = acc.w;
    let max_col = from_index(w - 1);
    // A segment inside one row (most chords at a fine tolerance) takes the general loop's
    // values without its division and bookkeeping. The loop's one `dy` is `by − ay`, and
    // its `x` is `ax + 0·dxdy`: `ax` itself, up to the sign of a zero `ax`, which no sum
    // below can tell (the bounds on the two differences keep `dxdy` finite, so that
    // `0·dxdy` is no NaN). So the bits are the loop's (tested). `by ≤ h` follows from
    // `ay < h` and `by ≤ ⌊ay⌋ + 1`.
    if ay >= 0.0 && by - ay > 1e-200 && (bx - ax).abs() < 1e100 {
        let r = floor_non_negative(ay);
        if by <= r + 1.0 {
            let row = to_index(r);
            let line = &mut acc.data[row * w..(row + 1) * w];
            let (c0, c1) = row_piece(line, ax, bx, (by - ay) * dir, max_col);
            return v.piece(row, c0, c1);
        }
    }
    line_rows(acc, [ax, ay], [bx, by], dir, v);
}

/// The segment in `acc`'s local coordinates, top end first, with the sign of its
/// direction (+1 going down); `None` when it is horizontal or lies wholly above or below
/// the buffer's rows, where it adds nothing.
#[inline(always)]
fn downward_local(acc: &Cells<f32>, p0: Point, p1: Point) -> Option<(Point, Point, f64)> {
    if p0[1] == p1[1] {
        return None;
    }
    let (dir, a, b) = if p0[1] < p1[1] {
        (1.0, p0, p1)
    } else {
        (-1.0, p1, p0)
    };
    let ox = acc.x0 as f64;
    let oy = acc.y0 as f64;
    let (a, b) = ([a[0] - ox, a[1] - oy], [b[0] - ox, b[1] - oy]);
    // Written as the test for nothing to do, so that NaN ends go on as they always did.
    if b[1] <= 0.0 || a[1] >= from_index(acc.h) {
        return None;
    }
    Some((a, b, dir))
}

/// [`line_local`]'s general case: `a` above `b` (`ay < by`, local coordinates), `dir` the
/// sign of the original segment's direction; row by row, clipped to the buffer's rows.
fn line_rows<V: CellVisitor>(
    acc: &mut Cells<f32>,
    [ax, ay]: Point,
    [bx, by]: Point,
    dir: f64,
    v: &mut V,
) {
    let h = from_index(acc.h);
    let ytop = ay.max(0.0);
    let ybot = by.min(h);
    // Both are non-negative here (`ytop ≥ 0`, `ybot > ytop`): floor and ceil by casts.
    let rows = to_index(floor_non_negative(ytop))..to_index(ceil_non_negative(ybot)).min(acc.h);
    if ax == bx && ax.is_finite() {
        return vertical_rows(acc, ax, ytop, ybot, dir, rows, v);
    }
    sloped_rows(acc, [ax, ay], [bx, by], dir, rows, v);
}

/// [`line_rows`]'s loop, for any segment.
fn sloped_rows<V: CellVisitor>(
    acc: &mut Cells<f32>,
    [ax, ay]: Point,
    [bx, by]: Point,
    dir: f64,
    rows: std::ops::Range<usize>,
    v: &mut V,
) {
    let (w, h) = (acc.w, from_index(acc.h));
    let max_col = from_index(w - 1);
    let dxdy = (bx - ax) / (by - ay);
    let ytop = ay.max(0.0);
    let ybot = by.min(h);
    let mut x = ax + (ytop - ay) * dxdy;
    let (mut row, last) = (rows.start, rows.end);
    while row < last {
        let r = from_index(row);
        let dy = (r + 1.0).min(ybot) - r.max(ytop);
        let xnext = if r + 1.0 < ybot {
            x + dxdy * dy
        } else if ybot == by {
            bx
        } else {
            ax + (ybot - ay) * dxdy
        };
        let line = &mut acc.data[row * w..(row + 1) * w];
        let (c0, c1) = row_piece(line, x, xnext, dy * dir, max_col);
        v.piece(row, c0, c1);
        x = xnext;
        row += 1;
    }
}

/// [`line_rows`] for a vertical segment at local column position `x`, over `rows` (its
/// clipped span `ytop..ybot`). Every whole row gets the same two values, so they are
/// worked out once: the loop's own values, since its `x` never moves (`x + 0·dy`) and its
/// `dy` is exactly 1 there; the end rows go through [`row_piece`] as in the loop. Frames,
/// rectangles and flags' stripes are mostly such edges, hundreds of rows long.
fn vertical_rows<V: CellVisitor>(
    acc: &mut Cells<f32>,
    x: f64,
    ytop: f64,
    ybot: f64,
    dir: f64,
    rows: std::ops::Range<usize>,
    v: &mut V,
) {
    let w = acc.w;
    let max_col = from_index(w - 1);
    let xl = x.clamp(0.0, max_col);
    let xlf = floor_non_negative(xl);
    let col = to_index(xlf);
    let xm = 0.5 * (xl + xl) - xlf;
    let (left, right) = ((dir * (1.0 - xm)) as f32, (dir * xm) as f32);
    for row in rows {
        let r = from_index(row);
        let line = &mut acc.data[row * w..(row + 1) * w];
        if r >= ytop && r + 1.0 <= ybot {
            line[col] += left;
            if col + 1 < w {
                line[col + 1] += right;
            }
            v.piece(row, col, col);
        } else {
            let dy = (r + 1.0).min(ybot) - r.max(ytop);
            let (c0, c1) = row_piece(line, x, x, dy * dir, max_col);
            v.piece(row, c0, c1);
        }
    }
}

/// Adds the piece of a segment crossing one row from `x` to `xnext` (local columns) with
/// signed height `d` to that row's deltas `line`: each cell it crosses gets the area right
/// of the piece, the next cell the rest of the height. Returns the first and last columns
/// whose interiors the piece crosses.
#[inline(always)]
fn row_piece(line: &mut [f32], x: f64, xnext: f64, d: f64, max_col: f64) -> (usize, usize) {
    let w = line.len();
    let (xl, xr) = if x < xnext { (x, xnext) } else { (xnext, x) };
    let xl = xl.clamp(0.0, max_col);
    let xr = xr.clamp(0.0, max_col);
    let xlf = floor_non_negative(xl);
    let xli = to_index(xlf);
    let xrc = ceil_non_negative(xr);
    let xri = to_index(xrc);
    if xri <= xli + 1 {
        // Within one cell: area right of the piece stays, the rest carries on.
        let xm = 0.5 * (xl + xr) - xlf;
        line[xli] += (d * (1.0 - xm)) as f32;
        if xli + 1 < w {
            line[xli + 1] += (d * xm) as f32;
        }
        (xli, xli)
    } else {
        // Across several cells: the piece's height is spread uniformly over x.
        let s = 1.0 / (xr - xl);
        let xlfrac = xl - xlf;
        let a0 = 0.5 * s * (1.0 - xlfrac) * (1.0 - xlfrac);
        let xrfrac = xr - xrc + 1.0;
        let am = 0.5 * s * xrfrac * xrfrac;
        line[xli] += (d * a0) as f32;
        if xri == xli + 2 {
            line[xli + 1] += (d * (1.0 - a0 - am)) as f32;
        } else {
            let a1 = s * (1.5 - xlfrac);
            line[xli + 1] += (d * (a1 - a0)) as f32;
            let ds = (d * s) as f32;
            for c in &mut line[xli + 2..xri - 1] {
                *c += ds;
            }
            let a2 = a1 + (xri - xli - 3) as f64 * s;
            line[xri - 1] += (d * (1.0 - a2 - am)) as f32;
        }
        if xri < w {
            line[xri] += (d * am) as f32;
        }
        (xli, xri - 1)
    }
}

/// Backward of [`accumulate_line`]: `∂L/∂p0` and `∂L/∂p1`.
///
/// `g` holds, per cell, the loss gradient with respect to the cell's winding integral as
/// two one-sided values: `[∂L/∂w⁺, ∂L/∂w⁻]` for `w` increasing and decreasing (they differ
/// only where the coverage rule has a kink, e.g. `w` exactly 0 or 1 under nonzero). Cells
/// outside `g` count as zero.
///
/// Moving the segment along its normal `N = (−dy, dx)` raises `w` in the cells on the side
/// `N` points to (the "low" side) and lowers it on the other. A piece inside one cell uses
/// the mean of the two one-sided values; a piece lying exactly on a cell boundary uses the
/// low cell's `∂L/∂w⁺` and the high cell's `∂L/∂w⁻`, averaged. So at kinks the result is the
/// mean of the one-sided derivatives, which is what a central difference measures, and a
/// shape whose edges sit exactly on pixel boundaries still gets a useful gradient.
///
/// Returns `[∂L/∂p0, ∂L/∂p1]`, each `+0.0` where nothing reaches it.
#[inline]
pub(crate) fn backward_line(g: &Cells<[f32; 2]>, p0: Point, p1: Point) -> [Point; 2] {
    let (dx, dy) = (p1[0] - p0[0], p1[1] - p0[1]);
    let (s0, s1) = line_weights(g, p0, p1, dx, dy);
    // `0.0 + …`: the bits of accumulating into zeroed gradients (a `−0.0` product adds
    // up to `+0.0`).
    let n = [-dy, dx];
    [
        [0.0 + s0 * n[0], 0.0 + s0 * n[1]],
        [0.0 + s1 * n[0], 0.0 + s1 * n[1]],
    ]
}

/// `(Σ G ∫(1 − t), Σ G ∫ t)` of [`backward_line`]'s segment, returned in registers (a
/// gradient written through a pointer and read back whole stalled the caller).
/// `dx`, `dy` are `p1 − p0` as the caller computed them.
fn line_weights(g: &Cells<[f32; 2]>, p0: Point, p1: Point, dx: f64, dy: f64) -> (f64, f64) {
    if (dx == 0.0 && dy == 0.0) || g.w == 0 || g.h == 0 {
        return (0.0, 0.0);
    }
    let (xlo, ylo) = (g.x0 as f64, g.y0 as f64);
    let (xhi, yhi) = (xlo + from_index(g.w), ylo + from_index(g.h));
    // Both ends inside the closed box (most segments): clipping would give exactly
    // `t ∈ [0, 1]`. Along an axis with `d > 0`, `lo ≤ o` makes `(lo − o) / d ≤ 0` and
    // `hi ≥ e` makes `hi − o ≥ e − o = d` after rounding (rounding is monotonic, and `d`
    // was computed as `e − o`), so `(hi − o) / d ≥ 1`; mirrored for `d < 0`. The only
    // difference is the sign of a zero `t0`, which no value below can tell (tested).
    let inside = |o: f64, e: f64, lo: f64, hi: f64| lo <= o.min(e) && o.max(e) <= hi;
    if !(inside(p0[0], p1[0], xlo, xhi) && inside(p0[1], p1[1], ylo, yhi)) {
        return match clip_to_box(p0, dx, dy, [xlo, ylo, xhi, yhi]) {
            Some((t0, t1)) => walk_pieces(g, p0, dx, dy, t0, t1),
            None => (0.0, 0.0),
        };
    }
    // Inside one cell of `g` as well (most chords at a fine tolerance): the walk finds no
    // grid line before `t = 1` (rounding is monotonic, so an end point short of the next
    // line gives a parameter of at least 1), so it takes one piece with
    // `∫ t = ∫ (1 − t) = 0.5` around the midpoint. The same bits without the walk's four
    // divisions (tested). Checked on the end point itself, not on `p0 + dx`, which may
    // round across a line the point is short of.
    let one_cell = |o: f64, d: f64, e: f64| {
        d == 0.0 || (d > 0.0 && e <= floor_f64(o) + 1.0) || (d < 0.0 && e >= ceil_f64(o) - 1.0)
    };
    if one_cell(p0[0], dx, p1[0]) && one_cell(p0[1], dy, p1[1]) {
        let gv = piece_gradient(g, [p0[0] + dx * 0.5, p0[1] + dy * 0.5], dx, dy);
        return if gv != 0.0 {
            (0.0 + gv * 0.5, 0.0 + gv * 0.5)
        } else {
            (0.0, 0.0)
        };
    }
    walk_pieces(g, p0, dx, dy, 0.0, 1.0)
}

/// The parameter range `[t0, t1] ⊆ [0, 1]` of the segment from `p0` along `(dx, dy)` inside
/// the closed box `[xlo, ylo, xhi, yhi]` (boundary lines count: the cell inside may see a
/// piece lying on them); `None` when it has no length there.
pub(crate) fn clip_to_box(
    p0: Point,
    dx: f64,
    dy: f64,
    [xlo, ylo, xhi, yhi]: [f64; 4],
) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (o, d, lo, hi) in [(p0[0], dx, xlo, xhi), (p0[1], dy, ylo, yhi)] {
        if d == 0.0 {
            if o < lo || o > hi {
                return None;
            }
        } else {
            let (a, b) = ((lo - o) / d, (hi - o) / d);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
    }
    (t1 > t0).then_some((t0, t1))
}

/// `(Σ G ∫(1 − t), Σ G ∫ t)` over the pieces between grid lines of the segment from `p0`
/// along `(dx, dy)` for `t ∈ [t0, t1]`.
fn walk_pieces(g: &Cells<[f32; 2]>, p0: Point, dx: f64, dy: f64, t0: f64, t1: f64) -> (f64, f64) {
    let at = |t: f64| [p0[0] + dx * t, p0[1] + dy * t];
    // Next integer grid line strictly after `v` in the direction of `d`, as a parameter.
    let next = |v: f64, o: f64, d: f64| -> f64 {
        if d > 0.0 {
            (floor_f64(v) + 1.0 - o) / d
        } else if d < 0.0 {
            (ceil_f64(v) - 1.0 - o) / d
        } else {
            f64::INFINITY
        }
    };
    let start = at(t0);
    let mut nx = next(start[0], p0[0], dx);
    let mut ny = next(start[1], p0[1], dy);
    let step_x = if dx != 0.0 {
        1.0 / dx.abs()
    } else {
        f64::INFINITY
    };
    let step_y = if dy != 0.0 {
        1.0 / dy.abs()
    } else {
        f64::INFINITY
    };
    let mut ta = t0;
    let (mut s0, mut s1) = (0.0f64, 0.0f64); // Σ G ∫(1 − t), Σ G ∫ t
    let mut guard = 0usize;
    while ta < t1 && guard < 1 << 24 {
        guard += 1;
        let tb = nx.min(ny).min(t1);
        if tb > ta {
            let gv = piece_gradient(g, at(0.5 * (ta + tb)), dx, dy);
            if gv != 0.0 {
                let it = 0.5 * (tb * tb - ta * ta);
                s1 += gv * it;
                s0 += gv * ((tb - ta) - it);
            }
        }
        ta = tb;
        if nx <= tb {
            nx += step_x;
        }
        if ny <= tb {
            ny += step_y;
        }
    }
    (s0, s1)
}

/// The gradient `G` that a piece of a segment with direction `(dx, dy)` and midpoint `m`
/// (device pixels) sees: the mean of its cell's two one-sided values, or, for a piece
/// lying on a grid line, the low cell's `∂L/∂w⁺` and the high cell's `∂L/∂w⁻` averaged
/// (see [`backward_line`]). Cells outside `g` count as zero.
#[inline(always)]
fn piece_gradient(g: &Cells<[f32; 2]>, m: Point, dx: f64, dy: f64) -> f64 {
    let cell = |col: f64, row: f64| -> [f32; 2] {
        let (c, r) = (to_index(col), to_index(row));
        if col >= 0.0 && row >= 0.0 && c < g.w && r < g.h {
            g.data[r * g.w + c]
        } else {
            [0.0; 2]
        }
    };
    let col = floor_f64(m[0] - g.x0 as f64);
    let row = floor_f64(m[1] - g.y0 as f64);
    if dx == 0.0 && m[0] == floor_f64(m[0]) {
        // On a vertical grid line: cells `col − 1` (left) and `col` (right).
        let (left, right) = (cell(col - 1.0, row), cell(col, row));
        let (low, high) = if dy > 0.0 {
            (left, right)
        } else {
            (right, left)
        };
        0.5 * (low[0] + high[1]) as f64
    } else if dy == 0.0 && m[1] == floor_f64(m[1]) {
        // On a horizontal grid line: rows `row − 1` (above) and `row` (below).
        let (above, below) = (cell(col, row - 1.0), cell(col, row));
        let (low, high) = if dx > 0.0 {
            (below, above)
        } else {
            (above, below)
        };
        0.5 * (low[0] + high[1]) as f64
    } else {
        let c = cell(col, row);
        0.5 * (c[0] + c[1]) as f64
    }
}

/// One-sided slopes `(d cov/dw⁺, d cov/dw⁻)` of the coverage rule at `w` (see
/// [`coverage`]); equal except at kinks.
#[inline]
pub(crate) fn coverage_slopes(w: f32, evenodd: bool) -> (f32, f32) {
    // A winding integral within rounding of an integer *is* that integer (a pixel wholly
    // inside or outside whose area was summed from fractions); its slopes are one-sided.
    const EPS: f32 = 4e-6;
    if !evenodd {
        // Fast path for the common fractional case.
        let a = w.abs();
        if a > EPS && a < 1.0 - EPS {
            let s = if w > 0.0 { 1.0 } else { -1.0 };
            return (s, s);
        }
        if a > 1.0 + EPS {
            return (0.0, 0.0);
        }
    }
    let r = round_f32(w);
    let w = if (w - r).abs() < EPS { r } else { w };
    if evenodd {
        // Triangle wave of period 2: rising on [0, 1], falling on [1, 2].
        let m = w - 2.0 * floor_f32(0.5 * w);
        let plus = if m < 1.0 { 1.0 } else { -1.0 };
        let minus = if m > 0.0 && m <= 1.0 { 1.0 } else { -1.0 };
        (plus, minus)
    } else {
        let plus = if (0.0..1.0).contains(&w) {
            1.0
        } else if (-1.0..0.0).contains(&w) {
            -1.0
        } else {
            0.0
        };
        let minus = if w > 0.0 && w <= 1.0 {
            1.0
        } else if w > -1.0 && w <= 0.0 {
            -1.0
        } else {
            0.0
        };
        (plus, minus)
    }
}

// Rounding without libm: on x86-64 without SSE4.1, `floor`, `ceil` and `round` are function
// calls, and they showed up as 11% of a painterly optimization step (perf). Truncating
// casts are single instructions; the fallbacks keep huge and non-finite values exact.

/// `x.floor()` for `x ≥ 0`.
#[inline]
fn floor_non_negative(x: f64) -> f64 {
    // Through i64, not u64: on x86-64 the signed conversions are one instruction each,
    // the unsigned ones a branchy sequence.
    if x < 4.5e15 {
        (x as i64) as f64
    } else {
        x.floor()
    }
}

/// A non-negative whole number held in an `f64` (below 2⁶³) as an index: through
/// `i64`, one instruction on x86-64, where a direct `as usize` is a branchy sequence.
/// Negative or NaN input gives 0 (and saturates above), as `as usize` would.
#[inline]
fn to_index(x: f64) -> usize {
    (x as i64).max(0) as usize
}

/// An index or size as an `f64`, through `i64` (one instruction on x86-64, where a
/// direct `as f64` from `usize` is a branchy sequence); exact below 2⁵³.
#[inline]
fn from_index(i: usize) -> f64 {
    i as i64 as f64
}

/// `x.ceil()` for `x ≥ 0`.
#[inline]
fn ceil_non_negative(x: f64) -> f64 {
    let t = floor_non_negative(x);
    if t < x { t + 1.0 } else { t }
}

/// (`floor` and `ceil` of any `f64` live beside the curve math, which uses them too.)
pub(crate) use crate::scene::geom::{ceil_f64, floor_f64};

/// `x.floor()`, without the library call that baseline x86-64 makes of it.
#[inline]
pub(crate) fn floor_f32(x: f32) -> f32 {
    if x.abs() < 8.0e6 {
        let t = (x as i32) as f32;
        if t > x { t - 1.0 } else { t }
    } else {
        x.floor()
    }
}

/// `x.round()` (halves away from zero).
#[inline]
fn round_f32(x: f32) -> f32 {
    if x.abs() < 8.0e6 {
        let t = floor_f32(x.abs());
        let r = if x.abs() - t >= 0.5 { t + 1.0 } else { t };
        r.copysign(x)
    } else {
        x.round()
    }
}

/// Coverage from a winding integral under a fill rule, and its derivative.
/// Nonzero: `min(|w|, 1)`; even-odd: `|w − 2·round(w/2)|`.
#[inline]
pub(crate) fn coverage(w: f32, evenodd: bool) -> (f32, f32) {
    if evenodd {
        let f = w - 2.0 * round_f32(0.5 * w);
        (
            f.abs(),
            if f > 0.0 {
                1.0
            } else if f < 0.0 {
                -1.0
            } else {
                0.0
            },
        )
    } else {
        let a = w.abs();
        if a >= 1.0 {
            (1.0, 0.0)
        } else {
            (
                a,
                if w > 0.0 {
                    1.0
                } else if w < 0.0 {
                    -1.0
                } else {
                    0.0
                },
            )
        }
    }
}

/// The coverages of a row of winding integrals: `out[i] = coverage(row[i], evenodd).0`
/// with the same bits, eight at a time.
///
/// Even-odd takes the nearest integer `r` of `w/2` from a truncation (any rule at ties:
/// there `|w − 2r|` is 1 either way) and forms `|w − 2r|` as [`coverage`] does; every step
/// is exact for `|w| < 8·10⁶`, and chunks with a larger value take the scalar rule.
pub(crate) fn coverage_row(row: &[f32], evenodd: bool, out: &mut [f32]) {
    use wide::f32x8;
    let n = row.len().min(out.len());
    let (one, half, big) = (f32x8::ONE, f32x8::splat(0.5), f32x8::splat(8.0e6));
    let mut k = 0;
    while k + 8 <= n {
        let w = f32x8::new(row[k..k + 8].try_into().expect("eight values"));
        let cov = if !evenodd {
            w.abs().fast_min(one)
        } else if w.abs().simd_lt(big).all() {
            let h = w * half;
            let t = h.trunc_int().round_float();
            let d = h - t;
            let r = t + (d.simd_gt(half) & one) - (d.simd_lt(-half) & one);
            (w - (r + r)).abs()
        } else {
            f32x8::new(std::array::from_fn(|i| coverage(row[k + i], true).0))
        };
        out[k..k + 8].copy_from_slice(&cov.to_array());
        k += 8;
    }
    for i in k..n {
        out[i] = coverage(row[i], evenodd).0;
    }
}

/// The one-sided slopes of a row of winding integrals: `(up[i], down[i]) =
/// coverage_slopes(row[i], evenodd)` with the same bits, eight at a time (chunks with a
/// value of `8·10⁶` or more take the scalar rule).
pub(crate) fn coverage_slopes_row(row: &[f32], evenodd: bool, up: &mut [f32], down: &mut [f32]) {
    use wide::f32x8;
    const EPS: f32 = 4e-6;
    let n = row.len().min(up.len()).min(down.len());
    let (one, half, zero) = (f32x8::ONE, f32x8::splat(0.5), f32x8::ZERO);
    let (eps, big) = (f32x8::splat(EPS), f32x8::splat(8.0e6));
    // `floor_f32` of each lane, for |x| < 8·10⁶.
    let floor = |x: f32x8| {
        let t = x.trunc_int().round_float();
        t - (t.simd_gt(x) & one)
    };
    let mut k = 0;
    while k + 8 <= n {
        let w = f32x8::new(row[k..k + 8].try_into().expect("eight values"));
        if !w.abs().simd_lt(big).all() {
            for i in k..k + 8 {
                (up[i], down[i]) = coverage_slopes(row[i], evenodd);
            }
            k += 8;
            continue;
        }
        // A value within rounding of an integer is that integer (ties never are).
        let t = w.trunc_int().round_float();
        let d = w - t;
        let r = t + (d.simd_gt(half) & one) - (d.simd_lt(-half) & one);
        let w = (w - r).abs().simd_lt(eps).select(r, w);
        let (plus, minus) = if evenodd {
            let m = w - 2.0 * floor(w * half);
            (
                m.simd_lt(one).select(one, -one),
                (m.simd_gt(zero) & m.simd_le(one)).select(one, -one),
            )
        } else {
            let plus = (w.simd_ge(zero) & w.simd_lt(one))
                .select(one, (w.simd_ge(-one) & w.simd_lt(zero)).select(-one, zero));
            let minus = (w.simd_gt(zero) & w.simd_le(one))
                .select(one, (w.simd_gt(-one) & w.simd_le(zero)).select(-one, zero));
            (plus, minus)
        };
        up[k..k + 8].copy_from_slice(&plus.to_array());
        down[k..k + 8].copy_from_slice(&minus.to_array());
        k += 8;
    }
    for i in k..n {
        (up[i], down[i]) = coverage_slopes(row[i], evenodd);
    }
}

/// Prefix-sums each row of `acc` into winding integrals, in place.
pub(crate) fn integrate_rows(acc: &mut Cells<f32>) {
    let w = acc.w;
    if w == 0 {
        return;
    }
    for row in acc.data.chunks_exact_mut(w) {
        let mut s = 0.0f32;
        for c in row.iter_mut() {
            s += *c;
            *c = s;
        }
    }
}

#[cfg(test)]
mod rounding_tests {
    use super::*;

    /// The eight-wide coverage and slopes have the bits of the scalar rules, near and
    /// away from every integer, for both fill rules and for huge values.
    #[test]
    fn row_rules_match_the_scalar_rules() {
        let mut ws: Vec<f32> = Vec::new();
        for k in -9..=9 {
            let b = k as f32;
            for d in [0.0f32, 1e-10, 1e-7, 4e-6, 0.25, 0.5, 0.75, 0.999_999] {
                ws.extend([b + d, b - d, 0.5 * b + d, 0.5 * b - d]);
            }
        }
        ws.extend([
            8.0e6,
            -8.0e6,
            7.9e6 + 0.5,
            1e9,
            -1e9,
            f32::MIN_POSITIVE,
            -0.0,
            -1e-30,
        ]);
        let mut rng = crate::scene::random::Rng::new(3);
        ws.extend((0..4000).map(|_| rng.range(-20.0, 20.0) as f32));
        let mut out = vec![0.0f32; ws.len()];
        let (mut up, mut down) = (out.clone(), out.clone());
        for evenodd in [false, true] {
            coverage_slopes_row(&ws, evenodd, &mut up, &mut down);
            for (i, w) in ws.iter().enumerate() {
                let (u, d) = coverage_slopes(*w, evenodd);
                assert_eq!(
                    (up[i].to_bits(), down[i].to_bits()),
                    (u.to_bits(), d.to_bits()),
                    "slopes at w {w} even-odd {evenodd}"
                );
            }
            coverage_row(&ws, evenodd, &mut out);
            for (w, c) in ws.iter().zip(&out) {
                let want = coverage(*w, evenodd).0;
                assert_eq!(
                    c.to_bits(),
                    want.to_bits(),
                    "w {w} even-odd {evenodd}: {c} vs {want}"
                );
            }
        }
    }

    #[test]
    fn fast_rounding_matches_std() {
        let mut v: Vec<f32> = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            0.49999997,
            -0.49999997,
            1e-30,
            -1e-30,
            7.9e6,
            -7.9e6,
            9e6,
            -9e6,
            1e20,
            f32::MAX,
            f32::MIN,
        ];
        for i in -400..400 {
            v.push(i as f32 * 0.0137);
        }
        for &x in &v {
            assert_eq!(floor_f32(x), x.floor(), "floor {x}");
            assert_eq!(round_f32(x), x.round(), "round {x}");
            let d = x.abs() as f64;
            assert_eq!(floor_non_negative(d), d.floor(), "floor {d}");
            // Equal as numbers (−0 may come out as +0, which compares and indexes alike).
            assert_eq!(floor_f64(d), d.floor(), "floor {d}");
            assert_eq!(floor_f64(-d), (-d).floor(), "floor {}", -d);
            assert_eq!(floor_f64(d + 0.5), (d + 0.5).floor(), "floor {}", d + 0.5);
            assert_eq!(ceil_f64(-d - 0.5), (-d - 0.5).ceil(), "ceil {}", -d - 0.5);
            assert_eq!(ceil_f64(d), d.ceil(), "ceil {d}");
            assert_eq!(ceil_non_negative(d), d.ceil(), "ceil {d}");
        }
        assert!(round_f32(f32::NAN).is_nan());
        assert!(floor_f32(f32::NAN).is_nan());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Winding integrals of a closed polygon on a `w × h` canvas.
    pub(crate) fn raster(poly: &[Point], w: usize, h: usize) -> Cells<f32> {
        let mut acc = Cells::default();
        acc.reset(0, 0, w + 1, h);
        for i in 0..poly.len() {
            accumulate_line(&mut acc, poly[i], poly[(i + 1) % poly.len()], w as f64);
        }
        integrate_rows(&mut acc);
        acc
    }

    /// Vertex gradients of a closed polygon from one-sided cell gradients `g`.
    fn polygon_grad(g: &Cells<[f32; 2]>, poly: &[Point]) -> Vec<Point> {
        let n = poly.len();
        let mut grad = vec![[0.0; 2]; n];
        for i in 0..n {
            let j = (i + 1) % n;
            let [a, b] = backward_line(g, poly[i], poly[j]);
            for c in 0..2 {
                grad[i][c] += a[c];
                grad[j][c] += b[c];
            }
        }
        grad
    }

    /// Asserts `grad` matches central differences of `loss` at `poly` within `tol`.
    fn assert_matches_differences(
        poly: &[Point],
        grad: &[Point],
        loss: impl Fn(&[Point]) -> f64,
        tol: f64,
    ) {
        let e = 1e-3;
        for i in 0..poly.len() {
            for c in 0..2 {
                let mut p = poly.to_vec();
                p[i][c] += e;
                let lp = loss(&p);
                p[i][c] -= 2.0 * e;
                let lm = loss(&p);
                let fd = (lp - lm) / (2.0 * e);
                assert!(
                    (fd - grad[i][c]).abs() < tol,
                    "v{i} c{c}: fd {fd} an {}",
                    grad[i][c]
                );
            }
        }
    }

    /// The bits of every value of `c`.
    fn bits(c: &Cells<f32>) -> Vec<u32> {
        c.data.iter().map(|v| v.to_bits()).collect()
    }

    /// [`line_local`] without its one-row shortcut: the general row loop for every segment.
    fn line_local_by_rows(acc: &mut Cells<f32>, p0: Point, p1: Point) {
        if let Some((a, b, dir)) = downward_local(acc, p0, p1) {
            line_rows(acc, a, b, dir, &mut ());
        }
    }

    #[test]
    fn one_row_shortcut_has_the_bits_of_the_row_loop() {
        let mut rng = crate::scene::random::Rng::new(11);
        // Coordinates snapped now and then to whole and half pixels, to the buffer's edges
        // (zero, of either sign) and to values a hair apart, where the shortcut's
        // conditions sit on their boundaries.
        let mut coord = |lo: f64, hi: f64| -> f64 {
            let v = rng.range(lo, hi);
            match rng.next_u64() % 8 {
                0 => v.round(),
                1 => (2.0 * v).round() / 2.0,
                2 => 0.0,
                3 => -0.0,
                4 => v.round() + 1e-12,
                _ => v,
            }
        };
        let (mut fast, mut slow) = (Cells::default(), Cells::default());
        let mut shortcuts = 0;
        for case in 0..20_000 {
            let (x0, y0) = if case % 2 == 0 { (0, 0) } else { (3, -2) };
            fast.reset(x0, y0, 9, 6);
            slow.reset(x0, y0, 9, 6);
            for _ in 0..4 {
                let ox = x0 as f64;
                let p0 = [ox + coord(0.0, 8.0).abs(), coord(-1.0, 7.0) + y0 as f64];
                let near = coord(-1.2, 1.2);
                let p1 = [(p0[0] + coord(-2.0, 2.0)).clamp(ox, ox + 8.0), p0[1] + near];
                line_local(&mut fast, p0, p1, &mut ());
                line_local_by_rows(&mut slow, p0, p1);
                let (ay, by) = (p0[1].min(p1[1]) - y0 as f64, p0[1].max(p1[1]) - y0 as f64);
                if ay >= 0.0 && by <= 6.0 && ay.floor() + 1.0 >= by && ay < by {
                    shortcuts += 1;
                }
            }
            assert_eq!(bits(&fast), bits(&slow), "case {case}");
        }
        assert!(shortcuts > 10_000, "only {shortcuts} one-row segments");
    }

    #[test]
    fn vertical_segments_have_the_bits_of_the_row_loop() {
        let mut rng = crate::scene::random::Rng::new(12);
        let (mut fast, mut slow) = (Cells::default(), Cells::default());
        let mut whole_rows = 0;
        for case in 0..20_000 {
            let (x0, y0) = if case % 2 == 0 { (0, 0) } else { (3, -2) };
            fast.reset(x0, y0, 9, 12);
            slow.reset(x0, y0, 9, 12);
            // Columns inside, on grid lines, on the last column and beyond it (clamped);
            // ends inside, on grid lines and beyond the rows.
            let x = match case % 5 {
                0 => rng.range(0.0, 8.0).round(),
                1 => 8.0 + rng.range(0.0, 3.0),
                _ => rng.range(0.0, 8.0),
            } + x0 as f64;
            let mut y = || match rng.next_u64() % 4 {
                0 => rng.range(-3.0, 15.0).round(),
                _ => rng.range(-3.0, 15.0),
            } + y0 as f64;
            let (ya, yb) = (y(), y());
            for (c, by_loop) in [(&mut fast, false), (&mut slow, true)] {
                let Some((a, b, dir)) = downward_local(c, [x, ya], [x, yb]) else {
                    continue;
                };
                if by_loop {
                    let rows = to_index(floor_non_negative(a[1].max(0.0)))
                        ..to_index(ceil_non_negative(b[1].min(12.0))).min(12);
                    sloped_rows(c, a, b, dir, rows, &mut ());
                } else {
                    line_rows(c, a, b, dir, &mut ());
                    whole_rows += (b[1].min(12.0).floor() - a[1].max(0.0).ceil()).max(0.0) as usize;
                }
            }
            assert_eq!(
                bits(&fast),
                bits(&slow),
                "case {case}: x {x}, y {ya} → {yb}"
            );
        }
        assert!(whole_rows > 50_000, "only {whole_rows} whole rows");
    }

    #[test]
    fn shortcuts_have_the_bits_of_the_clipped_walk() {
        let mut rng = crate::scene::random::Rng::new(5);
        let mut g: Cells<[f32; 2]> = Cells::default();
        g.reset(-1, 2, 6, 5);
        for v in &mut g.data {
            // Zeros, equal and unequal one-sided values.
            let a = rng.range(-1.0, 1.0) as f32;
            *v = match rng.next_u64() % 4 {
                0 => [0.0, 0.0],
                1 => [a, a],
                _ => [a, rng.range(-1.0, 1.0) as f32],
            };
        }
        let mut coord = |lo: f64, hi: f64| -> f64 {
            let v = rng.range(lo, hi);
            match rng.next_u64() % 8 {
                0 => v.round(),
                1 => (4.0 * v).round() / 4.0,
                2 => v.round() - 1e-13,
                3 => v.round() + 1e-13,
                _ => v,
            }
        };
        let (mut shortcuts, mut unclipped) = (0, 0);
        let bx = [
            g.x0 as f64,
            g.y0 as f64,
            (g.x0 + 6) as f64,
            (g.y0 + 5) as f64,
        ];
        for case in 0..100_000 {
            let p0 = [coord(-2.0, 6.0), coord(1.0, 8.0)];
            let p1 = match case % 3 {
                0 => [p0[0], coord(1.0, 8.0)],
                1 => [coord(-2.0, 6.0), p0[1]],
                _ => [p0[0] + coord(-1.0, 1.0), p0[1] + coord(-1.0, 1.0)],
            };
            let (dx, dy) = (p1[0] - p0[0], p1[1] - p0[1]);
            if dx == 0.0 && dy == 0.0 {
                continue;
            }
            let fast = line_weights(&g, p0, p1, dx, dy);
            // The walk with the clipping always done, as it was before the box shortcut.
            let walk = match clip_to_box(p0, dx, dy, bx) {
                Some((t0, t1)) => walk_pieces(&g, p0, dx, dy, t0, t1),
                None => (0.0, 0.0),
            };
            assert_eq!(
                (fast.0.to_bits(), fast.1.to_bits()),
                (walk.0.to_bits(), walk.1.to_bits()),
                "{p0:?} → {p1:?}"
            );
            let same_cell = |a: f64, b: f64| a.floor() == b.floor() || a.ceil() == b.ceil();
            let within = |a: f64, b: f64, lo: f64, hi: f64| lo <= a.min(b) && a.max(b) <= hi;
            if same_cell(p0[0], p1[0]) && same_cell(p0[1], p1[1]) {
                shortcuts += 1;
            } else if within(p0[0], p1[0], bx[0], bx[2]) && within(p0[1], p1[1], bx[1], bx[3]) {
                unclipped += 1;
            }
        }
        assert!(shortcuts > 10_000, "only {shortcuts} one-cell segments");
        assert!(unclipped > 10_000, "only {unclipped} unclipped walks");
    }

    #[test]
    fn unit_square_on_pixel_grid() {
        let sq = [[1.0, 1.0], [3.0, 1.0], [3.0, 3.0], [1.0, 3.0]];
        let acc = raster(&sq, 4, 4);
        for y in 0..4 {
            for x in 0..4 {
                let v = acc.data[y * 5 + x].abs();
                let inside = (1..3).contains(&x) && (1..3).contains(&y);
                assert!(
                    (v - if inside { 1.0 } else { 0.0 }).abs() < 1e-6,
                    "{x},{y}: {v}"
                );
            }
        }
    }

    #[test]
    fn half_pixel_offsets_give_fractional_area() {
        let sq = [[0.5, 0.25], [2.0, 0.25], [2.0, 1.0], [0.5, 1.0]];
        let acc = raster(&sq, 3, 2);
        assert!((acc.data[0].abs() - 0.375).abs() < 1e-6);
        assert!((acc.data[1].abs() - 0.75).abs() < 1e-6);
        assert!(acc.data[2].abs() < 1e-6);
    }

    #[test]
    fn triangle_total_area() {
        let tri = [[0.3, 0.7], [9.1, 2.2], [4.4, 8.9]];
        let acc = raster(&tri, 10, 10);
        let total: f32 = acc.data.iter().map(|v| v.abs()).sum();
        let area = 0.5
            * ((tri[1][0] - tri[0][0]) * (tri[2][1] - tri[0][1])
                - (tri[2][0] - tri[0][0]) * (tri[1][1] - tri[0][1]))
                .abs();
        assert!((total as f64 - area).abs() < 1e-4, "{total} vs {area}");
    }

    #[test]
    fn backward_matches_finite_differences() {
        // Loss = Σ G · w with fixed G: gradient of each vertex against differences.
        let tri = [[1.3, 0.7], [8.1, 2.2], [4.4, 7.9]];
        let (w, h) = (10usize, 10usize);
        let mut g = Cells::<[f32; 2]>::default();
        g.reset(0, 0, w + 1, h);
        for (i, v) in g.data.iter_mut().enumerate() {
            let x = ((i * 7919) % 13) as f32 / 13.0 - 0.4;
            *v = [x, x];
        }
        let loss = |poly: &[Point]| -> f64 {
            let acc = raster(poly, w, h);
            acc.data
                .iter()
                .zip(&g.data)
                .map(|(a, b)| *a as f64 * b[0] as f64)
                .sum()
        };
        let grad = polygon_grad(&g, &tri);
        assert_matches_differences(&tri, &grad, loss, 2e-3);
    }

    #[test]
    fn edges_on_pixel_boundaries_get_one_sided_means() {
        // Loss = Σ G · cov(w) with nonzero coverage; a unit-aligned square whose right edge
        // sits on x = 3 and bottom edge on y = 3. Central differences straddle the kink.
        let (w, h) = (6usize, 6usize);
        let gpix: Vec<f64> = (0..(w + 1) * h)
            .map(|i| ((i * 31) % 7) as f64 / 7.0 - 0.3)
            .collect();
        let loss = |poly: &[Point]| -> f64 {
            let acc = raster(poly, w, h);
            acc.data
                .iter()
                .zip(&gpix)
                .map(|(a, b)| coverage(*a, false).0 as f64 * b)
                .sum()
        };
        let sq = [[1.0, 1.0], [3.0, 1.0], [3.0, 3.0], [1.0, 3.0]];
        let acc = raster(&sq, w, h);
        let mut g = Cells::<[f32; 2]>::default();
        g.reset(0, 0, w + 1, h);
        for (k, v) in g.data.iter_mut().enumerate() {
            let (p, m) = coverage_slopes(acc.data[k], false);
            *v = [(gpix[k] as f32) * p, (gpix[k] as f32) * m];
        }
        let grad = polygon_grad(&g, &sq);
        assert_matches_differences(&sq, &grad, loss, 1e-3);
        assert!(grad.iter().flatten().any(|v| v.abs() > 0.05), "{grad:?}");
    }

    #[test]
    fn fill_rules() {
        assert_eq!(coverage(1.7, false), (1.0, 0.0));
        assert_eq!(coverage(-0.25, false), (0.25, -1.0));
        let (c, d) = coverage(1.75, true);
        assert!((c - 0.25).abs() < 1e-6 && d == -1.0);
        let (c, _) = coverage(2.0, true);
        assert_eq!(c, 0.0);
    }

    /// Crisp coverage: rows and columns whose centers lie inside, a center on the top or
    /// left edge outside and one on the bottom or right edge inside (tiny-skia's rule).
    #[test]
    fn centers_inside_a_rectangle() {
        let mut acc = Cells::<f32>::default();
        acc.reset(0, 0, 12, 10);
        let (x0, y0, x1, y1) = (2.5, 1.2, 7.5, 6.5);
        let ring = [[x0, y0], [x1, y0], [x1, y1], [x0, y1]];
        for k in 0..4 {
            accumulate_centers(&mut acc, ring[k], ring[(k + 1) % 4], 12.0);
        }
        for r in 0..10 {
            let mut w = 0.0;
            for c in 0..12 {
                w += acc.data[r * 12 + c];
                let (cx, cy) = (c as f64 + 0.5, r as f64 + 0.5);
                let inside = cx > x0 && cx <= x1 && cy > y0 && cy <= y1;
                assert_eq!(w.abs() == 1.0, inside, "pixel ({c}, {r}): winding {w}");
            }
        }
    }
}
