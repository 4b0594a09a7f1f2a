//! Where a path's pixels can hold three winding numbers.
//!
//! The clamped winding integral ([`coverage`](super::coverage)) is exact in every pixel
//! whose winding number takes at most two adjacent values; [`overlap`](super::overlap)
//! integrates the others exactly. This module finds, once per item, the cell boxes outside
//! which no pixel can hold three values, so that the search for such pixels walks only
//! those ([`danger_boxes`]).
//!
//! **Clean rings.** A ring is *clean* when
//! 1. none of its edges meets another edge, of its own ring (but the next one at their
//!    shared vertex) or of any other: so it is simple, and the other rings' winding number
//!    `W` is constant along it;
//! 2. the windings beside it, `W` outside and `W + o(R)` inside (`o(R) = ±1`, the sign of
//!    its area), are 0 and the item's one other value `o`, the same for every clean ring.
//!
//! Every face of the plane that touches an edge of a clean ring winds 0 or `o`. In a cell
//! whose pieces all belong to clean rings, every face touches one of them, so the cell
//! holds at most two adjacent windings and the accumulated integral is exact there, under
//! either fill rule. A glyph with its counters wound the other way, a shape with holes and
//! most strokes' outlines are made of clean rings; on a line of text, only the glyphs that
//! touch or overlap a neighbour (joined scripts, accents, tight kerning) are not.
//!
//! **Danger boxes.** Cells where two runs of [`BOX_EDGES`] consecutive edges can meet
//! (their cell boxes overlap), one of them of a ring that is not clean, and cells a run of
//! such a ring passes twice (it turns back in both x and y). Two consecutive runs of one
//! ring meeting in their junction's cell alone are one chain there and need no box. A cell
//! holding pieces of a clean ring only, or one monotone chain of any ring, can hold two
//! windings at most; every other cell lies in a box.
//!
//! **Finding the edges that meet.** Each ring is cut into chains monotone in the order of
//! `(y, x)`; two edges of one chain that do not follow each other cannot meet. The chains'
//! boxes are paired by [`sweep`](super::sweep), and two chains whose boxes overlap are
//! walked side by side in that order, testing only the pairs of edges whose spans overlap:
//! a glyph's few chains cost about one test per edge and per neighbouring chain. When every
//! edge is clean (most glyphs, most strokes), nothing more is done; otherwise the runs'
//! cell boxes are paired again for the danger boxes.
//!
//! **Bounds.** Chains and runs are paired within a budget of comparisons, and the walks
//! within a budget of edge tests; beyond either, or with a coordinate that is not finite,
//! the whole plane is one box (the search then walks every row, as it would for a path it
//! knows nothing about).

use super::coverage::floor_f64;
use super::sweep;
use crate::scene::Point;

/// Edges per run: short runs, whose boxes hug a curve (two sides of a stroke a few pixels
/// apart keep apart).
pub(crate) const BOX_EDGES: usize = 4;

/// Edges per block of a chain, whose box lets [`Rings::tangled`] skip the edges of two
/// chains that are far apart in x.
const CHAIN_BLOCK: usize = 8;

/// Box comparisons at most (edge runs, then rings), before the plane is one box.
const BUDGET: usize = 1 << 16;

/// A box covering every cell.
const EVERYWHERE: [f64; 4] = [
    f64::NEG_INFINITY,
    f64::NEG_INFINITY,
    f64::INFINITY,
    f64::INFINITY,
];

