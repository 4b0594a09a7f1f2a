//! Vectorization: an SVG built from nothing (or from a classical tracing) to match a
//! picture, with as few paths as it needs.
//!
//! **Adaptive** (the default): paths are added in rounds where the error is largest —
//! connected regions of pixels whose error is at least the mean, largest total error
//! first — each a small closed cubic "circle" at the region's center (or, for a region
//! that fills its bounding box and is wider than the largest circle, such as a flat
//! background, that box), colored with the region's mean target color. After each round
//! every path is optimized, then paths whose removal no longer changes the image are
//! pruned. Rounds go on until the path budget or the PSNR goal is reached; `iters` caps
//! the optimizer steps of all rounds together (0: paths are placed, not optimized). **Fixed** places all paths at once (DiffVG's random blobs), **painterly**
//! uses DiffVG's random open strokes, and **trace** starts from vtracer's tracing pruned
//! to the budget; these three are then optimized in one run.
//!
//! ```
//! use diffsvg::fit::Control;
//! use diffsvg::fit::vectorize::{Event, Mode, VectorizeOptions, vectorize};
//! use diffsvg::{Scene, Sizing, fit::Objective, loss::Loss, raster};
//! let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="32" height="32">
//!   <rect width="32" height="32" fill="white"/>
//!   <circle cx="12" cy="14" r="7" fill="teal"/><rect x="18" y="18" width="10" height="9" fill="orange"/></svg>"#;
//! let target = raster::render(&Scene::from_svg_str(svg, "t.svg", Sizing::Natural)?, &Default::default());
//! let objective = Objective::new(&target, Loss::Mse, Some([1.0; 4]), 1);
//! let opts = VectorizeOptions { mode: Mode::Adaptive, paths: 4, iters: 150, ..Default::default() };
//! let out = vectorize(&objective, &opts, &mut |_: Event| Control::Continue)?;
//! assert!(out.scene.path_count() <= 4 && out.psnr > 20.0);
//! # Ok::<(), diffsvg::Error>(())
//! ```

use std::time::{Duration, Instant};

use super::Objective;
use super::refine::{Control, FitOptions, Step, refine};
use super::shapes::{circle, random_blobs, random_strokes};
use super::trace::{prune_to_budget, prune_unneeded, trace};
use crate::Result;
use crate::image_io::Image;
use crate::metrics::median;
use crate::raster::render;
use crate::scene::geom::lerp;
use crate::scene::{Node, Scene};

/// How the paths are found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Mode {
    /// Add paths in rounds where the error is largest, prune the useless ones.
    #[default]
    Adaptive,
    /// All paths at once: DiffVG's random closed blobs.
    Fixed,
    /// DiffVG's random open strokes with widths (the painterly baseline).
    Painterly,
    /// vtracer's tracing, pruned to the budget, then refined.
    Trace,
}

/// Settings of a vectorization.
#[derive(Clone, Debug)]
pub struct VectorizeOptions {
    /// How paths are found.
    pub mode: Mode,
    /// Path budget (the count for fixed and painterly, the most for the others).
    pub paths: usize,
    /// Adaptive: stop adding paths once the PSNR reaches this many dB.
    pub target_psnr: Option<f64>,
    /// Cubic segments per new closed path (adaptive).
    pub segments: usize,
    /// Optimizer steps in all.
    pub iters: usize,
    /// Rates, schedule and Adam constants (its `iters` and `until_psnr` are set per round).
    pub fit: FitOptions,
    /// Seed of the random initial shapes.
    pub seed: u64,
}

impl Default for VectorizeOptions {
    fn default() -> Self {
        VectorizeOptions {
            mode: Mode::Adaptive,
            paths: 64,
            target_psnr: None,
            segments: 4,
            iters: 1000,
            fit: FitOptions::default(),
            seed: 0,
        }
    }
}

