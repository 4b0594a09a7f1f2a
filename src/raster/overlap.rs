//! Exact coverage in the pixels where a path overlaps itself.
//!
//! The accumulated winding integral `I = ∫_pixel w` ([`coverage`](super::coverage)) gives
//! the exact coverage of `{w ≠ 0}` (nonzero) or `{w odd}` (even-odd) wherever the winding
//! number takes at most two adjacent values inside the pixel. Where a path crosses itself,
//! or two of its rings share a pixel, it can take three or more, and the clamped integral
//! over-covers (two coincident half-covering rectangles in one path give 1.0, not 0.5).
//!
//! **Which cells.** Only items that can overlap look ([`Item::can_overlap`]: anything but
//! simple rings, convex or monotone in y, that share no pixel with each other). While such
//! an item is accumulated ([`accumulate_line_visiting`](super::coverage::accumulate_line_visiting)),
//! each cell an edge crosses keeps the chain of consecutive edges of one ring that passed
//! through it ([`ChainTags`]): a second chain, or a chain that turns back in both x and
//! y, makes the cell a candidate. (One chain monotone in x or in y crosses the cell once
//! and splits it into two regions of adjacent winding: the integral is exact there.) Two
//! chains that do not meet inside the cell and lie each on the same side of the other (a
//! thin stroke's two sides, a narrow stem) leave the two outer regions one winding and
//! the one between them an adjacent one: such a cell is judged exact once the
//! item is done ([`chains_wind_alike`]), without a search.
//!
//! **Exact area.** In a candidate cell the edges are clipped to the cell and the cell is
//! cut into horizontal strips at every piece's end and every crossing of two pieces. In a
//! strip no pieces cross: ordered by x, each gap between neighbours has one winding,
//! relative to the winding just inside the cell's left side (which changes only where a
//! piece leaves that side). That gives the area of each relative winding value, and the
//! absolute level comes from the accumulated integral itself: `I = Σ area_r (w0 + rel_r)`,
//! so `w0 = round(I − Σ area_r rel_r)` with no extra winding pass. Where the cell's
//! windings span at most two adjacent values after all (a false candidate: a ring's start,
//! a thin hole) the accumulated value is kept, bit for bit.
//!
//! **Gradient.** Moving a piece along its normal `N = (−dy, dx)` turns the area it sweeps
//! from the winding on the side `N` points to (`w`) into the other (`w + 1`). For the
//! winding integral every piece counts +1 (`coverage::backward_line`); for the exact
//! coverage each portion of a piece between two strip lines counts
//! `f(w + 1) − f(w) ∈ {−1, 0, 1}`, with `f` the fill rule's indicator: a portion buried
//! inside an overlap counts 0. A piece lying on a grid line counts half in each cell beside
//! it (the mean of the one-sided derivatives, as the accumulated backward does).
//!
//! **Pieces on grid lines.** A piece lying on a pixel line belongs to the cell on one
//! side; half of its gradient goes to each cell beside it, with the windings on both sides
//! of it. The accumulated slope of a cell assumes the cell's own pair of windings, which the
//! piece's far side can lie outside of: a cell holding a piece of its own (two windings)
//! beside such a piece is a candidate too, and every candidate cell integrated exactly takes
//! its gradient from its portions, whether or not its value replaced the accumulated one. A
//! piece on the line between two row bands reaches the cell above it from the band above.
//! The windings in a cell start just left of a piece on its left side, and the strip beside
//! a horizontal piece is the nearest one of some height (a piece ending within rounding of
//! a side leaves a sliver).
//!
//! **Which edges.** Only the candidate cells are searched, and only the edges with a piece
//! in one: each candidate's chains (recorded as their first and last edges when the cell
//! became one) and every edge seen in it afterwards, in ring order. The search walks them
//! through the candidate cells again, with the same rule, to keep every piece. For the
//! backward pass the cells beside pieces on grid lines are searched too (their gradient
//! needs the portions), with every edge of the item. A forward pass leaves out the cells
//! that are candidates only for a neighbour's piece on a grid line: they hold two
//! windings, and only their gradient needs the portions.
//!
//! **Off by default** ([`RenderOptions::exact_overlaps`](super::RenderOptions)): on, text
//! and the bundled drawings take about a fifth longer (the tags are written for every
//! cell an edge crosses; docs/performance.md); off, the clamped winding integral
//! everywhere, as before issue 29.
//!
//! **Bounds.** A cell with up to [`EXACT_PIECES`] pieces is exact (its pairwise crossings
//! are `O(k²)`, its strips `O(k²)` sorts of `k`). Up to [`SAMPLED_PIECES`] the cell is
//! integrated on [`SAMPLE_ROWS`] horizontal scanlines instead (exact along x, the midpoint
//! rule along y), and its gradient is that of the sampled coverage: each scanline's crossing
//! of a piece moves with it (horizontal pieces get none). A sampled cell whose windings span
//! two values keeps the accumulated value and slopes. Beyond that the clamped integral
//! is kept. Nothing is recorded for such a cell's pieces, so 20,000 coincident rings of
//! one path cost one counter per piece and per cell, no more.

use super::coverage::{clip_to_box, floor_f64};
use super::prepare::Item;
use super::sweep;
use crate::scene::Point;

/// Pieces in one cell up to which its coverage is exact.
pub(crate) const EXACT_PIECES: usize = 32;
/// Pieces in one cell up to which its coverage is sampled on [`SAMPLE_ROWS`] scanlines
/// (beyond, the clamped winding integral is kept).
pub(crate) const SAMPLED_PIECES: usize = 1024;
/// Scanlines per cell for cells of more than [`EXACT_PIECES`] pieces.
pub(crate) const SAMPLE_ROWS: usize = 16;

/// No vertex.
const NONE: u32 = u32::MAX;

/// What the candidate search keeps per cell.
#[derive(Clone, Copy)]
struct CellState {
    /// Vertex where the cell's chain starts, when its first piece starts there.
    head: u32,
    /// Vertex where the cell's chain ends, when its last piece ends there.
    tail: u32,
    /// Pieces seen.
    count: u32,
    /// Directions seen along the chain: bits for +x, −x, +y, −y.
    dirs: u8,
    /// More than one chain, or a chain monotone in neither x nor y.
    candidate: bool,
    /// A piece on one of its sides (its own or its neighbour's) lies on a grid line.
    on_line: bool,
    /// It holds a piece not on a grid line: its inside can hold two windings.
    inner: bool,
    /// Index among the band's candidate cells, once numbered.
    slot: u32,
}

impl Default for CellState {
    fn default() -> Self {
        CellState {
            head: NONE,
            tail: NONE,
            count: 0,
            dirs: 0,
            candidate: false,
            on_line: false,
            inner: false,
            slot: NONE,
        }
    }
}

/// The cells of a band's box where a candidate can be: per row, the range of flagged
/// columns and a bitmap of them.
#[derive(Default)]
struct Flags {
    /// Device column of the box's first cell.
    x0: f64,
    cols: usize,
    /// Words of `bits` per row.
    words: usize,
    /// Per row, the least and greatest flagged device column (empty when `lo > hi`).
    range: Vec<(f64, f64)>,
    /// Per row, one bit per column of the box.
    bits: Vec<u64>,
}

impl Flags {
    /// No cell flagged in a box of `cols × rows` cells whose first column is `x0`.
    fn reset(&mut self, x0: f64, cols: usize, rows: usize) {
        self.x0 = x0;
        self.cols = cols;
        self.words = cols.div_ceil(64);
        self.range.clear();
        self.range.resize(rows, (f64::INFINITY, f64::NEG_INFINITY));
        self.bits.clear();
        self.bits.resize(self.words * rows, 0);
    }

    /// Box columns `c0..=c1` (device columns) clamped to the box.
    #[inline]
    fn span(&self, c0: f64, c1: f64) -> (usize, usize) {
        let last = self.cols as f64 - 1.0;
        (
            (c0 - self.x0).clamp(0.0, last) as usize,
            (c1 - self.x0).clamp(0.0, last) as usize,
        )
    }

    /// Flags device columns `c0..=c1` of row `r`.
    fn mark(&mut self, r: usize, c0: f64, c1: f64) {
        let f = &mut self.range[r];
        *f = (f.0.min(c0), f.1.max(c1));
        let (i0, i1) = self.span(c0, c1);
        let row = &mut self.bits[r * self.words..(r + 1) * self.words];
        for (w, word) in row.iter_mut().enumerate().take(i1 / 64 + 1).skip(i0 / 64) {
            let lo = (w * 64).max(i0) - w * 64;
            let hi = ((w + 1) * 64 - 1).min(i1) - w * 64;
            *word |= (u64::MAX >> (63 - hi)) & (u64::MAX << lo);
        }
    }

    /// Calls `f(i0, i1)` for each run of consecutive flagged box columns `i0..=i1` of row
    /// `r` that reaches device columns `c0..=c1`, left to right.
    fn runs(&self, r: usize, c0: f64, c1: f64, f: &mut impl FnMut(usize, usize)) {
        let rg = self.range[r];
        if rg.0 > c1 || c0 > rg.1 {
            return;
        }
        let (i0, i1) = self.span(c0.max(rg.0), c1.min(rg.1));
        let row = &self.bits[r * self.words..(r + 1) * self.words];
        let (mut i, hi) = (i0, i1);
        while i <= hi {
            // The next flagged column at or after `i`.
            let w = i / 64;
            let rest = row[w] & (u64::MAX << (i % 64));
            if rest == 0 {
                i = (w + 1) * 64;
                continue;
            }
            let start = w * 64 + rest.trailing_zeros() as usize;
            if start > hi {
                break;
            }
            // The first unflagged column after it.
            let mut end = start;
            loop {
                let w = end / 64;
                let unset = !row[w] & (u64::MAX << (end % 64));
                if unset != 0 {
                    end = w * 64 + unset.trailing_zeros() as usize;
                    break;
                }
                end = (w + 1) * 64;
                if end >= self.cols {
                    break;
                }
            }
            let end = end.min(hi + 1);
            f(start, end - 1);
            i = end;
        }
    }

    /// Whether some device column in `c0..=c1` of row `r` is flagged.
    #[inline]
    fn near(&self, r: usize, c0: f64, c1: f64) -> bool {
        let f = self.range[r];
        if f.0 > c1 || c0 > f.1 {
            return false;
        }
        let (i0, i1) = self.span(c0.max(f.0), c1.min(f.1));
        let row = &self.bits[r * self.words..(r + 1) * self.words];
        (i0 / 64..=i1 / 64).any(|w| {
            let lo = (w * 64).max(i0) - w * 64;
            let hi = ((w + 1) * 64 - 1).min(i1) - w * 64;
            row[w] & (u64::MAX >> (63 - hi)) & (u64::MAX << lo) != 0
        })
    }
}

/// A cell whose coverage is computed here.
#[derive(Clone, Copy, Debug)]
pub(crate) struct ExactCell {
    /// Row in the band's cell box.
    pub(crate) row: u32,
    /// Column in the band's cell box.
    pub(crate) col: u32,
    /// Its areas by relative winding, a range of [`Overlaps::hist`].
    hist: (u32, u32),
    /// Its pieces' portions, a range of [`Overlaps::portions`].
    pub(crate) portions: (u32, u32),
    /// Winding just inside the cell's top left corner (from [`Overlaps::resolve_row`]).
    pub(crate) w0: i32,
    /// Whether the exact coverage replaced the accumulated one (windings spanning more
    /// than two adjacent values).
    pub(crate) active: bool,
    /// Integrated on [`SAMPLE_ROWS`] scanlines (more than [`EXACT_PIECES`] pieces): its
    /// portions are the scanlines' crossings, the derivative of the sampled coverage.
    sampled: bool,
    /// Whether the gradient goes through [`portions`](Self::portions) rather than the
    /// accumulated slopes: every resolved cell but a sampled one that kept the
    /// accumulated value.
    pub(crate) grad: bool,
}