/// The cell boxes `[col0, row0, col1, row1]` (device pixels, inclusive) outside which no
/// cell of the rings `(start, count)` of `pts` can hold more than two winding values
/// (module doc). Empty: none can.
pub(crate) fn danger_boxes(pts: &[Point], rings: &[(usize, usize)]) -> Vec<[f64; 4]> {
    let Some(mut rs) = Rings::clean(pts, rings) else {
        return vec![EVERYWHERE];
    };
    // 1. Edges that meet another edge.
    let Some(tangled) = rs.tangled() else {
        return vec![EVERYWHERE];
    };
    // 2. The windings beside each stretch of edges that meet nothing.
    let Some(clean) = rs.clean_edges(&tangled) else {
        return vec![EVERYWHERE];
    };
    if clean.iter().all(|&c| c) {
        return Vec::new();
    }
    rs.grid();
    let runs = rs.runs();
    let dirty_run = |r: &Run| (r.e0..r.e1).any(|e| !clean[e]);
    let dirty: Vec<bool> = runs.iter().map(dirty_run).collect();
    let cells: Vec<[f64; 4]> = runs.iter().map(|r| r.cells).collect();
    let mut pairs: Vec<(u32, u32)> = Vec::new();
    let end = sweep::overlapping_pairs(&cells, BUDGET, &mut sweep::Scratch::default(), |i, j| {
        if dirty[i] || dirty[j] {
            pairs.push((i as u32, j as u32));
        }
        true
    });
    if end != sweep::Pairs::All {
        return vec![EVERYWHERE];
    }
    // 3. Where a dirty edge can share a cell with another edge (but the next one of its
    // ring, one chain with it, unless either lies on a grid line).
    let mut out = Vec::new();
    let pair = |ea: usize, eb: usize, out: &mut Vec<[f64; 4]>| {
        let (c, d) = (rs.cells[ea], rs.cells[eb]);
        if (!clean[ea] || !clean[eb])
            && overlap(c, d)
            && (!rs.consecutive(ea, eb) || rs.on_line[ea] || rs.on_line[eb])
        {
            out.push([
                c[0].max(d[0]),
                c[1].max(d[1]),
                c[2].min(d[2]),
                c[3].min(d[3]),
            ]);
        }
    };
    for run in runs.iter().zip(&dirty).filter(|(_, d)| **d).map(|(r, _)| r) {
        for a in run.e0..run.e1 {
            for b in a + 1..run.e1 {
                pair(a, b, &mut out);
            }
        }
    }
    for &(i, j) in &pairs {
        let (a, b) = (&runs[i as usize], &runs[j as usize]);
        for ea in a.e0..a.e1 {
            for eb in b.e0..b.e1 {
                pair(ea, eb, &mut out);
            }
        }
    }
    out
}

/// An item's danger boxes ([`danger_boxes`]), sorted by their first row, to be read a
/// band of rows at a time.
#[derive(Clone, Debug, Default)]
pub(crate) struct Danger {
    boxes: Vec<[f64; 4]>,
    /// The most rows a box spans, less one.
    tallest: f64,
}

impl Danger {
    /// The danger boxes of the rings `(start, count)` of `pts`.
    pub(crate) fn of(pts: &[Point], rings: &[(usize, usize)]) -> Danger {
        let mut boxes = danger_boxes(pts, rings);
        boxes.sort_by(|a, b| a[1].total_cmp(&b[1]));
        let tallest = boxes.iter().map(|b| b[3] - b[1]).fold(0.0, f64::max);
        Danger { boxes, tallest }
    }

    /// Every cell.
    #[cfg(test)]
    pub(crate) fn everywhere() -> Danger {
        Danger {
            boxes: vec![EVERYWHERE],
            tallest: f64::INFINITY,
        }
    }

    /// No cell can hold three windings.
    pub(crate) fn is_empty(&self) -> bool {
        self.boxes.is_empty()
    }

    /// The boxes that reach some row in `lo..=hi`.
    pub(crate) fn near_rows(&self, lo: f64, hi: f64) -> impl Iterator<Item = &[f64; 4]> {
        let from = self.boxes.partition_point(|b| b[1] < lo - self.tallest);
        self.boxes[from..]
            .iter()
            .take_while(move |b| b[1] <= hi)
            .filter(move |b| b[3] >= lo)
    }
}

/// Whether two closed boxes `[x0, y0, x1, y1]` overlap.
#[inline]
fn overlap(a: [f64; 4], b: [f64; 4]) -> bool {
    a[0] <= b[2] && b[0] <= a[2] && a[1] <= b[3] && b[1] <= a[3]
}

/// Calls `visit(i, j)` for every pair of spans `i < la` of one sequence and `j < lb` of
/// another that share a point, each span given by `a(i)`/`b(j)` as its first and last point
/// in the order of `(y, x)` ([`before`]); each sequence ascends, one span ending where the
/// next starts. A merge: the span that ends first moves on (when both end at one point,
/// the next span of `b` starts there too and meets the current one of `a`).
fn spans_meeting(
    la: usize,
    lb: usize,
    a: impl Fn(usize) -> (Point, Point),
    b: impl Fn(usize) -> (Point, Point),
    mut visit: impl FnMut(usize, usize),
) {
    let (mut i, mut j) = (0, 0);
    while i < la && j < lb {
        let ((loa, hia), (lob, hib)) = (a(i), b(j));
        if before(hia, lob) {
            i += 1;
        } else if before(hib, loa) {
            j += 1;
        } else {
            visit(i, j);
            if before(hia, hib) {
                i += 1;
            } else if before(hib, hia) {
                j += 1;
            } else {
                if j + 1 < lb {
                    visit(i, j + 1);
                }
                i += 1;
            }
        }
    }
}

