//! Forward rendering straight to 8-bit RGBA, where big opaque fills cost what a memset
//! costs.
//!
//! Each band is drawn into a [`RunCanvas`]: every row of the band is a short list of
//! **runs** of columns, each either **solid** (all its pixels one color, held once, the
//! pixels themselves unwritten) or **mixed** (its pixels written in an `f32` buffer). A
//! solid paint at one coverage over a stretch of columns composites each solid run there
//! once (the `over` of each pixel would give the same bits), and an opaque one at
//! coverage 1 replaces them with one solid run; anything else makes its columns mixed
//! first (their color written out) and composites pixel by pixel as [`render_prepared`]
//! does. A solid item's row is collected as such stretches, left to right, and drawn in
//! one pass over the row's runs ([`RunCanvas::apply_row`]). A row holds at most [`MAX_RUNS`] runs; past that it becomes one mixed run, so a
//! row crossed by many small shapes costs its pixels, not a search per shape. A solid
//! paint reads only the chunks of [`CHUNK`] columns its edges can touch
//! ([`touched_chunks`]); between them its coverage is one value, snapped to an exact 0 or
//! 1 within a few `f32` steps ([`SLACK`]). At the end of the band each solid run is
//! converted once and written as copies of its four bytes, mixed runs pixel by pixel, and
//! a row of solid runs equal to the row above is copied whole. An item whose edges cross
//! its rows every few columns ([`dense`]: a line of text) is composited pixel by pixel
//! instead, as a paint of many colors is: there its chunks would cost more than its pixels. So the bytes are those of
//! converting [`render_prepared`]'s image (tested; within one level where the snap meets a
//! rounding boundary), while a drawing of a few big fills writes each byte of the result
//! once plus a few runs per row, and a row costs its edges, not its width.
//!
//! [`render_prepared`]: super::render_prepared

use rayon::prelude::*;

use super::coverage::{ceil_f64, coverage, coverage_row, floor_f64};
use super::layer::composite_layer;
use super::paint::PaintEval;
use super::prepare::{Item, Prepared};
use super::render::{Area, BAND_ROWS, BandRenderer, Canvas, covered_span, opaque_start, over};
use crate::image_io::{straight_rgba8, to_u8};
use crate::scene::BlendMode;

/// How [`render_rgba8`] stores a pixel in four bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Alpha {
    /// Colors multiplied by alpha, as tiny-skia's and resvg's pixmaps hold them: each
    /// channel of [`render_prepared`](super::render_prepared)'s image rounded to `0..=255`.
    Premultiplied,
    /// Colors divided by alpha, as PNG files hold them: the bytes of
    /// [`Image::to_rgba8`](crate::Image::to_rgba8) of
    /// [`render_prepared`](super::render_prepared)'s image.
    Straight,
}

impl Alpha {
    /// One premultiplied `f32` pixel as four bytes.
    #[inline]
    fn bytes(self, c: [f32; 4]) -> [u8; 4] {
        match self {
            Alpha::Premultiplied => c.map(to_u8),
            Alpha::Straight => straight_rgba8(c),
        }
    }
}

/// Columns per chunk.
const CHUNK: usize = 8;

/// Renders an already prepared scene straight to 8-bit RGBA, row-major, 4 bytes a pixel,
/// top row first: the bytes of converting
/// [`render_prepared`](super::render_prepared)'s `f32` image, without holding that image,
/// except that a run of pixels whose coverage is within four `f32` steps of 0 or 1 is
/// taken as exactly 0 or 1 (its true value inside or outside a shape),
/// which moves a byte by one level where the `f32` value sits on a rounding boundary
/// (an opacity of 0.7 is 178.5 of 255).
pub fn render_rgba8(p: &Prepared, alpha: Alpha) -> Vec<u8> {
    render_rgba8_with(p, alpha, SLACK)
}

/// [`render_rgba8`] with coverages within `slack` of 0 or 1 taken as 0 or 1 (with `0.0`,
/// exactly the bytes of converting the `f32` image).
fn render_rgba8_with(p: &Prepared, alpha: Alpha, slack: f32) -> Vec<u8> {
    let (w, h) = (p.width as usize, p.height as usize);
    let (start, group, fill) = opaque_start(p);
    if w == 0 || h == 0 {
        return Vec::new();
    }
    let band_bytes = w * 4 * BAND_ROWS;
    // Appends band `band`'s bytes to `bytes`.
    let draw = |band: usize, bytes: &mut Vec<u8>| {
        let rows = BAND_ROWS.min(h - band * BAND_ROWS);
        BAND_CANVAS.with(|canvas| {
            let mut canvas = canvas.borrow_mut();
            canvas.reset(w, rows, fill);
            canvas.slack = slack;
            BandRenderer::new(p, band * BAND_ROWS, rows).run(&mut *canvas, start, group);
            canvas.write_bytes(bytes, alpha);
        });
    };
    if rayon::current_num_threads() == 1 {
        // One band after the other, appended: each byte of the image is written once.
        // (`vec![0; n]` zeroes memory the allocator hands back from earlier use: for a big
        // image of a few fills that is a pass as long as drawing it.)
        let mut out = Vec::with_capacity(w * h * 4);
        for band in 0..h.div_ceil(BAND_ROWS) {
            draw(band, &mut out);
        }
        return out;
    }
    let mut out = vec![0u8; w * h * 4];
    out.par_chunks_mut(band_bytes)
        .with_min_len(p.min_bands_per_task())
        .enumerate()
        .for_each(|(band, bytes)| {
            BAND_BYTES.with(|b| {
                let mut b = b.borrow_mut();
                b.clear();
                draw(band, &mut b);
                bytes.copy_from_slice(&b);
            })
        });
    out
}