/// A portion of an edge inside one cell along which the winding on either side is
/// constant.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Portion {
    /// The edge's first vertex (index into the item's points).
    pub(crate) a: u32,
    /// The edge's second vertex.
    pub(crate) b: u32,
    /// Parameter range along the edge.
    pub(crate) t0: f64,
    pub(crate) t1: f64,
    /// The lower of the two windings beside it, relative to the cell's `w0`.
    pub(crate) rel_lo: i32,
    /// It lies on a grid line: half its weight belongs to the cell on the other side.
    pub(crate) half: bool,
}

/// An edge's piece inside a candidate cell.
#[derive(Clone, Copy)]
struct Piece {
    slot: u32,
    a: u32,
    b: u32,
    ta: f64,
    tb: f64,
    half: bool,
    /// It lies on the box's right or bottom line: `slot` is the cell inside the box
    /// beside it, which alone gets it (half).
    beyond: bool,
}

/// A piece in cell coordinates, for the area computation.
#[derive(Clone, Copy)]
struct Seg {
    q0: Point,
    q1: Point,
    /// `+1` going down, `−1` up, 0 horizontal.
    dir: i32,
    /// Sign of the x direction.
    sx: i32,
    ylo: f64,
    yhi: f64,
}

impl Seg {
    fn x_at(&self, y: f64) -> f64 {
        let (q0, q1) = (self.q0, self.q1);
        q0[0] + (y - q0[1]) * (q1[0] - q0[0]) / (q1[1] - q0[1])
    }
}

/// The exact cells of one item in one band, and the scratch that finds them.
#[derive(Default)]
pub(crate) struct Overlaps {
    /// Candidate cells, row-major.
    pub(crate) cells: Vec<ExactCell>,
    /// `(relative winding, area)` of every cell, back to back.
    hist: Vec<(i32, f64)>,
    /// Portions of every cell (when asked for), back to back.
    pub(crate) portions: Vec<Portion>,
    /// Next cell for [`resolve_row`](Self::resolve_row).
    next: usize,
    state: Vec<CellState>,
    touched: Vec<u32>,
    /// Every piece of the item in the box, its cell's index in `slot`.
    all: Vec<Piece>,
    pieces: Vec<Piece>,
    cuts: Vec<f64>,
    found: Vec<u32>,
    segs: Vec<Seg>,
    ys: Vec<f64>,
    order: Vec<(f64, usize)>,
    last_portion: Vec<u32>,
    left: Vec<(f64, i32)>,
    /// The cells of the box where a candidate can be ([`ChainTags::flag`]).
    flags: Flags,
    /// The chains in each cell, recorded while the item is accumulated ([`tags`](Self::tags)):
    /// boxed and made on first use, so that the band buffers, moved in and out of each
    /// thread's store once a band, stay small when exact overlaps are off.
    tags: Option<Box<ChainTags>>,
    /// Tests' reference: every cell searched.
    #[cfg(test)]
    pub(crate) everywhere: bool,
}

impl Overlaps {
    /// Forgets the previous item's cells.
    #[inline]
    pub(crate) fn clear(&mut self) {
        if !self.cells.is_empty() {
            self.cells.clear();
            self.hist.clear();
            self.portions.clear();
        }
        self.next = 0;
    }

    /// Finds the candidate cells of `item` inside the box of cells `cols × rows` whose
    /// first cell is device pixel `origin`, and their areas by relative winding; with
    /// `portions`, also what the backward pass needs. The item was just accumulated into
    /// that box with [`tags`](Self::tags) recording the chains in each cell.
    pub(crate) fn find(
        &mut self,
        item: &Item,
        origin: (i64, i64),
        cols: usize,
        rows: usize,
        portions: bool,
    ) {
        self.clear();
        if cols == 0 || rows == 0 {
            return;
        }
        let tags = self.tags();
        tags.judge_twos(&item.pts, &item.rings);
        #[cfg(test)]
        if self.everywhere {
            // The reference of the tests: every cell of the box searched, every edge walked.
            self.flags.reset(origin.0 as f64, cols, rows);
            for r in 0..rows {
                self.flags
                    .mark(r, origin.0 as f64, (origin.0 + cols as i64) as f64);
            }
            return self.search(item, origin, (cols, rows), portions, &[]);
        }
        let tags = self.tags.as_deref_mut().expect("made above");
        if !tags.flag(&mut self.flags, origin.0 as f64, cols, rows) {
            return;
        }
        tags.collect_edges(&item.rings);
        let edges = std::mem::take(&mut tags.edge_list);
        self.search(item, origin, (cols, rows), portions, &edges);
        self.tags().edge_list = edges;
    }

    /// The chain tags of the item being accumulated, made on first use.
    #[inline]
    pub(crate) fn tags(&mut self) -> &mut ChainTags {
        self.tags.get_or_insert_with(Default::default)
    }

    /// Finds the candidate cells among the flagged ones of the box of `(cols, rows)` cells
    /// whose first is device pixel `origin`, and integrates them, walking `edges` (every
    /// edge of the item when empty).
    fn search(
        &mut self,
        item: &Item,
        origin: (i64, i64),
        (cols, rows): (usize, usize),
        portions: bool,
        edges: &[(u32, u32)],
    ) {
        let (x0, y0) = (origin.0 as f64, origin.1 as f64);
        let bx = [x0, y0, x0 + cols as f64, y0 + rows as f64];
        if self.state.len() < cols * rows {
            self.state.resize(cols * rows, CellState::default());
        }
        let flagged = &self.flags;
        let row_of = |y: f64| (floor_f64(y) - y0).clamp(0.0, rows as f64 - 1.0) as usize;
        let near_flag = |r: usize, c0: f64, c1: f64| flagged.near(r, c0, c1);
        // 1. Candidates; every piece is kept (its cell in `slot` for now). A piece on a
        // grid line gives half of its gradient to each cell beside it, with the windings
        // on both sides of it. The accumulated slope of a cell assumes the cell's own pair
        // of windings, which the piece's far side can lie outside of when the cell holds
        // two windings (pieces inside it): such a cell beside a piece on a grid line is a
        // candidate. (A cell of one winding has an integral integer winding, whose
        // one-sided slopes are right whatever lies beyond its sides.) The walk reaches one
        // cell beyond the box's right and bottom lines for such pieces (the line between
        // two row bands: the band below has the piece's own cell).
        let (state, touched) = (&mut self.state, &mut self.touched);
        let all = &mut self.all;
        all.clear();
        let mut on_edge = |ia: usize, ib: usize| {
            let (p, q) = (item.pts[ia], item.pts[ib]);
            // Only the rows where a candidate can be (every edge touching them).
            let (r0, r1) = (row_of(p[1].min(q[1])), row_of(p[1].max(q[1])));
            let (c0, c1) = (
                floor_f64(p[0].min(q[0])) - 1.0,
                floor_f64(p[0].max(q[0])) + 1.0,
            );
            let bits = dir_bits(q[0] - p[0], q[1] - p[1]);
            let on_v = p[0] == q[0] && p[0] == floor_f64(p[0]);
            let on_h = p[1] == q[1] && p[1] == floor_f64(p[1]);
            let mut visit = |col: usize, row: usize, ta: f64, tb: f64| {
                let piece = |slot: usize, beyond: bool| Piece {
                    slot: slot as u32,
                    a: ia as u32,
                    b: ib as u32,
                    ta,
                    tb,
                    half: false,
                    beyond,
                };
                if col == cols || row == rows {
                    // Beyond the box: only a piece on the line, for the cell inside.
                    if col == cols && row < rows && on_v && col > 0 {
                        let k = row * cols + col - 1;
                        mark_on_line(state, touched, k);
                        all.push(piece(k, true));
                    } else if row == rows && col < cols && on_h && row > 0 {
                        let k = (row - 1) * cols + col;
                        mark_on_line(state, touched, k);
                        all.push(piece(k, true));
                    }
                    return;
                }
                let k = row * cols + col;
                all.push(piece(k, false));
                let s = &mut state[k];
                let (ia, ib) = (ia as u32, ib as u32);
                if s.count == 0 && !s.on_line {
                    touched.push(k as u32);
                    s.head = if ta == 0.0 { ia } else { NONE };
                    s.tail = if tb == 1.0 { ib } else { NONE };
                } else if s.count == 0 {
                    // Marked by a neighbour's piece on a grid line: already touched.
                    s.head = if ta == 0.0 { ia } else { NONE };
                    s.tail = if tb == 1.0 { ib } else { NONE };
                } else if s.tail != NONE && s.tail == ia && ta == 0.0 {
                    s.tail = if tb == 1.0 { ib } else { NONE };
                } else if s.head != NONE && s.head == ib && tb == 1.0 {
                    s.head = if ta == 0.0 { ia } else { NONE };
                } else {
                    s.candidate = true;
                }
                s.count = s.count.saturating_add(1);
                s.dirs |= bits;
                if s.dirs == 0b1111 {
                    s.candidate = true;
                }
                if on_v || on_h {
                    s.on_line = true;
                    if on_v && col > 0 {
                        mark_on_line(state, touched, k - 1);
                    } else if on_h
                        && row > 0
                        && near_flag(row - 1, x0 + col as f64, x0 + col as f64)
                    {
                        mark_on_line(state, touched, k - cols);
                    }
                } else {
                    s.inner = true;
                }
            };
            // Only the flagged cells of those rows are walked (and the cells beyond the
            // box's right and bottom lines beside them).
            for r in r0..=r1 {
                flagged.runs(r, c0, c1, &mut |a, b| {
                    let sub = [
                        x0 + a as f64,
                        y0 + r as f64,
                        x0 + b as f64 + if b + 1 == cols { 2.0 } else { 1.0 },
                        y0 + r as f64 + if r + 1 == rows { 2.0 } else { 1.0 },
                    ];
                    walk(p, q, sub, &mut |col, row, ta, tb| {
                        visit(col + a, row + r, ta, tb)
                    });
                });
            }
        };
        if edges.is_empty() {
            item.for_each_edge_near(bx[1], bx[3], on_edge);
        } else {
            for &(ia, ib) in edges {
                on_edge(ia as usize, ib as usize);
            }
        }
        let found = &mut self.found;
        found.clear();
        for &k in touched.iter() {
            let s = &state[k as usize];
            // A cell that is a candidate only for a neighbour's piece on a grid line holds
            // two windings: only its gradient needs it.
            if (s.candidate || (portions && s.on_line && s.inner))
                && s.count as usize <= SAMPLED_PIECES
            {
                found.push(k);
            }
        }
        if !found.is_empty() {
            found.sort_unstable();
            for (slot, &k) in found.iter().enumerate() {
                state[k as usize].slot = slot as u32;
            }
            // 2. The candidates' pieces; a piece on a grid line also counts (half) in the
            // cell on the line's other side.
            let pieces = &mut self.pieces;
            pieces.clear();
            for piece in &self.all {
                let k = piece.slot as usize;
                let (p, q) = (item.pts[piece.a as usize], item.pts[piece.b as usize]);
                let on_v = p[0] == q[0] && p[0] == floor_f64(p[0]);
                let on_h = p[1] == q[1] && p[1] == floor_f64(p[1]);
                let half = on_v || on_h;
                let mut push = |k: usize| {
                    let slot = state[k].slot;
                    if slot != NONE {
                        pieces.push(Piece {
                            slot,
                            half,
                            ..*piece
                        });
                    }
                };
                push(k);
                if piece.beyond {
                    continue;
                }
                let (row, col) = (k / cols, k % cols);
                if on_v && col > 0 {
                    push(k - 1);
                } else if on_h && row > 0 {
                    push(k - cols);
                }
            }
            self.pieces.sort_by_key(|p| p.slot);
            let mut at = 0;
            for slot in 0..self.found.len() {
                let k = self.found[slot];
                let end = at
                    + self.pieces[at..]
                        .iter()
                        .take_while(|p| p.slot == slot as u32)
                        .count();
                let (row, col) = (k as usize / cols, k as usize % cols);
                let cell = [x0 + col as f64, y0 + row as f64];
                self.cell(item, cell, at..end, portions);
                let c = self.cells.last_mut().expect("a cell");
                (c.row, c.col) = (row as u32, col as u32);
                at = end;
            }
        }
        for &k in &self.touched {
            self.state[k as usize] = CellState::default();
        }
        self.touched.clear();
    }