/// Whether `a` comes before `b` in the order of `(y, x)`.
#[inline]
fn before(a: Point, b: Point) -> bool {
    a[1] < b[1] || (a[1] == b[1] && a[0] < b[0])
}

/// Sign of the turn `a → b → c` (positive counterclockwise in x right, y up).
#[inline]
fn orient(a: Point, b: Point, c: Point) -> i8 {
    let v = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]);
    (v > 0.0) as i8 - (v < 0.0) as i8
}

/// A run of consecutive edges of one ring.
struct Run {
    /// Its edges `e0..e1` ([`Rings`] numbering).
    e0: usize,
    e1: usize,
    /// The cells it touches, inclusive ([`Rings::cells`]).
    cells: [f64; 4],
}

/// Rings without repeated vertices (a closing point equal to the first one, a point
/// twice in a row), and their edges: edge `e` goes from vertex `e` to the next vertex of
/// its ring.
struct Rings {
    pts: Vec<Point>,
    /// `(start, count)` in `pts`.
    rings: Vec<(usize, usize)>,
    /// The vertex after each one in its ring: edge `e` goes from `e` to `next[e]`, and
    /// edge `next[e]` follows it.
    next: Vec<u32>,
    /// Each edge's bounds.
    boxes: Vec<[f64; 4]>,
    /// The cells each edge touches, inclusive (one more on each side when it lies on a
    /// grid line: the cells beside it count).
    cells: Vec<[f64; 4]>,
    /// Whether each edge lies on a grid line.
    on_line: Vec<bool>,
}

impl Rings {
    /// `None` when a point is not finite.
    fn clean(pts: &[Point], rings: &[(usize, usize)]) -> Option<Rings> {
        let mut out = Vec::with_capacity(pts.len());
        let mut spans = Vec::with_capacity(rings.len());
        for &(s, n) in rings {
            let start = out.len();
            for &q in &pts[s..s + n] {
                if !(q[0].is_finite() && q[1].is_finite()) {
                    return None;
                }
                if out.len() == start || out.last() != Some(&q) {
                    out.push(q);
                }
            }
            while out.len() > start + 1 && out.last() == Some(&out[start]) {
                out.pop();
            }
            spans.push((start, out.len() - start));
        }
        let m = out.len();
        let mut rs = Rings {
            pts: out,
            rings: spans,
            next: Vec::with_capacity(m),
            boxes: Vec::with_capacity(m),
            cells: Vec::new(),
            on_line: Vec::new(),
        };
        for &(s, n) in &rs.rings {
            for e in s..s + n {
                let (a, b) = (rs.pts[e], rs.pts[if e + 1 == s + n { s } else { e + 1 }]);
                let bx = [
                    a[0].min(b[0]),
                    a[1].min(b[1]),
                    a[0].max(b[0]),
                    a[1].max(b[1]),
                ];
                rs.next.push(if e + 1 == s + n { s } else { e + 1 } as u32);
                rs.boxes.push(bx);
            }
        }
        Some(rs)
    }

    /// Fills [`cells`](Self::cells) and [`on_line`](Self::on_line).
    fn grid(&mut self) {
        let m = self.pts.len();
        (self.cells, self.on_line) = (Vec::with_capacity(m), Vec::with_capacity(m));
        for e in 0..m {
            let ((a, b), bx) = (self.edge(e), self.boxes[e]);
            let line = (a[0] == b[0] && a[0] == floor_f64(a[0]))
                || (a[1] == b[1] && a[1] == floor_f64(a[1]));
            let x = if line { 1.0 } else { 0.0 };
            self.cells.push([
                floor_f64(bx[0]) - x,
                floor_f64(bx[1]) - x,
                floor_f64(bx[2]) + x,
                floor_f64(bx[3]) + x,
            ]);
            self.on_line.push(line);
        }
    }