thread_local! {
    /// [`render_rgba8`]'s bytes of one band, on a pool of several threads.
    static BAND_BYTES: std::cell::RefCell<Vec<u8>> = const { std::cell::RefCell::new(Vec::new()) };
    /// [`render_rgba8`]'s band canvas, kept from one band to the next.
    static BAND_CANVAS: std::cell::RefCell<RunCanvas> =
        std::cell::RefCell::new(RunCanvas::default());
}

/// The most runs a band row holds before it is made one mixed run: a row crossed by
/// hundreds of small shapes then costs what compositing its pixels costs, not a search
/// and a splice per shape.
const MAX_RUNS: usize = 64;

/// Columns `x0..x1` of one band row: one color (solid) or pixels of their own (mixed).
#[derive(Clone, Copy, Debug)]
struct Run {
    x0: u32,
    x1: u32,
    /// Whether the pixels are held in [`RunCanvas::px`]; otherwise all are `color`.
    mixed: bool,
    /// The run's color when solid (premultiplied).
    color: [f32; 4],
}

impl Run {
    fn solid(x0: usize, x1: usize, color: [f32; 4]) -> Self {
        Run {
            x0: x0 as u32,
            x1: x1 as u32,
            mixed: false,
            color,
        }
    }

    fn mixed(x0: usize, x1: usize) -> Self {
        Run {
            x0: x0 as u32,
            x1: x1 as u32,
            mixed: true,
            color: [0.0; 4],
        }
    }

    fn cols(&self) -> std::ops::Range<usize> {
        self.x0 as usize..self.x1 as usize
    }

    /// Whether `self` followed by `next` can be one run: both mixed, or both solid with
    /// the same color bits.
    fn joins(&self, next: &Run) -> bool {
        self.mixed && next.mixed
            || !self.mixed && !next.mixed && bits(self.color) == bits(next.color)
    }

    /// The same columns, kind and color bits.
    fn same(&self, o: &Run) -> bool {
        self.x0 == o.x0 && self.x1 == o.x1 && self.mixed == o.mixed && self.joins(o)
    }
}

fn bits(c: [f32; 4]) -> [u32; 4] {
    c.map(f32::to_bits)
}

/// Whether two slices hold the same bits: one OR over the differences, without early
/// exits, which the compiler turns into vector instructions.
fn bits_equal(a: &[f32], b: &[f32]) -> bool {
    a.iter()
        .zip(b)
        .fold(0u32, |acc, (x, y)| acc | (x.to_bits() ^ y.to_bits()))
        == 0
}

/// One band's pixels as rows of runs that are solid or mixed (see the module's
/// documentation).
#[derive(Default)]
pub(crate) struct RunCanvas {
    /// Columns and rows.
    w: usize,
    rows: usize,
    /// Pixels, row-major; valid only in mixed runs.
    px: Vec<[f32; 4]>,
    /// Per band row: its runs, in column order, covering `0..w` (rows past `rows` are
    /// spare buffers).
    runs: Vec<Vec<Run>>,
    /// Per band row: whether it holds the same runs and pixels as the row above
    /// (false for the first).
    same_above: Vec<bool>,
    /// Scratch: `same_above` before an item is drawn.
    before: Vec<bool>,
    /// Scratch for [`touched_chunks`].
    touched: Vec<(u32, u32, u32)>,
    /// Scratch: one row's coverages.
    covs: Vec<f32>,
    /// Scratch: one row's stretches ([`RunCanvas::apply_row`]).
    ops: Vec<RowOp>,
    /// Scratch: the runs [`RunCanvas::apply_row`] writes a row's new list into.
    spare: Vec<Run>,
    /// Scratch: one row's bytes.
    line: Vec<u8>,
    /// How far from 0 or 1 a run's coverage may be and count as 0 or 1 ([`snap_run`]).
    slack: f32,
}

impl RunCanvas {
    /// A `w × rows` band of one color.
    fn reset(&mut self, w: usize, rows: usize, fill: [f32; 4]) {
        self.w = w;
        self.rows = rows;
        // The pixels keep whatever they held: every run is solid, so none is read.
        self.px.resize(w * rows, [0.0; 4]);
        if self.runs.len() < rows {
            self.runs.resize_with(rows, Vec::new);
        }
        for runs in &mut self.runs[..rows] {
            runs.clear();
            runs.push(Run::solid(0, w, fill));
        }
        self.same_above.clear();
        self.same_above.resize(rows, true);
        if let Some(first) = self.same_above.first_mut() {
            *first = false;
        }
    }

    /// The index of the run of `row` holding column `x < w`.
    #[inline]
    fn find(&self, row: usize, x: usize) -> usize {
        self.runs[row].partition_point(|r| r.x1 as usize <= x)
    }

