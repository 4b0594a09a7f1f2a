//! Forward rendering: coverage, paint and source-over compositing in row bands.

use rayon::prelude::*;

use super::coverage::{
    Cells, accumulate_centers, accumulate_line, accumulate_line_visiting, ceil_f64, coverage_row,
    floor_f64, integrate_rows,
};
use super::layer::{apply_mask, composite_layer};
use super::overlap::Overlaps;
use super::paint::PaintEval;
use super::prepare::{GroupSpan, Item, Op, Prepared, prepare_forward};
use crate::image_io::Image;
use crate::scene::BlendMode;
use crate::scene::Scene;

/// Rasterization settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    /// Largest distance between a curve and its flattened chords, in device pixels.
    pub tolerance: f64,
    /// Integrate exactly the pixels where a path overlaps itself (issue 29,
    /// `raster/overlap.rs`), and differentiate that coverage exactly (checked against
    /// central differences in `tests/hard_cases.rs`). Off (the default): the clamped
    /// winding integral there, which over-covers such pixels (two coincident
    /// half-covering rectangles in one path give 1.0, not 0.5). Off by default because
    /// it makes text about a fifth slower (docs/performance.md).
    pub exact_overlaps: bool,
    /// Evaluate filters as the SVG specification defines them rather than as resvg
    /// approximates them: feGaussianBlur (and feDropShadow's blur) as a true Gaussian
    /// (tapered to 0 from 4σ to 5σ; cost grows with σ) instead of resvg's box blurs, and feOffset's
    /// and feDropShadow's offsets by fractions of a pixel (bilinear) instead of truncated
    /// to whole pixels. Both are then smooth in their parameters, so deviations and
    /// offsets get a gradient; off (resvg's rendering) they get none.
    pub exact_filters: bool,
}

impl Default for RenderOptions {
    fn default() -> Self {
        RenderOptions {
            tolerance: crate::scene::geom::DEFAULT_TOLERANCE,
            exact_overlaps: false,
            exact_filters: false,
        }
    }
}

/// Rows per band: the unit of parallel work, and of the loss's partial sums.
pub(crate) const BAND_ROWS: usize = crate::loss::SUM_ROWS;

/// Renders `scene` onto a transparent canvas. Pixel values are premultiplied `f32`; paints
/// are evaluated at pixel centers and coverage is the exact area of each pixel square
/// inside the (flattened) shape.
pub fn render(scene: &Scene, opts: &RenderOptions) -> Image {
    let mut p = prepare_forward(scene, opts.tolerance, opts.exact_filters);
    p.set_exact_overlaps(opts.exact_overlaps);
    render_prepared(&p)
}

/// Renders an already prepared scene.
pub fn render_prepared(p: &Prepared) -> Image {
    let (w, h) = (p.width as usize, p.height as usize);
    // What an opaque item covering the canvas (a background) hides is not drawn: the
    // canvas starts as its color, which is what compositing it leaves in every pixel.
    let (start, group, fill) = opaque_start(p);
    let mut img = filled_canvas(p.width, p.height, fill);
    if w == 0 || h == 0 {
        return img;
    }
    img.data
        .par_chunks_mut(w * BAND_ROWS)
        .with_min_len(p.min_bands_per_task())
        .enumerate()
        .for_each(|(band, out)| {
            let mut r = BandRenderer::new(p, band * BAND_ROWS, out.len() / w);
            r.run(out, start, group);
        });
    img
}

/// Where a forward render may start: just after the last top-level item that paints the
/// whole canvas an opaque color ([`Item::opaque_cover`]), as `(op, groups opened before
/// it, color)`; `(0, 0, transparent)` when there is none.
pub(crate) fn opaque_start(p: &Prepared) -> (usize, usize, [f32; 4]) {
    let mut start = (0, 0, [0.0; 4]);
    let (mut depth, mut groups) = (0usize, 0usize);
    for (i, op) in p.ops.iter().enumerate() {
        match *op {
            Op::Draw(it) if depth == 0 => {
                if let Some(c) = p.items[it].opaque_cover(p.width, p.height) {
                    start = (i + 1, groups, c);
                }
            }
            Op::Draw(_) => {}
            Op::Push | Op::PushMask => {
                depth += 1;
                groups += 1;
            }
            Op::Pop { .. } | Op::PopMask { .. } => depth -= 1,
        }
    }
    start
}

/// A transparent canvas. A large one has its zeros written, in parallel, rather than
/// allocated zeroed: a large zeroed allocation comes fresh from the kernel, and
/// compositing reads a pixel before writing it, so the read maps the shared zero page and
/// the write then costs a copy-on-write fault that interrupts every other core to flush
/// its TLB (a third of the time of a 2048² step on 2 cores). Written zeros take one plain
/// fault per page. Smaller canvases are reused heap memory, where writing the zeros is
/// only a second pass (10% of a 256² drawing's time).
pub(crate) fn blank_canvas(width: u32, height: u32) -> Image {
    filled_canvas(width, height, [0.0; 4])
}

