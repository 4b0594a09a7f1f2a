//! Open cubic strokes fitted to small grayscale glyphs (MNIST digits): white ink on black.
//!
//! A digit starts as one stroke of one cubic segment laid along the longest walk through
//! the ink's skeleton. While its ink overlap (IoU) with the target stays below a goal, the
//! model grows by one curve at a time — a segment split in two (which leaves the shape
//! unchanged, so the fit warm-starts), then a second stroke laid along the ink still
//! missed — and is refined again. The result has the fewest curves that reached the goal,
//! or the most allowed.
//!
//! Units: the input is `w × h` intensities in `[0, 1]`, 1 = ink, row-major, pixel `(x, y)`
//! covering `[x, x+1) × [y, y+1)` (y down). Fitting runs at `scale` times that size against
//! a bilinear upsampling of the target; scores (MSE, IoU) are taken at the input size from
//! the fit's rendering averaged over `scale × scale` blocks. The returned scene is in
//! input pixels.
//!
//! ```
//! use diffsvg::fit::digit::{DigitOptions, fit_digit};
//! // A 28 × 28 "1": a vertical bar of ink.
//! let mut pixels = vec![0.0f32; 28 * 28];
//! for y in 5..23 {
//!     for x in 13..16 {
//!         pixels[y * 28 + x] = 1.0;
//!     }
//! }
//! let fit = fit_digit(&pixels, 28, 28, &DigitOptions::default());
//! assert_eq!(fit.curves(), 1); // one segment is enough
//! assert!(fit.iou > 0.7, "{}", fit.iou);
//! ```

use super::{LearningRates, Objective};
use crate::fit::refine::{Control, FitOptions, refine};
use crate::image_io::Image;
use crate::loss::Loss;
use crate::metrics::iou;
use crate::optim::Schedule;
use crate::raster::{RenderOptions, render};
use crate::scene::geom::{dist, split_half};
use crate::scene::{LineCap, LineJoin, Node, Paint, Path, Point, Scene, Stroke};

/// Settings of [`fit_digit`].
#[derive(Clone, Debug)]
pub struct DigitOptions {
    /// Fitting resolution as a multiple of the input's (2: 28² digits are fitted at 56²).
    pub scale: u32,
    /// Stop adding curves once the IoU of the inked areas reaches this.
    pub target_iou: f64,
    /// Most strokes per digit.
    pub max_strokes: usize,
    /// Most cubic segments per stroke.
    pub max_segments: usize,
    /// Optimizer steps for the first curve.
    pub steps: usize,
    /// Optimizer steps after each added curve.
    pub stage_steps: usize,
    /// Intensity at or above which a pixel counts as ink (for IoU and the skeleton).
    pub threshold: f32,
}

impl Default for DigitOptions {
    fn default() -> Self {
        DigitOptions {
            scale: 2,
            target_iou: 0.85,
            max_strokes: 2,
            max_segments: 3,
            steps: 60,
            stage_steps: 40,
            threshold: 0.5,
        }
    }
}

/// A fitted digit.
#[derive(Clone, Debug)]
pub struct DigitFit {
    /// White strokes (round caps and joins) in input pixels, on a transparent canvas of
    /// the input's size: draw it over black to compare with the target.
    pub scene: Scene,
    /// Segments per stroke.
    pub segments: Vec<usize>,
    /// Mean squared error at the input size, intensities in `[0, 1]`.
    pub mse: f64,
    /// Intersection over union of the inked areas (intensity ≥ threshold) at the input size.
    pub iou: f64,
    /// The fit's intensities at the input size, row-major.
    pub rendering: Vec<f32>,
    /// Optimizer steps taken over all stages.
    pub steps: usize,
}

impl DigitFit {
    /// Total cubic segments (the curves used).
    pub fn curves(&self) -> usize {
        self.segments.iter().sum()
    }
}