    /// Replaces the runs of `row` over columns `a..b` (`a < b`) with `run`, joined to
    /// its neighbors where they [join](Run::joins); keeps the row within [`MAX_RUNS`].
    fn replace(&mut self, row: usize, a: usize, b: usize, mut run: Run) {
        if a == 0 && b == self.w {
            let runs = &mut self.runs[row];
            runs.clear();
            runs.push(run);
            return;
        }
        // Runs `i..=j` meet `a..b`; they and any neighbor that joins `run` become at most
        // three runs, in one splice.
        let i = self.find(row, a);
        let j = self.find(row, b - 1);
        let runs = &mut self.runs[row];
        let (first, last) = (runs[i], runs[j]);
        let (mut lo, mut hi) = (i, j + 1);
        let mut new = [run; 3];
        let mut n = 0;
        if first.x0 as usize == a && i > 0 && runs[i - 1].joins(&run) {
            lo = i - 1;
            run.x0 = runs[i - 1].x0;
        } else if first.x0 as usize != a {
            if first.joins(&run) {
                run.x0 = first.x0;
            } else {
                new[0] = Run {
                    x1: a as u32,
                    ..first
                };
                n = 1;
            }
        }
        let mut right = None;
        if last.x1 as usize == b && hi < runs.len() && runs[hi].joins(&run) {
            run.x1 = runs[hi].x1;
            hi += 1;
        } else if last.x1 as usize != b {
            if last.joins(&run) {
                run.x1 = last.x1;
            } else {
                right = Some(Run {
                    x0: b as u32,
                    ..last
                });
            }
        }
        new[n] = run;
        n += 1;
        if let Some(r) = right {
            new[n] = r;
            n += 1;
        }
        if hi - lo == n {
            runs[lo..hi].copy_from_slice(&new[..n]);
        } else {
            runs.splice(lo..hi, new[..n].iter().copied());
        }
        if runs.len() > MAX_RUNS {
            self.mix(row, 0, self.w);
        }
    }

    /// Makes columns `a..b` of band row `row` part of a mixed run, writing out the
    /// colors of the solid runs there.
    fn mix(&mut self, row: usize, a: usize, b: usize) {
        if a >= b {
            return;
        }
        self.touch(row);
        let i = self.find(row, a);
        let first = self.runs[row][i];
        if first.mixed && first.x1 as usize >= b {
            return;
        }
        let line = &mut self.px[row * self.w..][..self.w];
        for r in &self.runs[row][i..] {
            if r.x0 as usize >= b {
                break;
            }
            if !r.mixed {
                line[r.x0.max(a as u32) as usize..r.x1.min(b as u32) as usize].fill(r.color);
            }
        }
        self.replace(row, a, b, Run::mixed(a, b));
    }

    /// Marks every column `x0..x1` of band rows `r0..r1` mixed.
    fn mix_area(&mut self, x0: usize, x1: usize, r0: usize, r1: usize) {
        for r in r0..r1 {
            self.mix(r, x0, x1);
        }
    }

    /// Draws one row's [`RowOp`]s of a solid color `s` (in column order, disjoint) in one
    /// pass over the row's runs, writing the new list into a spare one (no search, no
    /// splice per stretch):
    /// * a stretch at one coverage composites each solid run there once (the `over` of
    ///   each of its pixels would give the same bits) and a mixed run pixel by pixel; an
    ///   opaque `s` at coverage 1 replaces the runs there with one solid run;
    /// * a stretch of pixels of their own coverages (`covs[op.px..]`) makes its columns
    ///   mixed (the solid runs' colors written out) and composites pixel by pixel, as
    ///   [`render_prepared`](super::render_prepared) does.
    ///
    /// Neighbors that [join](Run::joins) become one run; a row past [`MAX_RUNS`] becomes one
    /// mixed run.
    fn apply_row(&mut self, row: usize, s: [f32; 4], ops: &[RowOp], covs: &[f32]) {
        if ops.is_empty() {
            return;
        }
        self.touch(row);
        let w = self.w;
        let old = std::mem::take(&mut self.runs[row]);
        let mut new = std::mem::take(&mut self.spare);
        new.clear();
        let line = &mut self.px[row * w..][..w];
        // The old runs are read left to right: run `i`, from column `x` on.
        let (mut i, mut x) = (0, 0);
        for op in ops {
            let (a, b) = (op.a as usize, op.b as usize);
            // The old runs left of the stretch, kept.
            while x < a {
                let r = old[i];
                let e = (r.x1 as usize).min(a);
                push_joined(
                    &mut new,
                    Run {
                        x0: x as u32,
                        x1: e as u32,
                        ..r
                    },
                );
                (i, x) = if e == r.x1 as usize {
                    (i + 1, e)
                } else {
                    (i, e)
                };
            }
            let pixels = op.px != NO_PIXELS;
            if !pixels && op.cov == 1.0 && s[3] == 1.0 {
                push_joined(&mut new, Run::solid(a, b, s));
                while (old[i].x1 as usize) <= b && i + 1 < old.len() {
                    i += 1;
                }
                x = b;
                continue;
            }
            while x < b {
                let r = old[i];
                let e = (r.x1 as usize).min(b);
                let run = if pixels {
                    if !r.mixed {
                        line[x..e].fill(r.color);
                    }
                    Run::mixed(x, e)
                } else if r.mixed {
                    for p in &mut line[x..e] {
                        over(p, s, op.cov);
                    }
                    Run::mixed(x, e)
                } else {
                    let mut c = r.color;
                    over(&mut c, s, op.cov);
                    Run::solid(x, e, c)
                };
                push_joined(&mut new, run);
                (i, x) = if e == r.x1 as usize {
                    (i + 1, e)
                } else {
                    (i, e)
                };
            }
            if pixels {
                for (p, &cov) in line[a..b].iter_mut().zip(&covs[op.px as usize..]) {
                    if cov > 0.0 {
                        over(p, s, cov);
                    }
                }
            }
        }
        // The old runs right of the last stretch.
        while x < w {
            let r = old[i];
            push_joined(&mut new, Run { x0: x as u32, ..r });
            (i, x) = (i + 1, r.x1 as usize);
        }
        self.runs[row] = new;
        self.spare = old;
        if self.runs[row].len() > MAX_RUNS {
            self.mix(row, 0, w);
        }
    }