/// A canvas of one premultiplied color, written as [`blank_canvas`] writes its zeros.
fn filled_canvas(width: u32, height: u32, color: [f32; 4]) -> Image {
    /// From this size on, glibc maps every allocation afresh (its largest mmap threshold).
    const FRESH_BYTES: usize = 32 << 20;
    let n = width as usize * height as usize;
    if n * std::mem::size_of::<[f32; 4]>() < FRESH_BYTES {
        if color == [0.0; 4] {
            return Image::new(width, height);
        }
        return Image {
            width,
            height,
            data: vec![color; n],
        };
    }
    let mut data = Vec::with_capacity(n);
    data.par_extend(rayon::iter::repeat_n(color, n));
    Image {
        width,
        height,
        data,
    }
}

/// Renders the rows `y0 .. y0 + rows` of a prepared scene; shared with the backward pass,
/// which renders a band while recording what its reverse walk needs.
///
/// An item is drawn in two steps: [`deltas`](Self::deltas) accumulates its edges into
/// `acc` as per-cell winding deltas, then [`take_row`](Self::take_row) turns one row at a
/// time into winding integrals (a running sum) while clearing it, so that `acc` is all
/// zero again when the item is done and the next item needs no clearing pass.
pub(crate) struct BandRenderer<'a> {
    pub(crate) p: &'a Prepared,
    pub(crate) y0: usize,
    pub(crate) rows: usize,
    pub(crate) acc: Cells<f32>,
    /// Whether every value of `acc.data` is zero.
    clean: bool,
    /// One row's winding integrals, from [`take_row`](Self::take_row).
    row: Vec<f32>,
    /// Per-row scratch.
    scratch: RowScratch,
    /// The current item's cells of exact coverage ([`deltas`](Self::deltas) finds them).
    pub(crate) overlaps: Overlaps,
    /// Whether [`overlaps`](Self::overlaps) keeps what the backward pass needs.
    pub(crate) for_backward: bool,
}

/// A band renderer's buffers, kept on each thread from one band to the next: a small
/// drawing's bands each allocated them afresh (seven allocations a band).
#[derive(Default)]
struct BandBuffers {
    /// [`BandRenderer::acc`]'s values, all zero.
    acc: Vec<f32>,
    row: Vec<f32>,
    scratch: RowScratch,
    overlaps: Overlaps,
}

thread_local! {
    static BAND_BUFFERS: std::cell::RefCell<BandBuffers> =
        std::cell::RefCell::new(BandBuffers::default());
}

/// Scratch values along one row of an item's box.
#[derive(Default)]
pub(crate) struct RowScratch {
    /// Coverages.
    pub(crate) covs: Vec<f32>,
    /// One-sided coverage slopes (backward pass only).
    pub(crate) ups: Vec<f32>,
    pub(crate) downs: Vec<f32>,
    /// Paint colors.
    pub(crate) colors: Vec<[f32; 4]>,
    /// Stretches of columns `a..b` with something to draw (solid rows only).
    spans: Vec<(usize, usize)>,
}

impl<'a> BandRenderer<'a> {
    pub(crate) fn new(p: &'a Prepared, y0: usize, rows: usize) -> Self {
        let b = BAND_BUFFERS.with(|b| std::mem::take(&mut *b.borrow_mut()));
        BandRenderer {
            p,
            y0,
            rows,
            acc: Cells {
                data: b.acc,
                ..Cells::default()
            },
            clean: true,
            row: b.row,
            scratch: b.scratch,
            overlaps: b.overlaps,
            for_backward: false,
        }
    }

    /// The whole band, as an [`Area`].
    pub(crate) fn band_area(&self) -> Area {
        Area {
            x0: 0,
            y0: self.y0,
            w: self.p.width as usize,
            h: self.rows,
        }
    }

    /// The part of this band a group's layer covers; `None` when the group draws nothing
    /// here (its ops can be skipped: compositing a transparent layer changes nothing).
    pub(crate) fn layer_area(&self, span: &GroupSpan) -> Option<Area> {
        let r = span.rect?;
        let y0 = r[1].max(self.y0);
        let y1 = r[3].min(self.y0 + self.rows);
        // Lazily: `y1 - y0` underflows where the band misses the layer.
        (y0 < y1).then(|| Area {
            x0: r[0],
            y0,
            w: r[2] - r[0],
            h: y1 - y0,
        })
    }

    /// Runs the program onto `out` (`rows × width`, transparent or not) from op `start`,
    /// which lies at the top level after `group` groups were opened (`0, 0`: all of it).
    pub(crate) fn run<C: Canvas + ?Sized>(&mut self, out: &mut C, start: usize, group: usize) {
        let base = self.band_area();
        // Open layers, each only as large as its group's content in this band.
        let mut layers: Vec<(Area, Vec<[f32; 4]>)> = Vec::new();
        let ops = &self.p.ops;
        let (mut i, mut group) = (start, group);
        while i < ops.len() {
            match ops[i] {
                Op::Draw(it) => match layers.last_mut() {
                    Some((a, l)) => self.draw(&self.p.items[it], l, *a),
                    None => out.draw(self, &self.p.items[it], base),
                },
                Op::Push | Op::PushMask => {
                    let span = self.p.groups[group];
                    match self.layer_area(&span) {
                        Some(a) if span.filter.is_some() => {
                            // A filtered layer, computed when prepared: its children's
                            // ops are skipped.
                            let fl = &self.p.filters[span.filter.unwrap_or_default()];
                            layers.push((a, fl.rows(a.y0, a.h)));
                            group = fl.groups_end;
                            i = fl.body_end;
                            continue;
                        }
                        Some(a) => {
                            layers.push((a, vec![[0.0; 4]; a.w * a.h]));
                            group += 1;
                        }
                        None => {
                            // A group drawing nothing here changes nothing; a mask
                            // drawing nothing here hides the layer it masks.
                            if ops[i] == Op::PushMask {
                                let (_, content) = layers.last_mut().expect("a masked layer");
                                content.fill([0.0; 4]);
                            }
                            group = span.groups_end;
                            i = span.end + 1;
                            continue;
                        }
                    }
                }
                Op::Pop { opacity, blend, .. } => {
                    let (ta, top) = layers.pop().expect("a layer per group");
                    match layers.last_mut() {
                        Some((a, l)) => composite_layer(l, *a, &top, ta, opacity, blend),
                        None => out.composite(base, &top, ta, opacity, blend),
                    }
                }
                Op::PopMask { kind } => {
                    let (ma, mask) = layers.pop().expect("a mask layer");
                    let (ca, content) = layers.last_mut().expect("a masked layer");
                    apply_mask(content, *ca, Some((&mask, ma)), kind);
                }
            }
            i += 1;
        }
    }