/// What a vectorization produced.
#[derive(Clone, Debug)]
pub struct VectorizeOutcome {
    /// The best scene found.
    pub scene: Scene,
    /// Its PSNR against the target, dB.
    pub psnr: f64,
    /// Its mean squared error (over the objective's channels).
    pub mse: f64,
    /// Optimizer steps taken.
    pub steps: usize,
    /// Rounds of adding paths (1 for the one-shot modes).
    pub rounds: usize,
    /// Paths removed by pruning.
    pub pruned: usize,
    /// Wall time.
    pub elapsed: Duration,
    /// Every evaluation: (steps so far, seconds, PSNR, paths).
    pub curve: Vec<(usize, f64, f64, usize)>,
    /// Median milliseconds per optimizer step (render, objective and gradient), over the
    /// rounds' medians.
    pub median_step_ms: f64,
}

/// Progress events.
#[derive(Clone, Copy, Debug)]
pub enum Event<'a> {
    /// A new round starts with this many paths.
    Round {
        /// Round number, from 1.
        round: usize,
        /// Paths in the scene.
        paths: usize,
    },
    /// One evaluation.
    Step(&'a Step, &'a Scene),
}

/// Vectorizes the objective's target. `observe` sees every round and evaluation and may
/// stop the run (the best scene so far is returned).
pub fn vectorize(
    objective: &Objective,
    opts: &VectorizeOptions,
    observe: &mut dyn FnMut(Event) -> Control,
) -> Result<VectorizeOutcome> {
    let start = Instant::now();
    let target = objective.target();
    let (w, h) = (target.width, target.height);
    let mut out = VectorizeOutcome {
        scene: Scene::new(w, h),
        psnr: f64::NEG_INFINITY,
        mse: f64::INFINITY,
        steps: 0,
        rounds: 0,
        pruned: 0,
        elapsed: Duration::ZERO,
        curve: Vec::new(),
        median_step_ms: 0.0,
    };
    let bg = objective.background().unwrap_or([0.0; 4]);
    let mut scene = match opts.mode {
        Mode::Adaptive => Scene::new(w, h),
        Mode::Fixed => random_blobs(opts.paths, w, h, opts.seed),
        Mode::Painterly => random_strokes(opts.paths, w, h, opts.seed),
        Mode::Trace => {
            let mut s = trace(target)?;
            prune_to_budget(&mut s, target, opts.paths, bg);
            s
        }
    };
    let schedule = match opts.mode {
        Mode::Adaptive => round_sizes(opts.paths),
        _ => vec![0],
    };
    // Rounds share 60% of the steps; the last round gets the rest. Never more than
    // `opts.iters` in all: 0 places the paths and optimizes nothing.
    let per_round = if schedule.len() > 1 && opts.iters > 0 {
        (opts.iters * 3 / 5 / (schedule.len() - 1)).max(1)
    } else {
        0
    };
    let mut step_ms = Vec::new();
    let mut stopped = false;
    for (r, &add) in schedule.iter().enumerate() {
        let last = r + 1 == schedule.len();
        if add > 0 {
            let img = render(&scene, &opts.fit.render);
            add_paths(&mut scene, objective, &img, add, opts.segments);
        }
        out.rounds += 1;
        if observe(Event::Round {
            round: out.rounds,
            paths: scene.path_count(),
        }) == Control::Stop
        {
            break;
        }
        let left = opts.iters.saturating_sub(out.steps);
        let iters = if last { left } else { per_round.min(left) };
        let fit = FitOptions {
            iters,
            until_psnr: if last { opts.target_psnr } else { None },
            ..opts.fit.clone()
        };
        let base_steps = out.steps;
        let base_secs = start.elapsed().as_secs_f64();
        let paths = scene.path_count();
        let run = refine(scene, objective, &fit, &mut |s, sc| {
            out.curve.push((
                base_steps + s.iter,
                base_secs + s.elapsed.as_secs_f64(),
                s.psnr,
                paths,
            ));
            let c = observe(Event::Step(s, sc));
            if c == Control::Stop {
                stopped = true;
            }
            c
        });
        out.steps += run.steps;
        step_ms.push(run.median_step_ms);
        scene = run.best;
        if opts.mode == Mode::Adaptive {
            // Drop what no longer changes the image (a change below 0.001 dB). The pruner
            // measures MSE over four channels composited over the background, the
            // objective over three when that background is opaque: hence ¾.
            let mse = objective.mse(&render(&scene, &opts.fit.render));
            let scale = if objective.background().is_some_and(|b| b[3] >= 1.0) {
                0.75
            } else {
                1.0
            };
            let tolerance = scale * mse * (10f64.powf(0.001 / 10.0) - 1.0);
            out.pruned += prune_unneeded(&mut scene, target, bg, tolerance);
        }
        let img = render(&scene, &opts.fit.render);
        let psnr = objective.psnr(&img);
        if psnr > out.psnr || !out.psnr.is_finite() {
            out.psnr = psnr;
            out.mse = objective.mse(&img);
            out.scene = scene.clone();
        }
        if stopped || opts.target_psnr.is_some_and(|g| psnr >= g) {
            break;
        }
    }
    out.elapsed = start.elapsed();
    out.median_step_ms = median(&mut step_ms);
    Ok(out)
}

