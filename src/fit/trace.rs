//! Classical tracing (vtracer) as a starting point for refinement.
//!
//! [`trace`] runs vtracer's `photo` preset in-process and reads its SVG back as a
//! [`Scene`]; [`prune_to_budget`] then cuts the scene down to a path budget, keeping the
//! paths that matter most for the target, and [`prune_unneeded`] drops the paths that
//! barely change (or worsen) the match.
//!
//! # How pruning works
//!
//! For one pixel, let the layers painted there be `L_0 … L_m` (in paint order, over the
//! background `B`), `s_k` being layer `k`'s premultiplied paint times its coverage.
//! Removing layer `k` changes the composited pixel by exactly
//! `δ_k = T_k · (s_k − s_k.a · B_k)`, where `B_k` is the composite of everything below `k`
//! and `T_k` the product of `1 − s_j.a` over the layers above it. With
//! `e = rendered − target`, the change of the summed squared error is `Σ (e − δ_k)² − e²`.
//! One forward and one backward sweep over a pixel's layers give its share of this cost
//! for every path painted there.
//!
//! The layers of every pixel are rasterized once and kept; the costs are summed over all
//! pixels. Then, greedily, the cheapest path is removed and only the pixels within its
//! bounds are swept again (their old shares subtracted, the new ones added), so each step
//! is exact and costs about the area of the removed path. Hidden and redundant paths go
//! first; a large lower shape goes only when what it would expose matches the target as
//! well.
//!
//! A path's fill and stroke are adjacent in paint order, so on each pixel they are merged
//! into one layer and removed together, exactly. Group opacity is folded into the paint of
//! each path in the group: exact when at most one path of a translucent group paints a
//! pixel (and always for opacity 0 or 1), an approximation otherwise.

use rayon::prelude::*;

use crate::raster::coverage::coverage;
use crate::raster::prepare::{Op, Prepared, prepare};
use crate::raster::render::{BAND_ROWS, BandRenderer, RenderOptions};
use crate::scene::{Node, Scene};
use crate::{Error, Image, Result};

/// Name used in errors about traced images.
const TRACE: &str = "<trace>";

/// Traces `target` (premultiplied, as every [`Image`]) with vtracer's `photo` preset and
/// returns a scene of the target's size: opaque solid-filled paths in device pixels, in
/// vtracer's stacked order (large background shapes first, details on top). The image is
/// handed to vtracer as straight 8-bit RGBA; vtracer leaves fully transparent pixels
/// unpainted and ignores partial transparency. Errors when the image is empty or vtracer
/// fails, or when the library was built without its `trace` feature (vtracer, which
/// brings its own command-line crates, so it is a feature of its own; the `cli` feature
/// enables it).
#[cfg(feature = "trace")]
pub fn trace(target: &Image) -> Result<Scene> {
    trace_with(target, vtracer::Config::from_preset(vtracer::Preset::Photo))
}

/// [`trace`] without vtracer: always an error that says which feature is missing.
#[cfg(not(feature = "trace"))]
pub fn trace(_target: &Image) -> Result<Scene> {
    Err(Error::Image {
        path: TRACE.into(),
        message: "tracing needs diffsvg built with its `trace` feature (vtracer)".into(),
    })
}

/// [`trace`] with any vtracer configuration.
#[cfg(feature = "trace")]
fn trace_with(target: &Image, config: vtracer::Config) -> Result<Scene> {
    let (w, h) = (target.width, target.height);
    let fail = |message: String| Error::Image {
        path: TRACE.into(),
        message,
    };
    if w == 0 || h == 0 {
        return Err(fail(format!("cannot trace an empty {w}×{h} image")));
    }
    let img = vtracer::ColorImage {
        pixels: target.to_rgba8(),
        width: w as usize,
        height: h as usize,
    };
    let svg = vtracer::convert(img, config).map_err(|e| fail(format!("vtracer: {e}")))?;
    let scene = Scene::from_svg_str(&svg.to_string(), TRACE, crate::Sizing::Exact(w, h))?;
    debug_assert_eq!((scene.width, scene.height), (w, h));
    Ok(scene)
}

/// Removes paths from `scene` until at most `budget` remain, keeping those that matter most
/// for matching `target` (premultiplied, the scene's size) when both are composited over
/// `background` (straight RGBA in `[0, 1]`): greedily, each step removes the path whose
/// removal raises the squared error (all four channels) least. The first path in paint
/// order (a traced scene's background) is kept unless `budget` is 0. Groups left empty are
/// removed. See the [module documentation](self) for the method.
///
/// Panics if `target`'s size differs from the scene's.
pub(crate) fn prune_to_budget(
    scene: &mut Scene,
    target: &Image,
    budget: usize,
    background: [f32; 4],
) {
    check_size(scene, target);
    let n = scene.path_count();
    if n <= budget {
        return;
    }
    let mut pruner = Pruner::new(scene, target, background);
    let first = usize::from(budget > 0);
    for _ in budget..n {
        let Some(k) = pruner.cheapest(first) else {
            break;
        };
        pruner.remove(k);
    }
    pruner.apply(scene);
}

