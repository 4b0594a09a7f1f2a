//! The backward pass: from `∂L/∂image` to the gradient of every scene parameter.
//!
//! Each row band is handled on its own, in parallel:
//!
//! 1. **Render, recording.** The band is rendered, keeping for every drawn item the color
//!    *below* it and its coverage and coverage slopes over the cells an edge touches or the
//!    shape covers, and for every group layer its content and the color below it. Memory
//!    per band grows with the widths of the shapes crossing it, not with the number of
//!    shapes times the canvas. With a per-pixel loss ([`render_and_backward_fused`]) this
//!    *is* the forward pass: the band's loss gradient is taken right after, while the
//!    record is in cache; otherwise ([`render_backward`]) the band's `∂L/∂pixel` comes from
//!    an image computed before.
//! 2. **Reverse walk.** The program is walked backwards. Source-over
//!    `out = s·cov + d·(1 − s_a·cov)` gives `∂L/∂cov`, `∂L/∂s` and `∂L/∂d` per pixel; the
//!    last is what the items below see (the transmittance walked top-down).
//! 3. **Boundary.** `∂L/∂cov` times the coverage rule's derivative is the gradient with
//!    respect to each pixel's winding integral; [`backward_line`] turns it into exact
//!    gradients of the polygon vertices (Reynolds transport over each edge piece in each
//!    pixel, no sampling).
//!
//! Per-band partial sums are added in band order, so the result has the same bits for any
//! number of threads. Vertex gradients then flow back through the stroke recipes, dashes,
//! stroke frame and flattening weights to the control points, laid out like
//! [`Scene::params`].
//!
//! Held fixed (piecewise constant in the parameters): chord counts, the number of round
//! join/cap vertices, which join style applies, and where dashes are cut (as blends of a
//! chord's vertices).

use rayon::prelude::*;

use super::coverage::{Cells, backward_line, coverage_row, coverage_slopes_row};
use super::filter::{self, FilterLayer};
use super::layer::{apply_mask, apply_mask_backward, composite_backward, composite_layer};
use super::overlap::{Overlaps, Portion, portion_weight};
use super::paint::PaintEval;
use super::prepare::{ItemKind, Op, Prepared, item_rect, prepare, stroke_outline};
use super::render::{
    Area, BAND_ROWS, BandRenderer, RenderOptions, RowScratch, blank_canvas, covered_span, over,
};
use super::stroke::NONE;
use crate::image_io::Image;
use crate::scene::params::join_closing_gradients;
use crate::scene::{BlendMode, MaskKind, ParamLayout, Path, Point, Scene};

/// Renders `scene` once and returns the image, the loss and its gradient with respect to
/// every parameter. `loss` receives the rendered image (premultiplied RGBA) and returns the
/// loss and `∂L/∂image`.
pub fn render_and_backward(
    scene: &Scene,
    opts: &RenderOptions,
    loss: impl FnOnce(&Image) -> (f64, Image),
) -> (Image, f64, Vec<f64>) {
    let prepared = Prepared::new(scene, opts);
    let img = super::render::render_prepared(&prepared);
    let (l, d) = loss(&img);
    let g = backward_prepared(scene, &prepared, &d);
    (img, l, g)
}

/// The gradient of a loss with respect to every parameter of `scene` (in
/// [`Scene::params`] order), given `d_image = ∂L/∂image`.
pub fn render_backward(scene: &Scene, opts: &RenderOptions, d_image: &Image) -> Vec<f64> {
    backward_prepared(scene, &Prepared::new(scene, opts), d_image)
}

/// [`render_backward`] after [`check_backward_memory`], preparing the scene once for both:
/// an error naming `name` instead of an allocation the machine may not have.
pub fn render_backward_checked(
    scene: &Scene,
    opts: &RenderOptions,
    d_image: &Image,
    name: &std::path::Path,
) -> crate::Result<Vec<f64>> {
    let p = Prepared::new(scene, opts);
    check_prepared(&p, name)?;
    Ok(backward_prepared(scene, &p, d_image))
}

/// Replay records the bands computed at once may hold together, in bytes, by an upper
/// estimate from the boxes of the items and layers in each band; one band always runs.
pub(crate) const TAPE_BUDGET_BYTES: usize = 256 << 20;

/// Refuses a scene whose backward pass would record more than
/// [`MAX_BAND_RECORD_BYTES`](crate::limits::MAX_BAND_RECORD_BYTES) for a single row band,
/// by the same upper estimate the pass uses to schedule its bands (every cell of every
/// item's box in the band). Bands run one at a time at worst, so this bounds the pass's
/// memory by the work one band asks for: 20,000 copies of one shape stacked at 128² ask
/// for gigabytes. Call it before fitting or differentiating; rendering alone needs no
/// record. `name` is the file named in the error.
pub fn check_backward_memory(
    scene: &Scene,
    opts: &RenderOptions,
    name: &std::path::Path,
) -> crate::Result<()> {
    check_prepared(&prepare(scene, opts.tolerance, None), name)
}

/// [`check_backward_memory`] on a prepared scene.
fn check_prepared(p: &Prepared, name: &std::path::Path) -> crate::Result<()> {
    use crate::limits::MAX_BAND_RECORD_BYTES;
    let bands = (p.height as usize).div_ceil(BAND_ROWS);
    let worst = tape_estimates(p, bands).into_iter().max().unwrap_or(0);
    if worst > MAX_BAND_RECORD_BYTES {
        return Err(crate::Error::Unsupported {
            path: name.to_path_buf(),
            what: format!(
                "too complex to differentiate: the backward pass would record about {} MiB \
                 for one band of {BAND_ROWS} rows (shapes stacked deep there), above the \
                 limit of {} MiB",
                worst >> 20,
                MAX_BAND_RECORD_BYTES >> 20
            ),
        });
    }
    Ok(())
}

/// Upper estimate of each band's replay record, in bytes: every cell of every item's box
/// in the band, and two colors per pixel of every layer's box.
fn tape_estimates(p: &Prepared, bands: usize) -> Vec<usize> {
    let mut est = vec![0usize; bands];
    let mut add = |r: [usize; 4], per_pixel: usize| {
        let cols = r[2] - r[0] + 2;
        for (b, e) in est
            .iter_mut()
            .enumerate()
            .take((r[3] - 1) / BAND_ROWS + 1)
            .skip(r[1] / BAND_ROWS)
        {
            let rows = (r[3].min((b + 1) * BAND_ROWS)).saturating_sub(r[1].max(b * BAND_ROWS));
            *e = e.saturating_add(rows * cols * per_pixel);
        }
    };
    for it in &p.items {
        if let Some(r) = item_rect(it.bbox, p.width, p.height) {
            add(r, std::mem::size_of::<TapeCell>());
        }
    }
    for g in &p.groups {
        if let Some(r) = g.rect {
            add(r, 32);
        }
    }
    est
}