/// Paths added per adaptive round for a budget: 4, then half as many again as there are
/// (4, 2, 3, 4, 7, 10, …), the last round topping up to the budget; a final 0 marks the
/// closing optimization.
pub(crate) fn round_sizes(budget: usize) -> Vec<usize> {
    let mut v = Vec::new();
    let mut have = 0usize;
    while have < budget {
        let add = if have == 0 { 4 } else { have.div_ceil(2) }.min(budget - have);
        v.push(add);
        have += add;
    }
    v.push(0);
    v
}

/// Adds up to `count` paths at the connected regions of largest error of `render`
/// against the objective's target.
fn add_paths(
    scene: &mut Scene,
    objective: &Objective,
    render: &Image,
    count: usize,
    segments: usize,
) {
    let target = objective.target();
    let img = objective.composite(render);
    let (w, h) = (target.width as usize, target.height as usize);
    let err: Vec<f32> = img
        .data
        .iter()
        .zip(&target.data)
        .map(|(p, t)| (0..4).map(|c| (p[c] - t[c]).powi(2)).sum())
        .collect();
    let mean = err.iter().map(|&e| e as f64).sum::<f64>() / err.len().max(1) as f64;
    // At least the mean, not above it: where the error is the same everywhere (a
    // single-color target against an empty scene) every pixel qualifies.
    let hot: Vec<bool> = err.iter().map(|&e| e as f64 >= mean && e > 1e-6).collect();
    let mut regions = components(&hot, w, h, &err);
    regions.sort_by(|a, b| b.score.total_cmp(&a.score));
    let base = scene.path_count();
    for (k, r) in regions.iter().take(count).enumerate() {
        let n = r.pixels.len() as f64;
        let (cx, cy) = r.pixels.iter().fold((0.0, 0.0), |(x, y), &i| {
            (x + (i % w) as f64, y + (i / w) as f64)
        });
        let (cx, cy) = (cx / n, cy / n);
        // The region's pixel nearest its centroid, so the new path starts inside it.
        let &center = r
            .pixels
            .iter()
            .min_by(|&&a, &&b| {
                let d = |i: usize| ((i % w) as f64 - cx).powi(2) + ((i / w) as f64 - cy).powi(2);
                d(a).total_cmp(&d(b))
            })
            .expect("regions are not empty");
        let mut color = [0.0f64; 3];
        for &i in &r.pixels {
            let t = target.data[i];
            let a = (t[3] as f64).max(1e-6);
            for c in 0..3 {
                color[c] += t[c] as f64 / a;
            }
        }
        let color = color.map(|c| (c / n).clamp(0.0, 1.0));
        let id = format!("p{}", base + k);
        if let Some(b) = r.rectangle(w, h) {
            // A region filling its bounding box and wider than the largest circle (a
            // flat background, a single-color picture) starts as that box.
            scene
                .nodes
                .push(Node::Path(rectangle(id, b, segments, color)));
            continue;
        }
        // At most a quarter of the smaller side, but never under 1.5 px: on a picture of
        // one to five pixels across the floor wins (the circle may overhang the canvas).
        let largest = (0.25 * w.min(h) as f64).max(1.5);
        let radius = (0.5 * (n / std::f64::consts::PI).sqrt()).clamp(1.5, largest);
        let c = [(center % w) as f64 + 0.5, (center / w) as f64 + 0.5];
        scene
            .nodes
            .push(Node::Path(circle(id, c, radius, segments, color)));
    }
}