/// Fits strokes to one `w × h` digit; deterministic.
pub fn fit_digit(pixels: &[f32], w: usize, h: usize, opts: &DigitOptions) -> DigitFit {
    assert_eq!(pixels.len(), w * h, "pixels must hold w × h intensities");
    let s = opts.scale.max(1) as f64;
    let (wh, hh) = (w as u32 * opts.scale.max(1), h as u32 * opts.scale.max(1));
    let target = gray_image(pixels, w, h).resized(wh, hh);
    let objective = Objective::new(&target, Loss::Mse, Some([0.0, 0.0, 0.0, 1.0]), 1);
    let mut rates = LearningRates {
        points: 0.5 * s,
        width: 0.1 * s,
        ..LearningRates::default()
    };
    rates.color = 0.0;
    rates.opacity = 0.0;

    let ink = mask(pixels, opts.threshold);
    let walk = longest_walk(&thin(&ink, w, h), w, h);
    let inked: f64 = pixels.iter().map(|&v| v as f64).sum();
    let width = (inked / polyline_length(&walk).max(1.0)).clamp(1.0, 4.0);
    let mut scene = Scene::new(wh, hh);
    scene
        .nodes
        .push(Node::Path(stroke_along(&walk, 1, width, s, "stroke0")));

    let mut steps = 0;
    let mut run = |scene: Scene, iters: usize| {
        let o = FitOptions {
            iters,
            rates,
            schedule: Schedule::Cosine,
            ..FitOptions::default()
        };
        let out = refine(scene, &objective, &o, &mut |_, _| Control::Continue);
        steps += out.steps;
        out.best
    };
    scene = run(scene, opts.steps);
    let mut scored = score(&scene, pixels, w, h, opts);
    loop {
        if scored.0 >= opts.target_iou {
            break;
        }
        let Some(next) = grow(&scene, &scored.2, pixels, w, h, opts) else {
            break;
        };
        let next = run(next, opts.stage_steps);
        scored = score(&next, pixels, w, h, opts);
        scene = next;
    }
    let (iou, mse, rendering) = scored;
    let segments = strokes(&scene)
        .iter()
        .map(|p| p.subpaths[0].segments())
        .collect();
    scene.scale_to(1.0 / s, w as u32, h as u32);
    DigitFit {
        scene,
        segments,
        mse,
        iou,
        rendering,
        steps,
    }
}

/// Renders a fitted scene (at any scale) over black and averages it down to `w × h`
/// intensities.
pub fn intensities(scene: &Scene, w: usize, h: usize) -> Vec<f32> {
    let img = render(scene, &RenderOptions::default());
    let k = (img.width as usize / w).max(1);
    let mut out = vec![0f32; w * h];
    for (y, row) in out.chunks_mut(w).enumerate() {
        for (x, v) in row.iter_mut().enumerate() {
            let mut sum = 0.0;
            for dy in 0..k {
                for dx in 0..k {
                    // Premultiplied white over black: the red channel is the intensity.
                    sum += img.data[(y * k + dy) * img.width as usize + x * k + dx][0];
                }
            }
            *v = sum / (k * k) as f32;
        }
    }
    out
}

/// Mean squared error of two intensity lists.
pub(crate) fn mse(a: &[f32], b: &[f32]) -> f64 {
    let s: f64 = a.iter().zip(b).map(|(x, y)| ((x - y) as f64).powi(2)).sum();
    s / a.len().max(1) as f64
}

/// Intensities as an opaque gray image.
pub fn gray_image(pixels: &[f32], w: usize, h: usize) -> Image {
    let mut img = Image::new(w as u32, h as u32);
    for (d, &v) in img.data.iter_mut().zip(pixels) {
        *d = [v, v, v, 1.0];
    }
    img
}

fn score(
    scene: &Scene,
    pixels: &[f32],
    w: usize,
    h: usize,
    o: &DigitOptions,
) -> (f64, f64, Vec<f32>) {
    let r = intensities(scene, w, h);
    (iou(&r, pixels, o.threshold), mse(&r, pixels), r)
}