    /// Which edges meet another edge ([`meet`](Self::meet)). Each ring is cut into
    /// chains monotone in the order of `(y, x)` (so in y): two edges of one chain that do
    /// not follow each other span disjoint ranges of that order, so they cannot meet. Two
    /// chains whose boxes overlap are walked side by side in that order, and each pair of
    /// their edges whose ranges overlap is tested. `None` when there are too many chains
    /// close together or too many edge pairs to test.
    fn tangled(&self) -> Option<Vec<bool>> {
        let m = self.pts.len();
        // Chains one after the other, each as its vertices in ascending order (`verts`) and
        // its edges (`edges`); a chain of `k` edges holds `k + 1` vertices, so the edge at
        // `edges[i]` of the `c`-th chain runs from `verts[i + c]` to `verts[i + c + 1]`.
        let mut verts: Vec<Point> = Vec::with_capacity(m + 2 * self.rings.len());
        let mut edges: Vec<u32> = Vec::with_capacity(m);
        // Blocks of up to `CHAIN_BLOCK` consecutive edges of a chain: the `verts` index of
        // their first vertex, the `edges` index of their first edge, their edge count, and
        // their box.
        let mut blocks: Vec<(usize, usize, usize, [f64; 4])> = Vec::new();
        // Chains: their range of `blocks`, and their box.
        let mut chains: Vec<(usize, usize)> = Vec::new();
        let mut boxes: Vec<[f64; 4]> = Vec::new();
        let up = |e: usize| {
            let (a, b) = self.edge(e);
            before(a, b)
        };
        for &(s, n) in &self.rings {
            // Chains start where the direction changes (anywhere when it never does).
            let start = (0..n)
                .find(|&k| up(s + k) != up(s + if k == 0 { n - 1 } else { k - 1 }))
                .unwrap_or(0);
            let at = |j: usize| {
                s + if start + j >= n {
                    start + j - n
                } else {
                    start + j
                }
            };
            let mut k = 0;
            while k < n {
                let dir = up(at(k));
                let len = (k + 1..n).find(|&j| up(at(j)) != dir).unwrap_or(n) - k;
                // Vertices in ascending order: the edges' first ends, then the last end.
                let (v0, e0) = (verts.len(), edges.len());
                for j in 0..len {
                    let e = at(if dir { k + j } else { k + len - 1 - j });
                    let (a, b) = self.edge(e);
                    edges.push(e as u32);
                    verts.push(if dir { a } else { b });
                }
                let (a, b) = self.edge(at(if dir { k + len - 1 } else { k }));
                verts.push(if dir { b } else { a });
                let b0 = blocks.len();
                let mut chain_box = [
                    f64::INFINITY,
                    f64::INFINITY,
                    f64::NEG_INFINITY,
                    f64::NEG_INFINITY,
                ];
                for f in (0..len).step_by(CHAIN_BLOCK) {
                    let t = (f + CHAIN_BLOCK).min(len);
                    let bx = verts[v0 + f..=v0 + t].iter().fold(
                        [
                            f64::INFINITY,
                            f64::INFINITY,
                            f64::NEG_INFINITY,
                            f64::NEG_INFINITY,
                        ],
                        |b, q| {
                            [
                                b[0].min(q[0]),
                                b[1].min(q[1]),
                                b[2].max(q[0]),
                                b[3].max(q[1]),
                            ]
                        },
                    );
                    chain_box = [
                        chain_box[0].min(bx[0]),
                        chain_box[1].min(bx[1]),
                        chain_box[2].max(bx[2]),
                        chain_box[3].max(bx[3]),
                    ];
                    blocks.push((v0 + f, e0 + f, t - f, bx));
                }
                chains.push((b0, blocks.len()));
                boxes.push(chain_box);
                k += len;
            }
        }
        let mut tangled = vec![false; m];
        let mut work = 0usize;
        let mut scratch = sweep::Scratch::default();
        let end = sweep::overlapping_pairs(&boxes, BUDGET, &mut scratch, |i, j| {
            let ((a0, a1), (b0, b1)) = (chains[i], chains[j]);
            let (ba, bb) = (&blocks[a0..a1], &blocks[b0..b1]);
            let ends = |&(v, _, k, _): &(usize, usize, usize, [f64; 4])| (verts[v], verts[v + k]);
            spans_meeting(
                ba.len(),
                bb.len(),
                |i| ends(&ba[i]),
                |j| ends(&bb[j]),
                |i, j| {
                    let ((va, fa, ka, xa), (vb, fb, kb, xb)) = (ba[i], bb[j]);
                    if !overlap(xa, xb) {
                        return;
                    }
                    spans_meeting(
                        ka,
                        kb,
                        |i| (verts[va + i], verts[va + i + 1]),
                        |j| (verts[vb + j], verts[vb + j + 1]),
                        |i, j| {
                            work += 1;
                            let (p, q) = (verts[va + i], verts[va + i + 1]);
                            let (u, v) = (verts[vb + j], verts[vb + j + 1]);
                            // Their (y, x) spans overlap, so their y ranges do.
                            if p[0].min(q[0]) <= u[0].max(v[0]) && u[0].min(v[0]) <= p[0].max(q[0])
                            {
                                let (ea, eb) = (edges[fa + i] as usize, edges[fb + j] as usize);
                                if self.meet(ea, eb) {
                                    tangled[ea] = true;
                                    tangled[eb] = true;
                                }
                            }
                        },
                    );
                },
            );
            work <= BUDGET * 16
        });
        (end == sweep::Pairs::All).then_some(tangled)
    }