    /// Accumulates the winding integrals of `item` over the band into `self.acc`.
    /// Returns `false` when the item does not touch the band.
    pub(crate) fn winding(&mut self, item: &Item) -> bool {
        if !self.deltas_with(item, false) {
            return false;
        }
        integrate_rows(&mut self.acc);
        self.clean = false;
        true
    }

    /// Accumulates the edges of `item` into `self.acc` as winding deltas, to be read row by
    /// row with [`take_row`](Self::take_row) (every row, which leaves `acc` clear).
    /// Returns `false` when the item does not touch the band.
    pub(crate) fn deltas(&mut self, item: &Item) -> bool {
        self.deltas_with(item, true)
    }

    /// [`deltas`](Self::deltas), finding the cells of exact coverage when `exact`.
    fn deltas_with(&mut self, item: &Item, exact: bool) -> bool {
        let w = self.p.width as f64;
        let b = item.bbox;
        if b[2] <= 0.0 || b[0] >= w {
            return false;
        }
        // One pixel of margin around the bounds: the backward pass needs the pixels next to
        // an edge that lies exactly on a pixel boundary.
        // `floor` and `ceil` without a libm call.
        let top = ((floor_f64(b[1]) - 1.0).max(self.y0 as f64)) as usize;
        let bottom = ((ceil_f64(b[3]) + 1.0).min((self.y0 + self.rows) as f64)).max(0.0) as usize;
        if top >= bottom {
            return false;
        }
        let cx0 = (floor_f64(b[0]) - 1.0).max(0.0);
        let cx1 = ceil_f64(b[2]).min(w);
        let cols = (cx1 - cx0) as usize + 2;
        if self.clean {
            self.acc
                .reshape_zeroed(cx0 as i64, top as i64, cols, bottom - top);
        } else {
            self.acc.reset(cx0 as i64, top as i64, cols, bottom - top);
            self.clean = true;
        }
        let (ylo, yhi) = (top as f64, bottom as f64);
        let acc = &mut self.acc;
        // Two loops rather than a function pointer: the area accumulation stays inlined
        // in the hot one.
        let near = |a: [f64; 2], c: [f64; 2]| a[1].max(c[1]) > ylo && a[1].min(c[1]) < yhi;
        if item.crisp {
            item.for_each_edge_near(ylo, yhi, |ia, ic| {
                let (a, c) = (item.pts[ia], item.pts[ic]);
                if near(a, c) {
                    accumulate_centers(acc, a, c, w);
                }
            });
            // A crisp item's winding numbers at pixel centers are exact already.
            self.overlaps.clear();
        } else if exact && item.can_overlap && self.p.exact_overlaps {
            self.deltas_tagged(item, ylo, yhi);
        } else {
            item.for_each_edge_near(ylo, yhi, |ia, ic| {
                let (a, c) = (item.pts[ia], item.pts[ic]);
                if near(a, c) {
                    accumulate_line(acc, a, c, w);
                }
            });
            self.overlaps.clear();
        }
        true
    }

    /// [`deltas_with`](Self::deltas_with)'s accumulation of an item that can overlap
    /// itself, exact overlaps on, over rows `ylo..yhi` of the sized and zeroed `acc`: each
    /// cell keeps the chain of edges crossing it as the edges are accumulated, so the cells
    /// that can hold three windings come out of the same pass, and are searched. Out of
    /// line: inlined, it made the plain accumulation's caller slower.
    #[inline(never)]
    fn deltas_tagged(&mut self, item: &Item, ylo: f64, yhi: f64) {
        let w = self.p.width as f64;
        let acc = &mut self.acc;
        let near = |a: [f64; 2], c: [f64; 2]| a[1].max(c[1]) > ylo && a[1].min(c[1]) < yhi;
        let tags = self.overlaps.tags();
        tags.begin(acc.x0, acc.y0, acc.w, acc.h, self.for_backward);
        item.for_each_edge_near(ylo, yhi, |ia, ic| {
            let (a, c) = (item.pts[ia], item.pts[ic]);
            if a[1] == c[1] {
                if a[1] >= ylo && a[1] <= yhi {
                    tags.horizontal(ia, ic, a, c, w);
                }
            } else if near(a, c) {
                tags.edge(ia, ic, a, c);
                accumulate_line_visiting(acc, a, c, w, tags);
            }
        });
        let cols = acc.w.min(self.p.width as usize - acc.x0 as usize);
        let (origin, rows) = ((acc.x0, acc.y0), acc.h);
        #[cfg(test)]
        {
            self.overlaps.everywhere = self.p.search_everywhere;
        }
        self.overlaps
            .find(item, origin, cols, rows, self.for_backward);
    }