fn strokes(scene: &Scene) -> Vec<&Path> {
    let mut v = Vec::new();
    scene.for_each_path(|p| v.push(p));
    v
}

/// The model with one more curve: a split segment of the last stroke while it has fewer
/// than the most allowed, else a new stroke along the ink still missed. `None` when the
/// model is full.
fn grow(
    scene: &Scene,
    fit: &[f32],
    pixels: &[f32],
    w: usize,
    h: usize,
    o: &DigitOptions,
) -> Option<Scene> {
    let paths = strokes(scene);
    let last = paths.last()?;
    let mut next = scene.clone();
    if last.subpaths[0].segments() < o.max_segments {
        let n = next.nodes.len();
        if let Node::Path(p) = &mut next.nodes[n - 1] {
            split_longest(p);
        }
        return Some(next);
    }
    if paths.len() >= o.max_strokes {
        return None;
    }
    let missed: Vec<f32> = pixels
        .iter()
        .zip(fit)
        .map(|(&t, &f)| {
            if t >= o.threshold && f < 0.5 * o.threshold {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    let mut walk = longest_walk(&thin(&mask(&missed, 0.5), w, h), w, h);
    if walk.len() < 2 {
        // Nothing missed in a line: start a short stroke at the worst pixel.
        let (i, _) = pixels
            .iter()
            .zip(fit)
            .map(|(t, f)| t - f)
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(&b.1))?;
        let c = [(i % w) as f64 + 0.5, (i / w) as f64 + 0.5];
        walk = vec![[c[0] - 1.0, c[1]], [c[0] + 1.0, c[1]]];
    }
    let width = last.stroke.as_ref().map_or(2.0, |s| s.width) / o.scale.max(1) as f64;
    let id = format!("stroke{}", paths.len());
    next.nodes.push(Node::Path(stroke_along(
        &walk,
        1,
        width,
        o.scale.max(1) as f64,
        &id,
    )));
    Some(next)
}

/// Splits the segment with the longest control polygon at its middle (de Casteljau), which
/// leaves the curve unchanged.
fn split_longest(p: &mut Path) {
    let sp = &p.subpaths[0];
    let n = sp.segments();
    let seg = |k: usize| p.segment_points(sp, k);
    let polygon = |c: &[Point; 4]| (0..3).map(|j| dist(c[j], c[j + 1])).sum::<f64>();
    let k = (0..n)
        .max_by(|&a, &b| polygon(&seg(a)).total_cmp(&polygon(&seg(b))))
        .unwrap_or(0);
    let ([_, ab, abc, m], [_, bcd, cd, _]) = split_half(&seg(k));
    let i = sp.start + 3 * k;
    p.points.splice(i + 1..i + 3, [ab, abc, m, bcd, cd]);
    let kind = p.subpaths[0].kinds[k];
    p.subpaths[0].kinds.insert(k, kind);
}

fn polyline_length(pts: &[Point]) -> f64 {
    pts.windows(2).map(|w| dist(w[0], w[1])).sum()
}

/// A white stroke of `segments` cubics fitted to the polyline `walk` (input pixels),
/// built at `scale`.
fn stroke_along(walk: &[Point], segments: usize, width: f64, scale: f64, id: &str) -> Path {
    let pts: Vec<Point> = if walk.len() >= 2 {
        walk.iter().map(|q| [q[0] * scale, q[1] * scale]).collect()
    } else {
        let c = walk.first().copied().unwrap_or([14.0, 14.0]);
        vec![
            [(c[0] - 3.0) * scale, c[1] * scale],
            [(c[0] + 3.0) * scale, c[1] * scale],
        ]
    };
    let ctrl = fit_cubics(&pts, segments.max(1));
    let mut p = Path::new(id);
    p.move_to(ctrl[0]);
    for c in ctrl[1..].chunks(3) {
        p.cubic_to(c[0], c[1], c[2]);
    }
    let mut s = Stroke::new(Paint::Solid([1.0, 1.0, 1.0]), width * scale);
    s.join = LineJoin::Round;
    s.cap = LineCap::Round;
    p.stroke = Some(s);
    p
}

/// Control points (`3k + 1`) of `k` cubics through a polyline: it is cut into `k` runs of
/// equal length, and each run gets the cubic through its ends whose inner control points
/// fit its points best in least squares.
fn fit_cubics(pts: &[Point], k: usize) -> Vec<Point> {
    let mut cum = vec![0.0];
    for w in pts.windows(2) {
        cum.push(cum.last().unwrap() + dist(w[0], w[1]));
    }
    let total = *cum.last().unwrap();
    let mut cuts = vec![0usize];
    for j in 1..k {
        let goal = total * j as f64 / k as f64;
        let i = cum.partition_point(|&c| c < goal).clamp(1, pts.len() - 1);
        cuts.push(i.max(*cuts.last().unwrap()));
    }
    cuts.push(pts.len() - 1);
    let mut out = vec![pts[0]];
    for j in 0..k {
        let run = &pts[cuts[j]..=cuts[j + 1]];
        let (c1, c2) = fit_one(run);
        out.extend([c1, c2, run[run.len() - 1]]);
    }
    out
}

/// Inner control points of the cubic through `run`'s ends that best fits its points
/// (the glyph fitter's least squares with Newton-improved parameters).
fn fit_one(run: &[Point]) -> (Point, Point) {
    let last = run.len() - 1;
    let c = crate::fit::glyph::fit_cubic(run[0], run[last], &run[1..last.max(1)]);
    (c[1], c[2])
}

fn mask(pixels: &[f32], threshold: f32) -> Vec<bool> {
    pixels.iter().map(|&v| v >= threshold).collect()
}

/// Zhang–Suen thinning of a binary image to one-pixel-wide lines (8-connected).
fn thin(mask: &[bool], w: usize, h: usize) -> Vec<bool> {
    let mut m = mask.to_vec();
    let at = |m: &[bool], x: isize, y: isize| -> bool {
        x >= 0 && y >= 0 && (x as usize) < w && (y as usize) < h && m[y as usize * w + x as usize]
    };
    loop {
        let mut changed = false;
        for pass in 0..2 {
            let mut remove = Vec::new();
            for y in 0..h as isize {
                for x in 0..w as isize {
                    if !at(&m, x, y) {
                        continue;
                    }
                    // P2..P9 clockwise from north.
                    let n = [
                        at(&m, x, y - 1),
                        at(&m, x + 1, y - 1),
                        at(&m, x + 1, y),
                        at(&m, x + 1, y + 1),
                        at(&m, x, y + 1),
                        at(&m, x - 1, y + 1),
                        at(&m, x - 1, y),
                        at(&m, x - 1, y - 1),
                    ];
                    let b = n.iter().filter(|&&v| v).count();
                    let a = (0..8).filter(|&i| !n[i] && n[(i + 1) % 8]).count();
                    let (p2, p4, p6, p8) = (n[0], n[2], n[4], n[6]);
                    // Zhang and Suen's two sub-iteration conditions, as the paper writes them.
                    #[allow(clippy::nonminimal_bool)]
                    let ok = if pass == 0 {
                        !(p2 && p4 && p6) && !(p4 && p6 && p8)
                    } else {
                        !(p2 && p4 && p8) && !(p2 && p6 && p8)
                    };
                    if (2..=6).contains(&b) && a == 1 && ok {
                        remove.push(y as usize * w + x as usize);
                    }
                }
            }
            changed |= !remove.is_empty();
            for i in remove {
                m[i] = false;
            }
        }
        if !changed {
            return m;
        }
    }
}

/// The longest of the walks through a skeleton that start at its end pixels (or at its
/// topmost pixel when it has none, as a loop does) and at each step move to an unvisited
/// neighbor, going as straight on as they can. Pixel centers, input pixels.
fn longest_walk(skel: &[bool], w: usize, h: usize) -> Vec<Point> {
    const DIRS: [(isize, isize); 8] = [
        (0, -1),
        (1, -1),
        (1, 0),
        (1, 1),
        (0, 1),
        (-1, 1),
        (-1, 0),
        (-1, -1),
    ];
    let on = |x: isize, y: isize| {
        x >= 0
            && y >= 0
            && (x as usize) < w
            && (y as usize) < h
            && skel[y as usize * w + x as usize]
    };
    let pixels: Vec<(isize, isize)> = (0..w * h)
        .filter(|&i| skel[i])
        .map(|i| ((i % w) as isize, (i / w) as isize))
        .collect();
    let degree = |&(x, y): &(isize, isize)| DIRS.iter().filter(|d| on(x + d.0, y + d.1)).count();
    let mut starts: Vec<(isize, isize)> =
        pixels.iter().copied().filter(|p| degree(p) <= 1).collect();
    if let Some(&top) = pixels.first() {
        starts.push(top);
    }
    let mut best: Vec<(isize, isize)> = Vec::new();
    let mut best_len = -1.0;
    for &s in &starts {
        let mut seen = vec![false; w * h];
        let mut walk = vec![s];
        seen[s.1 as usize * w + s.0 as usize] = true;
        let mut dir = (0.0f64, 0.0f64);
        let mut len = 0.0;
        loop {
            let (x, y) = *walk.last().unwrap();
            let next = DIRS
                .iter()
                .filter(|d| {
                    on(x + d.0, y + d.1) && !seen[(y + d.1) as usize * w + (x + d.0) as usize]
                })
                .max_by(|a, b| {
                    let score = |d: &(isize, isize)| {
                        let l = ((d.0 * d.0 + d.1 * d.1) as f64).sqrt();
                        (d.0 as f64 * dir.0 + d.1 as f64 * dir.1) / l - 0.01 * l
                    };
                    score(a).total_cmp(&score(b))
                });
            let Some(d) = next else { break };
            let p = (x + d.0, y + d.1);
            seen[p.1 as usize * w + p.0 as usize] = true;
            let l = ((d.0 * d.0 + d.1 * d.1) as f64).sqrt();
            len += l;
            // Direction: a running average, so one diagonal jog does not turn the walk.
            dir = (
                0.5 * dir.0 + 0.5 * d.0 as f64 / l,
                0.5 * dir.1 + 0.5 * d.1 as f64 / l,
            );
            walk.push(p);
        }
        if len > best_len {
            best_len = len;
            best = walk;
        }
    }
    best.iter()
        .map(|&(x, y)| [x as f64 + 0.5, y as f64 + 0.5])
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::geom::eval;

    /// Intensities of a scene rendered at its own size over black.
    fn draw(scene: &Scene) -> Vec<f32> {
        intensities(scene, scene.width as usize, scene.height as usize)
    }

    #[test]
    fn thinning_leaves_a_line_one_pixel_wide() {
        let (w, h) = (20, 9);
        let mut m = vec![false; w * h];
        for y in 3..6 {
            for x in 2..18 {
                m[y * w + x] = true;
            }
        }
        let t = thin(&m, w, h);
        let count = t.iter().filter(|&&v| v).count();
        assert!((12..=16).contains(&count), "{count} pixels");
        for x in 0..w {
            assert!((0..h).filter(|&y| t[y * w + x]).count() <= 1, "column {x}");
        }
        let walk = longest_walk(&t, w, h);
        assert_eq!(walk.len(), count);
        assert!(polyline_length(&walk) >= 11.0);
    }

    #[test]
    fn a_loop_is_walked_all_the_way_round() {
        let (w, h) = (20, 20);
        let mut m = vec![false; w * h];
        for y in 0..h {
            for x in 0..w {
                let r = ((x as f64 - 9.5).powi(2) + (y as f64 - 9.5).powi(2)).sqrt();
                m[y * w + x] = (5.0..7.5).contains(&r);
            }
        }
        let walk = longest_walk(&thin(&m, w, h), w, h);
        // Circumference of the mid circle ≈ 2π · 6.2 ≈ 39.
        assert!(polyline_length(&walk) > 30.0, "{}", polyline_length(&walk));
    }

    #[test]
    fn least_squares_cubic_recovers_its_curve() {
        let c = [[0.0, 0.0], [10.0, 20.0], [30.0, 20.0], [40.0, 0.0]];
        let pts: Vec<Point> = (0..=50).map(|i| eval(&c, i as f64 / 50.0)).collect();
        let ctrl = fit_cubics(&pts, 1);
        // Chord-length parameters differ from the curve's own, so the control points move
        // a little; the curve itself must pass close to every point.
        let ctrl = [ctrl[0], ctrl[1], ctrl[2], ctrl[3]];
        let fitted: Vec<Point> = (0..=400).map(|i| eval(&ctrl, i as f64 / 400.0)).collect();
        for q in &pts {
            let near = fitted
                .iter()
                .map(|f| dist(*f, *q))
                .fold(f64::INFINITY, f64::min);
            assert!(near < 1.0, "{q:?} is {near} px from the fit");
        }
        assert_eq!(fit_cubics(&pts, 3).len(), 10);
    }

    #[test]
    fn splitting_a_segment_keeps_the_drawing() {
        let walk: Vec<Point> = (0..20)
            .map(|i| [4.0 + i as f64, 10.0 + (i as f64 * 0.3).sin() * 4.0])
            .collect();
        let mut scene = Scene::new(28, 28);
        scene
            .nodes
            .push(Node::Path(stroke_along(&walk, 1, 2.0, 1.0, "s")));
        let before = draw(&scene);
        if let Node::Path(p) = &mut scene.nodes[0] {
            split_longest(p);
            assert_eq!(p.subpaths[0].segments(), 2);
            assert_eq!(p.points.len(), 7);
        }
        assert!(mse(&before, &draw(&scene)) < 1e-6);
    }

    /// A digit drawn by strokes is recovered by them: high IoU with few curves.
    #[test]
    fn recovers_a_drawn_seven() {
        let mut truth = Scene::new(28, 28);
        let mut p = Path::new("seven");
        p.move_to([7.0, 7.0]);
        p.line_to([21.0, 7.0]);
        p.cubic_to([18.0, 12.0], [14.0, 17.0], [12.0, 23.0]);
        let mut s = Stroke::new(Paint::Solid([1.0; 3]), 2.5);
        s.join = LineJoin::Round;
        s.cap = LineCap::Round;
        p.stroke = Some(s);
        truth.nodes.push(Node::Path(p));
        let target = draw(&truth);
        let fit = fit_digit(&target, 28, 28, &DigitOptions::default());
        assert!(fit.iou >= 0.85, "IoU {}", fit.iou);
        assert!(
            fit.curves() <= 6 && fit.segments.len() <= 2,
            "{:?}",
            fit.segments
        );
        assert!(fit.mse < 0.02, "MSE {}", fit.mse);
        // Deterministic.
        let again = fit_digit(&target, 28, 28, &DigitOptions::default());
        assert_eq!(again.rendering, fit.rendering);
        // The returned scene is in input pixels and draws what was scored.
        assert_eq!((fit.scene.width, fit.scene.height), (28, 28));
    }

    #[test]
    fn blank_input_stays_finite() {
        let fit = fit_digit(&vec![0.0; 28 * 28], 28, 28, &DigitOptions::default());
        assert!(fit.mse.is_finite() && fit.iou.is_finite());
    }
}