/// Gradients of one band.
#[derive(Default)]
struct BandGrads {
    /// `(vertex, ∂L/∂vertex)` in the order found, item after item (one flat list: no
    /// allocation per item and band).
    verts: Vec<(u32, Point)>,
    /// The touched items, in the order found (each once), with where their vertex
    /// gradients start in `verts` (they run to the next item's start) and their paint
    /// gradients ([`PaintEval::grad_len`](super::paint::PaintEval::grad_len) values) in
    /// `paint_vals`.
    touched: Vec<Touched>,
    /// The paint gradients of `touched`, back to back.
    paint_vals: Vec<f64>,
    /// Per group: ∂L/∂opacity.
    groups: Vec<(u32, f64)>,
    /// Per filtered layer drawn in this band: `(filter, area, ∂L/∂layer)`.
    filters: Vec<(usize, Area, Vec<[f32; 4]>)>,
    /// Bytes the replay kept for this band.
    tape_bytes: usize,
    /// The loss's partial sums over this band.
    sums: [f64; 2],
}

/// One item's share of a band's gradients ([`BandGrads::touched`]).
#[derive(Clone, Copy)]
struct Touched {
    item: u32,
    verts: u32,
    paint: u32,
}

/// Memory use of a backward pass.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BackwardStats {
    /// Largest replay record of one band, in bytes.
    pub band_bytes_max: usize,
    /// Bands held at once (a chunk processed in parallel).
    pub bands_in_flight: usize,
}

impl BackwardStats {
    /// Upper bound of the extra memory the replay needs at once, in bytes.
    pub fn peak_bytes(&self) -> usize {
        self.band_bytes_max * self.bands_in_flight
    }
}