    /// Appends the band's bytes (`w × rows × 4`) to `bytes`, writing each byte once (no
    /// zeroing first).
    fn write_bytes(&mut self, bytes: &mut Vec<u8>, alpha: Alpha) {
        let row_bytes = self.w * 4;
        let mut line = std::mem::take(&mut self.line);
        // Every byte of the row is written below, so the scratch row is never cleared.
        line.resize(row_bytes, 0);
        for r in 0..self.rows {
            let runs = &self.runs[r];
            // A row equal to the row above (the inside of a flag's stripe, or solid runs
            // drawn by separate items to the same ends and colors): the same bytes, copied.
            let same = r > 0
                && (self.same_above[r]
                    || runs.len() == self.runs[r - 1].len()
                        && runs
                            .iter()
                            .zip(&self.runs[r - 1])
                            .all(|(x, y)| !x.mixed && x.same(y)));
            if same {
                let end = bytes.len();
                bytes.extend_from_within(end - row_bytes..end);
                continue;
            }
            let px = &self.px[r * self.w..][..self.w];
            for run in runs {
                let (x0, x1) = (run.x0 as usize, run.x1 as usize);
                let out = &mut line[x0 * 4..x1 * 4];
                if !run.mixed {
                    // Its bytes once, then copies.
                    let b = alpha.bytes(run.color);
                    let pattern: [u8; 4 * CHUNK] = std::array::from_fn(|i| b[i % 4]);
                    let mut whole = out.chunks_exact_mut(4 * CHUNK);
                    for o in &mut whole {
                        o.copy_from_slice(&pattern);
                    }
                    let rest = whole.into_remainder();
                    rest.copy_from_slice(&pattern[..rest.len()]);
                } else if alpha == Alpha::Premultiplied {
                    // Channel by channel over flat slices: vector instructions.
                    for (o, &f) in out.iter_mut().zip(px[x0..x1].as_flattened()) {
                        *o = to_u8(f);
                    }
                } else {
                    for (o, &c) in out.chunks_exact_mut(4).zip(&px[x0..x1]) {
                        o.copy_from_slice(&straight_rgba8(c));
                    }
                }
            }
            bytes.extend_from_slice(&line);
        }
        self.line = line;
    }

    /// Draws a solid-paint item's rows (without cells of exact overlap coverage) straight
    /// from the accumulated deltas (clearing them, as [`BandRenderer::take_row`] does).
    ///
    /// Only the chunks an edge can have touched ([`touched_chunks`]) are read, pixel by
    /// pixel, with the running sum and the coverage rule of [`coverage_row`] (the same
    /// bits); such a chunk whose pixels all get one coverage is drawn as one stretch
    /// ([`fill`](Self::fill), the same bits as pixel by pixel). Between them the winding
    /// integral, and so the coverage, is one value over the whole stretch. So a row of a
    /// big fill costs its edges, not its width.
    fn draw_solid(&mut self, r: &mut BandRenderer<'_>, item: &Item, s: [f32; 4]) {
        let acc = &mut r.acc;
        let (x0, aw) = (acc.x0 as usize, acc.w);
        let cols = aw.min(self.w - x0);
        let band_row0 = acc.y0 as usize - r.y0;
        let end = x0 + cols;
        let mut touched = std::mem::take(&mut self.touched);
        touched_chunks(item, acc, self.w, &mut touched);
        // Which rows equalled the row above before this item.
        let mut before = std::mem::take(&mut self.before);
        before.clear();
        before.extend_from_slice(&self.same_above[band_row0..band_row0 + acc.h]);
        // Columns `lo..hi` of `acc`'s rows that a touched range covers.
        let local = |ka: u32, kb: u32| {
            let lo = (ka as usize * CHUNK).max(x0) - x0;
            (lo, (kb as usize * CHUNK).min(x0 + aw) - x0)
        };
        let mut covs = std::mem::take(&mut self.covs);
        let (mut t0, mut repeat) = (0, false);
        for k in 0..acc.h {
            let row = band_row0 + k;
            let t1 = t0
                + touched[t0..]
                    .iter()
                    .take_while(|t| t.0 as usize == k)
                    .count();
            let ranges = &touched[t0..t1];
            t0 = t1;
            // The next row repeats this one when its edges write the same deltas into the
            // same chunks (compared before this row's are cleared).
            let repeats_next = k + 1 < acc.h && {
                let n = touched[t1..]
                    .iter()
                    .take_while(|t| t.0 as usize == k + 1)
                    .count();
                let next = &touched[t1..t1 + n];
                let (this, below) = acc.data[k * aw..].split_at(aw);
                n == ranges.len()
                    && ranges
                        .iter()
                        .zip(next)
                        .all(|(a, b)| (a.1, a.2) == (b.1, b.2))
                    && ranges.iter().all(|&(_, ka, kb)| {
                        let (lo, hi) = local(ka, kb);
                        bits_equal(&this[lo..hi], &below[lo..hi])
                    })
            };
            let deltas = &mut acc.data[k * aw..(k + 1) * aw];
            if repeat && before[k] {
                // This row and the one above were equal and get the same drawing: copy.
                self.copy_row_above(row);
                for &(_, ka, kb) in ranges {
                    let (lo, hi) = local(ka, kb);
                    deltas[lo..hi].fill(0.0);
                }
                deltas[cols..].fill(0.0);
                repeat = repeats_next;
                continue;
            }
            repeat = repeats_next;
            let mut sum = 0.0f32;
            let mut x = x0;
            // The row's stretches, left to right, drawn in one pass at the end. Stretches of
            // one coverage are joined: a row of a big fill is one stretch.
            let mut ops = RowOps::new(std::mem::take(&mut self.ops), x0);
            covs.clear();
            for &(_, ka, kb) in ranges {
                let (lo, hi) = ((ka as usize * CHUNK).max(x), (kb as usize * CHUNK).min(end));
                // Only the columns from the range's first delta to its last are read pixel
                // by pixel; before and after them the coverage holds.
                let ds = &mut deltas[lo.min(hi) - x0..hi - x0];
                let Some(first) = ds.iter().position(|&d| d != 0.0) else {
                    continue;
                };
                let last = ds.iter().rposition(|&d| d != 0.0).map_or(0, |j| j + 1);
                let run_cov = snap_run(coverage(sum, item.evenodd).0, self.slack);
                ops.stretch(x, lo + first, run_cov);
                let start = covs.len();
                for dv in &mut ds[first..last] {
                    sum += *dv;
                    *dv = 0.0;
                    covs.push(coverage(sum, item.evenodd).0);
                }
                let a = lo + first;
                let here = &covs[start..];
                if here.iter().all(|c| c.to_bits() == here[0].to_bits()) {
                    let (n, c) = (here.len(), here[0]);
                    covs.truncate(start);
                    ops.stretch(a, a + n, c);
                } else if let Some((i, j)) = covered_span(here) {
                    ops.pixels(a + i, a + j, start + i);
                }
                x = lo + last;
            }
            let run_cov = snap_run(coverage(sum, item.evenodd).0, self.slack);
            ops.stretch(x, end, run_cov);
            let ops = ops.finish();
            self.apply_row(row, s, &ops, &covs);
            self.ops = ops;
            // Columns right of the canvas hold deltas too; leave them cleared.
            deltas[cols..].fill(0.0);
        }
        self.touched = touched;
        self.before = before;
        self.covs = covs;
    }

