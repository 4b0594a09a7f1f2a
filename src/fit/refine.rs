//! The refinement loop: render, loss, exact gradients, Adam, projection, repeated.

use std::time::{Duration, Instant};

use super::{Adam, AdamConfig, LearningRates, Objective};
use crate::metrics::{median, psnr_from_mse};
use crate::optim::Schedule;
use crate::raster::prepare::prepare_forward;
use crate::raster::{Prepared, RenderOptions, render_prepared};
use crate::scene::Scene;
use crate::scene::project;

/// Settings of one refinement run.
#[derive(Clone, Debug)]
pub struct FitOptions {
    /// Optimizer steps.
    pub iters: usize,
    /// Learning rates per group (0 freezes a group).
    pub rates: LearningRates,
    /// Rate schedule over the run.
    pub schedule: Schedule,
    /// Adam's constants.
    pub adam: AdamConfig,
    /// Stop as soon as the PSNR reaches this many dB.
    pub until_psnr: Option<f64>,
    /// Rasterizer settings.
    pub render: RenderOptions,
    /// Fit the background's color too (an opaque background only; its rate is
    /// 5 times `rates.color`): the drawing is compared over it, so a backdrop the drawing does
    /// not cover is matched by the background rather than by stretching shapes.
    pub fit_background: bool,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            iters: 500,
            rates: LearningRates::default(),
            schedule: Schedule::Constant,
            adam: AdamConfig::default(),
            until_psnr: None,
            render: RenderOptions::default(),
            fit_background: false,
        }
    }
}

/// The background's rate as a multiple of `rates.color`: it is one color under every
/// uncovered pixel, and at the colors' rate a drawing's shapes grow over a wrong backdrop
/// faster than the backdrop changes (a circle fitted from a white start toward a blue
/// backdrop covered the canvas, and the backdrop stopped moving).
const BACKGROUND_RATE: f64 = 5.0;

/// What the observer sees after each evaluation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Step {
    /// Steps taken before this evaluation (0 = the initial scene).
    pub iter: usize,
    /// Objective value.
    pub loss: f64,
    /// PSNR against the target, dB.
    pub psnr: f64,
    /// Wall time since the run started.
    pub elapsed: Duration,
    /// Milliseconds this evaluation took: preparation, rendering, the objective and, when
    /// a step follows, the gradient (rendered and differentiated in one pass for
    /// per-pixel objectives).
    pub step_ms: f64,
}

/// An observer's answer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Control {
    /// Keep going.
    Continue,
    /// Stop now (the best scene so far is returned).
    Stop,
}

/// Why a run ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StopReason {
    /// All iterations ran.
    Finished,
    /// The PSNR goal was reached.
    ReachedPsnr,
    /// The observer asked to stop (e.g. Ctrl-C).
    Interrupted,
}

/// The result of a run.
#[derive(Clone, Debug)]
pub struct FitOutcome {
    /// The scene with the lowest loss seen.
    pub best: Scene,
    /// Its loss.
    pub best_loss: f64,
    /// Its PSNR, dB.
    pub best_psnr: f64,
    /// Optimizer steps taken.
    pub steps: usize,
    /// Every evaluation, in order.
    pub history: Vec<Step>,
    /// Why the run ended.
    pub reason: StopReason,
    /// Median milliseconds per optimizer step: preparation, rendering, objective and
    /// gradient (the evaluations that a step followed).
    pub median_step_ms: f64,
    /// With [`FitOptions::fit_background`] (and an opaque background): the background,
    /// straight RGBA, that went with the best scene.
    pub background: Option<[f32; 4]>,
}