    /// Ends of edge `e`.
    #[inline]
    fn edge(&self, e: usize) -> (Point, Point) {
        (self.pts[e], self.pts[self.next[e] as usize])
    }

    /// How edge `e` (unless it is `skip`) adds to the winding number at `x`: its crossing
    /// of the ray from `x` towards +x, half-open in y.
    #[inline]
    fn crossing(&self, e: usize, x: Point, skip: usize) -> i64 {
        let (a, b) = self.edge(e);
        if e == skip {
            0
        } else if a[1] <= x[1] {
            (b[1] > x[1] && orient(a, b, x) > 0) as i64
        } else {
            -((b[1] <= x[1] && orient(a, b, x) < 0) as i64)
        }
    }

    /// Rings that cannot be clean whatever else holds: fewer than three vertices, or two
    /// consecutive edges folding back onto each other.
    fn degenerate(&self) -> Vec<bool> {
        self.rings
            .iter()
            .map(|&(s, n)| {
                n < 3
                    || (s..s + n).any(|e| {
                        let (a, b) = self.edge(e);
                        let (_, c) = self.edge(if e + 1 == s + n { s } else { e + 1 });
                        orient(a, b, c) == 0
                            && (b[0] - a[0]) * (c[0] - b[0]) + (b[1] - a[1]) * (c[1] - b[1]) <= 0.0
                    })
            })
            .collect()
    }

    /// The runs of [`BOX_EDGES`] edges of every ring, ring after ring (after
    /// [`grid`](Self::grid)).
    fn runs(&self) -> Vec<Run> {
        let mut out = Vec::with_capacity(self.pts.len().div_ceil(BOX_EDGES) + self.rings.len());
        for &(s, n) in &self.rings {
            for e0 in (s..s + n).step_by(BOX_EDGES) {
                let e1 = (e0 + BOX_EDGES).min(s + n);
                let cells = self.cells[e0 + 1..e1].iter().fold(self.cells[e0], |a, c| {
                    [
                        a[0].min(c[0]),
                        a[1].min(c[1]),
                        a[2].max(c[2]),
                        a[3].max(c[3]),
                    ]
                });
                out.push(Run { e0, e1, cells });
            }
        }
        out
    }

    /// Whether edges `a` and `b` of one ring follow each other.
    #[inline]
    fn consecutive(&self, a: usize, b: usize) -> bool {
        self.next[a] as usize == b || self.next[b] as usize == a
    }

    /// Whether edges `a` and `b` meet (consecutive edges of a ring at their shared vertex
    /// do not; their folding back is [`degenerate`](Self::degenerate)). Orientation signs
    /// in `f64`; any zero sign counts as meeting unless the two are collinear and apart.
    fn meet(&self, a: usize, b: usize) -> bool {
        if a == b || self.consecutive(a, b) {
            return false;
        }
        let ((p, q), (u, v)) = (self.edge(a), self.edge(b));
        let (o1, o2) = (orient(p, q, u), orient(p, q, v));
        let (o3, o4) = (orient(u, v, p), orient(u, v, q));
        if o1 == 0 && o2 == 0 {
            // Collinear: apart only when their extents along the line are apart.
            let ax = if (q[0] - p[0]).abs() >= (q[1] - p[1]).abs() {
                0
            } else {
                1
            };
            let (lo, hi) = (p[ax].min(q[ax]), p[ax].max(q[ax]));
            return !(u[ax].max(v[ax]) < lo || u[ax].min(v[ax]) > hi);
        }
        o1 * o2 <= 0 && o3 * o4 <= 0
    }