thread_local! {
    /// Each worker's record of cells, reused from band to band (and step to step): a
    /// fresh one per band cost allocations, copies as it grew, and page faults.
    static TAPE_CELLS: std::cell::RefCell<Vec<TapeCell>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// Largest record of cells a worker keeps between bands, bytes.
const KEEP_CELL_BYTES: usize = 32 << 20;

/// One pixel of a drawn item kept by the replay.
#[derive(Clone, Copy)]
struct TapeCell {
    /// Column in the item's box (below `MAX_SIDE` + 2).
    col: u16,
    /// Row in the item's box (below `BAND_ROWS`).
    row: u16,
    /// Coverage.
    cov: f32,
    /// One-sided slopes of the coverage rule at the winding integral (−1, 0 or 1).
    up: i8,
    down: i8,
    /// Whether the coverage is exact ([`overlap`](super::overlap)): the gradient goes
    /// through the cell's portions, not its slopes.
    exact: bool,
    /// Color below the item.
    below: [f32; 4],
}

/// What the replay kept for the reverse walk.
enum Rec {
    Draw {
        item: usize,
        /// The item's box in this band (with guard columns), as `Cells` without data.
        acc: Cells<f32>,
        /// The range of the band's record of cells that take part in the reverse walk, in
        /// row-major order: only those with coverage or a coverage slope (an edge passes),
        /// so that memory follows the pixels a shape's boundary and interior cover, not
        /// its box.
        cells: std::ops::Range<usize>,
        /// The range of the band's exact cells ([`ExactRec`]) of this item.
        exact: std::ops::Range<usize>,
    },
    Push,
    /// A filtered group's layer (its index in [`Prepared::filters`]) was opened, filled.
    PushFilter(usize),
    Pop {
        group: Option<usize>,
        opacity: f32,
        blend: BlendMode,
        /// The layer, over `area`.
        top: Vec<[f32; 4]>,
        /// The color below it, over `area` only (elsewhere the layer is transparent).
        below: Vec<[f32; 4]>,
        area: Area,
    },
    PushMask,
    /// A mask layer multiplied the layer below it.
    PopMask {
        kind: MaskKind,
        /// The mask layer, over `mask_area`.
        mask: Vec<[f32; 4]>,
        mask_area: Area,
        /// The masked layer before masking, over its own area.
        content: Vec<[f32; 4]>,
    },
    /// A mask drawing nothing in this band made the layer below it transparent.
    ZeroMask,
}

/// A cell of exact coverage kept by the replay: its winding level and its portions, a
/// range of the band's record of portions.
#[derive(Clone, Copy)]
struct ExactRec {
    w0: i32,
    portions: (u32, u32),
}

/// Like [`render_backward`], reusing a prepared scene (which must come from `scene`).
pub(crate) fn backward_prepared(scene: &Scene, p: &Prepared, d_image: &Image) -> Vec<f64> {
    backward_with_stats(scene, p, d_image).0
}

/// `backward_prepared`, also reporting memory use.
pub fn backward_with_stats(
    scene: &Scene,
    p: &Prepared,
    d_image: &Image,
) -> (Vec<f64>, BackwardStats) {
    assert_eq!(
        (d_image.width, d_image.height),
        (p.width, p.height),
        "gradient image size must match the canvas"
    );
    let mut out = device_backward(scene, p, d_image);
    crate::scene::params::parameter_gradient(scene, &mut out.grad, &out.frames);
    (out.grad, out.stats)
}

/// [`backward_with_stats`] before the gradient is carried into the frames of transformed
/// groups ([`chain_gradient`](crate::scene::transform::chain_gradient)): every slot's
/// gradient is that of its device value. A filtered layer's content is differentiated so,
/// its slots being part of the whole scene's, which is chained once.
fn device_backward(scene: &Scene, p: &Prepared, d_image: &Image) -> BandsOut {
    let w = p.width as usize;
    backward_bands(scene, p, None, &|y0, rows, _| {
        (d_image.data[y0 * w..(y0 + rows) * w].to_vec(), [0.0; 2])
    })
}

/// A loss that is a sum of per-pixel terms, so that it can be evaluated one row band at a
/// time inside the backward pass ([`render_and_backward_fused`]).
pub trait BandLoss: Sync {
    /// Given the rows `y0 .. y0 + rendered.len() / width` of the rendering (premultiplied,
    /// the canvas's full width, row-major), writes `∂L/∂pixel` into `d_out` (same length,
    /// zero on entry) and returns the band's partial sums (two quantities of the loss's
    /// choosing, e.g. the loss and the MSE), which are added up in band order.
    fn band(&self, y0: usize, rendered: &[[f32; 4]], d_out: &mut [[f32; 4]]) -> [f64; 2];
}

/// What [`render_and_backward_fused`] returns.
#[derive(Clone, Debug)]
pub struct Fused {
    /// The rendering, premultiplied.
    pub image: Image,
    /// The loss's partial sums, added in band order.
    pub sums: [f64; 2],
    /// The gradient, in [`Scene::params`] order.
    pub grad: Vec<f64>,
    /// Memory use of the pass.
    pub stats: BackwardStats,
}

/// Renders `p` (prepared from `scene` for the backward pass) and takes the gradient of a
/// per-pixel loss in one pass per row band: each band is rendered, its pixels' loss
/// gradient taken, and its backward pass run while the band's record is still in cache.
/// No second rendering and no whole-image record; the sums and the gradient have the
/// same bits for any number of threads, and equal those of
/// [`render_prepared`](super::render_prepared) followed by the loss and
/// [`backward_with_stats`].
pub fn render_and_backward_fused(scene: &Scene, p: &Prepared, loss: &dyn BandLoss) -> Fused {
    let mut image = blank_canvas(p.width, p.height);
    let out = backward_bands(scene, p, Some(&mut image), &|y0, _, rendered| {
        let mut d = vec![[0.0f32; 4]; rendered.len()];
        let sums = loss.band(y0, rendered, &mut d);
        (d, sums)
    });
    let mut grad = out.grad;
    crate::scene::params::parameter_gradient(scene, &mut grad, &out.frames);
    Fused {
        image,
        sums: out.sums,
        grad,
        stats: out.stats,
    }
}

/// Gradients beside the parameter vector's, by slot, for `chain_gradient`: a stroke
/// frame's `∂L/∂[a, b, c, d]` (then two zeros) at its width slot, a primitive's
/// ([`Primitive::frame`](crate::scene::Primitive::frame)) at its first slot, and a radial
/// gradient paint's transform terms (`PaintEval::transform_len`) at its first slot.
pub(crate) type SideGrads = Vec<(usize, [f64; 6])>;

/// The result of [`backward_bands`].
struct BandsOut {
    grad: Vec<f64>,
    stats: BackwardStats,
    sums: [f64; 2],
    /// The gradients of stroke frames and radial paints' transforms, where the scene has
    /// transform parameters ([`SideGrads`]).
    frames: SideGrads,
}

/// `∂L/∂pixel` of one band from its rendering: `(y0, rows, rendered) → (d_out, sums)`.
type BandGradient<'a> = dyn Fn(usize, usize, &[[f32; 4]]) -> (Vec<[f32; 4]>, [f64; 2]) + Sync + 'a;

/// The backward pass over every band: each band is rendered (into `image` when given),
/// `d_of` gives its pixels' gradient, and its reverse walk runs at once.
fn backward_bands(
    scene: &Scene,
    p: &Prepared,
    image: Option<&mut Image>,
    d_of: &BandGradient<'_>,
) -> BandsOut {
    assert!(
        p.for_backward,
        "the backward pass needs a scene made by prepare, not prepare_forward"
    );
    let (w, h) = (p.width as usize, p.height as usize);
    let layout = ParamLayout::new(scene);
    let mut grad = vec![0.0; layout.len()];
    let mut stats = BackwardStats::default();
    let mut sums = [0.0f64; 2];
    if w == 0 || h == 0 {
        return BandsOut {
            grad,
            stats,
            sums,
            frames: Vec::new(),
        };
    }
    let mut image = image.map(|img| img.data.as_mut_slice());
    let mut vert_g: Vec<Vec<Point>> = p
        .items
        .iter()
        .map(|it| vec![[0.0; 2]; it.pts.len()])
        .collect();
    let mut paint_g: Vec<Vec<f64>> = p
        .items
        .iter()
        .map(|it| vec![0.0; it.paint.grad_len()])
        .collect();
    let mut group_g: Vec<f64> = vec![0.0; layout.groups.len()];
    // Per filtered layer: ∂L/∂layer over its rect, gathered from the bands.
    let mut filter_g: Vec<Option<Vec<[f32; 4]>>> = vec![None; p.filters.len()];
    let bands = h.div_ceil(BAND_ROWS);
    // Bands are computed in parallel a chunk at a time and summed strictly in band order.
    // A chunk holds at most 4 bands per thread, and no more than `TAPE_BUDGET_BYTES` of
    // replay records by an estimate from the items' and layers' boxes (one band at least).
    let est = tape_estimates(p, bands);
    let max_chunk = 4 * rayon::current_num_threads().max(1);
    let mut first = 0;
    while first < bands {
        let (mut end, mut sum) = (first + 1, est[first]);
        while end < bands && end - first < max_chunk && sum + est[end] <= TAPE_BUDGET_BYTES {
            sum += est[end];
            end += 1;
        }
        stats.bands_in_flight = stats.bands_in_flight.max(end - first);
        let run = |b: usize, base: &mut [[f32; 4]]| {
            let y0 = b * BAND_ROWS;
            let rows = BAND_ROWS.min(h - y0);
            band_backward(p, y0, rows, base, d_of)
        };
        let results: Vec<BandGrads> = match image.as_deref_mut() {
            Some(img) => img[first * BAND_ROWS * w..(end * BAND_ROWS).min(h) * w]
                .par_chunks_mut(BAND_ROWS * w)
                .enumerate()
                .map(|(k, base)| run(first + k, base))
                .collect(),
            None => (first..end)
                .into_par_iter()
                .map(|b| {
                    let rows = BAND_ROWS.min(h - b * BAND_ROWS);
                    run(b, &mut vec![[0.0f32; 4]; rows * w])
                })
                .collect(),
        };
        first = end;
        for r in &results {
            stats.band_bytes_max = stats.band_bytes_max.max(r.tape_bytes);
            sums[0] += r.sums[0];
            sums[1] += r.sums[1];
            for &(g, v) in &r.groups {
                group_g[g as usize] += v;
            }
            for (f, a, g) in &r.filters {
                let rect = p.filters[*f].rect;
                let rw = rect[2] - rect[0];
                let dst =
                    filter_g[*f].get_or_insert_with(|| vec![[0.0; 4]; rw * (rect[3] - rect[1])]);
                for row in 0..a.h {
                    let at = (a.y0 + row - rect[1]) * rw + (a.x0 - rect[0]);
                    dst[at..at + a.w].copy_from_slice(&g[row * a.w..][..a.w]);
                }
            }
        }
        add_band_grads(&results, &mut vert_g, &mut paint_g);
    }
    // A path's parameters are one run of slots, apart from every other path's: the
    // gradient splits into the paths' runs, and paths are scattered in parallel (each
    // path's items in order, so the bits are those of one loop over the items).
    let mut paths: Vec<&Path> = Vec::new();
    scene.for_each_path(|q| paths.push(q));
    let blocks = path_blocks(&layout, paths.len());
    let mut items_of = vec![0..0; paths.len()];
    for (ii, item) in p.items.iter().enumerate() {
        let r = &mut items_of[item.path];
        if r.start == r.end {
            *r = ii..ii + 1;
        } else {
            debug_assert_eq!(r.end, ii, "a path's items are consecutive");
            r.end = ii + 1;
        }
    }
    let mut rest: &mut [f64] = &mut grad;
    let mut at = 0;
    let mut jobs = Vec::with_capacity(paths.len());
    for (pi, block) in blocks.iter().enumerate() {
        let tail = std::mem::take(&mut rest).split_at_mut(block.start - at).1;
        let (mine, tail) = tail.split_at_mut(block.len());
        jobs.push((
            pi,
            Block {
                base: block.start,
                g: mine,
            },
        ));
        rest = tail;
        at = block.end;
    }
    // The stroke frames' gradients, by width slot, for the transforms' chain
    // (`chain_gradient`): only where a transform can carry them.
    let want_frames = crate::scene::transform::any(&scene.nodes);
    let sides = jobs.into_par_iter().map(|(pi, mut block)| {
        let (path, off) = (paths[pi], &layout.paths[pi]);
        let mut frame_g = [0.0; 4];
        let mut maps = Vec::new();
        // A primitive's outline points are no slots: their gradient is chained to the
        // primitive's parameters once the path's items are summed.
        let mut outline_g = path
            .primitive
            .as_ref()
            .map(|_| vec![0.0; 2 * path.points.len()]);
        for ii in items_of[pi].clone() {
            scatter_item(
                p,
                ii,
                path,
                off,
                &vert_g,
                &paint_g,
                &mut block,
                outline_g.as_deref_mut(),
                &mut frame_g,
                &mut maps,
            );
        }
        match (&path.primitive, outline_g) {
            (Some(prim), Some(g)) => {
                let [a, b, c, d] = prim.chain(&g, &mut block.g[off.points - block.base..]);
                // A primitive's frame (a general group transform's map), keyed by its
                // first slot.
                if want_frames {
                    maps.push((off.points, [a, b, c, d, 0.0, 0.0]));
                }
            }
            _ => join_closing_gradients(path, off.points - block.base, block.g),
        }
        if want_frames && off.stroke.is_some() && frame_g != [0.0; 4] {
            let [a, b, c, d] = frame_g;
            maps.push((off.stroke_width, [a, b, c, d, 0.0, 0.0]));
        }
        if !want_frames {
            maps.clear();
        }
        maps
    });
    let mut frames: SideGrads = sides.flatten().collect();
    for (g, v) in group_g.iter().enumerate() {
        grad[layout.groups[g]] += v;
    }
    for (fl, g) in p.filters.iter().zip(filter_g) {
        if let Some(g) = g {
            filter_backward(p, fl, g, &layout, &mut grad, &mut frames);
        }
    }
    BandsOut {
        grad,
        stats,
        sums,
        frames,
    }
}

/// Adds to `grad` the gradient of a filtered layer's filters and children, given
/// `∂L/∂layer` over its rect: back through the filters (whose parameters are the slots
/// after the group's opacity), then through the children's own backward pass (whose
/// parameters follow the filters').
fn filter_backward(
    p: &Prepared,
    fl: &FilterLayer,
    g: Vec<[f32; 4]>,
    layout: &ParamLayout,
    grad: &mut [f64],
    frames: &mut SideGrads,
) {
    let (w, h) = (p.width as usize, p.height as usize);
    let opts = RenderOptions {
        tolerance: p.tolerance,
        exact_overlaps: p.exact_overlaps,
        exact_filters: p.exact_filters,
    };
    let src = super::render::render(&fl.content, &opts);
    let crop = filter::crop(&src.data, w, fl.rect);
    let (g_src, g_params) = filter::adjoint(&fl.filters, fl.rect, crop, g, p.exact_filters);
    let mut d = Image::new(w as u32, h as u32);
    let rw = fl.rect[2] - fl.rect[0];
    for (row, y) in (fl.rect[1]..fl.rect[3]).enumerate() {
        d.data[y * w + fl.rect[0]..y * w + fl.rect[2]].copy_from_slice(&g_src[row * rw..][..rw]);
    }
    let sub = device_backward(&fl.content, &Prepared::new(&fl.content, &opts), &d);
    // The filters' slots follow the group's opacity, and the children's follow them.
    let filters = layout.groups[fl.param_group] + 1;
    for (k, v) in g_params.iter().enumerate() {
        grad[filters + k] += v;
    }
    let base = filters + g_params.len();
    for (k, v) in sub.grad.iter().enumerate() {
        grad[base + k] += v;
    }
    frames.extend(sub.frames.iter().map(|&(k, g)| (base + k, g)));
}

/// The slots of path `k` (paint order) in `layout`: one run each, in walk order.
fn path_blocks(layout: &ParamLayout, paths: usize) -> Vec<std::ops::Range<usize>> {
    // Owners are paths and groups in walk order; path `k` is the `k`-th that is no group.
    let mut path_of = vec![usize::MAX; layout.owners.len()];
    let mut k = 0;
    for (o, owner) in layout.owners.iter().enumerate() {
        if !owner.is_group {
            path_of[o] = k;
            k += 1;
        }
    }
    let mut blocks: Vec<Option<std::ops::Range<usize>>> = vec![None; paths];
    for (s, slot) in layout.slots.iter().enumerate() {
        let Some(b) = path_of.get(slot.owner).and_then(|&k| blocks.get_mut(k)) else {
            continue;
        };
        match b {
            Some(r) => {
                assert_eq!(r.end, s, "a path's parameters are one run of slots");
                r.end = s + 1;
            }
            None => *b = Some(s..s + 1),
        }
    }
    // A path without parameters gets an empty run where the previous one ended.
    let mut end = 0;
    blocks
        .into_iter()
        .map(|b| {
            let r = b.unwrap_or(end..end);
            assert!(r.start >= end, "paths' parameters come in paint order");
            end = r.end;
            r
        })
        .collect()
}

/// A path's run of the parameter gradient, indexed by slot.
struct Block<'a> {
    base: usize,
    g: &'a mut [f64],
}