struct Region {
    pixels: Vec<usize>,
    score: f64,
}

impl Region {
    /// The region's pixel bounding box `[x0, y0, x1, y1]` (pixel edges) when the region
    /// fills at least 90% of it and its smaller side exceeds half the canvas's smaller
    /// side (the largest starting circle's diameter).
    fn rectangle(&self, w: usize, h: usize) -> Option<[f64; 4]> {
        let (mut x0, mut y0, mut x1, mut y1) = (usize::MAX, usize::MAX, 0, 0);
        for &i in &self.pixels {
            let (x, y) = (i % w, i / w);
            (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x + 1), y1.max(y + 1));
        }
        let (bw, bh) = (x1.checked_sub(x0)?, y1.checked_sub(y0)?);
        let filled = self.pixels.len() as f64 >= 0.9 * (bw * bh) as f64;
        let wide = 2 * bw.min(bh) > w.min(h);
        (filled && wide).then_some([x0 as f64, y0 as f64, x1 as f64, y1 as f64])
    }
}

/// A closed path of straight cubic segments along the rectangle `[x0, y0, x1, y1]`
/// (at least one per side, `segments` in all when that is 4 or more), filled with an
/// opaque straight RGB `color`, nonzero rule.
fn rectangle(id: String, b: [f64; 4], segments: usize, color: [f64; 3]) -> crate::scene::Path {
    let [x0, y0, x1, y1] = b;
    let corners = [[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]];
    let n = segments.max(4);
    let mut p = crate::scene::Path::new(id);
    p.move_to(corners[0]);
    for side in 0..4 {
        let (a, b) = (corners[side], corners[side + 1]);
        let k = n / 4 + usize::from(side < n % 4);
        let at = |t: f64| lerp(a, b, t);
        for j in 0..k {
            let (t0, t1) = (j as f64 / k as f64, (j + 1) as f64 / k as f64);
            let end = if j + 1 == k { b } else { at(t1) };
            p.cubic_to(
                at(t0 + (t1 - t0) / 3.0),
                at(t0 + 2.0 * (t1 - t0) / 3.0),
                end,
            );
        }
    }
    p.close();
    p.fill = Some(crate::scene::Fill {
        paint: crate::scene::Paint::Solid(color),
        opacity: 1.0,
        rule: crate::scene::FillRule::NonZero,
    });
    p
}

/// 4-connected components of `hot` pixels, each with its summed error.
fn components(hot: &[bool], w: usize, h: usize, err: &[f32]) -> Vec<Region> {
    let mut seen = vec![false; hot.len()];
    let mut out = Vec::new();
    let mut stack = Vec::new();
    for s in 0..hot.len() {
        if !hot[s] || seen[s] {
            continue;
        }
        seen[s] = true;
        stack.push(s);
        let mut r = Region {
            pixels: Vec::new(),
            score: 0.0,
        };
        while let Some(i) = stack.pop() {
            r.pixels.push(i);
            r.score += err[i] as f64;
            let (x, y) = (i % w, i / w);
            let mut visit = |j: usize| {
                if hot[j] && !seen[j] {
                    seen[j] = true;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if y + 1 < h {
                visit(i + w);
            }
        }
        out.push(r);
    }
    out
}

impl crate::choice::Choice for Mode {
    const WHAT: &'static str = "mode";
    const ALL: &'static [Self] = &[Self::Adaptive, Self::Fixed, Self::Painterly, Self::Trace];
    fn name(self) -> &'static str {
        match self {
            Self::Adaptive => "adaptive",
            Self::Fixed => "fixed",
            Self::Painterly => "painterly",
            Self::Trace => "trace",
        }
    }
    fn aliases(self) -> &'static [&'static str] {
        match self {
            Self::Fixed => &["blobs"],
            Self::Painterly => &["strokes"],
            _ => &[],
        }
    }
}