    /// Areas (and portions) of one candidate cell at device pixel `cell` from
    /// `self.pieces[range]`.
    fn cell(
        &mut self,
        item: &Item,
        cell: Point,
        range: std::ops::Range<usize>,
        want_portions: bool,
    ) {
        let [cx, cy] = cell;
        let hist_start = self.hist.len();
        let portions_start = self.portions.len();
        let pieces = &self.pieces[range];
        let segs = &mut self.segs;
        segs.clear();
        for p in pieces {
            let (pa, pb) = (item.pts[p.a as usize], item.pts[p.b as usize]);
            let at = |t: f64| [pa[0] + (pb[0] - pa[0]) * t, pa[1] + (pb[1] - pa[1]) * t];
            let clamp = |q: Point| [q[0].clamp(cx, cx + 1.0), q[1].clamp(cy, cy + 1.0)];
            let (q0, q1) = (clamp(at(p.ta)), clamp(at(p.tb)));
            let dy = pb[1] - pa[1];
            let dir = if q0[1] == q1[1] {
                0
            } else if dy > 0.0 {
                1
            } else {
                -1
            };
            let dx = pb[0] - pa[0];
            let sx = if dx > 0.0 {
                1
            } else if dx < 0.0 {
                -1
            } else {
                0
            };
            segs.push(Seg {
                q0,
                q1,
                dir,
                sx,
                ylo: q0[1].min(q1[1]),
                yhi: q0[1].max(q1[1]),
            });
        }
        let exact = pieces.len() <= EXACT_PIECES;
        // Strip lines.
        let ys = &mut self.ys;
        ys.clear();
        if exact {
            ys.extend([cy, cy + 1.0]);
            for s in segs.iter() {
                ys.extend([s.q0[1], s.q1[1]]);
            }
            for i in 0..segs.len() {
                let a = &segs[i];
                if a.dir == 0 {
                    continue;
                }
                for b in &segs[i + 1..] {
                    if b.dir == 0 {
                        continue;
                    }
                    let (lo, hi) = (a.ylo.max(b.ylo), a.yhi.min(b.yhi));
                    if !(hi > lo) {
                        continue;
                    }
                    let dlo = a.x_at(lo) - b.x_at(lo);
                    let dhi = a.x_at(hi) - b.x_at(hi);
                    if (dlo > 0.0 && dhi < 0.0) || (dlo < 0.0 && dhi > 0.0) {
                        ys.push(lo + (hi - lo) * (dlo / (dlo - dhi)));
                    }
                }
            }
            ys.sort_by(|a, b| a.total_cmp(b));
            ys.dedup();
        } else {
            ys.extend((0..=SAMPLE_ROWS).map(|k| cy + k as f64 / SAMPLE_ROWS as f64));
        }
        // Where pieces leave the cell's left side: the winding just inside it changes by
        // `−sign(dx)` going down past them.
        let left = &mut self.left;
        left.clear();
        const ON: f64 = 1e-9;
        for s in segs.iter() {
            let (near, far) = if s.q0[0] <= s.q1[0] {
                (s.q0, s.q1)
            } else {
                (s.q1, s.q0)
            };
            if near[0] <= cx + ON && far[0] > cx + ON {
                left.push((near[1], -s.sx));
            } else if s.dir != 0 && far[0] <= cx + ON {
                // On the left side: the strips start left of it (it adds its `dir` in
                // them), while the pieces above count the winding just inside.
                left.push((s.ylo, -s.dir));
                left.push((s.yhi, s.dir));
            }
        }
        let w_left = |y: f64| -> i32 { left.iter().filter(|l| l.0 < y).map(|l| l.1).sum() };
        let last = &mut self.last_portion;
        last.clear();
        last.resize(segs.len(), NONE);
        let hist = &mut self.hist;
        let portions = &mut self.portions;
        let order = &mut self.order;
        let mut add_area = |rel: i32, area: f64| {
            if area <= 0.0 {
                return;
            }
            match hist[hist_start..].iter_mut().find(|e| e.0 == rel) {
                Some(e) => e.1 += area,
                None => hist.push((rel, area)),
            }
        };
        let mut add_portion = |j: usize, y0: f64, y1: f64, rel_lo: i32, scanline: Option<f64>| {
            let p = &pieces[j];
            if let Some(h) = scanline {
                // A scanline's crossing at `y0`: `h / |dy|` of the edge's parameter at
                // `t`, written as a portion of that length centred on `t` (whose first
                // moment is then `t` times it): the derivative of the sampled coverage.
                let (pa, pb) = (item.pts[p.a as usize], item.pts[p.b as usize]);
                let dy = pb[1] - pa[1];
                let (t, m) = ((y0 - pa[1]) / dy, h / dy.abs());
                if t.is_finite() && m.is_finite() {
                    portions.push(Portion {
                        a: p.a,
                        b: p.b,
                        t0: t - 0.5 * m,
                        t1: t + 0.5 * m,
                        rel_lo,
                        half: p.half,
                    });
                }
                return;
            }
            let (pa, pb) = (item.pts[p.a as usize], item.pts[p.b as usize]);
            let dy = pb[1] - pa[1];
            let (u0, u1) = ((y0 - pa[1]) / dy, (y1 - pa[1]) / dy);
            let (lo, hi) = (p.ta.min(p.tb), p.ta.max(p.tb));
            let (t0, t1) = (u0.min(u1).clamp(lo, hi), u0.max(u1).clamp(lo, hi));
            if !(t1 > t0) {
                return;
            }
            let l = last[j];
            if l != NONE {
                let q = &mut portions[l as usize];
                if q.rel_lo == rel_lo && (q.t1 == t0 || q.t0 == t1) {
                    q.t0 = q.t0.min(t0);
                    q.t1 = q.t1.max(t1);
                    return;
                }
            }
            last[j] = portions.len() as u32;
            portions.push(Portion {
                a: p.a,
                b: p.b,
                t0,
                t1,
                rel_lo,
                half: p.half,
            });
        };
        for k in 0..ys.len().saturating_sub(1) {
            let (ya, yb) = (ys[k], ys[k + 1]);
            let h = yb - ya;
            if !(h > 1e-12) {
                continue;
            }
            let ym = 0.5 * (ya + yb);
            order.clear();
            for (j, s) in segs.iter().enumerate() {
                if s.dir != 0 && s.ylo < ym && ym < s.yhi {
                    order.push((s.x_at(ym).clamp(cx, cx + 1.0), j));
                }
            }
            order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let mut w = w_left(ym);
            let mut x_prev = cx;
            for &(x, j) in order.iter() {
                add_area(w, h * (x - x_prev));
                let wl = w;
                w += segs[j].dir;
                if want_portions && exact {
                    let s = &segs[j];
                    add_portion(j, ya.max(s.ylo), yb.min(s.yhi), wl.min(w), None);
                } else if want_portions {
                    add_portion(j, ym, ym, wl.min(w), Some(h));
                }
                x_prev = x;
            }
            add_area(w, h * (cx + 1.0 - x_prev));
        }
        if want_portions && exact {
            // Horizontal pieces: the winding beside each portion from the strip next to
            // it, coincident horizontal pieces stacked in their order.
            for (j, s) in segs.iter().enumerate() {
                if s.dir != 0 || s.q0[0] == s.q1[0] {
                    continue;
                }
                let yh = s.q0[1];
                let below = yh < cy + 1.0;
                // The strip beside the piece: the nearest one of some height (a piece
                // ending within rounding of the cell's side leaves a sliver strip, which
                // the areas skip too).
                let Some(k) = ys.iter().position(|&y| y >= yh) else {
                    continue;
                };
                let strip = if below {
                    (k + 1..ys.len())
                        .map(|i| (ys[i - 1], ys[i]))
                        .find(|(ya, yb)| yb - ya > 1e-12)
                } else {
                    (1..=k)
                        .rev()
                        .map(|i| (ys[i - 1], ys[i]))
                        .find(|(ya, yb)| yb - ya > 1e-12)
                };
                let Some((ya, yb)) = strip else {
                    continue;
                };
                let ym = 0.5 * (ya + yb);
                let (xl, xr) = (s.q0[0].min(s.q1[0]), s.q0[0].max(s.q1[0]));
                order.clear();
                for (i, t) in segs.iter().enumerate() {
                    if t.dir != 0 && t.ylo < ym && ym < t.yhi {
                        order.push((t.x_at(yh), i));
                    }
                }
                let cuts = &mut self.cuts;
                cuts.clear();
                cuts.extend([xl, xr]);
                cuts.extend(order.iter().map(|o| o.0).filter(|&x| x > xl && x < xr));
                cuts.sort_by(|a, b| a.total_cmp(b));
                let wl = w_left(ym);
                let p = &pieces[j];
                let (pa, pb) = (item.pts[p.a as usize], item.pts[p.b as usize]);
                let dx = pb[0] - pa[0];
                for c in cuts.windows(2) {
                    if !(c[1] > c[0]) {
                        continue;
                    }
                    let xp = 0.5 * (c[0] + c[1]);
                    let side: i32 = wl
                        + order
                            .iter()
                            .filter(|o| o.0 < xp)
                            .map(|o| segs[o.1].dir)
                            .sum::<i32>();
                    // Earlier coincident horizontal pieces covering `xp` lie between this
                    // one and the strip.
                    let stacked: i32 = segs[..j]
                        .iter()
                        .filter(|t| {
                            t.dir == 0
                                && t.q0[1] == yh
                                && t.q0[0].min(t.q1[0]) < xp
                                && xp < t.q0[0].max(t.q1[0])
                        })
                        .map(|t| t.sx)
                        .sum();
                    // Going up across a piece with `dx > 0` raises the winding by one.
                    let (w_below, w_above) = if below {
                        let wb = side + stacked;
                        (wb, wb + s.sx)
                    } else {
                        let wa = side - stacked;
                        (wa - s.sx, wa)
                    };
                    let (u0, u1) = ((c[0] - pa[0]) / dx, (c[1] - pa[0]) / dx);
                    let (lo, hi) = (p.ta.min(p.tb), p.ta.max(p.tb));
                    let (t0, t1) = (u0.min(u1).clamp(lo, hi), u0.max(u1).clamp(lo, hi));
                    if t1 > t0 {
                        portions.push(Portion {
                            a: p.a,
                            b: p.b,
                            t0,
                            t1,
                            rel_lo: w_below.min(w_above),
                            half: p.half,
                        });
                    }
                }
            }
        }
        self.cells.push(ExactCell {
            row: 0,
            col: 0,
            hist: (hist_start as u32, self.hist.len() as u32),
            portions: (portions_start as u32, self.portions.len() as u32),
            w0: 0,
            active: false,
            sampled: !exact,
            grad: false,
        });
    }