    /// The winding integrals of row `r` of `acc` (after [`deltas`](Self::deltas)), over
    /// its columns inside the canvas, and scratch rows at least as long; the row's deltas
    /// are cleared.
    pub(crate) fn take_row(&mut self, r: usize) -> (&[f32], &mut RowScratch, &mut Overlaps) {
        if self.row.len() < self.acc.w {
            self.take_row_scratch(self.acc.w);
        }
        let acc = &mut self.acc;
        let cols = acc.w.min(self.p.width as usize - acc.x0 as usize);
        running_sum_clearing(
            &mut acc.data[r * acc.w..(r + 1) * acc.w],
            &mut self.row[..acc.w],
        );
        (&self.row[..cols], &mut self.scratch, &mut self.overlaps)
    }

    /// Grows the row and its scratch to `w` values.
    fn take_row_scratch(&mut self, w: usize) {
        self.row.resize(w, 0.0);
        let sc = &mut self.scratch;
        sc.covs.resize(w, 0.0);
        sc.ups.resize(w, 0.0);
        sc.downs.resize(w, 0.0);
        sc.colors.resize(w, [0.0; 4]);
    }

    /// Draws one item source-over onto `target`, a layer covering `area` (which holds
    /// every pixel the item touches in this band).
    pub(crate) fn draw(&mut self, item: &Item, target: &mut [[f32; 4]], area: Area) {
        if !self.deltas(item) {
            return;
        }
        let (x0, y0) = (self.acc.x0 as usize, self.acc.y0 as usize);
        let solid = matches!(item.paint, PaintEval::Solid(_));
        #[cfg(test)]
        let solid = solid && !self.p.dense_rows;
        for r in 0..self.acc.h {
            let y = y0 + r;
            if solid && !self.overlaps.has_row(r) {
                let cols = self.acc.w.min(self.p.width as usize - x0);
                let dst = &mut target[area.index(x0, y)..][..cols];
                self.draw_solid_row(item, r, dst, x0, y);
                continue;
            }
            let (row, sc, ov) = self.take_row(r);
            let dst = &mut target[area.index(x0, y)..][..row.len()];
            if ov.has_row(r) {
                let covs = &mut sc.covs[..row.len()];
                coverage_row(row, item.evenodd, covs);
                ov.resolve_row(r, row, item.evenodd, covs);
                composite_covs(item, covs, &mut sc.colors, dst, x0, y);
            } else {
                composite_row(item, row, &mut sc.covs, &mut sc.colors, dst, x0, y);
            }
        }
    }

    /// [`draw`](Self::draw)'s row `r` of a solid item without exact cells, onto `dst`
    /// (device pixels from `(x0, y)`, as many as the row has inside the canvas): the
    /// running sum, the coverages and the compositing only over the stretches of eight
    /// columns where the winding integral is not zero (outside a shape, between a frame's
    /// two sides), which [`take_row`](Self::take_row) and [`composite_row`] would walk
    /// only to find nothing to draw. The same bits as those two: the sums are the same
    /// additions, and a skipped pixel has coverage 0, which compositing leaves alone.
    fn draw_solid_row(&mut self, item: &Item, r: usize, dst: &mut [[f32; 4]], x0: usize, y: usize) {
        const LANES: usize = 8;
        let w = self.acc.w;
        if self.row.len() < w {
            // Sized as `take_row` sizes them, which the other rows may use.
            self.take_row_scratch(w);
        }
        let deltas = &mut self.acc.data[r * w..(r + 1) * w];
        let out = &mut self.row[..w];
        let spans = &mut self.scratch.spans;
        spans.clear();
        // `running_sum_clearing`'s loop, skipping runs where the sum stays zero. One
        // function for both with a switch measured slower (masking + text 1.33× → 1.29×
        // resvg by default), so the two loops are kept apart.
        let mut s = 0.0f32;
        // The start of the stretch being drawn, if any.
        let mut open: Option<usize> = None;
        let full = w - w % LANES;
        let (d_full, d_rest) = deltas.split_at_mut(full);
        let (o_full, o_rest) = out.split_at_mut(full);
        for (i, (d, o)) in d_full
            .chunks_exact_mut(LANES)
            .zip(o_full.chunks_exact_mut(LANES))
            .enumerate()
        {
            if all_zero(d) {
                if s == 0.0 {
                    if let Some(a) = open.take() {
                        spans.push((a, i * LANES));
                    }
                    continue;
                }
                o.fill(s);
            } else {
                for (c, o) in d.iter_mut().zip(o) {
                    s += *c;
                    *c = 0.0;
                    *o = s;
                }
            }
            open.get_or_insert(i * LANES);
        }
        if full < w {
            for (c, o) in d_rest.iter_mut().zip(o_rest) {
                s += *c;
                *c = 0.0;
                *o = s;
            }
            open.get_or_insert(full);
        }
        if let Some(a) = open {
            spans.push((a, w));
        }
        let cols = dst.len();
        let sc = &mut self.scratch;
        for &(a, b) in &sc.spans {
            let b = b.min(cols);
            if a >= b {
                break;
            }
            coverage_row(&out[a..b], item.evenodd, &mut sc.covs[a..b]);
            composite_covs(
                item,
                &sc.covs[a..b],
                &mut sc.colors[a..b],
                &mut dst[a..b],
                x0 + a,
                y,
            );
        }
    }
}