/// Removes, greedily and exactly, every path whose removal raises the mean squared error
/// (same measure as [`prune_to_budget`]) by at most `tolerance` (absolute, MSE units,
/// ≥ 0); the cheapest first, re-scoring after each removal. Returns how many were removed.
///
/// The MSE is the mean, over all `4 × width × height` premultiplied channel values
/// (red, green, blue *and* alpha), of the squared difference between the scene's rendering
/// and `target` (premultiplied, the scene's size), both composited over `background`
/// (straight RGBA in `[0, 1]`), values in `[0, 1]`. With an opaque background the alpha
/// channel is 1 in both, so this MSE is `3/4` of the RGB-only MSE: to allow a PSNR drop of
/// `Δ` dB from an RGB-only MSE `m`, pass `0.75 · m · (10^(Δ/10) − 1)`.
///
/// Removals that lower the error (negative cost) go first, so paths that are hidden under
/// others, painted nowhere (shrunk to nothing, off the canvas, fully transparent) or wrong
/// are all removed, and with `tolerance = 0` the error never rises. The
/// first path (a background shape) gets no special treatment: it stays only if it matters.
/// Each step removes the cheapest remaining path (among equal costs, the upper one) and
/// stops when even that one would cost more than `tolerance`; the removals' costs add up,
/// so the total rise can exceed `tolerance`. A NaN tolerance counts as 0; a negative one
/// removes only paths whose removal lowers the MSE by at least its magnitude. Groups left
/// empty are removed. See the [module documentation](self) for the method and how group
/// opacity is handled.
///
/// Panics if `target`'s size differs from the scene's.
pub(crate) fn prune_unneeded(
    scene: &mut Scene,
    target: &Image,
    background: [f32; 4],
    tolerance: f64,
) -> usize {
    check_size(scene, target);
    if scene.path_count() == 0 {
        return 0;
    }
    let tolerance = if tolerance.is_nan() { 0.0 } else { tolerance };
    let values = (4 * target.data.len()).max(1) as f64;
    let mut pruner = Pruner::new(scene, target, background);
    while let Some(k) = pruner.cheapest(0) {
        let rise = pruner.cost[k] / values;
        if rise.is_nan() || rise > tolerance {
            break;
        }
        pruner.remove(k);
    }
    pruner.apply(scene)
}

/// Panics unless `target` has the scene's size.
fn check_size(scene: &Scene, target: &Image) {
    assert_eq!(
        (scene.width, scene.height),
        (target.width, target.height),
        "target size differs from the scene's"
    );
}

/// The greedy's state: every pixel's layers and the current cost of removing each path
/// that is still there.
struct Pruner {
    stacks: Stacks,
    /// The target composited over the background.
    goal: Image,
    /// The premultiplied background.
    bg: [f32; 4],
    width: usize,
    /// Pixels `[x0, y0, x1, y1)` each path paints.
    bounds: Vec<[u32; 4]>,
    /// Whether each path (paint order) is still there.
    alive: Vec<bool>,
    /// Change of the summed squared error (all pixels, four channels) if each path alone
    /// were removed now (stale for removed paths).
    cost: Vec<f64>,
    /// Scratch space for [`pixel_cost`].
    below: Vec<[f32; 4]>,
}

impl Pruner {
    /// Rasterizes `scene` and scores every path against `target` (the scene's size).
    fn new(scene: &Scene, target: &Image, background: [f32; 4]) -> Pruner {
        let n = scene.path_count();
        let mut goal = target.clone();
        goal.over_background(background);
        let a = background[3];
        let p = prepare(scene, RenderOptions::default().tolerance, None);
        debug_assert_eq!(p.geoms.len(), n);
        let stacks = Stacks::new(&p);
        let width = p.width as usize;
        let bounds = stacks.bounds(width, n);
        let mut pruner = Pruner {
            stacks,
            goal,
            bg: [background[0] * a, background[1] * a, background[2] * a, a],
            width,
            bounds,
            alive: vec![true; n],
            cost: vec![0.0; n],
            below: Vec::new(),
        };
        pruner.sweep([0, 0, p.width, p.height], 1.0);
        pruner
    }

    /// Adds `sign ×` the cost shares of the pixels in `[x0, y0, x1, y1)`.
    fn sweep(&mut self, [x0, y0, x1, y1]: [u32; 4], sign: f64) {
        let Pruner {
            stacks,
            goal,
            bg,
            width,
            alive,
            cost,
            below,
            ..
        } = self;
        let w = *width;
        for y in y0 as usize..y1 as usize {
            for px in y * w + x0 as usize..y * w + x1 as usize {
                pixel_cost(stacks.at(px), alive, goal.data[px], *bg, sign, cost, below);
            }
        }
    }

    /// The cheapest path still there from index `first` on; among equals, the later (upper)
    /// one.
    fn cheapest(&self, first: usize) -> Option<usize> {
        (first..self.alive.len())
            .filter(|&i| self.alive[i])
            .min_by(|&i, &j| self.cost[i].total_cmp(&self.cost[j]).then(j.cmp(&i)))
    }