/// Refines `scene` toward `objective`: `opts.iters` Adam steps, each preceded by an
/// evaluation, plus a last evaluation after the final step. Deterministic: the same inputs
/// give the same bits on any thread count. `observe` is called after every evaluation.
pub fn refine(
    mut scene: Scene,
    objective: &Objective,
    opts: &FitOptions,
    observe: &mut dyn FnMut(&Step, &Scene) -> Control,
) -> FitOutcome {
    let start = Instant::now();
    let rates = opts.rates.per_slot(&scene);
    let mut adam = Adam::new(rates.len(), opts.adam);
    // Only parameters change during a run: the best scene is the starting one with the
    // best parameters, kept as a vector (a scene clone per improvement cost copies and
    // allocations on the serial path of every step).
    let mut best = scene.clone();
    let mut best_params: Option<Vec<f64>> = None;
    let mut best_loss = f64::INFINITY;
    let mut best_psnr = f64::NEG_INFINITY;
    // Grown as steps are taken: `iters` is a request, not an allocation size.
    let mut history = Vec::new();
    let mut step_ms = Vec::new();
    let mut reason = StopReason::Finished;
    let mut steps = 0;
    // The background as a parameter: its own objective, moved by its own Adam.
    let mut bg = opts
        .fit_background
        .then(|| objective.background())
        .flatten()
        .filter(|b| b[3] >= 1.0)
        .map(|b| {
            let own = objective.clone();
            (
                own,
                [b[0] as f64, b[1] as f64, b[2] as f64],
                Adam::new(3, opts.adam),
            )
        });
    let mut best_bg = None;
    for it in 0..=opts.iters {
        let objective = bg.as_ref().map_or(objective, |b| &b.0);
        let t0 = Instant::now();
        // Every evaluation but the last is followed by a step: rendered and differentiated
        // together. The last one only renders.
        let (loss, mse, grads) = if it < opts.iters {
            let prepared = Prepared::new(&scene, &opts.render);
            let (img, loss, mse, g) = objective.render_and_backward(&scene, &prepared);
            let g_bg = bg
                .as_ref()
                .and_then(|_| objective.background_gradient(&img));
            (loss, mse, Some((g, g_bg)))
        } else {
            let mut forward =
                prepare_forward(&scene, opts.render.tolerance, opts.render.exact_filters);
            forward.set_exact_overlaps(opts.render.exact_overlaps);
            let img = render_prepared(&forward);
            let (loss, mse, _) = objective.eval_with_mse(&img);
            (loss, mse, None)
        };
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        let psnr = psnr_from_mse(mse);
        if loss < best_loss {
            best_loss = loss;
            best_psnr = psnr;
            best_params = Some(scene.params());
            best_bg = objective.background().filter(|_| bg.is_some());
        }
        let step = Step {
            iter: it,
            loss,
            psnr,
            elapsed: start.elapsed(),
            step_ms: ms,
        };
        history.push(step);
        if observe(&step, &scene) == Control::Stop {
            reason = StopReason::Interrupted;
            break;
        }
        if opts.until_psnr.is_some_and(|goal| psnr >= goal) {
            reason = StopReason::ReachedPsnr;
            break;
        }
        let Some((grads, g_bg)) = grads else {
            break;
        };
        let scale = opts.schedule.factor(it, opts.iters);
        if let (Some((own, color, bg_adam)), Some(g)) = (bg.as_mut(), g_bg) {
            bg_adam.step(color, &g, &[BACKGROUND_RATE * opts.rates.color; 3], scale);
            for c in color.iter_mut() {
                *c = c.clamp(0.0, 1.0);
            }
            *own = own.with_background([color[0] as f32, color[1] as f32, color[2] as f32, 1.0]);
        }
        step_ms.push(ms);
        let mut params = scene.params();
        adam.step(&mut params, &grads, &rates, scale);
        scene.set_params(&params);
        project(&mut scene);
        steps += 1;
    }
    if let Some(p) = best_params {
        best.set_params(&p);
    }
    FitOutcome {
        best,
        best_loss,
        best_psnr,
        steps,
        history,
        reason,
        median_step_ms: median(&mut step_ms),
        background: best_bg,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::loss::Loss;
    use crate::raster::render;
    use crate::scene::ParamLayout;
    use crate::scene::random::curved_paths;

    /// A scene refined toward a moved copy of itself gets close to it, monotonically
    /// better than where it started, and the best result is reported.
    /// `truth` with every point moved by 1.5 to 2 px.
    fn perturbed(truth: &Scene) -> Scene {
        let mut init = truth.clone();
        let mut p = init.params();
        let layout = ParamLayout::new(&init);
        for (i, s) in layout.slots.iter().enumerate() {
            if s.group == crate::scene::ParamGroup::Points {
                p[i] += if i % 3 == 0 { 2.0 } else { -1.5 };
            }
        }
        init.set_params(&p);
        init
    }

    /// The fit renders with its own render options (here exact overlaps), so the best
    /// PSNR it reports is that of rendering its result with them.
    #[test]
    fn renders_with_its_options() {
        let render_opts = RenderOptions {
            exact_overlaps: true,
            ..RenderOptions::default()
        };
        let truth = curved_paths(4, 48, 11);
        let target = render(&truth, &render_opts);
        let obj = Objective::new(&target, Loss::Mse, None, 1);
        let opts = FitOptions {
            iters: 10,
            render: render_opts,
            ..FitOptions::default()
        };
        let out = refine(perturbed(&truth), &obj, &opts, &mut |_, _| {
            Control::Continue
        });
        assert_eq!(obj.psnr(&render(&out.best, &render_opts)), out.best_psnr);
    }

    #[test]
    fn recovers_a_perturbed_scene() {
        let truth = curved_paths(4, 48, 11);
        let target = render(&truth, &RenderOptions::default());
        let init = perturbed(&truth);
        let obj = Objective::new(&target, Loss::Mse, None, 1);
        let opts = FitOptions {
            iters: 150,
            ..FitOptions::default()
        };
        let out = refine(init, &obj, &opts, &mut |_, _| Control::Continue);
        let first = out.history[0].psnr;
        assert!(out.best_psnr > first + 10.0, "{first} → {}", out.best_psnr);
        assert!(out.best_psnr > 35.0, "{}", out.best_psnr);
        assert_eq!(out.steps, 150);
        assert_eq!(out.history.len(), 151);
        let again = obj.psnr(&render(&out.best, &RenderOptions::default()));
        assert_eq!(again, out.best_psnr);
    }

    #[test]
    fn stops_at_the_psnr_goal_and_on_request() {
        let truth = curved_paths(2, 32, 5);
        let target = render(&truth, &RenderOptions::default());
        let obj = Objective::new(&target, Loss::Mse, None, 1);
        let opts = FitOptions {
            until_psnr: Some(30.0),
            ..FitOptions::default()
        };
        let out = refine(truth.clone(), &obj, &opts, &mut |_, _| Control::Continue);
        assert_eq!(out.reason, StopReason::ReachedPsnr);
        assert_eq!(out.steps, 0);
        let mut calls = 0;
        let out = refine(truth, &obj, &FitOptions::default(), &mut |_, _| {
            calls += 1;
            if calls == 3 {
                Control::Stop
            } else {
                Control::Continue
            }
        });
        assert_eq!(out.reason, StopReason::Interrupted);
        assert_eq!(out.steps, 2);
    }
}