/// What a band's top level is drawn onto: `f32` pixels, or
/// [`RunCanvas`](super::pixmap::RunCanvas) for 8-bit output.
pub(crate) trait Canvas {
    /// Draws one item source-over onto the band `area`.
    fn draw(&mut self, r: &mut BandRenderer<'_>, item: &Item, area: Area);
    /// Composites a group's layer `top`, covering `ta`, onto the band `area`.
    fn composite(&mut self, area: Area, top: &[[f32; 4]], ta: Area, opacity: f32, blend: BlendMode);
}

impl Canvas for [[f32; 4]] {
    fn draw(&mut self, r: &mut BandRenderer<'_>, item: &Item, area: Area) {
        r.draw(item, self, area);
    }

    fn composite(
        &mut self,
        area: Area,
        top: &[[f32; 4]],
        ta: Area,
        opacity: f32,
        blend: BlendMode,
    ) {
        composite_layer(self, area, top, ta, opacity, blend);
    }
}

impl Drop for BandRenderer<'_> {
    /// Leaves the buffers to the thread's next band renderer; the values of `acc` only
    /// when they are all zero again (`clean`: as drawing an item leaves them), else none.
    fn drop(&mut self) {
        let mut acc = std::mem::take(&mut self.acc.data);
        // Every drawing reads (and so clears) every row of the deltas it accumulates.
        debug_assert!(
            !self.clean || all_zero(&acc),
            "deltas left in the accumulator"
        );
        if !self.clean {
            acc.clear();
        }
        let kept = BandBuffers {
            acc,
            row: std::mem::take(&mut self.row),
            scratch: std::mem::take(&mut self.scratch),
            overlaps: std::mem::take(&mut self.overlaps),
        };
        BAND_BUFFERS.with(|b| *b.borrow_mut() = kept);
    }
}

/// Whether every value is `±0`: one OR over the bits less the sign, without early exits,
/// which the compiler turns into a few vector instructions.
#[inline]
pub(crate) fn all_zero(v: &[f32]) -> bool {
    v.iter().fold(0u32, |a, &x| a | (x.to_bits() << 1)) == 0
}

/// Whether every value is exactly `1.0`, as [`all_zero`].
#[inline]
pub(crate) fn all_one(v: &[f32]) -> bool {
    v.iter()
        .fold(0u32, |a, &x| a | (x.to_bits() ^ 1.0f32.to_bits()))
        == 0
}

/// Writes the running sum of `deltas` into `out` (as long) and zeroes `deltas` (a `−0`
/// may stay `−0`, which adds nothing to any later sum).
///
/// The sum is taken left to right, one addition per nonzero delta, so its bits are
/// those of the plain sequential sum (adding a zero changes nothing: the sum starts at
/// `+0` and so is never `−0`). Runs of eight zero deltas, the inside and outside of
/// shapes, are stored without the chain of additions, which is what bounds the plain
/// loop's speed.
#[inline]
fn running_sum_clearing(deltas: &mut [f32], out: &mut [f32]) {
    const LANES: usize = 8;
    debug_assert_eq!(deltas.len(), out.len());
    let mut s = 0.0f32;
    let mut chunks = deltas.chunks_exact_mut(LANES);
    let mut outs = out.chunks_exact_mut(LANES);
    for (d, o) in (&mut chunks).zip(&mut outs) {
        if all_zero(d) {
            o.fill(s);
        } else {
            for (c, o) in d.iter_mut().zip(o) {
                s += *c;
                *c = 0.0;
                *o = s;
            }
        }
    }
    for (c, o) in chunks
        .into_remainder()
        .iter_mut()
        .zip(outs.into_remainder())
    {
        s += *c;
        *c = 0.0;
        *o = s;
    }
}

/// Composites one row of `item` onto `dst` from its winding integrals `row`, the row's
/// first pixel being device pixel `(x0, y)`; `covs` and `colors` (as long) are scratch
/// for the coverages and the paint's colors along the row.
#[inline]
pub(crate) fn composite_row(
    item: &Item,
    row: &[f32],
    covs: &mut [f32],
    colors: &mut [[f32; 4]],
    dst: &mut [[f32; 4]],
    x0: usize,
    y: usize,
) {
    let covs = &mut covs[..row.len()];
    coverage_row(row, item.evenodd, covs);
    composite_covs(item, covs, colors, dst, x0, y);
}