    /// Makes band row `row` a copy of the row above (runs and mixed pixels).
    fn copy_row_above(&mut self, row: usize) {
        let (above, this) = self.runs.split_at_mut(row);
        let above = &above[row - 1];
        this[0].clear();
        this[0].extend_from_slice(above);
        let w = self.w;
        for run in above.iter().filter(|r| r.mixed) {
            let c = run.cols();
            self.px.copy_within(
                (row - 1) * w + c.start..(row - 1) * w + c.end,
                row * w + c.start,
            );
        }
        self.touch(row);
        self.same_above[row] = true;
    }

    /// Notes that band row `row` changes: it and the row below no longer equal their
    /// rows above.
    #[inline]
    fn touch(&mut self, row: usize) {
        self.same_above[row] = false;
        if let Some(s) = self.same_above.get_mut(row + 1) {
            *s = false;
        }
    }

    /// Composites one row from its coverages `covs` (a paint of more than one color, or a
    /// row with cells of exact overlap coverage), columns `x0 ..`, band row `r`, device
    /// row `y`, as
    /// [`composite_row`](super::render::composite_row) does onto `f32` pixels.
    fn composite_row(
        &mut self,
        item: &Item,
        covs: &[f32],
        colors: &mut [[f32; 4]],
        x0: usize,
        r: usize,
        y: usize,
    ) {
        let Some((a, b)) = covered_span(covs) else {
            return;
        };
        let (xa, xb) = (x0 + a, x0 + b);
        self.mix(r, xa, xb);
        item.paint.row(xa, y, &mut colors[a..b]);
        let dst = &mut self.px[r * self.w + xa..r * self.w + xb];
        for ((&cov, d), s) in covs[a..b].iter().zip(dst).zip(&colors[a..b]) {
            if cov > 0.0 {
                over(d, *s, cov);
            }
        }
    }
}

/// A stretch of columns `a..b` of one row to draw with a solid color
/// ([`RunCanvas::apply_row`]): at one coverage `cov`, or, when `px` is not
/// [`NO_PIXELS`], at the coverages `covs[px..px + b - a]` of the row's scratch.
#[derive(Clone, Copy, Debug)]
struct RowOp {
    a: u32,
    b: u32,
    cov: f32,
    px: u32,
}

/// [`RowOp::px`] of a stretch at one coverage.
const NO_PIXELS: u32 = u32::MAX;

/// A row's [`RowOp`]s as [`RunCanvas::draw_solid`] finds them, left to right: adjacent
/// stretches of one coverage are joined, stretches at coverage 0 dropped.
struct RowOps {
    ops: Vec<RowOp>,
    /// The stretch at one coverage not yet pushed.
    pending: RowOp,
}

impl RowOps {
    /// Empty, reusing `ops`' memory, starting at column `x`.
    fn new(mut ops: Vec<RowOp>, x: usize) -> Self {
        ops.clear();
        let pending = RowOp {
            a: x as u32,
            b: x as u32,
            cov: 0.0,
            px: NO_PIXELS,
        };
        RowOps { ops, pending }
    }