    /// Whether the current item has no candidate cell at all.
    #[inline]
    pub(crate) fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// Whether row `row` (of the band's cell box) holds a candidate cell not yet resolved.
    #[inline]
    pub(crate) fn has_row(&self, row: usize) -> bool {
        self.cells
            .get(self.next)
            .is_some_and(|c| c.row as usize == row)
    }

    /// Resolves the candidate cells of row `row` from its winding integrals `wrow`:
    /// where the windings inside span more than two adjacent values, `covs` gets the exact
    /// coverage and the cell is marked active. Rows must come in order. Returns the range
    /// of [`cells`](Self::cells) in this row.
    pub(crate) fn resolve_row(
        &mut self,
        row: usize,
        wrow: &[f32],
        evenodd: bool,
        covs: &mut [f32],
    ) -> std::ops::Range<usize> {
        let start = self.next;
        while let Some(c) = self.cells.get_mut(self.next) {
            if c.row as usize != row {
                break;
            }
            self.next += 1;
            let col = c.col as usize;
            let Some(&integral) = wrow.get(col) else {
                continue;
            };
            let hist = &self.hist[c.hist.0 as usize..c.hist.1 as usize];
            let (mut lo, mut hi, mut moment) = (i32::MAX, i32::MIN, 0.0f64);
            for &(rel, area) in hist {
                moment += rel as f64 * area;
                if area > 1e-9 {
                    lo = lo.min(rel);
                    hi = hi.max(rel);
                }
            }
            let w0 = (integral as f64 - moment).round();
            if !w0.is_finite() || w0.abs() > 1e9 {
                continue;
            }
            let w0 = w0 as i32;
            c.w0 = w0;
            // A cell whose windings span two adjacent values keeps its accumulated value
            // (the same area); its gradient still goes through its pieces when they are
            // integrated exactly, with the windings on both sides of the pieces on its
            // sides.
            c.grad = !c.sampled;
            if hi <= lo.saturating_add(1) {
                continue;
            }
            let cov: f64 = hist
                .iter()
                .filter(|e| inside(w0.saturating_add(e.0), evenodd))
                .map(|e| e.1)
                .sum();
            covs[col] = cov.clamp(0.0, 1.0) as f32;
            c.active = true;
            c.grad = true;
        }
        start..self.next
    }
}

/// The fill rule's indicator: whether winding `w` is inside.
#[inline]
pub(crate) fn inside(w: i32, evenodd: bool) -> bool {
    if evenodd { w & 1 != 0 } else { w != 0 }
}

/// `f(w + 1) − f(w)` for the fill rule's indicator `f`: the weight of a portion whose
/// lower side has winding `w`.
#[inline]
pub(crate) fn portion_weight(w: i32, evenodd: bool) -> f64 {
    inside(w.saturating_add(1), evenodd) as i32 as f64 - inside(w, evenodd) as i32 as f64
}

/// [`TagCell::meta`]: more than one chain, or a chain monotone in neither x nor y.
const TAG_CANDIDATE: u32 = 1 << 4;
/// [`TagCell::meta`]: two chains, not yet judged (the first one's ends are in
/// [`ChainTags::twos`] at [`TagCell::slot`]).
const TAG_TWO: u32 = 1 << 5;
/// [`TagCell::meta`] and [`ChainTags::bits`]: an edge that closes its ring (it ends at
/// the ring's first vertex), so that no edge continues it.
const TAG_CLOSES: u32 = 1 << 6;
/// [`TagCell::meta`]: the generation is kept above this bit.
const TAG_GEN_SHIFT: u32 = 16;

/// One cell's latest chain, as the start vertices of its first and last edges, and what
/// [`ChainTags`] knows of the cell. The chain's end vertices need not be kept: edges come
/// in ring order, so an edge continues the chain when it starts where the last one ended
/// (`last + 1`, unless the last closed its ring) inside the cell, and extends it backward
/// when it ends where the first one started inside the cell (a ring's closing edge).
#[derive(Clone, Copy, Default)]
struct TagCell {
    first: u32,
    last: u32,
    /// Direction bits (+x, −x, +y, −y), [`TAG_CANDIDATE`], [`TAG_TWO`], [`TAG_CLOSES`],
    /// generation above [`TAG_GEN_SHIFT`].
    meta: u32,
    /// With [`TAG_TWO`]: the cell's index in [`ChainTags::twos`].
    slot: u32,
}

/// Which cells of an item's box can hold three winding values, recorded while its edges are
/// accumulated ([`accumulate_line_visiting`](super::coverage::accumulate_line_visiting)):
/// each cell keeps the chain of consecutive edges that crossed its interior; a second
/// chain, or a chain monotone in neither x nor y, makes it a candidate (the rule of
/// [`Overlaps::search`]'s walk, which then looks at the candidates alone). Entries carry a
/// generation, so nothing is cleared between items.
#[derive(Default)]
pub(crate) struct ChainTags {
    cells: Vec<TagCell>,
    generation: u32,
    w: usize,
    h: usize,
    x0: f64,
    y0: f64,
    /// Candidate cells (local, row-major index), each once.
    cands: Vec<u32>,
    /// Cells that got a second chain, with the first chain's first and last edges.
    twos: Vec<(u32, u32, u32)>,
    /// Scratch of [`judge_twos`](Self::judge_twos): the two chains' edges.
    chain_a: Vec<(Point, Point)>,
    chain_b: Vec<(Point, Point)>,
    /// `(row, c0, c1)`: cells beside a piece on a grid line (for the backward pass).
    lines: Vec<(u32, u32, u32)>,
    /// Chains of the candidate cells, as `(first, last)` edges, before they were.
    chains: Vec<(u32, u32)>,
    /// Edges with a piece in a candidate cell once it was one, and edges on grid lines.
    edges: Vec<(u32, u32)>,
    /// Every edge with a piece in a candidate cell, in ring order, once each
    /// ([`collect_edges`](Self::collect_edges)); empty to search every edge.
    edge_list: Vec<(u32, u32)>,
    for_backward: bool,
    /// The current edge's vertices, direction bits and the cells of its ends.
    ia: u32,
    ic: u32,
    bits: u32,
    cell_a: usize,
    cell_c: usize,
    on_v: bool,
}

impl ChainTags {
    /// Starts an item accumulated into the box of `w × h` cells whose first is device
    /// pixel `(x0, y0)`.
    pub(crate) fn begin(&mut self, x0: i64, y0: i64, w: usize, h: usize, for_backward: bool) {
        self.generation += 1;
        if self.generation >= 1 << (32 - TAG_GEN_SHIFT) {
            self.cells.clear();
            self.generation = 1;
        }
        if self.cells.len() < w * h {
            self.cells.resize(w * h, TagCell::default());
        }
        (self.w, self.h, self.x0, self.y0) = (w, h, x0 as f64, y0 as f64);
        self.cands.clear();
        self.twos.clear();
        self.lines.clear();
        self.chains.clear();
        self.edges.clear();
        self.for_backward = for_backward;
    }

    /// The local cell index of device point `q`, or `usize::MAX` outside the box.
    #[inline]
    fn cell_of(&self, q: Point) -> usize {
        let (c, r) = (floor_f64(q[0] - self.x0), floor_f64(q[1] - self.y0));
        if c >= 0.0 && r >= 0.0 && c < self.w as f64 && r < self.h as f64 {
            r as usize * self.w + c as usize
        } else {
            usize::MAX
        }
    }

    /// Starts edge `ia → ic` (`a → c`, device pixels) before it is accumulated.
    #[inline(always)]
    pub(crate) fn edge(&mut self, ia: usize, ic: usize, a: Point, c: Point) {
        self.ia = ia as u32;
        self.ic = ic as u32;
        self.bits =
            dir_bits(c[0] - a[0], c[1] - a[1]) as u32 | if ic <= ia { TAG_CLOSES } else { 0 };
        self.cell_a = self.cell_of(a);
        self.cell_c = self.cell_of(c);
        self.on_v = a[0] == c[0] && a[0] == floor_f64(a[0]);
    }

    /// A horizontal edge `ia → ic` (`a → c`), which accumulating skips: it still parts the
    /// cells it crosses. One on a grid line crosses none (the cells beside it are kept for
    /// the backward pass). `x_max` is the canvas's width.
    pub(crate) fn horizontal(&mut self, ia: usize, ic: usize, a: Point, c: Point, x_max: f64) {
        let y = a[1] - self.y0;
        let (xl, xr) = (
            a[0].min(c[0]).clamp(0.0, x_max) - self.x0,
            a[0].max(c[0]).clamp(0.0, x_max) - self.x0,
        );
        if xl == xr && (a[0] < 0.0 || a[0] > x_max) {
            return;
        }
        let last = self.w as f64 - 1.0;
        let c0 = floor_f64(xl).clamp(0.0, last);
        let c1 = (super::coverage::ceil_f64(xr) - 1.0).clamp(c0, last);
        if y == floor_f64(y) {
            self.edges.push((ia as u32, ic as u32));
            if self.for_backward {
                for r in [y - 1.0, y] {
                    if r >= 0.0 && r < self.h as f64 {
                        self.lines
                            .push((r as u32, c0 as u32, (c1 + 1.0).min(last) as u32));
                    }
                }
            }
            return;
        }
        if y < 0.0 || y >= self.h as f64 {
            return;
        }
        self.edge(ia, ic, a, c);
        super::coverage::CellVisitor::piece(self, y as usize, c0 as usize, c1 as usize);
    }

    /// Judges the cells of two chains once the item is done: where the chains do not meet
    /// inside the cell and each lies on the same side of the other (so the windings
    /// beside them are equal and the one between differs by one,
    /// [`chains_wind_alike`]), the cell holds two adjacent windings; anything else makes
    /// it a candidate.
    fn judge_twos(&mut self, pts: &[Point], rings: &[(usize, usize)]) {
        for i in 0..self.twos.len() {
            let (k, other, other_last) = self.twos[i];
            let k = k as usize;
            let t = self.cells[k];
            if t.meta & TAG_CANDIDATE != 0 {
                continue;
            }
            let cell = [self.x0 + (k % self.w) as f64, self.y0 + (k / self.w) as f64];
            let (a, b) = (&mut self.chain_a, &mut self.chain_b);
            chain_edges(pts, rings, other, other_last, a);
            chain_edges(pts, rings, t.first, t.last, b);
            if !chains_wind_alike(a, b, cell) {
                self.cells[k].meta |= TAG_CANDIDATE;
                self.cands.push(k as u32);
                self.chains.push((other, other_last));
                self.chains.push((t.first, t.last));
            }
        }
    }

    /// Fills [`edge_list`](Self::edge_list) with every edge that has a piece in a
    /// candidate cell (each chain's edges, and the edges seen once the cell was one), and
    /// every edge on a grid line, sorted by their first vertex (ring order), once each.
    /// For the backward pass, whose flags also hold cells beside pieces on grid lines,
    /// the list stays empty: every edge is searched.
    fn collect_edges(&mut self, rings: &[(usize, usize)]) {
        let list = &mut self.edge_list;
        list.clear();
        if self.for_backward {
            return;
        }
        list.extend_from_slice(&self.edges);
        for &(first, last) in &self.chains {
            for_chain_edges(rings, first, last, usize::MAX, |a, c| {
                list.push((a as u32, c as u32))
            });
        }
        list.sort_unstable();
        list.dedup();
    }