impl std::ops::Index<usize> for Block<'_> {
    type Output = f64;
    fn index(&self, slot: usize) -> &f64 {
        &self.g[slot - self.base]
    }
}

impl std::ops::IndexMut<usize> for Block<'_> {
    fn index_mut(&mut self, slot: usize) -> &mut f64 {
        &mut self.g[slot - self.base]
    }
}

/// Adds item `ii`'s vertex and paint gradients to its path's parameters in `grad`:
/// outline vertices back to the centerline (strokes), flattened vertices to control
/// points (into `outline_g`, `x, y` per point, when the path is a primitive's outline).
#[allow(clippy::too_many_arguments)]
fn scatter_item(
    p: &Prepared,
    ii: usize,
    path: &Path,
    off: &crate::scene::params::PathOffsets,
    vert_g: &[Vec<Point>],
    paint_g: &[Vec<f64>],
    grad: &mut Block<'_>,
    mut outline_g: Option<&mut [f64]>,
    frame_g: &mut [f64; 4],
    maps: &mut Vec<(usize, [f64; 6])>,
) {
    let item = &p.items[ii];
    let geom = &p.geoms[item.path];
    let mut flat_g = vec![[0.0f64; 2]; geom.flat.pts.len()];
    match item.kind {
        ItemKind::Fill => {
            for (j, g) in vert_g[ii].iter().enumerate() {
                let k = item.src[j] as usize;
                flat_g[k][0] += g[0];
                flat_g[k][1] += g[1];
            }
            if let Some(po) = off.fill {
                let m = scatter_paint(
                    grad,
                    po,
                    off.fill_opacity,
                    &paint_g[ii],
                    item.paint.transform_len(),
                );
                maps.extend(m.map(|m| (po.base, m)));
            }
        }
        ItemKind::Stroke => {
            let (Some(stroke), Some(inv)) = (&path.stroke, geom.frame_inv) else {
                return;
            };
            let [fa, fb, fc, fd] = stroke.frame;
            let hw = 0.5 * stroke.width;
            let fpts: Vec<Point> = geom
                .flat
                .pts
                .iter()
                .map(|q| [inv[0] * q[0] + inv[2] * q[1], inv[1] * q[0] + inv[3] * q[1]])
                .collect();
            // The outline's recipes, rebuilt as prepare built them (not kept there).
            let ol = stroke_outline(stroke, geom, &fpts, p.tolerance);
            debug_assert_eq!(ol.recipes.len(), item.pts.len());
            let center: &[Point] = match &geom.dashed {
                Some(d) => &d.pts,
                None => &fpts,
            };
            let mut cg = vec![[0.0f64; 2]; center.len()];
            let mut gh = 0.0;
            for (j, g) in vert_g[ii].iter().enumerate() {
                if g[0] == 0.0 && g[1] == 0.0 {
                    continue;
                }
                // Device = F · frame point.
                let gf = [fa * g[0] + fb * g[1], fc * g[0] + fd * g[1]];
                // … and `∂/∂F = g ⊗ frame point`.
                let q = item.pts[j];
                let o = [inv[0] * q[0] + inv[2] * q[1], inv[1] * q[0] + inv[3] * q[1]];
                frame_g[0] += g[0] * o[0];
                frame_g[1] += g[1] * o[0];
                frame_g[2] += g[0] * o[1];
                frame_g[3] += g[1] * o[1];
                let r = ol.recipes[j];
                let ins = r.inputs();
                let at = |k: u32| {
                    if k == NONE {
                        [0.0; 2]
                    } else {
                        center[k as usize]
                    }
                };
                let (gp, ghh) = r.vjp(at(ins[0]), at(ins[1]), at(ins[2]), hw, gf);
                for (k, d) in ins.iter().zip(gp) {
                    if *k != NONE {
                        cg[*k as usize][0] += d[0];
                        cg[*k as usize][1] += d[1];
                    }
                }
                gh += ghh;
            }
            let fg = match &geom.dashed {
                Some(d) => {
                    let mut fg = vec![[0.0f64; 2]; fpts.len()];
                    for (s, g) in d.src.iter().zip(&cg) {
                        for c in 0..2 {
                            fg[s.a as usize][c] += (1.0 - s.u) * g[c];
                            fg[s.b as usize][c] += s.u * g[c];
                        }
                    }
                    fg
                }
                None => cg,
            };
            // Frame point = inv · device point, and `∂/∂F = −(invᵀ·g) ⊗ frame point`
            // (`∂ inv = −inv · ∂F · inv`).
            for (k, g) in fg.iter().enumerate() {
                let gd = [inv[0] * g[0] + inv[1] * g[1], inv[2] * g[0] + inv[3] * g[1]];
                flat_g[k][0] += gd[0];
                flat_g[k][1] += gd[1];
                let o = fpts[k];
                frame_g[0] -= gd[0] * o[0];
                frame_g[1] -= gd[1] * o[0];
                frame_g[2] -= gd[0] * o[1];
                frame_g[3] -= gd[1] * o[1];
            }
            // A clip shape's stroke has no width or paint parameters.
            if let Some(po) = off.stroke {
                grad[off.stroke_width] += 0.5 * gh;
                let m = scatter_paint(
                    grad,
                    po,
                    off.stroke_opacity,
                    &paint_g[ii],
                    item.paint.transform_len(),
                );
                maps.extend(m.map(|m| (po.base, m)));
            }
        }
    }
    // Flattened vertices are Bernstein blends of control points.
    for (k, g) in flat_g.iter().enumerate() {
        if g[0] == 0.0 && g[1] == 0.0 {
            continue;
        }
        let s = geom.flat.src[k];
        for (m, wgt) in s.weights().iter().enumerate() {
            if *wgt != 0.0 {
                let k = 2 * (s.first as usize + m);
                let pair = match outline_g.as_deref_mut() {
                    Some(og) => &mut og[k..k + 2],
                    None => &mut grad.g[off.points + k - grad.base..][..2],
                };
                pair[0] += wgt * g[0];
                pair[1] += wgt * g[1];
            }
        }
    }
}