    /// Removes path `k`, re-scoring the paths it overlaps. Only the pixels under it change:
    /// their old shares are swapped for new ones.
    fn remove(&mut self, k: usize) {
        let b = self.bounds[k];
        self.sweep(b, -1.0);
        self.alive[k] = false;
        self.sweep(b, 1.0);
    }

    /// Removes the removed paths (and groups left empty) from `scene`; returns how many.
    fn apply(&self, scene: &mut Scene) -> usize {
        let remove: Vec<bool> = self.alive.iter().map(|a| !a).collect();
        let count = remove.iter().filter(|&&r| r).count();
        if count > 0 {
            remove_paths(scene, &remove);
        }
        count
    }
}

/// One path painted on one pixel.
#[derive(Clone, Copy, Default)]
struct Layer {
    /// Path index in paint order.
    path: u32,
    /// Premultiplied paint at the pixel center times coverage (and group opacity): the
    /// layer composites as `s + below · (1 − s.a)`.
    color: [f32; 4],
}

/// The layers painted on each pixel, in paint order, one per path.
struct Stacks {
    /// Pixel `i`'s layers are `layers[start[i]..start[i + 1]]`.
    start: Vec<usize>,
    layers: Vec<Layer>,
}

impl Stacks {
    /// Rasterizes every item of `p`, band by band in parallel.
    fn new(p: &Prepared) -> Stacks {
        let (w, h) = (p.width as usize, p.height as usize);
        let scale = group_opacity(p);
        let bands: Vec<(Vec<usize>, Vec<Layer>)> = (0..h.div_ceil(BAND_ROWS))
            .into_par_iter()
            .map(|band| {
                let y0 = band * BAND_ROWS;
                let rows = BAND_ROWS.min(h - y0);
                let mut r = BandRenderer::new(p, y0, rows);
                let mut found: Vec<(u32, Layer)> = Vec::new();
                for op in &p.ops {
                    let &Op::Draw(i) = op else { continue };
                    let item = &p.items[i];
                    let scale = scale[i];
                    if scale <= 0.0 || !r.winding(item) {
                        continue;
                    }
                    let acc = &r.acc;
                    let cols = acc.w.min(w - acc.x0 as usize);
                    for row in 0..acc.h {
                        let y = acc.y0 as usize + row;
                        for (c, &wv) in acc.data[row * acc.w..][..cols].iter().enumerate() {
                            let (cov, _) = coverage(wv, item.evenodd);
                            if cov > 0.0 {
                                let x = acc.x0 as usize + c;
                                let paint = item.paint.at([x as f64 + 0.5, y as f64 + 0.5]);
                                let color = paint.map(|v| v * cov * scale);
                                if color != [0.0; 4] {
                                    let path = item.path as u32;
                                    found.push((((y - y0) * w + x) as u32, Layer { path, color }));
                                }
                            }
                        }
                    }
                }
                // Counting sort by pixel, stable: each pixel's layers stay in paint order.
                let mut start = vec![0usize; rows * w + 1];
                for &(px, _) in &found {
                    start[px as usize + 1] += 1;
                }
                for i in 0..rows * w {
                    start[i + 1] += start[i];
                }
                let mut next = start.clone();
                let mut sorted = vec![Layer::default(); found.len()];
                for (px, l) in found {
                    sorted[next[px as usize]] = l;
                    next[px as usize] += 1;
                }
                // A path's fill and stroke are adjacent in paint order: merge them.
                let mut layers: Vec<Layer> = Vec::with_capacity(sorted.len());
                let mut merged = Vec::with_capacity(rows * w + 1);
                merged.push(0);
                for px in 0..rows * w {
                    let base = layers.len();
                    for l in &sorted[start[px]..start[px + 1]] {
                        let m = layers.len();
                        if m > base && layers[m - 1].path == l.path {
                            let under = &mut layers[m - 1];
                            let k = 1.0 - l.color[3];
                            under.color = std::array::from_fn(|c| l.color[c] + under.color[c] * k);
                        } else {
                            layers.push(*l);
                        }
                    }
                    merged.push(layers.len());
                }
                (merged, layers)
            })
            .collect();
        let mut out = Stacks {
            start: vec![0],
            layers: Vec::new(),
        };
        for (start, layers) in bands {
            let base = out.layers.len();
            out.start.extend(start[1..].iter().map(|s| s + base));
            out.layers.extend(layers);
        }
        out
    }

    /// The layers of pixel `px` (row-major index).
    fn at(&self, px: usize) -> &[Layer] {
        &self.layers[self.start[px]..self.start[px + 1]]
    }

    /// The pixels `[x0, y0, x1, y1)` holding each of the `n` paths' layers (a canvas
    /// `width` wide); empty (all zero) for a path painted nowhere.
    fn bounds(&self, width: usize, n: usize) -> Vec<[u32; 4]> {
        let mut b = vec![[u32::MAX, u32::MAX, 0, 0]; n];
        for px in 0..self.start.len() - 1 {
            let (x, y) = ((px % width) as u32, (px / width) as u32);
            for l in self.at(px) {
                let o = &mut b[l.path as usize];
                *o = [o[0].min(x), o[1].min(y), o[2].max(x + 1), o[3].max(y + 1)];
            }
        }
        for o in &mut b {
            if o[0] >= o[2] {
                *o = [0; 4];
            }
        }
        b
    }
}

