//! Forward rendering straight to 8-bit RGBA, where big opaque fills cost what a memset
//! costs.
//!
//! Each band is drawn into a [`ChunkCanvas`]: the band's `f32` pixels in runs of
//! [`CHUNK`] columns (aligned to the canvas), each run either **solid** (all its pixels one
//! color, held once, the pixels themselves unwritten) or **mixed** (its pixels written).
//! A run of a solid paint that covers all of a chunk stays solid: an opaque one replaces
//! the chunk's color, a translucent one composites onto it once (the `over` of each pixel
//! would give the same bits). Anything else turns the chunk mixed first (its color is
//! written out) and composites pixel by pixel as [`render_prepared`] does. At the end of
//! the band, solid chunks are converted once and copied, mixed ones pixel by pixel, and a
//! row of solid chunks equal to the row above is copied whole. A solid paint reads only
//! the chunks its edges can touch ([`touched_chunks`]); between them its coverage is one
//! value, snapped to an exact 0 or 1 within a few `f32` steps ([`SLACK`]). So the bytes
//! are those of converting [`render_prepared`]'s image (tested; within one level where the
//! snap meets a rounding boundary), while a drawing of a few big fills writes each byte of
//! the result once, plus a few values per chunk, and a row costs its edges, not its width.
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
    let mut out = vec![0u8; w * h * 4];
    if w == 0 || h == 0 {
        return out;
    }
    out.par_chunks_mut(w * 4 * BAND_ROWS)
        .with_min_len(p.min_bands_per_task())
        .enumerate()
        .for_each(|(band, bytes)| {
            let rows = bytes.len() / (4 * w);
            BAND_CANVAS.with(|canvas| {
                let mut canvas = canvas.borrow_mut();
                canvas.reset(w, rows, fill);
                canvas.slack = slack;
                BandRenderer::new(p, band * BAND_ROWS, rows).run(&mut *canvas, start, group);
                canvas.write_bytes(bytes, alpha);
            });
        });
    out
}

thread_local! {
    /// [`render_rgba8`]'s band canvas, kept from one band to the next.
    static BAND_CANVAS: std::cell::RefCell<ChunkCanvas> =
        std::cell::RefCell::new(ChunkCanvas::default());
}

/// One band's pixels in chunks that are solid or mixed (see the module's documentation).
#[derive(Default)]
pub(crate) struct ChunkCanvas {
    /// Columns and rows.
    w: usize,
    rows: usize,
    /// Chunks per row.
    per_row: usize,
    /// Pixels, row-major; valid only in mixed chunks.
    px: Vec<[f32; 4]>,
    /// Per chunk, row-major: its color when solid.
    color: Vec<[f32; 4]>,
    /// Per chunk: whether it is solid.
    solid: Vec<bool>,
    /// Scratch for [`touched_chunks`].
    touched: Vec<(u32, u32, u32)>,
    /// How far from 0 or 1 a run's coverage may be and count as 0 or 1 ([`snap_run`]).
    slack: f32,
}

impl ChunkCanvas {
    /// A `w × rows` band of one color.
    fn reset(&mut self, w: usize, rows: usize, fill: [f32; 4]) {
        self.w = w;
        self.rows = rows;
        self.per_row = w.div_ceil(CHUNK);
        let n = self.per_row * rows;
        // The pixels keep whatever they held: every chunk is solid, so none is read.
        self.px.resize(w * rows, [0.0; 4]);
        self.color.clear();
        self.color.resize(n, fill);
        self.solid.clear();
        self.solid.resize(n, true);
    }

    /// Writes chunk `k` of row `r` out as pixels, if it is solid, and marks it mixed.
    #[inline]
    fn mix(&mut self, r: usize, k: usize) {
        let c = r * self.per_row + k;
        if self.solid[c] {
            self.solid[c] = false;
            let x0 = k * CHUNK;
            let x1 = (x0 + CHUNK).min(self.w);
            self.px[r * self.w + x0..r * self.w + x1].fill(self.color[c]);
        }
    }

    /// Marks every chunk of `area` (band-relative rows) mixed.
    fn mix_area(&mut self, x0: usize, x1: usize, r0: usize, r1: usize) {
        for r in r0..r1 {
            for k in x0 / CHUNK..x1.div_ceil(CHUNK) {
                self.mix(r, k);
            }
        }
    }