/// [`composite_row`] from the row's coverages `covs`.
#[inline]
pub(crate) fn composite_covs(
    item: &Item,
    covs: &[f32],
    colors: &mut [[f32; 4]],
    dst: &mut [[f32; 4]],
    x0: usize,
    y: usize,
) {
    let colors = &mut colors[..covs.len()];
    if let PaintEval::Solid(solid) = &item.paint {
        // One color: no per-pixel position or paint call. Eight pixels at a time, runs
        // outside the shape are skipped and runs of an opaque color fully inside it are
        // stores (`over` gives `s·1 + d·0`, the same bits).
        let s = solid.premul;
        let opaque = s[3] == 1.0;
        // Hidden from the optimizer: knowing the alpha is 1 (from `opaque`), it would
        // store each pixel as three pieces around that constant instead of one.
        let run = std::hint::black_box([s; 8]);
        let mut cc = covs.chunks_exact(8);
        let mut dd = dst.chunks_exact_mut(8);
        for (c, d) in (&mut cc).zip(&mut dd) {
            if all_zero(c) {
                continue;
            }
            if opaque && all_one(c) {
                // From a row of eight colors: whole 16-byte stores (a fill of `s` is split
                // into smaller ones around the known alpha of 1).
                d.copy_from_slice(&run);
                continue;
            }
            for (&cov, d) in c.iter().zip(d) {
                if cov > 0.0 {
                    over(d, s, cov);
                }
            }
        }
        for (&cov, d) in cc.remainder().iter().zip(dd.into_remainder()) {
            if cov > 0.0 {
                over(d, s, cov);
            }
        }
        return;
    }
    let Some((a, b)) = covered_span(covs) else {
        return;
    };
    item.paint.row(x0 + a, y, &mut colors[a..b]);
    for ((&cov, d), s) in covs[a..b].iter().zip(&mut dst[a..b]).zip(&colors[a..b]) {
        if cov > 0.0 {
            over(d, *s, cov);
        }
    }
}

/// The columns `a..b` from the first to the last pixel of a row with coverage above 0,
/// the only ones whose paint is needed; `None` when there is none.
#[inline]
pub(crate) fn covered_span(covs: &[f32]) -> Option<(usize, usize)> {
    let a = covs.iter().position(|&c| c > 0.0)?;
    let b = covs.iter().rposition(|&c| c > 0.0)? + 1;
    Some((a, b))
}

/// A rectangle of pixels `[x0, x0 + w) × [y0, y0 + h)` (device coordinates) stored
/// row-major: a band, or the part of a band a group's layer covers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Area {
    pub(crate) x0: usize,
    pub(crate) y0: usize,
    pub(crate) w: usize,
    pub(crate) h: usize,
}

impl Area {
    /// Index of pixel `(x, y)`, which must lie inside.
    #[inline]
    pub(crate) fn index(&self, x: usize, y: usize) -> usize {
        debug_assert!(x >= self.x0 && x < self.x0 + self.w && y >= self.y0 && y < self.y0 + self.h);
        (y - self.y0) * self.w + (x - self.x0)
    }

    /// Number of pixels.
    pub(crate) fn len(&self) -> usize {
        self.w * self.h
    }
}