/// Each item's factor from group opacity: the product of its groups' opacities.
fn group_opacity(p: &Prepared) -> Vec<f32> {
    let mut scale = vec![1.0f32; p.items.len()];
    // The items drawn so far in each open group, outermost (the canvas) first.
    let mut open: Vec<Vec<usize>> = vec![Vec::new()];
    for op in &p.ops {
        match *op {
            Op::Draw(i) => open.last_mut().unwrap().push(i),
            Op::Push | Op::PushMask => open.push(Vec::new()),
            // A mask's or clip path's shapes paint nothing themselves.
            Op::PopMask { .. } => {
                for i in open.pop().unwrap_or_default() {
                    scale[i] = 0.0;
                }
            }
            Op::Pop { opacity, .. } => {
                if open.len() > 1 {
                    let inner = open.pop().unwrap();
                    for &i in &inner {
                        scale[i] *= opacity.clamp(0.0, 1.0);
                    }
                    open.last_mut().unwrap().extend(inner);
                }
            }
        }
    }
    scale
}

/// Adds `sign ×` this pixel's share of each alive path's removal cost to `cost`: the change
/// of the pixel's squared error against `goal` if that path alone were removed. `bg` is
/// the premultiplied background; `below` is scratch space.
fn pixel_cost(
    stack: &[Layer],
    alive: &[bool],
    goal: [f32; 4],
    bg: [f32; 4],
    sign: f64,
    cost: &mut [f64],
    below: &mut Vec<[f32; 4]>,
) {
    // Forward: the composite below each layer.
    below.clear();
    let mut acc = bg;
    for l in stack.iter().filter(|l| alive[l.path as usize]) {
        below.push(acc);
        let k = 1.0 - l.color[3];
        acc = std::array::from_fn(|c| l.color[c] + acc[c] * k);
    }
    let e: [f64; 4] = std::array::from_fn(|c| acc[c] as f64 - goal[c] as f64);
    // Backward: `t` is the transmittance of the layers above.
    let mut t = 1.0f64;
    let mut j = below.len();
    for l in stack.iter().rev().filter(|l| alive[l.path as usize]) {
        j -= 1;
        let b = below[j];
        let a = l.color[3] as f64;
        let mut d_sse = 0.0;
        for c in 0..4 {
            let d = t * (l.color[c] as f64 - a * b[c] as f64);
            d_sse += d * d - 2.0 * e[c] * d;
        }
        cost[l.path as usize] += sign * d_sse;
        t *= 1.0 - a;
    }
}