/// Adds a chunk of bands' vertex and paint gradients (`results`, in band order) into
/// each item's, items in parallel: every item's sums take its bands in order, so the bits
/// are those of adding band after band.
fn add_band_grads(results: &[BandGrads], vert_g: &mut [Vec<Point>], paint_g: &mut [Vec<f64>]) {
    const NONE: u32 = u32::MAX;
    let items = vert_g.len();
    // `at[b · items + i]`: the entry of item `i` in band `b`'s `touched`, if any.
    let mut at = vec![NONE; results.len() * items];
    for (b, r) in results.iter().enumerate() {
        for (e, t) in r.touched.iter().enumerate() {
            at[b * items + t.item as usize] = e as u32;
        }
    }
    vert_g
        .par_iter_mut()
        .zip(paint_g.par_iter_mut())
        .enumerate()
        .for_each(|(i, (vg, pg))| {
            for (b, r) in results.iter().enumerate() {
                let e = at[b * items + i];
                if e == NONE {
                    continue;
                }
                let t = r.touched[e as usize];
                let end = r
                    .touched
                    .get(e as usize + 1)
                    .map_or(r.verts.len(), |n| n.verts as usize);
                for &(k, d) in &r.verts[t.verts as usize..end] {
                    let g = &mut vg[k as usize];
                    g[0] += d[0];
                    g[1] += d[1];
                }
                let vals = &r.paint_vals[t.paint as usize..][..pg.len()];
                for (a, v) in pg.iter_mut().zip(vals) {
                    *a += v;
                }
            }
        });
}

/// Adds an item's paint gradient into the parameter gradient.
fn scatter_paint(
    grad: &mut Block<'_>,
    po: crate::scene::params::PaintOffsets,
    opacity: usize,
    pg: &[f64],
    tail: usize,
) -> Option<[f64; 6]> {
    // Paint slots are contiguous from `base` (geometry, then stops); the item opacity
    // next, and a radial gradient's `tail` transform terms last
    // (`PaintEval::transform_len`).
    let (main, rest) = pg.split_at(pg.len() - tail);
    let n = main.len();
    for (k, v) in main[..n - 1].iter().enumerate() {
        grad[po.base + k] += v;
    }
    grad[opacity] += main[n - 1];
    (tail == 6).then(|| std::array::from_fn(|k| rest[k]))
}

/// Draws one row of `item` onto `dst` from its winding integrals `wrow` (first pixel at
/// device `(x0, y)`, row `row` of the item's box), recording the cells that take part in
/// the reverse walk: touched by an edge (or on a grid-aligned item, where untouched cells
/// next to an edge count), with coverage or a coverage slope. The pixels get the bits of
/// [`composite_row`](super::render::composite_row).
#[allow(clippy::too_many_arguments)]
fn record_row(
    item: &super::prepare::Item,
    wrow: &[f32],
    sc: &mut RowScratch,
    ov: &mut Overlaps,
    dst: &mut [[f32; 4]],
    x0: usize,
    y: usize,
    row: usize,
    cells: &mut Vec<TapeCell>,
) {
    let n = wrow.len();
    let (covs, ups, downs) = (&mut sc.covs[..n], &mut sc.ups[..n], &mut sc.downs[..n]);
    let colors = &mut sc.colors[..n];
    coverage_row(wrow, item.evenodd, covs);
    if item.crisp {
        // Coverage by pixel centers: piecewise constant in the points.
        ups.fill(0.0);
        downs.fill(0.0);
    } else {
        coverage_slopes_row(wrow, item.evenodd, ups, downs);
    }
    // Cells of exact coverage: recorded whatever their values, with no slopes (their
    // gradient goes through their pieces' portions).
    let exact = if ov.has_row(row) {
        let range = ov.resolve_row(row, wrow, item.evenodd, covs);
        &ov.cells[range]
    } else {
        &[]
    };
    let mut next_exact = exact
        .iter()
        .filter(|c| c.grad)
        .map(|c| c.col as usize)
        .peekable();
    // A gradient's colors only where some coverage is (where `over` reads them), over
    // the same columns as the forward pass's `composite_row`, so the bits agree.
    match &item.paint {
        PaintEval::Solid(s) => colors.fill(s.premul),
        PaintEval::Gradient(_) | PaintEval::Image(_) => {
            if let Some((a, b)) = covered_span(covs) {
                item.paint.row(x0 + a, y, &mut colors[a..b]);
            }
        }
    }
    for col in 0..n {
        let is_exact = next_exact.next_if_eq(&col).is_some();
        if wrow[col] == 0.0 && !item.grid_aligned && !is_exact {
            continue;
        }
        let (cov, up, down) = if is_exact {
            (covs[col], 0.0, 0.0)
        } else {
            (covs[col], ups[col], downs[col])
        };
        if cov == 0.0 && up == 0.0 && down == 0.0 && !is_exact {
            continue;
        }
        let d = &mut dst[col];
        cells.push(TapeCell {
            col: col as u16,
            row: row as u16,
            cov,
            up: up as i8,
            down: down as i8,
            exact: is_exact,
            below: *d,
        });
        if cov > 0.0 {
            over(d, colors[col], cov);
        }
    }
}

