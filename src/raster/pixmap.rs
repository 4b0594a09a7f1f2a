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
//! the band, solid chunks are converted once and copied; mixed ones pixel by pixel. So the
//! bytes are those of converting [`render_prepared`]'s image (tested), while a drawing of
//! a few big fills writes each byte of the result once, plus a few values per chunk.
//!
//! [`render_prepared`]: super::render_prepared

use rayon::prelude::*;

use super::coverage::{coverage, coverage_row};
use super::layer::composite_layer;
use super::paint::PaintEval;
use super::prepare::{Item, Prepared};
use super::render::{
    Area, BAND_ROWS, BandRenderer, Canvas, all_zero, covered_span, opaque_start, over,
};
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
/// top row first: the same bytes as converting
/// [`render_prepared`](super::render_prepared)'s `f32` image, without holding that image.
pub fn render_rgba8(p: &Prepared, alpha: Alpha) -> Vec<u8> {
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
        for r in 0..self.rows {
            let line = &mut bytes[r * self.w * 4..][..self.w * 4];
            let px = &self.px[r * self.w..][..self.w];
            let solid = &self.solid[r * self.per_row..][..self.per_row];
            let color = &self.color[r * self.per_row..][..self.per_row];
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
    /// from the accumulated deltas (clearing them, as [`BandRenderer::take_row`] does):
    /// over runs of whole chunks without a
    /// delta the winding integral, and so the coverage, is one value, applied chunk by
    /// chunk ([`span`](Self::span)); elsewhere the running sum and the coverage rule go
    /// pixel by pixel, with the same bits as [`coverage_row`].
    fn draw_solid(&mut self, r: &mut BandRenderer<'_>, item: &Item, s: [f32; 4]) {
        let acc = &mut r.acc;
        let (x0, aw) = (acc.x0 as usize, acc.w);
        let cols = aw.min(self.w - x0);
        let band_row0 = acc.y0 as usize - r.y0;
        let end = x0 + cols;
        for k in 0..acc.h {
            let row = band_row0 + k;
            let deltas = &mut acc.data[k * aw..(k + 1) * aw];
            let mut sum = 0.0f32;
            let mut x = x0;
            while x < end {
                if x % CHUNK == 0 {
                    // Four chunks a test while they last (one reduction for 32 values).
                    let mut e = x;
                    while e + 4 * CHUNK <= end && all_zero(&deltas[e - x0..][..4 * CHUNK]) {
                        e += 4 * CHUNK;
                    }
                    while e + CHUNK <= end && all_zero(&deltas[e - x0..][..CHUNK]) {
                        e += CHUNK;
                    }
                    if e > x {
                        let cov = coverage(sum, item.evenodd).0;
                        if cov > 0.0 {
                            self.span(row, x / CHUNK, e / CHUNK, s, cov);
                        }
                        x = e;
                        continue;
                    }
                }
                // Pixel by pixel up to the next chunk boundary.
                let next = ((x / CHUNK + 1) * CHUNK).min(end);
                let mut mixed = false;
                for (i, dv) in deltas[x - x0..next - x0].iter_mut().enumerate() {
                    sum += *dv;
                    *dv = 0.0;
                    let cov = coverage(sum, item.evenodd).0;
                    if cov > 0.0 {
                        if !mixed {
                            self.mix(row, x / CHUNK);
                            mixed = true;
                        }
                        over(&mut self.px[row * self.w + x + i], s, cov);
                    }
                }
                x = next;
            }
            // Columns right of the canvas hold deltas too; leave them cleared.
            deltas[cols..].fill(0.0);
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
    use crate::scene::Scene;

    /// `render_rgba8` against converting the `f32` image, both alpha forms, with and
    /// without exact overlaps.
    fn same_bytes(svg: &str) {
        let scene = Scene::from_svg_str(svg, "t.svg", crate::Sizing::Natural).unwrap();
        for exact_overlaps in [false, true] {
            let opts = RenderOptions {
                exact_overlaps,
                ..RenderOptions::default()
            };
            let p = Prepared::new(&scene, &opts);
            let img = render_prepared(&p);
            assert_eq!(render_rgba8(&p, Alpha::Straight), img.to_rgba8(), "{svg}");
            let premul: Vec<u8> = img.data.iter().flatten().map(|&v| to_u8(v)).collect();
            assert_eq!(render_rgba8(&p, Alpha::Premultiplied), premul, "{svg}");
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
}