    /// Converts the band to bytes (`w × rows × 4`).
    fn write_bytes(&self, bytes: &mut [u8], alpha: Alpha) {
        let n = self.per_row;
        for r in 0..self.rows {
            let solid = &self.solid[r * n..][..n];
            let color = &self.color[r * n..][..n];
            // A row of solid chunks with the colors of the row above, itself all solid (the
            // inside of a flag's stripe): the same bytes, copied.
            if r > 0
                && !solid.contains(&false)
                && !self.solid[(r - 1) * n..][..n].contains(&false)
                && same_bits(color, &self.color[(r - 1) * n..][..n])
            {
                let row_bytes = self.w * 4;
                bytes.copy_within((r - 1) * row_bytes..r * row_bytes, r * row_bytes);
                continue;
            }
            let line = &mut bytes[r * self.w * 4..][..self.w * 4];
            let px = &self.px[r * self.w..][..self.w];
            let mut k = 0;
            while k < self.per_row {
                let (x0, x1) = (k * CHUNK, ((k + 1) * CHUNK).min(self.w));
                if solid[k] {
                    // A run of solid chunks of one color: its bytes once, then copies.
                    let bits = color[k].map(f32::to_bits);
                    let mut e = k + 1;
                    while e < self.per_row && solid[e] && color[e].map(f32::to_bits) == bits {
                        e += 1;
                    }
                    let b = alpha.bytes(color[k]);
                    let run: [u8; 4 * CHUNK] = std::array::from_fn(|i| b[i % 4]);
                    let out = &mut line[x0 * 4..(e * CHUNK).min(self.w) * 4];
                    let mut whole = out.chunks_exact_mut(4 * CHUNK);
                    for o in &mut whole {
                        o.copy_from_slice(&run);
                    }
                    let rest = whole.into_remainder();
                    rest.copy_from_slice(&run[..rest.len()]);
                    k = e;
                    continue;
                }
                let out = &mut line[x0 * 4..x1 * 4];
                if alpha == Alpha::Premultiplied {
                    // Channel by channel over flat slices: vector instructions.
                    for (o, &f) in out.iter_mut().zip(px[x0..x1].as_flattened()) {
                        *o = to_u8(f);
                    }
                } else {
                    for (o, &c) in out.chunks_exact_mut(4).zip(&px[x0..x1]) {
                        o.copy_from_slice(&straight_rgba8(c));
                    }
                }
                k += 1;
            }
        }
    }

    /// Composites the whole chunks `k0..k1` of band row `row` with one solid color `s` at
    /// one coverage `cov > 0`.
    fn span(&mut self, row: usize, k0: usize, k1: usize, s: [f32; 4], cov: f32) {
        let (c0, c1) = (row * self.per_row + k0, row * self.per_row + k1);
        if cov == 1.0 && s[3] == 1.0 {
            self.color[c0..c1].fill(s);
            self.solid[c0..c1].fill(true);
            return;
        }
        for k in k0..k1 {
            let c = row * self.per_row + k;
            if cov == 1.0 && self.solid[c] {
                over(&mut self.color[c], s, 1.0);
                continue;
            }
            self.mix(row, k);
            for p in &mut self.px[row * self.w + k * CHUNK..][..CHUNK] {
                over(p, s, cov);
            }
        }
    }