/// One band: rendered onto `base` (transparent, `rows × width`) while recording, then its
/// pixels' gradient from `d_of`, then the reverse walk.
fn band_backward(
    p: &Prepared,
    y0: usize,
    rows: usize,
    base: &mut [[f32; 4]],
    d_of: &BandGradient<'_>,
) -> BandGrads {
    // 1. Render, recording.
    let mut r = BandRenderer::new(p, y0, rows);
    r.for_backward = true;
    let (mut ex_cells, mut ex_portions): (Vec<ExactRec>, Vec<Portion>) = (Vec::new(), Vec::new());
    let base_area = r.band_area();
    let mut layers: Vec<(Area, Vec<[f32; 4]>)> = Vec::new();
    let mut tape: Vec<Rec> = Vec::new();
    let mut cells = TAPE_CELLS.with(|c| c.take());
    cells.clear();
    let (mut i, mut group_ix) = (0usize, 0usize);
    while i < p.ops.len() {
        match p.ops[i] {
            Op::Draw(ix) => {
                let item = &p.items[ix];
                if !r.deltas(item) {
                    i += 1;
                    continue;
                }
                let (area, target) = match layers.last_mut() {
                    Some((a, l)) => (*a, l.as_mut_slice()),
                    None => (base_area, &mut *base),
                };
                let shape = Cells {
                    x0: r.acc.x0,
                    y0: r.acc.y0,
                    w: r.acc.w,
                    h: r.acc.h,
                    data: Vec::new(),
                };
                let (x0, first) = (shape.x0 as usize, cells.len());
                for row in 0..shape.h {
                    let y = shape.y0 as usize + row;
                    let (wrow, sc, ov) = r.take_row(row);
                    let dst = &mut target[area.index(x0, y)..][..wrow.len()];
                    record_row(item, wrow, sc, ov, dst, x0, y, row, &mut cells);
                }
                let ex_first = ex_cells.len();
                for c in r.overlaps.cells.iter().filter(|c| c.grad) {
                    let at = ex_portions.len() as u32;
                    ex_portions.extend_from_slice(
                        &r.overlaps.portions[c.portions.0 as usize..c.portions.1 as usize],
                    );
                    ex_cells.push(ExactRec {
                        w0: c.w0,
                        portions: (at, ex_portions.len() as u32),
                    });
                }
                tape.push(Rec::Draw {
                    item: ix,
                    acc: shape,
                    cells: first..cells.len(),
                    exact: ex_first..ex_cells.len(),
                });
            }
            Op::Push | Op::PushMask => {
                let span = p.groups[group_ix];
                let mask = p.ops[i] == Op::PushMask;
                match r.layer_area(&span) {
                    Some(a) if span.filter.is_some() => {
                        let f = span.filter.unwrap_or_default();
                        let fl = &p.filters[f];
                        layers.push((a, fl.rows(a.y0, a.h)));
                        tape.push(Rec::PushFilter(f));
                        group_ix = fl.groups_end;
                        i = fl.body_end;
                        continue;
                    }
                    Some(a) => {
                        layers.push((a, vec![[0.0; 4]; a.len()]));
                        tape.push(if mask { Rec::PushMask } else { Rec::Push });
                        group_ix += 1;
                    }
                    None => {
                        // Nothing inside touches this band: a group's layer changes
                        // nothing and gets no gradient; a mask's hides what it masks.
                        if mask {
                            let (_, content) = layers.last_mut().expect("a masked layer");
                            content.fill([0.0; 4]);
                            tape.push(Rec::ZeroMask);
                        }
                        group_ix = span.groups_end;
                        i = span.end + 1;
                        continue;
                    }
                }
            }
            Op::PopMask { kind } => {
                let (mask_area, mask) = layers.pop().expect("a mask layer");
                let (ca, content) = layers.last_mut().expect("a masked layer");
                let before = content.clone();
                apply_mask(content, *ca, Some((&mask, mask_area)), kind);
                tape.push(Rec::PopMask {
                    kind,
                    mask,
                    mask_area,
                    content: before,
                });
            }
            Op::Pop {
                opacity,
                group,
                blend,
            } => {
                let (ta, top) = layers.pop().expect("a layer per group");
                let (ba, below_buf) = match layers.last_mut() {
                    Some((a, l)) => (*a, l.as_mut_slice()),
                    None => (base_area, &mut *base),
                };
                let mut below = Vec::with_capacity(ta.len());
                for row in 0..ta.h {
                    let start = ba.index(ta.x0, ta.y0 + row);
                    below.extend_from_slice(&below_buf[start..start + ta.w]);
                }
                composite_layer(below_buf, ba, &top, ta, opacity, blend);
                tape.push(Rec::Pop {
                    group,
                    opacity,
                    blend,
                    top,
                    below,
                    area: ta,
                });
            }
        }
        i += 1;
    }
    // 2. The pixels' gradient, then the reverse walk with ∂L/∂(current layer).
    let (d_out, sums) = d_of(y0, rows, base);
    let mut out = BandGrads {
        sums,
        tape_bytes: tape
            .iter()
            .map(|r| match r {
                Rec::Draw { .. }
                | Rec::Push
                | Rec::PushFilter(_)
                | Rec::PushMask
                | Rec::ZeroMask => 0,
                Rec::Pop { top, below, .. } => (top.len() + below.len()) * 16,
                Rec::PopMask { mask, content, .. } => (mask.len() + content.len()) * 16,
            })
            .sum::<usize>()
            + cells.len() * std::mem::size_of::<TapeCell>()
            + ex_cells.len() * std::mem::size_of::<ExactRec>()
            + ex_portions.len() * std::mem::size_of::<Portion>()
            + 2 * d_out.len() * 16,
        ..BandGrads::default()
    };
    let mut g_stack: Vec<(Area, Vec<[f32; 4]>)> = vec![(base_area, d_out)];
    let mut gw = Cells::<[f32; 2]>::default();
    // `∂L/∂cov` of the current item's exact cells, in their order.
    let mut exact_g: Vec<f32> = Vec::new();
    for rec in tape.iter().rev() {
        match rec {
            Rec::Pop {
                group,
                opacity,
                blend,
                top,
                below,
                area,
            } => {
                let (ga, g) = g_stack.last_mut().expect("layer gradient");
                let ga = *ga;
                let mut g_top = vec![[0.0f32; 4]; area.len()];
                let mut g_op = 0.0f64;
                // Outside `area` the layer is transparent: the gradient below passes
                // unchanged and adds nothing to the opacity's.
                for row in 0..area.h {
                    let kg0 = ga.index(area.x0, area.y0 + row);
                    for col in 0..area.w {
                        let k = row * area.w + col;
                        let kg = kg0 + col;
                        let (gt, gb, go) =
                            composite_backward(*blend, *opacity, g[kg], top[k], below[k]);
                        g_top[k] = gt;
                        g[kg] = gb;
                        g_op += go as f64;
                    }
                }
                if let Some(group) = group {
                    out.groups.push((*group as u32, g_op));
                }
                g_stack.push((*area, g_top));
            }
            Rec::Push | Rec::PushMask => {
                g_stack.pop();
            }
            Rec::PushFilter(f) => {
                let (a, g) = g_stack.pop().expect("layer gradient");
                out.filters.push((*f, a, g));
            }
            Rec::ZeroMask => {
                let (_, g) = g_stack.last_mut().expect("layer gradient");
                g.fill([0.0; 4]);
            }
            Rec::PopMask {
                kind,
                mask,
                mask_area,
                content,
            } => {
                let (ca, g) = g_stack.last_mut().expect("layer gradient");
                let gm = apply_mask_backward(g, *ca, content, mask, *mask_area, *kind);
                g_stack.push((*mask_area, gm));
            }
            Rec::Draw {
                item,
                acc,
                cells: range,
                exact,
            } => {
                exact_g.clear();
                let it = &p.items[*item];
                let (ga, g) = g_stack.last_mut().expect("layer gradient");
                let ga = *ga;
                // `gw` is all zero between items: only the cells written below are
                // cleared again after the boundary pass.
                gw.reshape_zeroed(acc.x0, acc.y0, acc.w, acc.h);
                let pg_at = out.paint_vals.len();
                out.touched.push(Touched {
                    item: *item as u32,
                    verts: out.verts.len() as u32,
                    paint: pg_at as u32,
                });
                out.paint_vals.resize(pg_at + it.paint.grad_len(), 0.0);
                let pg = &mut out.paint_vals[pg_at..];
                let solid = match &it.paint {
                    PaintEval::Solid(c) => Some(c.premul),
                    PaintEval::Gradient(_) | PaintEval::Image(_) => None,
                };
                let mut gs_sum = [0.0f64; 4];
                let item_cells = &cells[range.clone()];
                for cell in item_cells {
                    let (row, col) = (cell.row as usize, cell.col as usize);
                    let y = acc.y0 as usize + row;
                    let cov = cell.cov;
                    let x = acc.x0 as usize + col;
                    // Pixel center, for gradient paints only (through `u32`: the
                    // conversion from `usize` is a branchy sequence on x86-64).
                    let center = || [x as u32 as f64 + 0.5, y as u32 as f64 + 0.5];
                    let s = match solid {
                        Some(s) => s,
                        None => it.paint.at(center()),
                    };
                    let k = ga.index(x, y);
                    let go = g[k];
                    let d = cell.below;
                    let gd: f32 = (0..4).map(|c| go[c] * d[c]).sum();
                    // Inside a shape both slopes are 0: `gw` keeps its zero.
                    if cell.exact {
                        let gsrc: f32 = (0..4).map(|c| go[c] * s[c]).sum();
                        exact_g.push(gsrc - s[3] * gd);
                    } else if cell.up != 0 || cell.down != 0 {
                        let gsrc: f32 = (0..4).map(|c| go[c] * s[c]).sum();
                        let g_cov = gsrc - s[3] * gd;
                        gw.data[row * acc.w + col] =
                            [g_cov * cell.up as f32, g_cov * cell.down as f32];
                    }
                    if cov == 0.0 {
                        continue;
                    }
                    let mut gs = [0.0f64; 4];
                    for c in 0..4 {
                        gs[c] = (go[c] * cov) as f64;
                    }
                    gs[3] -= (cov * gd) as f64;
                    if solid.is_some() {
                        for c in 0..4 {
                            gs_sum[c] += gs[c];
                        }
                    } else {
                        it.paint.backward(center(), gs, pg);
                    }
                    let keep = 1.0 - s[3] * cov;
                    for c in 0..4 {
                        g[k][c] = go[c] * keep;
                    }
                }
                if solid.is_some() {
                    it.paint.backward([0.0; 2], gs_sum, pg);
                }
                // Boundary gradients of the edges crossing this band.
                let (ylo, yhi) = (acc.y0 as f64, (acc.y0 as usize + acc.h) as f64);
                let verts = &mut out.verts;
                it.for_each_edge_near(ylo, yhi, |ia, ib| {
                    let (a, b) = (it.pts[ia], it.pts[ib]);
                    // Inclusive: an edge on the band's boundary line counts in both
                    // bands, each for the cells on its side.
                    if a[1].max(b[1]) < ylo || a[1].min(b[1]) > yhi {
                        return;
                    }
                    let [da, db] = backward_line(&gw, a, b);
                    if da != [0.0; 2] {
                        verts.push((ia as u32, da));
                    }
                    if db != [0.0; 2] {
                        verts.push((ib as u32, db));
                    }
                });
                // Exact cells: each portion of a piece by its own weight.
                for (e, &g_cov) in ex_cells[exact.clone()].iter().zip(&exact_g) {
                    if g_cov == 0.0 {
                        continue;
                    }
                    for q in &ex_portions[e.portions.0 as usize..e.portions.1 as usize] {
                        let w = portion_weight(e.w0.saturating_add(q.rel_lo), it.evenodd);
                        let scale = g_cov as f64 * w * if q.half { 0.5 } else { 1.0 };
                        if scale == 0.0 {
                            continue;
                        }
                        let (a, b) = (it.pts[q.a as usize], it.pts[q.b as usize]);
                        let n = [-(b[1] - a[1]), b[0] - a[0]];
                        let it1 = 0.5 * (q.t1 * q.t1 - q.t0 * q.t0);
                        let (s0, s1) = (scale * ((q.t1 - q.t0) - it1), scale * it1);
                        verts.push((q.a, [s0 * n[0], s0 * n[1]]));
                        verts.push((q.b, [s1 * n[0], s1 * n[1]]));
                    }
                }
                for cell in item_cells {
                    if cell.up != 0 || cell.down != 0 {
                        gw.data[cell.row as usize * acc.w + cell.col as usize] = [0.0; 2];
                    }
                }
            }
        }
    }
    // Kept for this thread's next band unless it grew past what is worth holding idle.
    if cells.capacity() * std::mem::size_of::<TapeCell>() <= KEEP_CELL_BYTES {
        TAPE_CELLS.with(|c| c.replace(cells));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Fill, FillRule, Group, Node, Paint};

    /// Every path's parameters form one run, in paint order, holding exactly the slots
    /// it owns (groups' opacities fall between runs), even with paths nested in groups,
    /// gradient paints and strokes: what lets the scatter split the gradient by path.
    #[test]
    fn path_blocks_are_each_paths_own_slots() {
        let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="64" height="64">
          <defs><linearGradient id="g"><stop offset="0" stop-color="red"/><stop offset="1" stop-color="blue"/></linearGradient></defs>
          <rect x="2" y="2" width="20" height="20" fill="url(#g)" stroke="black" stroke-width="2"/>
          <g opacity="0.5"><circle cx="30" cy="30" r="9" fill="teal"/>
            <g opacity="0.7"><path d="M40 40 L60 44 L50 60 Z" fill="none" stroke="orange"/></g></g>
          <ellipse cx="12" cy="50" rx="8" ry="5" fill="url(#g)" fill-opacity="0.6"/></svg>"##;
        let scene = Scene::from_svg_str(svg, "t.svg", crate::Sizing::Natural).unwrap();
        let layout = ParamLayout::new(&scene);
        let mut paths = 0;
        scene.for_each_path(|_| paths += 1);
        assert_eq!(paths, 4);
        let blocks = path_blocks(&layout, paths);
        let path_owners: Vec<usize> = (0..layout.owners.len())
            .filter(|&o| !layout.owners[o].is_group)
            .collect();
        let mut covered = 0;
        for (k, r) in blocks.iter().enumerate() {
            assert!(r.start < r.end, "path {k} has parameters");
            let owned: Vec<usize> = (0..layout.slots.len())
                .filter(|&s| layout.slots[s].owner == path_owners[k])
                .collect();
            assert_eq!(owned, r.clone().collect::<Vec<_>>(), "path {k}");
            let off = &layout.paths[k];
            assert!(r.contains(&off.points), "path {k}: points");
            if let Some(po) = off.fill {
                assert!(
                    r.contains(&po.base) && r.contains(&off.fill_opacity),
                    "path {k}: fill"
                );
            }
            if let Some(po) = off.stroke {
                let slots = [po.base, off.stroke_opacity, off.stroke_width];
                assert!(slots.iter().all(|s| r.contains(s)), "path {k}: stroke");
            }
            covered += r.len();
        }
        assert!(blocks.windows(2).all(|w| w[0].end <= w[1].start));
        assert_eq!(covered + layout.groups.len(), layout.len());
    }

    /// A 10-pixel square inside `levels` nested groups of opacity 0.9, on a wide canvas.
    fn nested(levels: usize, size: u32) -> Scene {
        let mut p = Path::new("sq");
        p.move_to([10.5, 10.0]);
        p.line_to([20.5, 10.0]);
        p.line_to([20.5, 20.0]);
        p.line_to([10.5, 20.0]);
        p.close();
        p.fill = Some(Fill {
            paint: Paint::Solid([1.0, 0.0, 0.0]),
            opacity: 1.0,
            rule: FillRule::NonZero,
        });
        let mut node = Node::Path(p);
        for _ in 0..levels {
            node = Node::Group(Group::new(String::new(), 0.9, vec![node]));
        }
        let mut s = Scene::new(size, size);
        s.nodes.push(node);
        s
    }

    #[test]
    fn nested_group_layers_cover_only_their_content() {
        let opts = RenderOptions::default();
        let s = nested(100, 1024);
        let p = prepare(&s, opts.tolerance, None);
        let img = super::super::render::render_prepared(&p);
        let want = 0.9f32.powi(100);
        assert!((img.get(15, 15)[3] - want).abs() < 1e-5);
        assert_eq!(img.get(500, 500)[3], 0.0);
        let d = Image::filled(1024, 1024, [0.0, 0.0, 0.0, 1.0]);
        let (g, stats) = backward_with_stats(&s, &p, &d);
        // A band-wide layer per level would record 100 × 2 × 16 rows × 1024 px × 16 bytes
        // (52 MB) per band; a layer the size of the square, a few hundred kB.
        assert!(stats.band_bytes_max < 1 << 20, "{stats:?}");
        // ∂(Σ alpha)/∂(opacity) of each group: 100 px of alpha 0.9^100, divided by 0.9.
        let layout = ParamLayout::new(&s);
        let want = 100.0 * 0.9f64.powi(99);
        for &slot in &layout.groups {
            assert!(
                (g[slot] - want).abs() < 1e-3 * want,
                "{} vs {want}",
                g[slot]
            );
        }
    }
}