    /// Adds columns `a..b` at coverage `cov`, joined to the pending stretch when that ends
    /// at `a` with the same coverage bits.
    #[inline]
    fn stretch(&mut self, a: usize, b: usize, cov: f32) {
        if a >= b {
            return;
        }
        let p = &mut self.pending;
        if a as u32 == p.b && cov.to_bits() == p.cov.to_bits() {
            p.b = b as u32;
        } else {
            self.flush();
            self.pending = RowOp {
                a: a as u32,
                b: b as u32,
                cov,
                px: NO_PIXELS,
            };
        }
    }

    /// Adds columns `a..b` at the coverages from `covs[px]` on.
    fn pixels(&mut self, a: usize, b: usize, px: usize) {
        self.flush();
        self.ops.push(RowOp {
            a: a as u32,
            b: b as u32,
            cov: 0.0,
            px: px as u32,
        });
    }

    fn flush(&mut self) {
        let p = self.pending;
        if p.a < p.b && p.cov > 0.0 {
            self.ops.push(p);
        }
        self.pending.a = p.b;
    }

    /// The stretches, in column order.
    fn finish(mut self) -> Vec<RowOp> {
        self.flush();
        self.ops
    }
}

/// Appends `run` to a row's runs, as part of the last one when they [join](Run::joins).
#[inline]
fn push_joined(runs: &mut Vec<Run>, run: Run) {
    if let Some(last) = runs.last_mut()
        && last.joins(&run)
    {
        last.x1 = run.x1;
    } else {
        runs.push(run);
    }
}

/// The chunks of `acc`'s rows an item's edges can have written deltas into: sorted
/// `(row of acc, first chunk, end chunk)` triples (chunks of the canvas, ends exclusive),
/// overlapping or adjacent ones merged.
///
/// An edge crossing row `y` writes into the columns from the floor of its least `x` in
/// that row to one past the floor of its greatest (the guard column), after clamping to
/// `0 ..= canvas_w` as [`accumulate_line`](super::coverage::accumulate_line) does; each
/// range is widened by a column on either side so that rounding can never hide a delta.
/// Horizontal edges write none.
fn touched_chunks(
    item: &Item,
    acc: &super::coverage::Cells<f32>,
    canvas_w: usize,
    out: &mut Vec<(u32, u32, u32)>,
) {
    out.clear();
    let (ylo, yhi) = (acc.y0 as f64, (acc.y0 as usize + acc.h) as f64);
    let xmax = canvas_w as f64;
    let first = acc.x0 as f64;
    let last = (acc.x0 as usize + acc.w) as f64;
    let chunk = CHUNK as f64;
    item.for_each_edge_near(ylo, yhi, |ia, ic| {
        let (a, c) = (item.pts[ia], item.pts[ic]);
        if a[1] == c[1] || a[1].max(c[1]) <= ylo || a[1].min(c[1]) >= yhi {
            return;
        }
        let (a, c) = if a[1] < c[1] { (a, c) } else { (c, a) };
        // The chunks around columns `xa..xb` (either order), if any.
        let chunks = |xa: f64, xb: f64| {
            let lo = (floor_f64(xa.min(xb)) - 1.0).max(first);
            let hi = (floor_f64(xa.max(xb)) + 3.0).min(last);
            (lo < hi).then(|| (floor_f64(lo / chunk) as u32, ceil_f64(hi / chunk) as u32))
        };
        let r1 = ceil_f64(c[1].min(yhi));
        let mut y = floor_f64(a[1].max(ylo));
        if a[0] == c[0] {
            // A vertical edge (a stripe's side): the same chunks in every row.
            let x = a[0].clamp(0.0, xmax);
            if let Some((ka, kb)) = chunks(x, x) {
                while y < r1 {
                    out.push(((y - ylo) as u32, ka, kb));
                    y += 1.0;
                }
            }
            return;
        }
        let slope = (c[0] - a[0]) / (c[1] - a[1]);
        let x_at = |y: f64| a[0] + (y - a[1]) * slope;
        while y < r1 {
            let (ya, yb) = (y.max(a[1]), (y + 1.0).min(c[1]));
            let (xa, xb) = (x_at(ya).clamp(0.0, xmax), x_at(yb).clamp(0.0, xmax));
            if let Some((ka, kb)) = chunks(xa, xb) {
                out.push(((y - ylo) as u32, ka, kb));
            }
            y += 1.0;
        }
    });
    out.sort_unstable();
    // Merge a row's overlapping or adjacent ranges in place.
    let mut n = 0;
    for i in 0..out.len() {
        let t = out[i];
        if n > 0 && out[n - 1].0 == t.0 && t.1 <= out[n - 1].2 {
            out[n - 1].2 = out[n - 1].2.max(t.2);
        } else {
            out[n] = t;
            n += 1;
        }
    }
    out.truncate(n);
}

/// A run's coverage within `slack` of 1 taken as 1, and within it of 0 as 0, so that a
/// fill beside a slanted edge sets (or leaves) its chunks rather than blending them.
///
/// A row crossed by a slanted edge sums the edge's pieces to `1 − 2⁻²⁴` rather than 1
/// inside the shape, and to a few `2⁻²⁴` rather than 0 outside it. This 8-bit path is
/// forward only (never differentiated), so the exact 0 or 1 costs nothing; the `f32`
/// render keeps the unsnapped value, since a snap there is a discontinuity that finite
/// differences see.
#[inline]
fn snap_run(cov: f32, slack: f32) -> f32 {
    if cov >= 1.0 - slack {
        1.0
    } else if cov <= slack {
        0.0
    } else {
        cov
    }
}