    /// Which edges are clean: in a stretch of consecutive edges that meet nothing
    /// (`tangled` marks those that do), of a ring that does not fold back, whose two
    /// sides wind 0 and the item's one other value `o` (the value most stretches agree
    /// on). No edge crosses such a stretch, so each side's winding is constant along it:
    /// it is read once, beside the middle of one of its edges that is not horizontal.
    /// `None` when there are too many stretches to read.
    fn clean_edges(&self, tangled: &[bool]) -> Option<Vec<bool>> {
        let degenerate = self.degenerate();
        // Stretches: `(ring, first edge, edges)`, cyclic within the ring.
        let mut stretches: Vec<(usize, usize, usize)> = Vec::new();
        for (r, &(s, n)) in self.rings.iter().enumerate() {
            if degenerate[r] {
                continue;
            }
            let Some(t) = (s..s + n).find(|&e| tangled[e]) else {
                stretches.push((r, s, n));
                continue;
            };
            // Walk once around from the first tangled edge.
            let mut len = 0;
            for step in 1..=n {
                let e = s + (t - s + step) % n;
                if tangled[e] {
                    if len > 0 {
                        stretches.push((r, s + (e - s + n - len) % n, len));
                    }
                    len = 0;
                } else {
                    len += 1;
                }
            }
        }
        // A few rays look at every edge; more share an index of the edges by rows.
        let index = if stretches.len() > 16 {
            Some(RowIndex::new(self)?)
        } else {
            None
        };
        let mut work = 0usize;
        let values: Vec<i64> = stretches
            .iter()
            .map(|&(r, first, len)| {
                let (s, n) = self.rings[r];
                let Some(e) = (0..len)
                    .map(|k| s + (first - s + k) % n)
                    .find(|&e| self.boxes[e][1] < self.boxes[e][3])
                else {
                    return 0;
                };
                let (a, b) = self.edge(e);
                let mid = [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1])];
                // The winding just right of `e` at `mid`, and just left of it.
                let right = match &index {
                    Some(index) => index.winding(self, mid, e, &mut work),
                    None => {
                        work += self.pts.len();
                        (0..self.pts.len()).map(|f| self.crossing(f, mid, e)).sum()
                    }
                };
                let left = right + if b[1] > a[1] { 1 } else { -1 };
                match (left, right) {
                    (0, x) | (x, 0) if x.abs() == 1 => x,
                    _ => 0,
                }
            })
            .collect();
        if work > BUDGET * 16 {
            return None;
        }
        let plus = values.iter().filter(|&&v| v == 1).count();
        let minus = values.iter().filter(|&&v| v == -1).count();
        let o = if plus >= minus { 1 } else { -1 };
        let mut clean = vec![false; self.pts.len()];
        for (&(r, first, len), v) in stretches.iter().zip(values) {
            if v == o {
                let (s, n) = self.rings[r];
                for k in 0..len {
                    clean[s + (first - s + k) % n] = true;
                }
            }
        }
        Some(clean)
    }
}

/// Edges bucketed by horizontal bands of rows, for winding numbers at points.
struct RowIndex {
    y0: f64,
    /// Bands per unit of y: the inverse of the band height (a power of two, at least 1),
    /// chosen so that no more than about eight entries per edge are made.
    per: f64,
    /// Edge indices band after band; band `k` is `edges[starts[k]..starts[k + 1]]`.
    starts: Vec<u32>,
    edges: Vec<u32>,
}