#[cfg(test)]
mod memory_check_tests {
    use super::*;
    use crate::scene::Sizing;

    /// Issue 27's fuzz finding: copies of one shape stacked thousands deep are refused
    /// before the backward pass allocates; DiffVG's painterly workload at its largest is not.
    #[test]
    fn stacked_copies_are_refused_and_painterly_passes() {
        let one = r#"<path d="M10 10H100V120H10Z"/>"#;
        let svg = format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="128" height="128">{}</svg>"#,
            one.repeat(20_000)
        );
        let s = Scene::from_svg_str(&svg, "stack.svg", Sizing::Natural).unwrap();
        let opts = RenderOptions::default();
        let e = check_backward_memory(&s, &opts, std::path::Path::new("stack.svg"))
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("stack.svg: unsupported: too complex to differentiate"),
            "{e}"
        );
        let d = Image::new(128, 128);
        let e = render_backward_checked(&s, &opts, &d, std::path::Path::new("stack.svg"));
        assert!(e.is_err());
        // A hundred copies pass, with the same gradient as the unchecked pass.
        let svg = svg.replace(&one.repeat(19_900), "");
        let s = Scene::from_svg_str(&svg, "stack.svg", Sizing::Natural).unwrap();
        let d = Image::filled(128, 128, [0.1, 0.2, 0.3, 0.4]);
        let g = render_backward_checked(&s, &opts, &d, std::path::Path::new("s")).unwrap();
        assert_eq!(g, render_backward(&s, &opts, &d));
        // The painterly benchmark's largest setting: 2048 blobs at 2048² (as circles of
        // DiffVG's blob radii, 2% to 7% of the canvas, where a hash puts them).
        let circles: String = (0..2048u64)
            .map(|i| {
                let h = i.wrapping_mul(0x9e37_79b9_7f4a_7c15);
                let (x, y, r) = (h % 2048, (h >> 16) % 2048, 41 + (h >> 32) % 103);
                format!(r#"<circle cx="{x}" cy="{y}" r="{r}" fill="red"/>"#)
            })
            .collect();
        let svg = format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="2048" height="2048">{circles}</svg>"#
        );
        let blobs = Scene::from_svg_str(&svg, "blobs.svg", Sizing::Natural).unwrap();
        let p = prepare(&blobs, opts.tolerance, None);
        let worst = tape_estimates(&p, 2048 / BAND_ROWS)
            .into_iter()
            .max()
            .unwrap();
        println!("painterly 2048: worst band estimate {} MiB", worst >> 20);
        assert!(worst < crate::limits::MAX_BAND_RECORD_BYTES / 4, "{worst}");
    }
}