/// How far from 0 or 1 a run's coverage may fall from rounding and still count as 0 or 1
/// in [`render_rgba8`]: four `f32` steps below 1 (each `2⁻²⁴`).
const SLACK: f32 = 2.0 * f32::EPSILON;

/// Whether an item's rows are composited pixel by pixel rather than as solid stretches
/// ([`RunCanvas::draw_solid`]): when its edges cross a row more often than once per
/// [`DENSE_COLUMNS`] columns of its box, on average (a line of text, a detailed emblem).
/// There each crossing's chunks cost more than the pixels between them.
/// `cols` is the width of the columns it is accumulated over.
fn dense(item: &Item, cols: usize) -> bool {
    let height = (item.bbox[3] - item.bbox[1]).max(1.0);
    item.row_crossings / height * DENSE_COLUMNS > cols as f64
}

/// Columns per edge crossing of a row below which an item is [`dense`]. Measured on
/// resvg's suite (`bench --rgba8`, one thread): masking and text 0.80× → 0.96× resvg with
/// 16, the flags unchanged (1.47×); 64 sent big fills pixel by pixel (0.60×).
const DENSE_COLUMNS: f64 = 16.0;

impl Canvas for RunCanvas {
    fn draw(&mut self, r: &mut BandRenderer<'_>, item: &Item, _area: Area) {
        if !r.deltas(item) {
            return;
        }
        if let PaintEval::Solid(solid) = &item.paint
            && r.overlaps.is_empty()
            && !dense(item, r.acc.w)
        {
            return self.draw_solid(r, item, solid.premul);
        }
        let (x0, y0, band_y0) = (r.acc.x0 as usize, r.acc.y0 as usize, r.y0);
        for k in 0..r.acc.h {
            let y = y0 + k;
            let (row, sc, ov) = r.take_row(k);
            let n = row.len();
            coverage_row(row, item.evenodd, &mut sc.covs[..n]);
            if ov.has_row(k) {
                ov.resolve_row(k, row, item.evenodd, &mut sc.covs[..n]);
            }
            self.composite_row(item, &sc.covs[..n], &mut sc.colors[..n], x0, y - band_y0, y);
        }
    }