/// `d = s·cov + d·(1 − s.a·cov)`, premultiplied.
#[inline]
pub(crate) fn over(d: &mut [f32; 4], s: [f32; 4], cov: f32) {
    let k = 1.0 - s[3] * cov;
    for c in 0..4 {
        d[c] = s[c] * cov + d[c] * k;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Fill, FillRule, Paint, Path};
    use crate::scene::{Node, Scene};

    fn rect_scene(x0: f64, y0: f64, x1: f64, y1: f64, rule: FillRule) -> Scene {
        let mut p = Path::new("r");
        p.move_to([x0, y0]);
        p.line_to([x1, y0]);
        p.line_to([x1, y1]);
        p.line_to([x0, y1]);
        p.close();
        p.fill = Some(Fill {
            paint: Paint::Solid([1.0, 0.0, 0.0]),
            opacity: 1.0,
            rule,
        });
        let mut s = Scene::new(40, 40);
        s.nodes.push(Node::Path(p));
        s
    }

    fn total_alpha(img: &Image) -> f64 {
        img.data.iter().map(|p| p[3] as f64).sum()
    }

    /// [`render_prepared`] without skipping what an opaque background hides.
    fn render_every_op(p: &Prepared) -> Image {
        let (w, h) = (p.width as usize, p.height as usize);
        let mut img = blank_canvas(p.width, p.height);
        for (band, out) in img.data.chunks_mut(w * BAND_ROWS).enumerate() {
            BandRenderer::new(p, band * BAND_ROWS, out.len() / w).run(out, 0, 0);
        }
        assert_eq!(img.data.len(), w * h);
        img
    }

    fn bits(img: &Image) -> Vec<u32> {
        img.data.iter().flatten().map(|v| v.to_bits()).collect()
    }

    #[test]
    fn sparse_solid_rows_have_the_bits_of_whole_rows() {
        let load = |svg: &str| Scene::from_svg_str(svg, "t.svg", crate::Sizing::Natural).unwrap();
        // Widths that are and are not multiples of eight; shapes beyond every side; a
        // frame (sides far apart), even-odd and nonzero windings of 2, strokes, crisp
        // edges, hairlines and translucent colors over each other.
        let body = r##"<rect x="1" y="1" width="198" height="98" fill="none" stroke="black"/>
            <path d="M20 2 L30 98 L4 10 L36 10 L10 98 Z" fill="#4a8" fill-rule="evenodd" opacity="0.8"/>
            <path d="M60 5 h60 v60 h-60 z M70 15 h40 v40 h-40 z" fill="#a48"/>
            <path d="M-10 40 L250 60 L240 120 Z" fill="#48a" fill-opacity="0.5"/>
            <rect x="150.5" y="20" width="30" height="50" fill="teal" shape-rendering="crispEdges"/>
            <path d="M5 90 C60 -40 140 200 195 10" fill="none" stroke="#333" stroke-width="0.3"/>
            <circle cx="100" cy="50" r="40" fill="none" stroke="orange" stroke-width="9" stroke-dasharray="7 3"/>"##;
        for width in [200, 203, 61] {
            let svg = format!(
                r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="100">{body}</svg>"#
            );
            let scene = load(&svg);
            for exact in [false, true] {
                let opts = RenderOptions {
                    exact_overlaps: exact,
                    ..RenderOptions::default()
                };
                let mut p = Prepared::new(&scene, &opts);
                let sparse = render_prepared(&p);
                p.dense_rows = true;
                let dense = render_prepared(&p);
                assert_eq!(bits(&sparse), bits(&dense), "width {width}, exact {exact}");
                assert!(total_alpha(&sparse) > 1000.0);
            }
        }
        for seed in 0..20 {
            let scene = crate::scene::random::curved_paths(30, 64 + seed as u32, seed);
            let mut p = Prepared::new(&scene, &RenderOptions::default());
            let sparse = render_prepared(&p);
            p.dense_rows = true;
            assert_eq!(bits(&sparse), bits(&render_prepared(&p)), "seed {seed}");
        }
    }

    #[test]
    fn starting_after_an_opaque_background_keeps_the_bits() {
        let load = |svg: &str| Scene::from_svg_str(svg, "t.svg", crate::Sizing::Natural).unwrap();
        let wrap = |body: &str| {
            format!(
                r#"<svg xmlns="http://www.w3.org/2000/svg" width="40" height="30">{body}</svg>"#
            )
        };
        let star = r##"<path d="M20 2 L30 28 L4 10 L36 10 L10 28 Z" fill="#4a8" fill-rule="evenodd" opacity="0.8"/>"##;
        // (body, whether the render may start after a background)
        let cases = [
            (
                format!(r#"<rect width="40" height="30" fill="white"/>{star}"#),
                true,
            ),
            (
                format!(r#"{star}<rect x="-5" y="-3" width="60" height="40" fill="teal"/>{star}"#),
                true,
            ),
            (
                format!(r#"<rect width="40" height="30" fill="white" fill-rule="evenodd"/>{star}"#),
                true,
            ),
            (
                format!(r#"<rect width="40" height="30" fill="white" opacity="0.5"/>{star}"#),
                false,
            ),
            (
                format!(
                    r#"{star}<rect width="40" height="30" fill="white" fill-opacity="0.5"/>{star}"#
                ),
                false,
            ),
            (
                format!(r#"<rect x="0.5" width="40" height="30" fill="white"/>{star}"#),
                false,
            ),
            (
                format!(r#"<rect width="39.9" height="30" fill="white"/>{star}"#),
                false,
            ),
            (
                format!(
                    r#"<rect width="40" height="30" fill="white" transform="rotate(1 20 15)"/>{star}"#
                ),
                false,
            ),
            (
                format!(r#"<g opacity="0.5"><rect width="40" height="30" fill="red"/></g>{star}"#),
                false,
            ),
            (
                format!(
                    r#"<g opacity="0.5">{star}</g><rect width="40" height="30" fill="red"/><g opacity="0.7">{star}</g>"#
                ),
                true,
            ),
            (
                format!(r#"<rect width="40" height="30" fill="none" stroke="red"/>{star}"#),
                false,
            ),
        ];
        for (body, skips) in &cases {
            let scene = load(&wrap(body));
            let p = prepare_forward(&scene, 0.02, false);
            assert_eq!(opaque_start(&p).0 > 0, *skips, "{body}");
            assert_eq!(
                bits(&render_prepared(&p)),
                bits(&render_every_op(&p)),
                "{body}"
            );
        }
        // The bundled drawings, most of which have a background.
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("svg-samples");
        let mut started_late = 0;
        for entry in std::fs::read_dir(&dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_none_or(|e| e != "svg") {
                continue;
            }
            let scene = Scene::load(&path, crate::Sizing::Natural).unwrap();
            let p = prepare_forward(&scene, 0.02, false);
            started_late += usize::from(opaque_start(&p).0 > 0);
            assert_eq!(
                bits(&render_prepared(&p)),
                bits(&render_every_op(&p)),
                "{path:?}"
            );
        }
        assert!(started_late >= 8, "{started_late}");
    }

    #[test]
    fn band_buffers_left_by_earlier_bands_change_no_bits() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("svg-samples");
        let scenes: Vec<Scene> = [
            "07-glyph.svg",
            "03-linear-gradient.svg",
            "09-transforms.svg",
        ]
        .iter()
        .map(|f| Scene::load(dir.join(f), crate::Sizing::Natural).unwrap())
        .collect();
        let opts = RenderOptions::default();
        // Each scene on a thread of its own, whose buffers start empty.
        let fresh: Vec<Vec<u32>> = scenes
            .iter()
            .map(|s| std::thread::scope(|t| t.spawn(|| bits(&render(s, &opts))).join().unwrap()))
            .collect();
        // On one thread, after each other, and after a renderer left its winding cells
        // integrated (not zero) when it was dropped.
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        pool.install(|| {
            for _ in 0..2 {
                for (s, want) in scenes.iter().zip(&fresh) {
                    let p = prepare_forward(s, 0.02, false);
                    let item = &p.items[0];
                    let mut r = BandRenderer::new(&p, item.bbox[1].max(0.0) as usize, BAND_ROWS);
                    assert!(r.winding(item));
                    assert!(!all_zero(&r.acc.data));
                    drop(r);
                    assert_eq!(&bits(&render(s, &opts)), want);
                }
            }
        });
    }

    #[test]
    fn pixel_aligned_rect_is_crisp() {
        let img = render(
            &rect_scene(5.0, 5.0, 15.0, 25.0, FillRule::NonZero),
            &RenderOptions::default(),
        );
        assert_eq!(img.get(5, 5), [1.0, 0.0, 0.0, 1.0]);
        assert_eq!(img.get(14, 24), [1.0, 0.0, 0.0, 1.0]);
        assert_eq!(img.get(4, 5)[3], 0.0);
        assert_eq!(img.get(15, 5)[3], 0.0);
        assert!((total_alpha(&img) - 200.0).abs() < 1e-3);
    }

    #[test]
    fn fractional_rect_has_exact_area() {
        let img = render(
            &rect_scene(5.3, 5.25, 15.7, 30.5, FillRule::NonZero),
            &RenderOptions::default(),
        );
        let area = (15.7 - 5.3) * (30.5 - 5.25);
        assert!(
            (total_alpha(&img) - area).abs() < 1e-3,
            "{}",
            total_alpha(&img)
        );
        assert!((img.get(5, 10)[3] - 0.7).abs() < 1e-5);
        assert!((img.get(5, 5)[3] - 0.7 * 0.75).abs() < 1e-5);
    }

    #[test]
    fn shapes_beyond_the_canvas_are_clipped() {
        // Straddles all four edges: only the canvas part counts.
        let img = render(
            &rect_scene(-10.0, -7.5, 50.0, 45.0, FillRule::EvenOdd),
            &RenderOptions::default(),
        );
        assert!((total_alpha(&img) - 1600.0).abs() < 1e-2);
        // Wholly outside.
        let img = render(
            &rect_scene(-30.0, 5.0, -10.0, 15.0, FillRule::NonZero),
            &RenderOptions::default(),
        );
        assert_eq!(total_alpha(&img), 0.0);
    }

    #[test]
    fn running_sums_have_the_bits_of_the_sequential_sum() {
        // Sparse deltas (runs of zeros of every length, ±0, tiny and huge values), rows of
        // every length around the chunk size.
        let mut rng = crate::scene::random::Rng::new(7);
        let mut next = || (rng.next_u64() >> 32) as u32;
        for len in 0..40 {
            for _ in 0..50 {
                let mut deltas: Vec<f32> = (0..len)
                    .map(|_| match next() % 8 {
                        0 => (next() as f32 / u32::MAX as f32) - 0.5,
                        1 => -0.0,
                        2 => 1e-30,
                        3 => -3.0e7,
                        _ => 0.0,
                    })
                    .collect();
                let mut expected = Vec::new();
                let mut s = 0.0f32;
                for &d in &deltas {
                    s += d;
                    expected.push(s.to_bits());
                }
                let mut out = vec![f32::NAN; len];
                running_sum_clearing(&mut deltas, &mut out);
                let got: Vec<u32> = out.iter().map(|v| v.to_bits()).collect();
                assert_eq!(got, expected, "length {len}");
                assert!(deltas.iter().all(|&d| d == 0.0), "deltas cleared");
            }
        }
        assert!(all_zero(&[0.0, -0.0, 0.0]) && !all_zero(&[0.0, 1e-45]));
        assert!(all_one(&[1.0; 8]) && !all_one(&[1.0, 0.99999994]) && !all_one(&[-1.0]));
    }

    #[test]
    fn large_canvases_are_written_zeros_and_render_the_same() {
        // 2048 × 1100 pixels of 16 bytes: above the size whose zeros are written rather
        // than allocated zeroed.
        let (w, h) = (2048u32, 1100u32);
        assert!(w as usize * h as usize * 16 >= 32 << 20);
        let blank = blank_canvas(w, h);
        assert_eq!(
            (blank.width, blank.height, blank.data.len()),
            (w, h, 2048 * 1100)
        );
        assert!(blank.data.iter().all(|p| *p == [0.0; 4]));
        let mut s = rect_scene(100.25, 1000.5, 1900.0, 1090.0, FillRule::NonZero);
        s.width = w;
        s.height = h;
        let img = render(&s, &RenderOptions::default());
        let area = (1900.0 - 100.25) * (1090.0 - 1000.5);
        assert!(
            (total_alpha(&img) - area).abs() < 1e-2,
            "{}",
            total_alpha(&img)
        );
        assert_eq!(img.get(1000, 1050), [1.0, 0.0, 0.0, 1.0]);
        assert_eq!(img.get(1000, 10), [0.0; 4]);
    }

    #[test]
    fn bands_do_not_change_bits_with_threads() {
        let s = rect_scene(3.3, 2.7, 37.1, 38.9, FillRule::NonZero);
        let a = render(&s, &RenderOptions::default());
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let b = pool.install(|| render(&s, &RenderOptions::default()));
        assert_eq!(a.data, b.data);
    }
}