    /// Draws a solid-paint item's rows (without cells of exact overlap coverage) straight
    /// from the accumulated deltas (clearing them, as [`BandRenderer::take_row`] does).
    ///
    /// Only the chunks an edge can have touched ([`touched_chunks`]) are read, pixel by
    /// pixel, with the running sum and the coverage rule of [`coverage_row`] (the same
    /// bits); such a chunk whose pixels all get one coverage is still drawn as a chunk
    /// ([`span`](Self::span), the same bits as pixel by pixel). Between them the winding
    /// integral, and so the coverage, is one value over the whole stretch
    /// ([`stretch`](Self::stretch)). So a row of a big fill costs its edges, not its width.
    fn draw_solid(&mut self, r: &mut BandRenderer<'_>, item: &Item, s: [f32; 4]) {
        let acc = &mut r.acc;
        let (x0, aw) = (acc.x0 as usize, acc.w);
        let cols = aw.min(self.w - x0);
        let band_row0 = acc.y0 as usize - r.y0;
        let end = x0 + cols;
        let mut touched = std::mem::take(&mut self.touched);
        touched_chunks(item, acc, self.w, &mut touched);
        let mut next = touched.iter().peekable();
        let mut covs = [0.0f32; CHUNK];
        for k in 0..acc.h {
            let row = band_row0 + k;
            let deltas = &mut acc.data[k * aw..(k + 1) * aw];
            let mut sum = 0.0f32;
            let mut x = x0;
            while let Some(&(_, ka, kb)) = next.next_if(|t| t.0 as usize == k) {
                let (lo, hi) = ((ka as usize * CHUNK).max(x), (kb as usize * CHUNK).min(end));
                if lo >= hi {
                    continue;
                }
                self.stretch(
                    row,
                    x,
                    lo,
                    s,
                    snap_run(coverage(sum, item.evenodd).0, self.slack),
                );
                let mut a = lo;
                while a < hi {
                    let b = ((a / CHUNK + 1) * CHUNK).min(hi);
                    let n = b - a;
                    // The running sum is a chain of dependent additions: run it only up
                    // to the chunk's last delta; past it the coverage holds.
                    let ds = &mut deltas[a - x0..b - x0];
                    let m = ds.iter().rposition(|&d| d != 0.0).map_or(0, |j| j + 1);
                    for (c, dv) in covs.iter_mut().zip(&mut ds[..m]) {
                        sum += *dv;
                        *dv = 0.0;
                        *c = coverage(sum, item.evenodd).0;
                    }
                    covs[m..n].fill(coverage(sum, item.evenodd).0);
                    if n == CHUNK && covs.iter().all(|c| c.to_bits() == covs[0].to_bits()) {
                        if covs[0] > 0.0 {
                            self.span(row, a / CHUNK, a / CHUNK + 1, s, covs[0]);
                        }
                    } else {
                        for (i, &cov) in covs[..n].iter().enumerate() {
                            if cov > 0.0 {
                                self.mix(row, a / CHUNK);
                                over(&mut self.px[row * self.w + a + i], s, cov);
                            }
                        }
                    }
                    a = b;
                }
                x = hi;
            }
            self.stretch(
                row,
                x,
                end,
                s,
                snap_run(coverage(sum, item.evenodd).0, self.slack),
            );
            // Columns right of the canvas hold deltas too; leave them cleared.
            deltas[cols..].fill(0.0);
        }
        self.touched = touched;
    }

    /// Composites columns `xa..xb` of band row `row` with one solid color `s` at one
    /// coverage `cov`: whole chunks with [`span`](Self::span), the ends pixel by pixel.
    fn stretch(&mut self, row: usize, xa: usize, xb: usize, s: [f32; 4], cov: f32) {
        if cov <= 0.0 || xa >= xb {
            return;
        }
        let (ka, kb) = (xa.div_ceil(CHUNK), xb / CHUNK);
        let (pa, pb) = if ka < kb {
            self.span(row, ka, kb, s, cov);
            ((xa, ka * CHUNK), (kb * CHUNK, xb))
        } else {
            ((xa, xb), (xb, xb))
        };
        for x in (pa.0..pa.1).chain(pb.0..pb.1) {
            self.mix(row, x / CHUNK);
            over(&mut self.px[row * self.w + x], s, cov);
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
        self.mix_area(xa, xb, r, r + 1);
        item.paint.row(xa, y, &mut colors[a..b]);
        let dst = &mut self.px[r * self.w + xa..r * self.w + xb];
        for ((&cov, d), s) in covs[a..b].iter().zip(dst).zip(&colors[a..b]) {
            if cov > 0.0 {
                over(d, *s, cov);
            }
        }
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
        let slope = (c[0] - a[0]) / (c[1] - a[1]);
        let x_at = |y: f64| a[0] + (y - a[1]) * slope;
        let r1 = ceil_f64(c[1].min(yhi));
        let mut y = floor_f64(a[1].max(ylo));
        while y < r1 {
            let (ya, yb) = (y.max(a[1]), (y + 1.0).min(c[1]));
            let (xa, xb) = (x_at(ya).clamp(0.0, xmax), x_at(yb).clamp(0.0, xmax));
            let lo = (floor_f64(xa.min(xb)) - 1.0).max(first);
            let hi = (floor_f64(xa.max(xb)) + 3.0).min(last);
            if lo < hi {
                let (ka, kb) = (floor_f64(lo / chunk), ceil_f64(hi / chunk));
                out.push(((y - ylo) as u32, ka as u32, kb as u32));
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

/// Whether two rows of colors hold the same bits: one OR over the differences, without
/// early exits, which the compiler turns into vector instructions (as
/// [`all_zero`](super::render::all_zero)).
fn same_bits(a: &[[f32; 4]], b: &[[f32; 4]]) -> bool {
    a.as_flattened()
        .iter()
        .zip(b.as_flattened())
        .fold(0u32, |acc, (x, y)| acc | (x.to_bits() ^ y.to_bits()))
        == 0
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

impl Canvas for ChunkCanvas {
    fn draw(&mut self, r: &mut BandRenderer<'_>, item: &Item, _area: Area) {
        if !r.deltas(item) {
            return;
        }
        if let PaintEval::Solid(solid) = &item.paint
            && r.overlaps.is_empty()
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