    fn composite(
        &mut self,
        band: Area,
        top: &[[f32; 4]],
        ta: Area,
        opacity: f32,
        blend: BlendMode,
    ) {
        let (r0, r1) = (ta.y0 - band.y0, ta.y0 - band.y0 + ta.h);
        self.mix_area(ta.x0, ta.x0 + ta.w, r0, r1);
        composite_layer(&mut self.px, band, top, ta, opacity, blend);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::{RenderOptions, render_prepared};
    use crate::rng::Rng;
    use crate::scene::Scene;

    /// `render_rgba8` against converting the `f32` image, both alpha forms, with and
    /// without exact overlaps: the same bytes without snapping, and within one level
    /// with it.
    fn same_bytes(svg: &str) {
        let scene = Scene::from_svg_str(svg, "t.svg", crate::Sizing::Natural).unwrap();
        for exact_overlaps in [false, true] {
            let opts = RenderOptions {
                exact_overlaps,
                ..RenderOptions::default()
            };
            let p = Prepared::new(&scene, &opts);
            let img = render_prepared(&p);
            let premul: Vec<u8> = img.data.iter().flatten().map(|&v| to_u8(v)).collect();
            for (slack, tolerance) in [(0.0, 0), (SLACK, 1)] {
                for (ours, theirs) in [
                    (
                        render_rgba8_with(&p, Alpha::Straight, slack),
                        img.to_rgba8(),
                    ),
                    (
                        render_rgba8_with(&p, Alpha::Premultiplied, slack),
                        premul.clone(),
                    ),
                ] {
                    assert_eq!(ours.len(), theirs.len());
                    let off = |i: usize| ours[i].abs_diff(theirs[i]) > tolerance;
                    if let Some(i) = (0..ours.len()).find(|&i| off(i)) {
                        let (x, y) = ((i / 4) % p.width as usize, i / 4 / p.width as usize);
                        panic!(
                            "slack {slack}: pixel ({x}, {y}): {:?}, the f32 image's {:?}\n{svg}",
                            &ours[i / 4 * 4..][..4],
                            &theirs[i / 4 * 4..][..4]
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn bytes_are_those_of_the_f32_image() {
        let wrap = |w: u32, h: u32, body: &str| {
            format!(
                r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}">{body}</svg>"#
            )
        };
        let body = r##"
            <rect x="-3" y="5" width="70" height="20" fill="#c01"/>
            <rect x="4" y="0" width="33.5" height="61" fill="white" opacity="0.6"/>
            <rect x="8" y="8" width="16" height="16" fill="#00f" fill-opacity="0.5"/>
            <circle cx="30" cy="30" r="13.3" fill="teal"/>
            <path d="M5 60 L60 3 L63 60 Z" fill="#282" fill-rule="evenodd"/>
            <g opacity="0.5" style="mix-blend-mode:multiply">
              <rect x="10" y="30" width="40" height="9" fill="orange"/>
            </g>
            <linearGradient id="g"><stop offset="0" stop-color="red"/><stop offset="1" stop-color="blue" stop-opacity="0.3"/></linearGradient>
            <rect x="2" y="44" width="61" height="7.2" fill="url(#g)"/>
            <rect x="0" y="52" width="64" height="8" fill="none" stroke="black" stroke-width="0.7"/>
            <path d="M3.3 3 h5.2 v20 h-5.2 z M3.3 3 h5.2 v20 h-5.2 z M1 40 L20 44 L1 48 L20 36 Z" fill="#a0a"/>"##;
        // Widths around a chunk multiple, heights around a band.
        for (w, h) in [(64, 64), (61, 70), (1, 1), (9, 17), (8, 40), (130, 33)] {
            same_bytes(&wrap(w, h, body));
            let bg = format!(r##"<rect width="{w}" height="{h}" fill="#eee"/>{body}"##);
            same_bytes(&wrap(w, h, &bg));
        }
        same_bytes(&wrap(5, 5, ""));
    }

    /// The bundled drawings and the flags (big fills beside slanted and axis-aligned edges
    /// on and off chunk boundaries), where the 8-bit path reads only touched chunks and
    /// snaps runs' coverages: still the bytes of the `f32` image.
    #[test]
    fn bytes_of_bundled_drawings_and_flags() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut n = 0;
        for dir in ["svg-samples", "benches/flags"] {
            let mut files: Vec<_> = std::fs::read_dir(root.join(dir))
                .unwrap()
                .map(|e| e.unwrap().path())
                .filter(|p| p.extension().is_some_and(|e| e == "svg"))
                .collect();
            files.sort();
            for f in files {
                same_bytes(&std::fs::read_to_string(&f).unwrap());
                n += 1;
            }
        }
        assert!(n >= 15, "{n} drawings");
    }

    /// Rows crossed by hundreds of small shapes (more runs than [`MAX_RUNS`], so rows
    /// become one mixed run part way), opaque and translucent, under and over big
    /// fills; and a band of rows that repeat the row above only in part.
    #[test]
    fn bytes_of_many_small_shapes() {
        let mut rng = Rng::new(11);
        let mut body =
            String::from(r##"<rect x="3.5" y="2" width="190" height="30" fill="#345"/>"##);
        for i in 0..400 {
            let (x, y) = (rng.uniform() * 200.0, rng.uniform() * 36.0);
            let (w, h) = (0.3 + rng.uniform() * 2.5, 0.5 + rng.uniform() * 12.0);
            let opacity = if i % 3 == 0 { 0.6 } else { 1.0 };
            body += &format!(
                r##"<rect x="{x:.3}" y="{y:.3}" width="{w:.3}" height="{h:.3}" fill="#{:06x}" fill-opacity="{opacity}"/>"##,
                (rng.uniform() * 16_777_215.0) as u32
            );
        }
        body +=
            r##"<rect x="20" y="5.25" width="150" height="20" fill="#fa0" fill-opacity="0.8"/>"##;
        body += r##"<rect x="0" y="9" width="201" height="5" fill="#0a0"/>"##;
        same_bytes(&format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="201" height="37">{body}</svg>"#
        ));
    }

    /// A line of small glyph-like rings is drawn pixel by pixel ([`dense`]), the stripes
    /// under and over it as solid stretches: the same bytes either way.
    #[test]
    fn bytes_of_dense_and_sparse_items() {
        let mut d = String::new();
        for k in 0..40 {
            let x = 3.3 + k as f64 * 4.7;
            // An "o": a ring and its counter, a few pixels across.
            d += &format!(
                "M{x} 20 a2 2.5 0 1 0 4 0 a2 2.5 0 1 0 -4 0 Z M{} 20 a1 1.5 0 1 1 2 0 a1 1.5 0 1 1 -2 0 Z ",
                x + 1.0
            );
        }
        let svg = format!(
            r##"<svg xmlns="http://www.w3.org/2000/svg" width="197" height="40">
              <rect x="0.5" y="10" width="196" height="12.3" fill="#8ad"/>
              <path d="{d}" fill="#222"/>
              <rect x="-2" y="21" width="190" height="1.5" fill="#c00" fill-opacity="0.7"/></svg>"##
        );
        let scene = Scene::from_svg_str(&svg, "t.svg", crate::Sizing::Natural).unwrap();
        let p = Prepared::new(&scene, &RenderOptions::default());
        let width = |it: &Item| (it.bbox[2] - it.bbox[0]).ceil() as usize + 2;
        let dense_items: Vec<bool> = p.items.iter().map(|it| dense(it, width(it))).collect();
        assert_eq!(dense_items, [false, true, false]);
        same_bytes(&svg);
    }

    /// Random polygons of a few big solid fills, slanted and straight, on a canvas whose
    /// width is not a chunk multiple.
    #[test]
    fn bytes_of_random_fills() {
        let mut rng = Rng::new(7);
        for case in 0..40 {
            let mut body = String::new();
            for _ in 0..4 {
                let mut d = String::from("M");
                for k in 0..(3 + case % 4) {
                    let (x, y) = (rng.uniform() * 140.0 - 10.0, rng.uniform() * 90.0 - 5.0);
                    d += &format!("{}{x:.3} {y:.3} ", if k == 0 { "" } else { "L" });
                }
                let opacity = if case % 3 == 0 { 0.7 } else { 1.0 };
                body += &format!(
                    r##"<path d="{d}Z" fill="#{:06x}" fill-opacity="{opacity}" fill-rule="{}"/>"##,
                    (rng.uniform() * 16_777_215.0) as u32,
                    if case % 2 == 0 { "nonzero" } else { "evenodd" }
                );
            }
            same_bytes(&format!(
                r#"<svg xmlns="http://www.w3.org/2000/svg" width="123" height="77">{body}</svg>"#
            ));
        }
    }
}