/// Removes the paths flagged in `remove` (indexed in paint order) and any group left empty.
fn remove_paths(scene: &mut Scene, remove: &[bool]) {
    fn walk(nodes: &mut Vec<Node>, remove: &[bool], next: &mut usize) {
        nodes.retain_mut(|node| match node {
            Node::Path(_) => {
                *next += 1;
                !remove[*next - 1]
            }
            Node::Group(g) => {
                walk(&mut g.children, remove, next);
                !g.children.is_empty()
            }
        });
    }
    walk(&mut scene.nodes, remove, &mut 0);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::render;
    use crate::scene::random::Rng;
    use crate::scene::{Fill, FillRule, Group, Paint, Path};
    use std::time::Instant;

    const WHITE: [f32; 4] = [1.0; 4];

    /// PSNR in dB over RGB only, both images composited over white.
    fn psnr_rgb_over_white(a: &Image, b: &Image) -> f64 {
        let (mut a, mut b) = (a.clone(), b.clone());
        a.over_background(WHITE);
        b.over_background(WHITE);
        let sq: f64 = a
            .data
            .iter()
            .zip(&b.data)
            .map(|(p, q)| {
                (0..3)
                    .map(|c| (p[c] as f64 - q[c] as f64).powi(2))
                    .sum::<f64>()
            })
            .sum();
        crate::metrics::psnr_from_mse(sq / (3 * a.data.len()) as f64)
    }

    fn psnr_of(scene: &Scene, target: &Image) -> f64 {
        psnr_rgb_over_white(&render(scene, &RenderOptions::default()), target)
    }

    /// An opaque image: discs `(cx, cy, r, straight color)` painted in order on white,
    /// anti-aliased by 4×4 supersampling.
    fn discs(w: u32, h: u32, discs: &[(f32, f32, f32, [f32; 3])]) -> Image {
        let mut img = Image::filled(w, h, [1.0; 4]);
        for (i, px) in img.data.iter_mut().enumerate() {
            let (x, y) = ((i as u32 % w) as f32, (i as u32 / w) as f32);
            for &(cx, cy, r, c) in discs {
                let inside = (0..16)
                    .filter(|s| {
                        let sx = x + (s % 4) as f32 * 0.25 + 0.125 - cx;
                        let sy = y + (s / 4) as f32 * 0.25 + 0.125 - cy;
                        sx * sx + sy * sy <= r * r
                    })
                    .count();
                let k = inside as f32 / 16.0;
                for ch in 0..3 {
                    px[ch] += k * (c[ch] - px[ch]);
                }
            }
        }
        img
    }

    /// Overlapping discs of random sizes and colors.
    fn busy_image() -> Image {
        let mut rng = Rng::new(7);
        let list: Vec<_> = (0..16)
            .map(|_| {
                let (x, y) = (rng.range(0.0, 64.0) as f32, rng.range(0.0, 64.0) as f32);
                let r = rng.range(3.0, 14.0) as f32;
                (x, y, r, [0; 3].map(|_| rng.range(0.0, 1.0) as f32))
            })
            .collect();
        discs(64, 64, &list)
    }

    #[test]
    #[cfg(feature = "trace")]
    fn traced_discs_render_close_to_the_image() {
        let img = discs(
            96,
            64,
            &[
                (24.0, 28.0, 18.0, [0.9, 0.1, 0.1]),
                (66.0, 32.0, 22.0, [0.1, 0.2, 0.8]),
            ],
        );
        let scene = trace(&img).unwrap();
        assert_eq!((scene.width, scene.height), (96, 64));
        assert!(
            (2..=6).contains(&scene.path_count()),
            "{}",
            scene.path_count()
        );
        // vtracer outlines the pixels it assigns to a region, so edges move by up to half a
        // pixel: about 25 dB here, where an empty (white) scene scores 6.
        let psnr = psnr_of(&scene, &img);
        eprintln!("{} paths, {psnr:.2} dB", scene.path_count());
        assert!(psnr > 23.0, "PSNR {psnr:.2} dB");
        // Inside the discs the colors match.
        let out = render(&scene, &RenderOptions::default());
        for (x, y) in [(24, 28), (66, 32), (90, 60)] {
            let (a, b) = (out.get(x, y), img.get(x, y));
            assert!((0..4).all(|c| (a[c] - b[c]).abs() < 0.03), "{a:?} {b:?}");
        }
        assert!(trace(&Image::new(0, 5)).is_err());
    }

    #[test]
    #[cfg(feature = "trace")]
    fn pruning_beats_dropping_top_or_random_paths() {
        let img = busy_image();
        let scene = trace(&img).unwrap();
        let n = scene.path_count();
        assert!(n >= 8, "{n} paths");
        let budget = n / 2;

        let mut pruned = scene.clone();
        prune_to_budget(&mut pruned, &img, budget, WHITE);
        assert_eq!(pruned.path_count(), budget);
        // The background shape survives.
        assert_eq!(pruned.nodes[0], scene.nodes[0]);
        let ours = psnr_of(&pruned, &img);

        let drop = |remove: &[bool]| {
            let mut s = scene.clone();
            remove_paths(&mut s, remove);
            assert_eq!(s.path_count(), budget);
            psnr_of(&s, &img)
        };
        let top: Vec<bool> = (0..n).map(|i| i >= budget).collect();
        let mut rng = Rng::new(3);
        let mut best_random = f64::NEG_INFINITY;
        for _ in 0..5 {
            let mut idx: Vec<usize> = (1..n).collect();
            let mut remove = vec![false; n];
            for _ in 0..n - budget {
                let k = (rng.next_u64() % idx.len() as u64) as usize;
                remove[idx.swap_remove(k)] = true;
            }
            best_random = best_random.max(drop(&remove));
        }
        let (full, top) = (psnr_of(&scene, &img), drop(&top));
        eprintln!(
            "{n} → {budget} paths: full {full:.2} dB, pruned {ours:.2}, top dropped {top:.2}, best random {best_random:.2}"
        );
        assert!(ours > top + 1.0 && ours > best_random + 1.0);

        // Exact greedy (re-render every candidate) as a reference: close to it.
        let mut greedy = scene.clone();
        while greedy.path_count() > budget {
            let m = greedy.path_count();
            let best = (1..m)
                .map(|i| {
                    let mut s = greedy.clone();
                    let mut remove = vec![false; m];
                    remove[i] = true;
                    remove_paths(&mut s, &remove);
                    (psnr_of(&s, &img), i)
                })
                .max_by(|a, b| a.0.total_cmp(&b.0))
                .unwrap();
            let mut remove = vec![false; m];
            remove[best.1] = true;
            remove_paths(&mut greedy, &remove);
        }
        let g = psnr_of(&greedy, &img);
        eprintln!("exact greedy by re-rendering {g:.2} dB");
        assert!(
            (ours - g).abs() < 1e-3,
            "pruned {ours:.2} dB, greedy {g:.2} dB"
        );

        // Budget 0 removes everything; a budget above the count changes nothing.
        let mut s = scene.clone();
        prune_to_budget(&mut s, &img, n + 5, WHITE);
        assert_eq!(s, scene);
        prune_to_budget(&mut s, &img, 0, WHITE);
        assert_eq!(s.path_count(), 0);
    }

    fn square(x0: f64, y0: f64, side: f64, color: [f64; 3]) -> Path {
        let mut p = Path::new("");
        p.move_to([x0, y0]);
        p.line_to([x0 + side, y0]);
        p.line_to([x0 + side, y0 + side]);
        p.line_to([x0, y0 + side]);
        p.close();
        p.fill = Some(Fill {
            paint: Paint::Solid(color),
            opacity: 1.0,
            rule: FillRule::NonZero,
        });
        p
    }

    #[test]
    fn pruning_drops_hidden_and_wrong_paths_first() {
        // Target: red square on gray. Scene: gray background, a hidden path under the red
        // square, the red square, and a wrong blue square in a translucent group.
        let gray = [0.5; 3];
        let mut target = Scene::new(32, 32);
        target.nodes.push(Node::Path(square(0.0, 0.0, 32.0, gray)));
        target
            .nodes
            .push(Node::Path(square(4.0, 4.0, 12.0, [1.0, 0.0, 0.0])));
        let target = render(&target, &RenderOptions::default());
        let mut scene = Scene::new(32, 32);
        scene.nodes.push(Node::Path(square(0.0, 0.0, 32.0, gray)));
        scene
            .nodes
            .push(Node::Path(square(6.0, 6.0, 4.0, [0.0, 1.0, 0.0])));
        scene
            .nodes
            .push(Node::Path(square(4.0, 4.0, 12.0, [1.0, 0.0, 0.0])));
        scene.nodes.push(Node::Group(Group::new(
            String::new(),
            0.5,
            vec![Node::Path(square(20.0, 20.0, 8.0, [0.0, 0.0, 1.0]))],
        )));
        let mut s = scene.clone();
        prune_to_budget(&mut s, &target, 3, [0.0; 4]);
        assert_eq!(s.nodes, scene.nodes[..3]);
        prune_to_budget(&mut s, &target, 2, [0.0; 4]);
        assert_eq!(s.nodes, [scene.nodes[0].clone(), scene.nodes[2].clone()]);
        assert_eq!(render(&s, &RenderOptions::default()), target);
        // The first path is kept while the budget allows one.
        prune_to_budget(&mut s, &target, 1, [1.0, 0.0, 0.0, 1.0]);
        assert_eq!(s.nodes, [scene.nodes[0].clone()]);
    }

    /// The pruning measure: mean squared error over all four premultiplied channels, both
    /// images composited over `bg`.
    fn mse4(scene: &Scene, target: &Image, bg: [f32; 4]) -> f64 {
        let mut a = render(scene, &RenderOptions::default());
        let mut b = target.clone();
        a.over_background(bg);
        b.over_background(bg);
        crate::metrics::compare(&a, &b).mse
    }

    fn without(scene: &Scene, i: usize) -> Scene {
        let mut s = scene.clone();
        let mut remove = vec![false; scene.path_count()];
        remove[i] = true;
        remove_paths(&mut s, &remove);
        s
    }

    fn ids(scene: &Scene) -> Vec<String> {
        let mut out = Vec::new();
        scene.for_each_path(|p| out.push(p.id.clone()));
        out
    }

    fn named(mut p: Path, id: &str) -> Path {
        p.id = id.into();
        p
    }

    #[test]
    fn prune_unneeded_drops_what_changes_nothing() {
        let gray = [0.5; 3];
        let bg = named(square(0.0, 0.0, 32.0, gray), "bg");
        let red = named(square(4.0, 4.0, 12.0, [1.0, 0.0, 0.0]), "red");
        let blue = named(square(20.0, 20.0, 6.0, [0.0, 0.0, 1.0]), "blue");
        let mut target = Scene::new(32, 32);
        for p in [&bg, &red, &blue] {
            target.nodes.push(Node::Path(p.clone()));
        }
        let target = render(&target, &RenderOptions::default());

        let mut clear = named(square(18.0, 4.0, 8.0, [0.0, 1.0, 0.0]), "clear");
        clear.fill.as_mut().unwrap().opacity = 0.0;
        let mut scene = Scene::new(32, 32);
        scene.nodes = vec![
            Node::Path(bg.clone()),
            // Under the opaque red square.
            Node::Path(named(square(6.0, 6.0, 4.0, [0.0, 1.0, 0.0]), "hidden")),
            Node::Path(red.clone()),
            Node::Path(clear),
            Node::Path(named(square(40.0, -20.0, 8.0, [0.0, 1.0, 0.0]), "outside")),
            Node::Group(Group::new(
                String::new(),
                0.0,
                vec![Node::Path(named(
                    square(2.0, 20.0, 8.0, [1.0, 0.0, 1.0]),
                    "in clear group",
                ))],
            )),
            Node::Path(named(square(20.0, 20.0, 6.0, [0.0, 0.0, 1.0]), "blue")),
            Node::Path(named(square(2.0, 24.0, 5.0, [1.0, 1.0, 0.0]), "wrong")),
        ];
        let white = WHITE;
        let mut s = scene.clone();
        assert_eq!(prune_unneeded(&mut s, &target, white, 0.0), 5);
        assert_eq!(ids(&s), ["bg", "red", "blue"]);
        assert_eq!(s.nodes.len(), 3, "the emptied group is gone");
        assert_eq!(render(&s, &RenderOptions::default()), target);
        // Nothing more to remove; NaN counts as 0.
        assert_eq!(prune_unneeded(&mut s, &target, white, f64::NAN), 0);

        // A path stays while its removal costs more than the tolerance.
        let cost = mse4(&without(&s, 2), &target, white) - mse4(&s, &target, white);
        assert!(cost > 0.0);
        let mut t = s.clone();
        assert_eq!(prune_unneeded(&mut t, &target, white, 0.9 * cost), 0);
        assert_eq!(prune_unneeded(&mut t, &target, white, 1.1 * cost), 1);
        assert_eq!(ids(&t), ["bg", "red"]);
        // A negative tolerance keeps paths whose removal costs nothing.
        let mut t = scene.clone();
        assert_eq!(prune_unneeded(&mut t, &target, white, -1e-9), 1);
        assert_eq!(ids(&t).last().unwrap(), "blue");

        // The first path goes when the background shows the same.
        let mut t = s.clone();
        assert_eq!(
            prune_unneeded(&mut t, &target, [0.5, 0.5, 0.5, 1.0], 0.0),
            1
        );
        assert_eq!(ids(&t), ["red", "blue"]);

        // Degenerate scenes.
        let mut empty = Scene::new(32, 32);
        assert_eq!(prune_unneeded(&mut empty, &target, white, 0.0), 0);
        let mut one = Scene::new(32, 32);
        one.nodes.push(Node::Path(bg.clone()));
        assert_eq!(
            prune_unneeded(&mut one.clone(), &target, white, f64::NAN),
            0
        );
        assert_eq!(prune_unneeded(&mut one, &target, white, f64::INFINITY), 1);
        assert_eq!(one.path_count(), 0);
        let mut far = Scene::new(32, 32);
        far.nodes.push(Node::Path(square(-50.0, 5.0, 10.0, gray)));
        assert_eq!(prune_unneeded(&mut far, &target, white, 0.0), 1);
        let mut nothing = Scene::new(0, 0);
        nothing.nodes.push(Node::Path(bg.clone()));
        assert_eq!(
            prune_unneeded(&mut nothing, &Image::new(0, 0), white, 0.0),
            1
        );
    }

    /// Greedy by re-rendering: the reference for [`prune_unneeded`].
    fn prune_unneeded_by_rendering(
        scene: &mut Scene,
        target: &Image,
        bg: [f32; 4],
        tolerance: f64,
    ) -> usize {
        let mut removed = 0;
        while scene.path_count() > 0 {
            let now = mse4(scene, target, bg);
            let (rise, i) = (0..scene.path_count())
                .map(|i| (mse4(&without(scene, i), target, bg) - now, i))
                .min_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)))
                .unwrap();
            if rise > tolerance {
                break;
            }
            *scene = without(scene, i);
            removed += 1;
        }
        removed
    }

    #[test]
    fn prune_unneeded_matches_re_rendering() {
        let curved = crate::scene::random::curved_paths(14, 40, 5);
        let mut stroked = curved.clone();
        // A filled and stroked path, and a translucent group of one path.
        if let Node::Path(p) = &mut stroked.nodes[3] {
            let mut st = crate::scene::Stroke::new(Paint::Solid([0.1, 0.6, 0.2]), 2.5);
            st.opacity = 0.7;
            p.stroke = Some(st);
        }
        let lone = stroked.nodes.remove(6);
        stroked
            .nodes
            .insert(6, Node::Group(Group::new(String::new(), 0.6, vec![lone])));
        let blobs = crate::fit::shapes::random_blobs(14, 40, 40, 9);
        let mut total = 0;
        for (name, scene) in [("curved", curved), ("stroked", stroked), ("blobs", blobs)] {
            // The target: a perturbed copy missing a few paths.
            let mut t = crate::scene::random::perturb(&scene, 3.0, 0.2, 1);
            let n = scene.path_count();
            remove_paths(&mut t, &(0..n).map(|i| i % 4 == 1).collect::<Vec<_>>());
            let target = render(&t, &RenderOptions::default());
            for tolerance in [0.0, 2e-5, 2e-4] {
                let (mut ours, mut reference) = (scene.clone(), scene.clone());
                let k = prune_unneeded(&mut ours, &target, WHITE, tolerance);
                let r = prune_unneeded_by_rendering(&mut reference, &target, WHITE, tolerance);
                eprintln!("{name}, tolerance {tolerance}: {k} of {n} removed");
                assert_eq!(ids(&ours), ids(&reference), "{name}, tolerance {tolerance}");
                assert_eq!((k, ours.path_count()), (r, n - k));
                total += k;
            }
        }
        assert!(total >= 10, "{total} removed in all");
    }

    #[test]
    fn prunes_unneeded_paths_quickly() {
        let scene = crate::scene::random::curved_paths(150, 256, 11);
        let n = scene.path_count();
        let mut t = crate::scene::random::perturb(&scene, 4.0, 0.15, 2);
        remove_paths(&mut t, &(0..n).map(|i| i % 5 == 2).collect::<Vec<_>>());
        let target = render(&t, &RenderOptions::default());
        let before = mse4(&scene, &target, WHITE);
        for tolerance in [0.0, 1e-6, 1e-5] {
            let mut s = scene.clone();
            let t0 = Instant::now();
            let k = prune_unneeded(&mut s, &target, WHITE, tolerance);
            let secs = t0.elapsed().as_secs_f64();
            let after = mse4(&s, &target, WHITE);
            eprintln!(
                "{n} paths 256²: tolerance {tolerance}: {k} removed in {secs:.3} s, MSE {before:.3e} → {after:.3e}"
            );
            assert!(k > 0);
            if tolerance == 0.0 {
                assert!(after <= before);
            }
        }
    }

    /// Loads a sample picture from `../shared/data/images` (or `$DIFFSVG_DATA/images`), or
    /// `None` with a printed reason; with `DIFFSVG_REQUIRE_DATA=1` a missing picture fails
    /// the test instead of skipping it.
    fn sample(name: &str) -> Option<Image> {
        let data = std::env::var_os("DIFFSVG_DATA")
            .map(std::path::PathBuf::from)
            .unwrap_or_else(|| {
                std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data")
            });
        let path = data.join("images").join(name);
        if !path.exists() {
            let why = format!("{} is missing", path.display());
            if std::env::var_os("DIFFSVG_REQUIRE_DATA").is_some_and(|v| v == "1") {
                panic!("{why}, and DIFFSVG_REQUIRE_DATA=1 forbids skipping");
            }
            println!("SKIPPED: {why} (set DIFFSVG_DATA)");
            return None;
        }
        Some(Image::load(&path).unwrap())
    }

    #[test]
    #[cfg(feature = "trace")]
    fn traces_real_pictures_like_vtracer_documents() {
        // (file, width, documented paths and PSNR with resvg, accepted path range)
        let cases = [
            ("astronaut.png", 256, 142, 21.96, 100..=200),
            ("chelsea.png", 256, 58, 25.16, 35..=90),
        ];
        for (name, width, paths, db, range) in cases {
            let Some(img) = sample(name) else { return };
            let height = (img.height as f64 * width as f64 / img.width as f64).round() as u32;
            let img = img.resized(width, height);
            let t = Instant::now();
            let scene = trace(&img).unwrap();
            let secs = t.elapsed().as_secs_f64();
            let psnr = psnr_of(&scene, &img);
            eprintln!(
                "{name} {width}×{height}: {} paths, {psnr:.2} dB in {secs:.3} s (vtracer documents {paths}, {db} dB)",
                scene.path_count()
            );
            assert_eq!((scene.width, scene.height), (width, height));
            assert!(
                range.contains(&scene.path_count()),
                "{} paths",
                scene.path_count()
            );
            assert!(psnr >= db - 1.0, "{psnr:.2} dB");

            let budget = scene.path_count() / 4;
            let mut pruned = scene.clone();
            let t = Instant::now();
            prune_to_budget(&mut pruned, &img, budget, WHITE);
            let secs = t.elapsed().as_secs_f64();
            let after = psnr_of(&pruned, &img);
            let mut top = scene.clone();
            let n = scene.path_count();
            remove_paths(&mut top, &(0..n).map(|i| i >= budget).collect::<Vec<_>>());
            let top = psnr_of(&top, &img);
            eprintln!(
                "  pruned to {budget}: {after:.2} dB in {secs:.3} s (top paths dropped: {top:.2} dB)"
            );
            assert_eq!(pruned.path_count(), budget);
            assert!(after > psnr - 4.0 && after > top, "{after:.2} dB");

            // Dropping what does not help never lowers the PSNR.
            let mut lean = scene.clone();
            let t = Instant::now();
            let k = prune_unneeded(&mut lean, &img, WHITE, 0.0);
            let secs = t.elapsed().as_secs_f64();
            let after = psnr_of(&lean, &img);
            eprintln!("  {k} unneeded paths removed: {after:.2} dB in {secs:.3} s");
            assert!(after >= psnr - 1e-4, "{after:.2} dB");
        }
    }

    #[test]
    #[cfg(feature = "trace")]
    fn prunes_a_thousand_paths_quickly() {
        let Some(img) = sample("astronaut.png") else {
            return;
        };
        let img = img.resized(256, 256);
        // A finer configuration than `photo`, to get about a thousand paths.
        let mut config = vtracer::Config::from_preset(vtracer::Preset::Photo);
        config.layer_difference = 8;
        config.filter_speckle = 4;
        let scene = trace_with(&img, config).unwrap();
        let n = scene.path_count();
        assert!(n > 600, "{n} paths");
        let mut last = psnr_of(&scene, &img);
        for budget in [n / 2, 142, 32] {
            let mut pruned = scene.clone();
            let t = Instant::now();
            prune_to_budget(&mut pruned, &img, budget, WHITE);
            let secs = t.elapsed().as_secs_f64();
            let after = psnr_of(&pruned, &img);
            eprintln!("{n} paths ({last:.2} dB) → {budget}: {after:.2} dB in {secs:.3} s");
            assert_eq!(pruned.path_count(), budget);
            // About 0.1 s on two cores (printed, not asserted: timings vary by machine).
            assert!(after < last + 1.0, "{after:.2} dB");
            last = after;
        }
    }
}