    /// Flags the candidate cells (and, for the backward pass, the cells beside pieces on
    /// grid lines) in `flags`, over the box's first `cols` columns (first device column
    /// `x0`) and `rows` rows. Returns whether any is flagged.
    fn flag(&self, flags: &mut Flags, x0: f64, cols: usize, rows: usize) -> bool {
        if self.cands.is_empty() && self.lines.is_empty() {
            return false;
        }
        flags.reset(x0, cols, rows);
        let mut any = false;
        for &k in &self.cands {
            let (r, c) = (k as usize / self.w, k as usize % self.w);
            if c < cols && r < rows {
                flags.mark(r, x0 + c as f64, x0 + c as f64);
                any = true;
            }
        }
        for &(r, c0, c1) in &self.lines {
            if (c0 as usize) < cols && (r as usize) < rows {
                flags.mark(r as usize, x0 + c0 as f64, x0 + c1 as f64);
                any = true;
            }
        }
        any
    }
}

impl super::coverage::CellVisitor for ChainTags {
    #[inline(always)]
    fn piece(&mut self, row: usize, c0: usize, c1: usize) {
        let gen_bits = self.generation << TAG_GEN_SHIFT;
        let first = row * self.w;
        for k in first + c0..=first + c1 {
            let t = self.cells[k];
            if t.meta >> TAG_GEN_SHIFT != self.generation {
                self.cells[k] = TagCell {
                    first: self.ia,
                    last: self.ia,
                    meta: gen_bits | self.bits,
                    slot: 0,
                };
                continue;
            }
            if t.meta & TAG_CANDIDATE != 0 {
                self.edges.push((self.ia, self.ic));
                continue;
            }
            let mut n = t;
            n.meta |= self.bits;
            if t.last.wrapping_add(1) == self.ia && t.meta & TAG_CLOSES == 0 && k == self.cell_a {
                // The last edge ended where this one starts, inside the cell.
                n.last = self.ia;
            } else if t.first == self.ic && k == self.cell_c {
                // This edge ends where the first one started, inside the cell.
                n.first = self.ia;
            } else if t.meta & TAG_TWO == 0 {
                // A second chain: judged when the item is done. The direction bits are
                // the second chain's from here on.
                n.meta = (t.meta & !0b1111 & !TAG_CLOSES) | TAG_TWO | self.bits;
                n.slot = self.twos.len() as u32;
                self.twos.push((k as u32, t.first, t.last));
                (n.first, n.last) = (self.ia, self.ia);
            } else {
                n.meta |= TAG_CANDIDATE;
            }
            if n.meta & 0b1111 == 0b1111 {
                n.meta |= TAG_CANDIDATE;
            }
            if n.meta & TAG_CANDIDATE != 0 {
                self.cands.push(k as u32);
                if t.meta & TAG_TWO != 0 {
                    let (_, other, other_last) = self.twos[t.slot as usize];
                    self.chains.push((other, other_last));
                }
                self.chains.push((t.first, t.last));
                self.edges.push((self.ia, self.ic));
            }
            self.cells[k] = n;
        }
        if self.on_v {
            self.edges.push((self.ia, self.ic));
            if self.for_backward {
                self.lines
                    .push((row as u32, c0.saturating_sub(1) as u32, c0 as u32));
            }
        }
    }
}

/// Calls `f(a, c)` for each edge `a → c` of a chain, from the one starting at vertex
/// `first` to the one starting at `last`, in ring order (round the end of the ring that
/// holds `first`). Returns `false`, having stopped, after `max` edges or a whole ring
/// without reaching `last`.
fn for_chain_edges(
    rings: &[(usize, usize)],
    first: u32,
    last: u32,
    max: usize,
    mut f: impl FnMut(usize, usize),
) -> bool {
    // The ring holding the chain (rings are in order of their first vertex).
    let at = rings.partition_point(|r| r.0 <= first as usize) - 1;
    let (s, n) = rings[at];
    let mut e = first as usize;
    for _ in 0..max.min(n) {
        let c = if e + 1 == s + n { s } else { e + 1 };
        f(e, c);
        if e == last as usize {
            return true;
        }
        e = c;
    }
    false
}

/// The edges of a chain from the one starting at vertex `first` to the one starting at
/// `last`, in ring order, into `out` (at most [`EXACT_PIECES`]; more leaves `out` empty).
fn chain_edges(
    pts: &[Point],
    rings: &[(usize, usize)],
    first: u32,
    last: u32,
    out: &mut Vec<(Point, Point)>,
) {
    out.clear();
    if !for_chain_edges(rings, first, last, EXACT_PIECES, |a, c| {
        out.push((pts[a], pts[c]))
    }) {
        out.clear();
    }
}

/// Whether chains `a` and `b` (edges in ring order), each crossing the unit cell whose
/// first corner is `cell` from side to side, part it into three regions whose windings
/// the two outer ones share: no piece of one meets a piece of the other inside the
/// (closed) cell, and each chain lies on the same side (left or right) of the other.
/// `false` when unsure.
fn chains_wind_alike(a: &[(Point, Point)], b: &[(Point, Point)], cell: Point) -> bool {
    let bx = [cell[0], cell[1], cell[0] + 1.0, cell[1] + 1.0];
    let clip = |&(p, q): &(Point, Point)| {
        let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
        clip_to_box(p, dx, dy, bx).map(|(t0, t1)| {
            (
                [p[0] + dx * t0, p[1] + dy * t0],
                [p[0] + dx * t1, p[1] + dy * t1],
            )
        })
    };
    let mut pa = [([0.0; 2], [0.0; 2]); EXACT_PIECES];
    let mut pb = [([0.0; 2], [0.0; 2]); EXACT_PIECES];
    let pieces = |chain: &[(Point, Point)], out: &mut [(Point, Point); EXACT_PIECES]| {
        if chain.is_empty() || chain.len() > EXACT_PIECES {
            return None;
        }
        for (o, e) in out.iter_mut().zip(chain) {
            *o = clip(e)?;
        }
        Some(chain.len())
    };
    let (Some(na), Some(nb)) = (pieces(a, &mut pa), pieces(b, &mut pb)) else {
        return false;
    };
    let (pa, pb) = (&pa[..na], &pb[..nb]);
    // Each chain enters and leaves through the cell's sides.
    let on_side = |p: Point| {
        let e = 1e-9;
        p[0] <= bx[0] + e || p[0] >= bx[2] - e || p[1] <= bx[1] + e || p[1] >= bx[3] - e
    };
    if !on_side(pa[0].0) || !on_side(pa[na - 1].1) || !on_side(pb[0].0) || !on_side(pb[nb - 1].1) {
        return false;
    }
    for &(p, q) in pa {
        for &(r, t) in pb {
            if segments_meet(p, q, r, t) {
                return false;
            }
        }
    }
    let mid = |s: &[(Point, Point)]| {
        let (p, q) = s[s.len() / 2];
        [0.5 * (p[0] + q[0]), 0.5 * (p[1] + q[1])]
    };
    match (side_region(pa, mid(pb), bx), side_region(pb, mid(pa), bx)) {
        (Some(x), Some(y)) => x == y,
        _ => false,
    }
}

/// Orientation of `r` against the line `p → q`: the sign of the cross product, `0` when
/// within rounding of the line.
#[inline]
fn orient(p: Point, q: Point, r: Point) -> i32 {
    let (dx, dy) = (q[0] - p[0], q[1] - p[1]);
    let c = dx * (r[1] - p[1]) - dy * (r[0] - p[0]);
    let scale = (dx.abs() + dy.abs()) * ((r[0] - p[0]).abs() + (r[1] - p[1]).abs());
    if c > 1e-12 * scale {
        1
    } else if c < -1e-12 * scale {
        -1
    } else {
        0
    }
}

/// Whether segments `p → q` and `r → t` meet (touching, or collinear and near, counts).
fn segments_meet(p: Point, q: Point, r: Point, t: Point) -> bool {
    let (d1, d2) = (orient(r, t, p), orient(r, t, q));
    let (d3, d4) = (orient(p, q, r), orient(p, q, t));
    d1 * d2 <= 0 && d3 * d4 <= 0
}

/// Whether `q` lies in the region that the chain of pieces `chain` (from the box's side
/// back to its side) closes with the box's sides walked clockwise on screen from the
/// chain's end to its start: the same side of every chain, so two chains that lie each
/// on the same side of the other give the same answer. `None` when `q` is on a side.
fn side_region(chain: &[(Point, Point)], q: Point, bx: [f64; 4]) -> Option<bool> {
    let e = 1e-9;
    if q[0] <= bx[0] + e || q[0] >= bx[2] - e || q[1] <= bx[1] + e || q[1] >= bx[3] - e {
        return None;
    }
    // Position along the sides, clockwise on screen from the first corner: top 0–1,
    // right 1–2, bottom 2–3, left 3–4.
    let along = |p: Point| {
        let d = [p[1] - bx[1], bx[2] - p[0], bx[3] - p[1], p[0] - bx[0]];
        let side = (0..4)
            .min_by(|&i, &j| d[i].abs().total_cmp(&d[j].abs()))
            .unwrap_or(0);
        match side {
            0 => p[0] - bx[0],
            1 => 1.0 + (p[1] - bx[1]),
            2 => 2.0 + (bx[2] - p[0]),
            _ => 3.0 + (bx[3] - p[1]),
        }
    };
    let corner = |m: usize| match m % 4 {
        0 => [bx[0], bx[1]],
        1 => [bx[2], bx[1]],
        2 => [bx[2], bx[3]],
        _ => [bx[0], bx[3]],
    };
    let (start, end) = (chain[0].0, chain[chain.len() - 1].1);
    let (s_end, mut s_start) = (along(end), along(start));
    if s_start <= s_end {
        s_start += 4.0;
    }
    let mut inside = false;
    let mut cross = |u: Point, v: Point| {
        if (u[1] > q[1]) != (v[1] > q[1])
            && q[0] < u[0] + (q[1] - u[1]) * (v[0] - u[0]) / (v[1] - u[1])
        {
            inside = !inside;
        }
    };
    for &(u, v) in chain {
        cross(u, v);
    }
    // The sides from the chain's end, clockwise, back to its start.
    let mut at = end;
    let mut m = s_end.floor() as usize + 1;
    while (m as f64) < s_start {
        let c = corner(m);
        cross(at, c);
        at = c;
        m += 1;
    }
    cross(at, start);
    Some(inside)
}

/// Marks cell `k` as beside a piece on a grid line, touched.
#[inline]
fn mark_on_line(state: &mut [CellState], touched: &mut Vec<u32>, k: usize) {
    let s = &mut state[k];
    if s.count == 0 && !s.on_line {
        touched.push(k as u32);
    }
    s.on_line = true;
}

/// Bits for the directions of `(dx, dy)`: +x, −x, +y, −y.
#[inline]
fn dir_bits(dx: f64, dy: f64) -> u8 {
    (dx > 0.0) as u8 | ((dx < 0.0) as u8) << 1 | ((dy > 0.0) as u8) << 2 | ((dy < 0.0) as u8) << 3
}