impl RowIndex {
    fn new(rs: &Rings) -> Option<RowIndex> {
        let m = rs.boxes.len();
        if m == 0 || m > u32::MAX as usize / 16 {
            return None;
        }
        let (y0, y1) = rs
            .boxes
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), b| {
                (lo.min(b[1]), hi.max(b[3]))
            });
        // Bands per unit of y: a power of two, so products are exact quotients.
        let mut per = 1.0f64;
        let band = |y: f64, per: f64| ((y - y0) * per) as usize;
        loop {
            let bands = band(y1, per) + 1;
            let entries: usize = rs
                .boxes
                .iter()
                .map(|b| band(b[3], per) - band(b[1], per) + 1)
                .sum();
            if bands <= 8 * m + 8 && entries <= 8 * m + 8 {
                break;
            }
            per *= 0.5;
        }
        let spans: Vec<(usize, usize)> = rs
            .boxes
            .iter()
            .map(|b| (band(b[1], per), band(b[3], per)))
            .collect();
        let bands = band(y1, per) + 1;
        let mut starts = vec![0u32; bands + 1];
        for &(k0, k1) in &spans {
            for k in k0..=k1 {
                starts[k + 1] += 1;
            }
        }
        for k in 0..bands {
            starts[k + 1] += starts[k];
        }
        let mut next = starts.clone();
        let mut edges = vec![0u32; starts[bands] as usize];
        for (e, &(k0, k1)) in spans.iter().enumerate() {
            for k in k0..=k1 {
                edges[next[k] as usize] = e as u32;
                next[k] += 1;
            }
        }
        Some(RowIndex {
            y0,
            per,
            starts,
            edges,
        })
    }

    /// The winding number at `x` (crossings of the ray from `x` towards +x, half-open in
    /// y) of every edge but `skip`, which passes through `x`; `work` counts the edges
    /// looked at.
    fn winding(&self, rs: &Rings, x: Point, skip: usize, work: &mut usize) -> i64 {
        let k = (((x[1] - self.y0) * self.per) as usize).min(self.starts.len() - 2);
        let list = &self.edges[self.starts[k] as usize..self.starts[k + 1] as usize];
        *work += list.len();
        list.iter().map(|&e| rs.crossing(e as usize, x, skip)).sum()
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Danger boxes of rings given as point lists.
    fn danger(rings: &[Vec<Point>]) -> Vec<[f64; 4]> {
        let mut pts = Vec::new();
        let mut spans = Vec::new();
        for r in rings {
            spans.push((pts.len(), r.len()));
            pts.extend_from_slice(r);
        }
        danger_boxes(&pts, &spans)
    }

    pub(crate) fn rect(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<Point> {
        vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
    }

    /// A regular polygon of `n` vertices around `c`, counterclockwise in `(x, y)` when
    /// `ccw`.
    pub(crate) fn polygon(c: Point, r: f64, n: usize, ccw: bool) -> Vec<Point> {
        let mut v: Vec<Point> = (0..n)
            .map(|k| {
                let t = std::f64::consts::TAU * k as f64 / n as f64;
                [c[0] + r * t.cos(), c[1] + r * t.sin()]
            })
            .collect();
        if !ccw {
            v.reverse();
        }
        v
    }

    /// Whether some box holds cell `(col, row)`.
    fn covers(boxes: &[[f64; 4]], col: f64, row: f64) -> bool {
        boxes
            .iter()
            .any(|b| b[0] <= col && col <= b[2] && b[1] <= row && row <= b[3])
    }

    /// Which rings need no search: two-valued windings (a shape with a hole wound the
    /// other way, apart rings wound alike, a closing point repeated), and rings wound
    /// opposite ways that never share a cell, against three values (a hole wound the same
    /// way, coincident or touching rings, a self-crossing star, a fold back, degenerate
    /// rings).
    #[test]
    fn which_items_need_no_search() {
        let two_valued = |rings: &[Vec<Point>]| danger(rings).is_empty();
        let outer = polygon([10.0, 10.0], 8.0, 40, true);
        let hole = polygon([10.0, 10.0], 3.0, 24, false);
        let same_hole = polygon([10.0, 10.0], 3.0, 24, true);
        assert!(two_valued(&[outer.clone(), hole.clone()]));
        assert!(two_valued(&[hole.clone(), outer.clone()]));
        // An island inside the hole, wound like the outer ring.
        let island = polygon([10.0, 10.0], 1.0, 12, true);
        assert!(two_valued(&[outer.clone(), hole.clone(), island.clone()]));
        assert!(!two_valued(&[outer.clone(), same_hole.clone()]));
        let apart = polygon([30.0, 10.0], 5.0, 16, true);
        let apart_cw = polygon([30.0, 10.0], 5.0, 16, false);
        assert!(two_valued(&[outer.clone(), apart]));
        assert!(two_valued(&[outer.clone(), apart_cw]));
        // A repeated closing point is no edge.
        let mut closed = outer.clone();
        closed.push(outer[0]);
        assert!(two_valued(&[closed, hole.clone()]));
        // Coincident, touching along an edge, and at a vertex.
        let r = rect(1.0, 1.0, 1.5, 3.0);
        assert!(!two_valued(&[r.clone(), r.clone()]));
        assert!(!two_valued(&[r.clone(), rect(1.5, 1.0, 2.25, 3.0)]));
        assert!(!two_valued(&[r.clone(), rect(1.5, 3.0, 2.0, 4.0)]));
        // Collinear edges apart are no meeting.
        assert!(two_valued(&[r.clone(), rect(2.0, 1.0, 2.5, 3.0)]));
        // A pentagram crosses itself; a ring folding back on itself is not simple.
        let star: Vec<Point> = (0..5)
            .map(|k| {
                let t = std::f64::consts::TAU * (2 * k) as f64 / 5.0;
                [10.0 + 8.0 * t.cos(), 10.0 + 8.0 * t.sin()]
            })
            .collect();
        assert!(!two_valued(&[star]));
        assert!(!two_valued(&[vec![
            [0.0, 0.0],
            [4.0, 0.0],
            [2.0, 0.0],
            [2.0, 3.0]
        ]]));
        // Degenerate rings (fewer than three distinct vertices, zero area) wind 0
        // everywhere, and their edges follow each other; non-finite points box everything.
        assert!(two_valued(&[vec![[0.0, 0.0], [1.0, 1.0]]]));
        assert!(two_valued(&[vec![[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]]));
        assert!(!two_valued(&[vec![
            [0.0, 0.0],
            [f64::NAN, 1.0],
            [2.0, 0.0]
        ]]));
    }

    /// Boxes where three windings can be, and only near them: a hole wound the same way,
    /// coincident rectangles, two glyph-like rings overlapping at one end of a row of
    /// clean ones, a self-crossing star, a fold back.
    #[test]
    fn tangled_rings_get_boxes_where_they_meet() {
        let outer = polygon([10.0, 10.0], 8.0, 40, true);
        let same = polygon([10.0, 10.0], 3.0, 24, true);
        let b = danger(&[outer.clone(), same]);
        // The hole's ring is not clean: cells where two of its edges that do not follow
        // each other can meet are boxed, none near the outer ring.
        assert!(!b.is_empty() && !covers(&b, 2.0, 10.0), "{b:?}");
        assert!(
            b.iter()
                .all(|c| (6.0..=13.0).contains(&c[0]) && (6.0..=13.0).contains(&c[3]))
        );
        let r = rect(1.0, 1.0, 1.5, 3.0);
        assert!(covers(&danger(&[r.clone(), r.clone()]), 1.0, 2.0));
        // A row of letters: the last two overlap, the others are boxed nowhere.
        let mut row: Vec<Vec<Point>> = (0..6)
            .map(|k| polygon([10.0 + 12.0 * k as f64, 10.0], 5.0, 16, true))
            .collect();
        row.push(polygon([75.0, 10.0], 5.0, 16, true));
        let b = danger(&row);
        // Only near where the last two cross (x = 72.5).
        assert!(
            !b.is_empty() && b.iter().all(|c| c[0] >= 69.0 && c[2] <= 76.0),
            "{b:?}"
        );
        for c in [5.0, 15.0, 30.0, 40.0, 50.0] {
            assert!(!covers(&b, c, 10.0), "column {c}: {b:?}");
        }
        let star: Vec<Point> = (0..5)
            .map(|k| {
                let a = (k * 2) as f64 * std::f64::consts::TAU / 5.0;
                [10.0 + 8.0 * a.cos(), 10.0 + 8.0 * a.sin()]
            })
            .collect();
        assert!(!danger(&[star]).is_empty());
        let fold = vec![[1.0, 1.0], [9.0, 1.0], [5.0, 1.0], [5.0, 6.0]];
        assert!(!danger(&[fold]).is_empty());
    }

    /// The walk along chains finds exactly the edges that meet another, as testing every
    /// pair of edges does: on random rings whose points often sit on whole numbers, so
    /// that horizontal, collinear, touching and repeated edges are common.
    #[test]
    fn chains_find_every_meeting_edge() {
        let mut rng = crate::rng::Rng::new(41);
        let mut some = 0;
        for case in 0..400 {
            let mut pts: Vec<Point> = Vec::new();
            let mut spans = Vec::new();
            for _ in 0..1 + rng.below(3) {
                if case % 3 == 0 {
                    // Long chains (many blocks): polygons, some snapped to half pixels.
                    let c = [rng.range(2.0, 6.0), rng.range(2.0, 6.0)];
                    let r = rng.range(1.0, 4.0);
                    let ring = polygon(c, r, 20 + rng.below(60), rng.below(2) == 0);
                    let snap = rng.below(2) == 0;
                    spans.push((pts.len(), ring.len()));
                    pts.extend(ring.iter().map(|q| match snap {
                        true => q.map(|v| (2.0 * v).round() / 2.0),
                        false => *q,
                    }));
                    continue;
                }
                let n = 2 + rng.below(11);
                spans.push((pts.len(), n));
                for _ in 0..n {
                    let q = [rng.range(0.0, 8.0), rng.range(0.0, 8.0)];
                    pts.push(if rng.below(2) == 0 {
                        q.map(f64::round)
                    } else {
                        q
                    });
                }
            }
            let rs = Rings::clean(&pts, &spans).expect("finite points");
            let m = rs.pts.len();
            let mut want = vec![false; m];
            for a in 0..m {
                for b in a + 1..m {
                    if rs.meet(a, b) {
                        (want[a], want[b]) = (true, true);
                    }
                }
            }
            some += want.iter().any(|&t| t) as usize;
            assert_eq!(rs.tangled(), Some(want), "case {case}: {pts:?} {spans:?}");
        }
        assert!(some > 100, "only {some} of 400 cases meet");
    }

    /// A point that is not finite makes the whole plane one box.
    #[test]
    fn non_finite_points_box_everything() {
        let r = vec![[1.0, 1.0], [f64::NAN, 2.0], [3.0, 4.0]];
        assert_eq!(danger(&[r]), vec![EVERYWHERE]);
    }
}