crate::choice::from_str_by_name!(Mode);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::loss::Loss;
    use crate::raster::RenderOptions;
    use crate::scene::random::curved_paths;

    #[test]
    fn round_sizes_reach_the_budget() {
        assert_eq!(round_sizes(1), vec![1, 0]);
        assert_eq!(round_sizes(4), vec![4, 0]);
        assert_eq!(round_sizes(10), vec![4, 2, 3, 1, 0]);
        for b in [7, 64, 142, 256, 512] {
            let r = round_sizes(b);
            assert_eq!(r.iter().sum::<usize>(), b);
            assert!(r.len() < 16, "{b}: {r:?}");
        }
    }

    /// Adaptive vectorization of a drawing reaches a good PSNR with few paths and beats
    /// random blobs with the same budget.
    #[test]
    fn adaptive_beats_random_blobs() {
        let truth = curved_paths(6, 64, 4);
        let mut target = render(&truth, &RenderOptions::default());
        target.over_background([1.0; 4]);
        let obj = Objective::new(&target, Loss::Mse, Some([1.0; 4]), 1);
        let run = |mode| {
            let opts = VectorizeOptions {
                mode,
                paths: 8,
                iters: 300,
                ..VectorizeOptions::default()
            };
            vectorize(&obj, &opts, &mut |_| Control::Continue).unwrap()
        };
        let a = run(Mode::Adaptive);
        let f = run(Mode::Fixed);
        assert!(a.scene.path_count() <= 8);
        assert!(
            a.psnr > f.psnr + 1.0,
            "adaptive {} fixed {}",
            a.psnr,
            f.psnr
        );
        assert!(a.psnr > 22.0, "{}", a.psnr);
        let again = obj.psnr(&render(&a.scene, &RenderOptions::default()));
        assert!((again - a.psnr).abs() < 1e-9);
    }

    /// issue 13, case 5: a single-color picture used to give 0 paths (no pixel's error
    /// was strictly above the mean). It now starts from one canvas-sized rectangle.
    #[test]
    fn single_color_image_gets_a_path() {
        let target = Image::filled(40, 30, [0.2, 0.4, 0.8, 1.0]);
        let obj = Objective::new(&target, Loss::Mse, Some([1.0; 4]), 1);
        let opts = VectorizeOptions {
            paths: 4,
            iters: 20,
            ..VectorizeOptions::default()
        };
        let out = vectorize(&obj, &opts, &mut |_| Control::Continue).unwrap();
        assert_eq!(out.scene.path_count(), 1);
        assert!(out.psnr > 40.0, "{}", out.psnr);
    }

    /// issue 13: `--iters 0` ran 8 steps (one per round at least). 0 means none.
    #[test]
    fn iters_0_takes_no_steps() {
        let truth = curved_paths(3, 32, 2);
        let mut target = render(&truth, &RenderOptions::default());
        target.over_background([1.0; 4]);
        let obj = Objective::new(&target, Loss::Mse, Some([1.0; 4]), 1);
        for (mode, iters) in [(Mode::Adaptive, 0), (Mode::Fixed, 0), (Mode::Adaptive, 5)] {
            let opts = VectorizeOptions {
                mode,
                paths: 64,
                iters,
                ..VectorizeOptions::default()
            };
            let out = vectorize(&obj, &opts, &mut |_| Control::Continue).unwrap();
            assert!(
                out.steps <= iters,
                "{mode:?}: {} steps for {iters}",
                out.steps
            );
            assert!(out.scene.path_count() > 0, "{mode:?}");
        }
    }

    #[test]
    fn mode_names_round_trip() {
        crate::choice::tests::round_trip::<Mode>();
    }
}