/// Calls `f(col, row, ta, tb)` for each piece between grid lines of the segment `p0 → p1`
/// inside the box `bx` (device pixels, whole numbers), with the cell of its midpoint
/// relative to the box's first cell: a piece on a vertical grid line belongs to the cell
/// on its right, one on a horizontal line to the cell below.
fn walk(p0: Point, p1: Point, bx: [f64; 4], f: &mut impl FnMut(usize, usize, f64, f64)) {
    let (dx, dy) = (p1[0] - p0[0], p1[1] - p0[1]);
    if dx == 0.0 && dy == 0.0 {
        return;
    }
    let (c0, r0) = (floor_f64(p0[0]), floor_f64(p0[1]));
    if c0 == floor_f64(p1[0]) && r0 == floor_f64(p1[1]) {
        // Inside one cell (most chords at a fine tolerance): one piece, as the walk below
        // would give it without a sliver from rounding.
        let (c, r) = (c0 - bx[0], r0 - bx[1]);
        if c >= 0.0 && r >= 0.0 && c < bx[2] - bx[0] && r < bx[3] - bx[1] {
            f(c as usize, r as usize, 0.0, 1.0);
        }
        return;
    }
    let Some((t0, t1)) = clip_to_box(p0, dx, dy, bx) else {
        return;
    };
    let at = |t: f64| [p0[0] + dx * t, p0[1] + dy * t];
    let next = |v: f64, o: f64, d: f64| -> f64 {
        if d > 0.0 {
            (floor_f64(v) + 1.0 - o) / d
        } else if d < 0.0 {
            (super::coverage::ceil_f64(v) - 1.0 - o) / d
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
    let (cols, rows) = (bx[2] - bx[0], bx[3] - bx[1]);
    let mut ta = t0;
    let mut guard = 0usize;
    while ta < t1 && guard < 1 << 24 {
        guard += 1;
        let tb = nx.min(ny).min(t1);
        if tb > ta {
            let m = at(0.5 * (ta + tb));
            let (c, r) = (floor_f64(m[0]) - bx[0], floor_f64(m[1]) - bx[1]);
            if c >= 0.0 && r >= 0.0 && c < cols && r < rows {
                f(c as usize, r as usize, ta, tb);
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
}

/// Whether no pixel can hold three winding values: every ring is simple (convex, or
/// monotone in y with its two sides apart), and any two rings that can share a pixel (by
/// their boxes) are one convex ring holding the other strictly inside, wound the other
/// way: a stroke's outline around a convex shape (every file's frame), a ring with a
/// hole. Then a pixel holds the windings of at most two adjacent regions, 0 and that of
/// the space between. `false` when unsure (many rings close together, a ring neither
/// convex nor y-monotone, rings nested and wound alike, which give three values).
pub(crate) fn rings_cannot_overlap(pts: &[Point], rings: &[(usize, usize)]) -> bool {
    /// Pairs of rings compared at most, before giving up.
    const MAX_PAIRS: usize = 4096;
    /// Vertex-against-edge tests of nested rings at most, before giving up.
    const MAX_INSIDE_TESTS: usize = 1 << 16;
    let ring = |i: usize| {
        let (s, n) = rings[i];
        &pts[s..s + n]
    };
    let mut convex = Vec::with_capacity(rings.len());
    for i in 0..rings.len() {
        let c = ring_is_convex(ring(i));
        if !c && !ring_is_y_monotone_simple(ring(i)) {
            return false;
        }
        convex.push(c);
    }
    if rings.len() == 1 {
        return true;
    }
    // The cells each ring's box touches, `[x0, y0, x1, y1]` inclusive.
    let boxes: Vec<[f64; 4]> = (0..rings.len())
        .map(|i| {
            let mut b = [
                f64::INFINITY,
                f64::INFINITY,
                f64::NEG_INFINITY,
                f64::NEG_INFINITY,
            ];
            for q in ring(i) {
                b = [
                    b[0].min(q[0]),
                    b[1].min(q[1]),
                    b[2].max(q[0]),
                    b[3].max(q[1]),
                ];
            }
            b.map(floor_f64)
        })
        .collect();
    // Any two sharing a cell that are not nested apart, or too many to tell.
    let mut tests = MAX_INSIDE_TESTS;
    let mut nested_apart = |i: usize, j: usize| {
        let (a, b) = (ring(i), ring(j));
        let (sa, sb) = (ring_area(a), ring_area(b));
        if !(sa * sb < 0.0) || a.len() * b.len() > tests {
            return false;
        }
        tests -= a.len() * b.len();
        (convex[i] && b.iter().all(|&q| strictly_inside_convex(a, sa, q)))
            || (convex[j] && a.iter().all(|&q| strictly_inside_convex(b, sb, q)))
    };
    let mut scratch = sweep::Scratch::default();
    sweep::overlapping_pairs(&boxes, MAX_PAIRS, &mut scratch, &mut nested_apart)
        == sweep::Pairs::All
}

/// Twice the signed area of a ring (shoelace; positive when it turns from +x to +y).
fn ring_area(ring: &[Point]) -> f64 {
    let n = ring.len();
    (0..n)
        .map(|k| {
            let (a, b) = (ring[k], ring[(k + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum()
}

/// Whether `q` lies strictly inside the convex ring `ring`, whose signed area
/// ([`ring_area`]) is `area`: strictly on the inner side of every edge of non-zero length.
fn strictly_inside_convex(ring: &[Point], area: f64, q: Point) -> bool {
    let n = ring.len();
    (0..n).all(|k| {
        let (a, b) = (ring[k], ring[(k + 1) % n]);
        let e = [b[0] - a[0], b[1] - a[1]];
        (e[0] == 0.0 && e[1] == 0.0) || area * (e[0] * (q[1] - a[1]) - e[1] * (q[0] - a[0])) > 0.0
    })
}

/// Whether a ring is monotone in y (its direction's y component changes sign twice, with
/// horizontal edges only at its top and bottom) with its two sides apart between them:
/// then it is simple.
fn ring_is_y_monotone_simple(ring: &[Point]) -> bool {
    let n = ring.len();
    if n < 3 {
        return true;
    }
    let (mut top, mut bottom) = (0, 0);
    for k in 0..n {
        if ring[k][1] < ring[top][1] {
            top = k;
        }
        if ring[k][1] > ring[bottom][1] {
            bottom = k;
        }
    }
    let (ymin, ymax) = (ring[top][1], ring[bottom][1]);
    if !(ymax > ymin) {
        return false;
    }
    // The two sides from `top` to `bottom`, each with y never decreasing.
    let side = |step: usize| -> Option<Vec<Point>> {
        let mut v = vec![ring[top]];
        let mut k = top;
        while k != bottom {
            let next = (k + step) % n;
            let (a, b) = (ring[k], ring[next]);
            if b[1] < a[1] || (b[1] == a[1] && a[1] > ymin && a[1] < ymax) {
                return None;
            }
            v.push(b);
            k = next;
        }
        Some(v)
    };
    let (Some(a), Some(b)) = (side(1), side(n - 1)) else {
        return false;
    };
    // x of a side at height y (its first edge reaching y that is not horizontal), read
    // from the edge `at` on: that edge only moves on as y grows, so the walk along one
    // side reads the other side once (a scan from its start each time made a long ring
    // cost the square of its length).
    let x_at = |s: &[Point], y: f64, at: &mut usize| -> f64 {
        while *at + 1 < s.len() && !(s[*at + 1][1] >= y && s[*at + 1][1] > s[*at][1]) {
            *at += 1;
        }
        match (s.get(*at), s.get(*at + 1)) {
            (Some(a), Some(b)) => a[0] + (y - a[1]) / (b[1] - a[1]) * (b[0] - a[0]),
            _ => s[s.len() - 1][0],
        }
    };
    // Where each side leaves the top and reaches the bottom: apart there too, or the same
    // point.
    let leave = |s: &[Point]| {
        s.iter()
            .rev()
            .find(|q| q[1] == ymin)
            .map_or(s[0][0], |q| q[0])
    };
    let reach = |s: &[Point]| {
        s.iter()
            .find(|q| q[1] == ymax)
            .map_or(s[s.len() - 1][0], |q| q[0])
    };
    let mut sign = 0.0f64;
    for d in [leave(&a) - leave(&b), reach(&a) - reach(&b)] {
        if d != 0.0 {
            if sign != 0.0 && (d > 0.0) != (sign > 0.0) {
                return false;
            }
            sign = d;
        }
    }
    for (s, o, flip) in [(&a, &b, 1.0), (&b, &a, -1.0)] {
        let mut at = 0;
        for q in s.iter() {
            if q[1] <= ymin || q[1] >= ymax {
                continue;
            }
            let d = flip * (q[0] - x_at(o, q[1], &mut at));
            if !(d != 0.0) || (sign != 0.0 && (d > 0.0) != (sign > 0.0)) {
                return false;
            }
            sign = d;
        }
    }
    true
}

/// Whether a ring is convex: turns all one way, with its direction's y component changing
/// sign at most twice around it (a pentagram turns one way too, twice around).
pub(crate) fn ring_is_convex(ring: &[Point]) -> bool {
    let n = ring.len();
    if n < 3 {
        return true;
    }
    let edge = |k: usize| {
        let (a, b) = (ring[k], ring[(k + 1) % n]);
        [b[0] - a[0], b[1] - a[1]]
    };
    // The last edge of non-zero length, to start the cyclic comparison.
    let Some(mut prev) = (0..n).rev().map(edge).find(|e| e[0] != 0.0 || e[1] != 0.0) else {
        return true;
    };
    // Turns all one way, and the y direction changes sign at most twice around the ring
    // (horizontal edges skipped).
    let mut turn = 0.0f64;
    let (mut changes, mut last_dy) = (0usize, prev[1]);
    if last_dy == 0.0 {
        last_dy = (0..n)
            .rev()
            .map(|k| edge(k)[1])
            .find(|&d| d != 0.0)
            .unwrap_or(0.0);
    }
    for k in 0..n {
        let e = edge(k);
        if e[0] == 0.0 && e[1] == 0.0 {
            continue;
        }
        let cross = prev[0] * e[1] - prev[1] * e[0];
        let dot = prev[0] * e[0] + prev[1] * e[1];
        if cross == 0.0 && dot < 0.0 {
            return false;
        }
        if cross != 0.0 {
            if turn != 0.0 && (cross > 0.0) != (turn > 0.0) {
                return false;
            }
            turn = cross;
        }
        if e[1] != 0.0 {
            if (e[1] > 0.0) != (last_dy > 0.0) {
                changes += 1;
            }
            last_dy = e[1];
        }
        prev = e;
    }
    changes <= 2
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Image;
    use crate::raster::render::BandRenderer;
    use crate::raster::{RenderOptions, render, render_backward};
    use crate::rng::Rng;
    use crate::scene::{Fill, FillRule, Node, Paint, Path, Scene};

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

    /// The options with exact overlaps on.
    fn exact() -> RenderOptions {
        RenderOptions {
            exact_overlaps: true,
            ..RenderOptions::default()
        }
    }

    fn scene(w: u32, h: u32, rings: &[Vec<Point>], evenodd: bool) -> Scene {
        let mut p = Path::new("p");
        for ring in rings {
            p.move_to(ring[0]);
            for &q in &ring[1..] {
                p.line_to(q);
            }
            p.close();
        }
        p.fill = Some(Fill {
            paint: Paint::Solid([0.0, 0.0, 0.0]),
            opacity: 1.0,
            rule: if evenodd {
                FillRule::EvenOdd
            } else {
                FillRule::NonZero
            },
        });
        let mut s = Scene::new(w, h);
        s.nodes.push(Node::Path(p));
        s
    }

    fn alpha(s: &Scene) -> Vec<f64> {
        render(s, &exact())
            .data
            .iter()
            .map(|p| p[3] as f64)
            .collect()
    }

    /// Winding number of `q` around `rings`.
    fn winding(rings: &[Vec<Point>], q: Point) -> i32 {
        let mut w = 0;
        for ring in rings {
            for i in 0..ring.len() {
                let (a, b) = (ring[i], ring[(i + 1) % ring.len()]);
                if (a[1] <= q[1]) != (b[1] <= q[1]) {
                    let x = a[0] + (q[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
                    if x < q[0] {
                        w += if b[1] > a[1] { 1 } else { -1 };
                    }
                }
            }
        }
        w
    }

    /// Coverage of every pixel by `n × n` point samples.
    fn sampled(w: u32, h: u32, rings: &[Vec<Point>], evenodd: bool, n: usize) -> Vec<f64> {
        let mut out = Vec::new();
        for py in 0..h {
            for px in 0..w {
                let mut hits = 0;
                for sy in 0..n {
                    for sx in 0..n {
                        let q = [
                            px as f64 + (sx as f64 + 0.5) / n as f64,
                            py as f64 + (sy as f64 + 0.5) / n as f64,
                        ];
                        hits += inside(winding(rings, q), evenodd) as usize;
                    }
                }
                out.push(hits as f64 / (n * n) as f64);
            }
        }
        out
    }

    /// Cells whose exact coverage replaced the accumulated one, over the whole canvas.
    fn active_cells(s: &Scene) -> usize {
        let p = crate::raster::Prepared::new(s, &exact());
        let mut count = 0;
        for y0 in (0..p.height as usize).step_by(16) {
            let rows = 16.min(p.height as usize - y0);
            let mut r = BandRenderer::new(&p, y0, rows);
            for item in &p.items {
                if !r.deltas(item) {
                    continue;
                }
                for row in 0..r.acc.h {
                    let (wrow, sc, ov) = r.take_row(row);
                    let covs = &mut sc.covs[..wrow.len()];
                    ov.resolve_row(row, wrow, item.evenodd, covs);
                }
                count += r.overlaps.cells.iter().filter(|c| c.active).count();
            }
        }
        count
    }

    /// Outside the cells that the chain tags make candidates the clamped integral is the
    /// exact coverage: random rings (a polygon with a hole close to it, random polygons, a
    /// spike folding back beside a shared side, a row of glyph-like rings two of which
    /// overlap, a thin ring like a stroke's two sides, wound either way) render, pixel
    /// for pixel, as the same item searched in every cell.
    #[test]
    fn searching_the_tagged_cells_alone_is_exact() {
        let mut rng = Rng::new(29);
        let (mut none, mut fewer, mut searched) = (0, 0, 0);
        for case in 0..150 {
            let n = 3 + rng.below(9);
            let c = [rng.range(8.0, 12.0), rng.range(8.0, 12.0)];
            let rings = match case % 5 {
                0 => vec![
                    polygon(c, 6.0, n + 8, true),
                    // A hole within a pixel or two of the outer ring, wound either way
                    // (wound the same way, a pixel there holds three windings).
                    polygon(
                        [c[0] + rng.range(0.0, 0.4), c[1]],
                        rng.range(2.0, 5.2),
                        n + 3,
                        rng.below(2) == 0,
                    ),
                ],
                1 => (0..2)
                    .map(|_| {
                        (0..n)
                            .map(|_| [rng.range(1.0, 19.0), rng.range(1.0, 19.0)])
                            .collect()
                    })
                    .collect(),
                3 => {
                    // A square with a spike folding back on itself, and a rectangle
                    // sharing part of its right side.
                    let (a, b) = (rng.range(3.0, 6.0), rng.range(12.0, 15.0));
                    let t = rng.range(a + 0.5, b - 0.5);
                    let tip = rng.range(b + 0.5, 18.0);
                    vec![
                        vec![[a, a], [b, a], [b, b], [t, b], [t, tip], [t, b], [a, b]],
                        rect(b, rng.range(a, b), b + 2.0, b),
                    ]
                }
                4 => {
                    // A thin ring, as a stroke's two sides; wound the same way, the pixels
                    // between them hold three windings.
                    let r = rng.range(4.0, 7.0);
                    let inner = [c[0] + rng.range(-0.1, 0.1), c[1]];
                    vec![
                        polygon(c, r, 3 * n + 12, true),
                        polygon(
                            inner,
                            r - rng.range(0.1, 0.9),
                            3 * n + 12,
                            rng.below(3) != 0,
                        ),
                    ]
                }
                _ => {
                    // Letters with counters, a little apart, the last two overlapping by a
                    // random amount (or touching).
                    let mut v = Vec::new();
                    let r = rng.range(1.5, 2.5);
                    let gap = rng.range(0.0, 0.6);
                    for k in 0..4 {
                        let x = 3.0 + k as f64 * (2.0 * r + gap);
                        let x = if k == 3 { x - rng.range(0.0, 1.5) } else { x };
                        v.push(polygon([x, 10.0 + 0.3 * k as f64], r, n + 6, true));
                        v.push(polygon([x + 0.2, 10.0], 0.45 * r, n + 3, false));
                    }
                    v
                }
            };
            for evenodd in [false, true] {
                let s = scene(20, 20, &rings, evenodd);
                let mut p = crate::raster::Prepared::new(&s, &exact());
                let got = crate::raster::render_prepared(&p);
                let tagged = candidate_cells(&p);
                // The reference: the same item searched in every cell.
                p.search_everywhere = true;
                let truth = crate::raster::render_prepared(&p);
                let everywhere = candidate_cells(&p);
                let worst = got
                    .data
                    .iter()
                    .zip(&truth.data)
                    .map(|(a, b)| (a[3] - b[3]).abs())
                    .fold(0.0, f32::max);
                assert!(
                    worst < 1e-5,
                    "case {case} even-odd {evenodd}: off by {worst}"
                );
                none += (tagged == 0) as usize;
                // Items that `rings_cannot_overlap` settles are searched in neither.
                if p.items.iter().any(|it| it.can_overlap) {
                    searched += 1;
                    fewer += (tagged < everywhere) as usize;
                }
            }
        }
        assert!(none >= 20, "only {none} of 300 need no search");
        assert!(
            searched >= 200 && fewer >= searched / 2,
            "only {fewer} of the {searched} searched search fewer cells than all"
        );
    }

    /// Cells whose pieces are searched, over the whole canvas.
    fn candidate_cells(p: &crate::raster::Prepared) -> usize {
        let mut count = 0;
        for y0 in (0..p.height as usize).step_by(16) {
            let rows = 16.min(p.height as usize - y0);
            let mut r = BandRenderer::new(p, y0, rows);
            for item in &p.items {
                if r.deltas(item) {
                    count += r.overlaps.cells.len();
                    // Every row taken, which leaves the band's buffers clear.
                    for row in 0..r.acc.h {
                        r.take_row(row);
                    }
                }
            }
        }
        count
    }

    /// A thin ring wound against its outer ring, as a stroke's two sides, shares every
    /// pixel between the two sides but holds two windings: cells crossed by one edge of
    /// each side are judged without a search (`chains_wind_alike`; cells holding a vertex
    /// of either side are still searched); wound the same way they are all searched.
    #[test]
    fn thin_rings_wound_apart_are_judged_without_a_search() {
        let count = |ccw: bool| {
            let rings = [
                polygon([10.0, 10.0], 6.0, 24, true),
                polygon([10.0, 10.0], 5.7, 24, ccw),
            ];
            let p = crate::raster::Prepared::new(&scene(20, 20, &rings, false), &exact());
            candidate_cells(&p)
        };
        let (apart, alike) = (count(false), count(true));
        assert!(alike > 20, "{alike} cells searched for rings wound alike");
        assert!(
            apart * 5 < alike,
            "{apart} searched, against {alike} wound alike"
        );
    }

    /// Two chains crossing a cell: apart and wound against each other (a stroke's sides),
    /// wound alike, crossing, touching; bent chains of several edges too.
    #[test]
    fn chains_wind_alike_only_when_apart_and_opposite() {
        let cell = [0.0, 0.0];
        let alike = |a: &[Point], b: &[Point]| {
            let edges = |v: &[Point]| v.windows(2).map(|w| (w[0], w[1])).collect::<Vec<_>>();
            chains_wind_alike(&edges(a), &edges(b), cell)
        };
        let line = |x0: f64, y0: f64, x1: f64, y1: f64| vec![[x0, y0], [x1, y1]];
        let cases = [
            // Across the cell at y = 0.3 to the right and at y = 0.7 to the left.
            (line(-1.0, 0.3, 2.0, 0.3), line(2.0, 0.7, -1.0, 0.7), true),
            // Both to the right: windings w, w + 1, w + 2.
            (line(-1.0, 0.3, 2.0, 0.3), line(-1.0, 0.7, 2.0, 0.7), false),
            // Crossing inside the cell, and touching on its side.
            (line(-1.0, -1.0, 2.0, 2.0), line(2.0, 0.0, -1.0, 1.0), false),
            (line(0.0, -1.0, 0.0, 2.0), line(1.0, 2.0, 0.0, 0.5), false),
            // Crossing outside the cell only: apart inside it.
            (line(-2.0, 0.5, 3.0, 0.5), line(3.0, 0.85, -2.0, 0.35), true),
            // One of them missing the cell.
            (line(-1.0, 0.3, 2.0, 0.3), line(-1.0, 3.0, 2.0, 3.0), false),
        ];
        for (a, b, want) in &cases {
            assert_eq!(alike(a, b), *want, "{a:?} and {b:?}");
        }
        // Bent: down the cell on the left, and back up on the right, each through a
        // vertex inside it; wound the same way, or bent across each other.
        let left = [[0.2, -0.5], [0.4, 0.5], [0.2, 1.5]];
        let right_up = [[0.8, 1.5], [0.6, 0.5], [0.8, -0.5]];
        let right_down = [[0.8, -0.5], [0.6, 0.5], [0.8, 1.5]];
        let across = [[0.8, 1.5], [0.1, 0.5], [0.8, -0.5]];
        assert!(alike(&left, &right_up));
        assert!(!alike(&left, &right_down));
        assert!(!alike(&left, &across));
        // A chain from the top side to the left side (a corner cut off) beside one
        // across the cell, wound either way.
        let corner = [[0.5, -0.5], [0.3, 0.3], [-0.5, 0.5]];
        assert!(alike(&corner, &[[-0.5, 0.9], [1.5, 0.6]]));
        assert!(!alike(&corner, &[[1.5, 0.6], [-0.5, 0.9]]));
    }

    /// Issue 29: two coincident rectangles in one path, each covering the left half of
    /// a column of pixels, cover half of each pixel (the clamped integral gave 1.0); under
    /// even-odd the doubled part is empty.
    #[test]
    fn test_issue_29_coincident_half_rectangles() {
        let r = rect(1.0, 1.0, 1.5, 3.0);
        let nonzero = alpha(&scene(4, 4, &[r.clone(), r.clone()], false));
        let evenodd = alpha(&scene(4, 4, &[r.clone(), r.clone()], true));
        for y in 1..3 {
            assert!((nonzero[y * 4 + 1] - 0.5).abs() < 1e-6, "{nonzero:?}");
            assert!(evenodd[y * 4 + 1].abs() < 1e-6, "{evenodd:?}");
        }
        let total: f64 = nonzero.iter().sum();
        assert!((total - 1.0).abs() < 1e-5, "{total}");
        // A third copy reversed: winding 1 under both rules, half of each pixel.
        let mut back = r.clone();
        back.reverse();
        for evenodd in [false, true] {
            let a = alpha(&scene(4, 4, &[r.clone(), r.clone(), back.clone()], evenodd));
            assert!((a[5] - 0.5).abs() < 1e-6, "{a:?}");
        }
    }

    #[test]
    fn figure_eight_and_star_match_sampling() {
        let bowtie = vec![[1.2, 1.1], [6.3, 6.4], [6.1, 1.2], [1.1, 6.3]];
        let star: Vec<Point> = (0..5)
            .map(|k| {
                let a = (k * 2) as f64 * std::f64::consts::TAU / 5.0 + 0.3;
                [6.1 + 5.2 * a.cos(), 5.9 + 5.1 * a.sin()]
            })
            .collect();
        for (name, ring, w) in [("bow-tie", bowtie, 8u32), ("pentagram", star, 12)] {
            for evenodd in [false, true] {
                let rings = vec![ring.clone()];
                let s = scene(w, w, &rings, evenodd);
                assert!(active_cells(&s) > 0, "{name}: no exact cells");
                let got = alpha(&s);
                let want = sampled(w, w, &rings, evenodd, 64);
                for (i, (g, r)) in got.iter().zip(&want).enumerate() {
                    assert!(
                        (g - r).abs() < 0.03,
                        "{name} even-odd {evenodd}: pixel {i} {g} vs sampled {r}"
                    );
                }
                let mae = got
                    .iter()
                    .zip(&want)
                    .map(|(g, r)| (g - r).abs())
                    .sum::<f64>()
                    / got.len() as f64;
                assert!(mae < 2e-3, "{name} even-odd {evenodd}: MAE {mae}");
            }
        }
    }

    /// Two subpaths sharing a pixel without overlapping keep the accumulated value, bit
    /// for bit: the cell is a candidate (two chains) but its windings span two values.
    #[test]
    fn subpaths_sharing_a_pixel_keep_their_bits() {
        let (a, b) = (rect(1.0, 1.0, 1.5, 3.0), rect(1.5, 1.0, 2.25, 3.0));
        let s = scene(4, 4, &[a, b], false);
        assert_eq!(active_cells(&s), 0);
        let img = alpha(&s);
        assert!(
            (img[5] - 1.0).abs() < 1e-6 && (img[6] - 0.25).abs() < 1e-6,
            "{img:?}"
        );
        let p = crate::raster::Prepared::new(&s, &exact());
        assert!(p.items[0].can_overlap);
        let apart = scene(
            4,
            4,
            &[rect(0.2, 0.2, 0.8, 0.8), rect(1.2, 1.2, 2.8, 2.8)],
            false,
        );
        assert!(!crate::raster::Prepared::new(&apart, &exact()).items[0].can_overlap);
        // Off, the clamped integral everywhere: the same values here.
        let off = render(
            &s,
            &RenderOptions {
                exact_overlaps: false,
                ..RenderOptions::default()
            },
        );
        assert!((off.data[5][3] as f64 - img[5]).abs() < 1e-6);
    }

    /// Many coincident rings in one cell: sampled, then kept clamped, always finite.
    #[test]
    fn many_coincident_rings_stay_bounded() {
        for copies in [40, 2000] {
            let rings = vec![rect(1.0, 1.0, 1.5, 3.0); copies];
            let a = alpha(&scene(4, 4, &rings, false));
            assert!(a.iter().all(|v| v.is_finite()));
            let want = if copies <= SAMPLED_PIECES / 2 {
                0.5
            } else {
                1.0
            };
            assert!((a[5] - want).abs() < 1e-6, "{copies}: {a:?}");
        }
    }

    /// Degenerate pieces: zero-length edges, edges on pixel lines, a ring inside one cell.
    #[test]
    fn degenerate_pieces_stay_finite() {
        let rings = vec![
            vec![[1.0, 1.0], [1.0, 1.0], [3.0, 1.0], [3.0, 3.0], [1.0, 3.0]],
            vec![[2.0, 1.0], [2.0, 3.0], [1.0, 2.0], [3.0, 2.0]],
            vec![[1.2, 1.2], [1.4, 1.7], [1.7, 1.3], [1.2, 1.6]],
        ];
        for evenodd in [false, true] {
            let s = scene(4, 4, &rings, evenodd);
            let got = alpha(&s);
            let want = sampled(4, 4, &rings, evenodd, 64);
            for (g, r) in got.iter().zip(&want) {
                assert!((g - r).abs() < 0.03, "{got:?} vs {want:?}");
            }
            let d = Image::filled(4, 4, [0.1, 0.2, 0.3, 0.4]);
            let g = render_backward(&s, &exact(), &d);
            assert!(g.iter().all(|v| v.is_finite()));
        }
    }

    /// Central differences of `Σ d·image` on a self-overlapping path, at points where
    /// exact cells exist, for both fill rules.
    #[test]
    fn exact_cells_gradient_matches_differences() {
        let rings = vec![
            vec![[1.3, 1.2], [8.7, 7.6], [8.2, 1.4], [1.6, 8.3]],
            vec![[2.1, 2.6], [7.4, 2.2], [6.8, 6.9], [2.4, 7.3]],
        ];
        for evenodd in [false, true] {
            let s = scene(10, 10, &rings, evenodd);
            assert!(active_cells(&s) > 3, "{}", active_cells(&s));
            let mut d = Image::new(10, 10);
            for (i, px) in d.data.iter_mut().enumerate() {
                let k = ((i * 7919) % 13) as f32 / 13.0 - 0.4;
                *px = [0.0, 0.0, 0.0, k];
            }
            let opts = exact();
            let loss = |s: &Scene| -> f64 {
                let img = render(s, &opts);
                img.data
                    .iter()
                    .zip(&d.data)
                    .map(|(a, b)| a[3] as f64 * b[3] as f64)
                    .sum()
            };
            let g = render_backward(&s, &opts, &d);
            let p0 = s.params();
            let layout = crate::scene::ParamLayout::new(&s);
            let mut checked = 0;
            for i in 0..p0.len() {
                if layout.slots[i].group != crate::scene::ParamGroup::Points {
                    continue;
                }
                let e = 1e-3;
                let mut t = s.clone();
                let mut p = p0.clone();
                p[i] += e;
                t.set_params(&p);
                let lp = loss(&t);
                p[i] -= 2.0 * e;
                t.set_params(&p);
                let lm = loss(&t);
                let fd = (lp - lm) / (2.0 * e);
                assert!(
                    (fd - g[i]).abs() < 2e-3 + 1e-2 * fd.abs(),
                    "even-odd {evenodd} param {i}: differences {fd}, analytic {}",
                    g[i]
                );
                checked += 1;
            }
            assert!(checked >= 16);
        }
    }

    #[test]
    fn convexity() {
        let sq = [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]];
        assert!(ring_is_convex(&sq));
        let mut rev = sq;
        rev.reverse();
        assert!(ring_is_convex(&rev));
        // A pentagram turns one way but winds twice.
        let star: Vec<Point> = (0..5)
            .map(|k| {
                let a = (k * 2) as f64 * std::f64::consts::TAU / 5.0;
                [a.cos(), a.sin()]
            })
            .collect();
        assert!(!ring_is_convex(&star));
        let bowtie = [[0.0, 0.0], [2.0, 2.0], [2.0, 0.0], [0.0, 2.0]];
        assert!(!ring_is_convex(&bowtie));
        let l = [
            [0.0, 0.0],
            [2.0, 0.0],
            [2.0, 1.0],
            [1.0, 1.0],
            [1.0, 2.0],
            [0.0, 2.0],
        ];
        assert!(!ring_is_convex(&l));
        // Repeated and collinear vertices.
        let sq2 = [
            [0.0, 0.0],
            [1.0, 0.0],
            [2.0, 0.0],
            [2.0, 0.0],
            [2.0, 2.0],
            [0.0, 2.0],
        ];
        assert!(ring_is_convex(&sq2));
        let back = [[0.0, 0.0], [2.0, 0.0], [1.0, 0.0], [1.0, 1.0]];
        assert!(!ring_is_convex(&back));
        // Monotone in y and simple: a chevron; its sides crossed: a bow-tie on its side.
        let chevron = [
            [0.0, 0.0],
            [1.0, 1.0],
            [0.0, 2.0],
            [3.0, 2.0],
            [2.0, 1.0],
            [3.0, 0.0],
        ];
        assert!(!ring_is_convex(&chevron) && ring_is_y_monotone_simple(&chevron));
        let crossed = [[0.0, 0.0], [3.0, 2.0], [0.0, 2.0], [3.0, 0.0]];
        assert!(!ring_is_y_monotone_simple(&crossed));
        let hourglass = [
            [0.0, 0.0],
            [2.0, 0.0],
            [0.5, 1.0],
            [2.0, 2.0],
            [0.0, 2.0],
            [1.5, 1.0],
        ];
        assert!(!ring_is_y_monotone_simple(&hourglass));
        let star: Vec<Point> = (0..5)
            .map(|k| {
                let a = (k * 2) as f64 * std::f64::consts::TAU / 5.0 + 0.3;
                [a.cos(), a.sin()]
            })
            .collect();
        assert!(!ring_is_y_monotone_simple(&star));
        // A long wiggly ring monotone in y, its two sides at heights that interleave, and
        // the same with its sides made to cross near the bottom: each side is read
        // against the other at every height, far from where the reading starts.
        let n = 20_000;
        let side = |x0: f64, f: f64, dy: f64| -> Vec<Point> {
            (0..n)
                .map(|i| [x0 + (i as f64 * f).sin(), i as f64 * 0.01 + dy])
                .collect()
        };
        let mut wiggle = side(0.0, 0.37, 0.0);
        wiggle.extend(side(5.0, 0.41, 0.004).into_iter().rev());
        assert!(!ring_is_convex(&wiggle) && ring_is_y_monotone_simple(&wiggle));
        wiggle[n - 50][0] = 7.0;
        assert!(!ring_is_y_monotone_simple(&wiggle));
        // Rings apart, and rings sharing a pixel.
        let pts = [
            [0.2, 0.2],
            [1.8, 0.2],
            [1.8, 1.8],
            [0.2, 1.8],
            [3.2, 0.2],
            [4.8, 0.2],
            [4.8, 1.8],
        ];
        assert!(rings_cannot_overlap(&pts, &[(0, 4), (4, 3)]));
        let near = [
            [0.2, 0.2],
            [1.8, 0.2],
            [1.8, 1.8],
            [1.9, 0.2],
            [3.8, 0.2],
            [3.8, 1.8],
        ];
        assert!(!rings_cannot_overlap(&near, &[(0, 3), (3, 3)]));
        // A frame: one ring inside the other, a pixel apart, wound the other way (a
        // stroke's outline): two windings in any pixel. Wound alike, the inner region
        // winds twice; the inner ring touching the outer or poking out of it, or an outer
        // ring that is not convex, leave it unsure.
        let rect = |x0: f64, y0: f64, x1: f64, y1: f64, cw: bool| {
            let r = vec![[x0, y0], [x1, y0], [x1, y1], [x0, y1]];
            if cw {
                r
            } else {
                r.into_iter().rev().collect::<Vec<Point>>()
            }
        };
        let frame = |inner: Vec<Point>, outer_cw: bool| {
            let mut pts = rect(0.5, 0.5, 199.5, 199.5, outer_cw);
            let n = inner.len();
            pts.extend(inner);
            rings_cannot_overlap(&pts, &[(0, 4), (4, n)])
                && rings_cannot_overlap(&pts, &[(4, n), (0, 4)])
        };
        assert!(frame(rect(1.5, 1.5, 198.5, 198.5, false), true));
        assert!(frame(rect(1.5, 1.5, 198.5, 198.5, true), false));
        assert!(!frame(rect(1.5, 1.5, 198.5, 198.5, true), true));
        assert!(!frame(rect(0.5, 1.5, 198.5, 198.5, false), true));
        assert!(!frame(rect(1.5, 1.5, 200.0, 198.5, false), true));
        let mut notched = rect(1.5, 1.5, 198.5, 198.5, false);
        notched.insert(2, [100.0, 150.0]);
        assert!(
            frame(notched.clone(), true),
            "a y-monotone hole in a convex ring"
        );
        let mut pts = notched;
        pts.extend(rect(10.0, 160.0, 20.0, 170.0, true));
        assert!(
            !rings_cannot_overlap(&pts, &[(0, 5), (5, 4)]),
            "a ring inside a ring that is not convex"
        );
    }
}
