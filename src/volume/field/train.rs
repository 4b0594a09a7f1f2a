//! Fitting a field to posed pixels: mini-batches of rays, MSE loss, Adam on every
//! parameter (lazily on the hash table entries a batch touched), the occupancy grid
//! refreshed as training goes.
//!
//! **Determinism.** A batch is cut into chunks of [`CHUNK`] rays whatever the number of
//! threads; each chunk is marched and back-propagated by one thread into its own
//! gradient buffers, and the buffers are reduced in chunk order: the networks' gradients
//! summed chunk after chunk, the hash table's scattered level by level (levels in
//! parallel, each walking the chunks' samples in order). So a fixed seed gives the same
//! model bits on any number of threads.

use std::time::Instant;

use rayon::prelude::*;

use super::hash::F;
use super::model::{Ngp, mix};
use super::render::{Grads, RayTape, RenderSettings, ray_backward, ray_forward, record_len};
use crate::error::{Error, Result};
use crate::optim::{Moments, Rule, exponential};
use crate::rng::Rng;
use crate::volume::Ray;

/// Rays per chunk of a batch (the unit of work and of the gradient reduction).
pub(crate) const CHUNK: usize = 64;

/// Everything [`train`] needs besides the model and the rays.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainOptions {
    /// Number of iterations (mini-batches), at least 1.
    pub iterations: usize,
    /// Time budget in seconds of training (0: none); when it runs out training stops,
    /// and the learning-rate schedule follows the fraction of the budget spent instead
    /// of the iteration count (so such runs depend on the machine's speed).
    pub seconds: f32,
    /// Most rays per iteration.
    pub batch_size: usize,
    /// Samples (network evaluations) aimed at per iteration, as Instant-NGP does: each
    /// iteration draws `batch_samples / (samples per ray of the last iteration)` rays,
    /// between 64 (the chunk of rays) and `batch_size` (the first iteration draws 64). 0: always
    /// `batch_size` rays.
    pub batch_samples: usize,
    /// Seed of the ray batches, the jitter and the occupancy updates.
    pub seed: u64,
    /// How training rays are marched (the background should be the photos').
    pub render: RenderSettings,
    /// Adam's rule for every parameter (Instant-NGP: β₁ 0.9, β₂ 0.99, ε 1e-15).
    pub optimizer: Rule<f32>,
    /// Learning rate at the start and at the end, decaying exponentially in between.
    pub lr: [f32; 2],
    /// Refresh the occupancy grid every this many iterations (0: never; all cells
    /// occupied).
    pub occupancy_every: usize,
    /// Refresh every cell (instead of a random quarter) until this iteration.
    pub occupancy_warmup: usize,
    /// A cell stays occupied while `σ·Δ` exceeds this (or the mean over cells, if lower).
    pub occupancy_threshold: f32,
}

impl Default for TrainOptions {
    /// 2000 iterations of 2¹⁶ samples (at most 8192 rays), Adam (0.9, 0.99, 1e-15) at 1e-2 → 1e-3, the
    /// occupancy grid refreshed every 16 iterations (every cell for the first 128) with
    /// threshold 0.01.
    fn default() -> Self {
        TrainOptions {
            iterations: 2000,
            seconds: 0.0,
            batch_size: 8192,
            batch_samples: 1 << 16,
            seed: 0,
            render: RenderSettings::default(),
            optimizer: Rule::Adam {
                beta1: 0.9,
                beta2: 0.99,
                eps: 1e-15,
            },
            lr: [1e-2, 1e-3],
            occupancy_every: 16,
            occupancy_warmup: 128,
            occupancy_threshold: 0.01,
        }
    }
}

/// Progress after one iteration, passed to the observer of [`train`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrainStep {
    /// Iterations done so far (1 after the first).
    pub iteration: usize,
    /// Mean squared error of this batch (over rays and channels), before the update.
    pub loss: f32,
    /// PSNR of this batch, dB.
    pub psnr: f32,
    /// Network evaluations (samples) of this batch.
    pub samples: usize,
    /// Samples per second of this iteration's wall time (forward, backward, update).
    pub samples_per_second: f32,
    /// Rays per second of this iteration's wall time.
    pub rays_per_second: f32,
    /// Fraction of occupancy cells marked occupied.
    pub occupied: f32,
    /// Seconds of training so far (the observer's time not counted).
    pub elapsed: f32,
}

/// How [`train`] ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrainOutcome {
    /// Iterations done.
    pub iterations: usize,
    /// Whether the observer stopped training early.
    pub stopped: bool,
    /// Batch MSE of the last iteration.
    pub loss: f32,
    /// Wall time of training, seconds (the observer's time not counted).
    pub seconds: f32,
    /// Samples evaluated over the run.
    pub samples: u64,
}

/// Fits `model` to the colors `colors[i]` seen along `rays[i]` (unit directions, linear
/// RGB in `[0, 1]` composited over `opts.render.background`). `observe` runs after every
/// iteration and returns false to stop.
///
/// Errors: mismatched or empty ray and color lists, non-finite colors, invalid options.
pub fn train(
    model: &mut Ngp,
    rays: &[Ray],
    colors: &[[f32; 3]],
    opts: &TrainOptions,
    observe: &mut dyn FnMut(&TrainStep, &Ngp) -> bool,
) -> Result<TrainOutcome> {
    validate(rays, colors, opts).map_err(|what| Error::InvalidValue {
        path: "ngp training".into(),
        what,
    })?;
    let mut rng = Rng::new(opts.seed);
    let mut hash_m = Moments::new(opts.optimizer, model.hash.params.len());
    let mut dens_m = Moments::new(opts.optimizer, model.density.params.len());
    let mut col_m = Moments::new(opts.optimizer, model.color.params.len());
    let levels = model.hash.levels();
    let ll = model.hash.level_len();
    let mut hash_grad = vec![0.0f32; model.hash.params.len()];
    let mut touched = vec![false; model.hash.params.len() / F];
    let mut lists: Vec<Vec<u32>> = vec![Vec::new(); levels];
    let rl = record_len(model);
    let delta = opts.render.delta(model);
    let start = Instant::now();
    let mut observing = std::time::Duration::ZERO;
    let mut outcome = TrainOutcome {
        iterations: 0,
        stopped: false,
        loss: f32::NAN,
        seconds: 0.0,
        samples: 0,
    };
    let (mut last_samples, mut last_rays) = (0usize, 0usize);
    for it in 0..opts.iterations {
        let spent = (start.elapsed() - observing).as_secs_f32();
        if opts.seconds > 0.0 && spent >= opts.seconds {
            break;
        }
        // Refresh the grid every `occupancy_every` iterations, and at iterations 1, 2, 4, 8,
        // … before that: a fresh model fills the box, and its rays are long.
        let every = opts.occupancy_every;
        if every > 0 && it > 0 && (it % every == 0 || (it < every && it.is_power_of_two())) {
            let seed = mix(opts.seed ^ 0x0CC0 ^ (it as u64) << 20);
            model.update_occupancy(
                seed,
                it < opts.occupancy_warmup,
                delta,
                opts.occupancy_threshold,
                0.95,
            );
        }
        let t_step = Instant::now();
        let n_rays = if opts.batch_samples == 0 {
            opts.batch_size
        } else if it == 0 {
            CHUNK.min(opts.batch_size)
        } else {
            let per_ray = (last_samples as f64 / last_rays.max(1) as f64).max(1.0);
            ((opts.batch_samples as f64 / per_ray) as usize)
                .clamp(CHUNK.min(opts.batch_size), opts.batch_size)
        };
        let batch: Vec<u32> = (0..n_rays).map(|_| rng.below(rays.len()) as u32).collect();
        let scale = 2.0 / (3.0 * batch.len() as f32);
        let m: &Ngp = model;
        let step_seed = mix(opts.seed ^ (it as u64).wrapping_mul(0xA24B_AED4_963E_E407));
        let outs: Vec<(f64, Grads)> = batch
            .par_chunks(CHUNK)
            .enumerate()
            .map(|(ci, idx)| {
                let mut grads = Grads::new(m);
                let mut tape = RayTape::default();
                let mut sse = 0.0f64;
                for (k, &i) in idx.iter().enumerate() {
                    let pos = (ci * CHUNK + k) as u64;
                    let jitter = (mix(step_seed ^ pos) >> 40) as f32 / (1u64 << 24) as f32;
                    let (ray, y) = (&rays[i as usize], colors[i as usize]);
                    let c = ray_forward(m, ray, &opts.render, jitter, &mut tape, true);
                    let mut d = [0.0f32; 3];
                    for ch in 0..3 {
                        let e = c[ch] - y[ch];
                        sse += (e * e) as f64;
                        d[ch] = scale * e;
                    }
                    ray_backward(m, &opts.render, &mut tape, c, d, &mut grads);
                }
                (sse, grads)
            })
            .collect();
        // Reduce in chunk order.
        let mut sse = 0.0f64;
        let mut samples = 0usize;
        let (first, rest) = outs.split_first().expect("a batch has a chunk");
        let mut gd = first.1.density.clone();
        let mut gc = first.1.color.clone();
        for (s, g) in &outs {
            sse += s;
            samples += g.records.len() / rl;
        }
        for (_, g) in rest {
            gd.iter_mut().zip(&g.density).for_each(|(a, b)| *a += b);
            gc.iter_mut().zip(&g.color).for_each(|(a, b)| *a += b);
        }
        // The hash table: per level, the chunks' samples in order.
        let hash = &model.hash;
        hash_grad
            .par_chunks_mut(ll)
            .zip(touched.par_chunks_mut(ll / F))
            .zip(lists.par_iter_mut())
            .enumerate()
            .for_each(|(l, ((grad, flags), list))| {
                for (_, g) in &outs {
                    for r in g.records.chunks_exact(rl) {
                        let x = glam::Vec3::new(r[0], r[1], r[2]);
                        hash.scatter_level(l, x, &r[3 + l * F..3 + (l + 1) * F], grad, flags, list);
                    }
                }
                // Visit the touched entries in index order (so the update does not depend on
                // which sample touched an entry first).
                list.sort_unstable();
            });
        let frac = if opts.seconds > 0.0 {
            ((start.elapsed() - observing).as_secs_f32() / opts.seconds).min(1.0)
        } else {
            crate::optim::progress(it, opts.iterations)
        };
        let lr = exponential(opts.lr, frac);
        let lr_d = vec![lr; gd.len()];
        let lr_c = vec![lr; gc.len()];
        dens_m.step(&mut model.density.params, &gd, &lr_d, 1.0);
        col_m.step(&mut model.color.params, &gc, &lr_c, 1.0);
        let blocks: Vec<_> = hash_m.lazy_step().blocks(ll).collect();
        model
            .hash
            .params
            .par_chunks_mut(ll)
            .zip(hash_grad.par_chunks_mut(ll))
            .zip(touched.par_chunks_mut(ll / F))
            .zip(lists.par_iter_mut())
            .zip(blocks.into_par_iter())
            .for_each(|((((p, grad), flags), list), mut step)| {
                for &e in list.iter() {
                    let e = e as usize;
                    flags[e] = false;
                    for j in 0..F {
                        let i = e * F + j;
                        step.apply(i, &mut p[i], grad[i], lr);
                        grad[i] = 0.0;
                    }
                }
                list.clear();
            });
        (last_samples, last_rays) = (samples, batch.len());
        let loss = (sse / (3.0 * batch.len() as f64)) as f32;
        let secs = t_step.elapsed().as_secs_f32().max(1e-9);
        outcome.iterations = it + 1;
        outcome.loss = loss;
        outcome.samples += samples as u64;
        let step = TrainStep {
            iteration: it + 1,
            loss,
            psnr: -10.0 * loss.max(1e-12).log10(),
            samples,
            samples_per_second: samples as f32 / secs,
            rays_per_second: batch.len() as f32 / secs,
            occupied: model.occupied_fraction(),
            elapsed: (start.elapsed() - observing).as_secs_f32(),
        };
        let t_observe = Instant::now();
        let go_on = observe(&step, model);
        observing += t_observe.elapsed();
        if !go_on {
            outcome.stopped = true;
            break;
        }
    }
    outcome.seconds = (start.elapsed() - observing).as_secs_f32();
    Ok(outcome)
}

fn validate(rays: &[Ray], colors: &[[f32; 3]], o: &TrainOptions) -> Result<(), String> {
    super::super::check_rays_and_colors(rays, colors)?;
    if o.batch_size == 0 {
        return Err("batch_size is 0".into());
    }
    o.render.validate()?;
    if !o.lr.iter().all(|r| r.is_finite() && *r >= 0.0) {
        return Err(format!("learning rates {:?} must be finite and ≥ 0", o.lr));
    }
    if !(o.seconds.is_finite() && o.seconds >= 0.0) {
        return Err(format!("seconds {} must be finite and ≥ 0", o.seconds));
    }
    if !(o.occupancy_threshold.is_finite() && o.occupancy_threshold >= 0.0) {
        return Err(format!(
            "occupancy_threshold {} must be finite and ≥ 0",
            o.occupancy_threshold
        ));
    }
    if !o.optimizer.is_valid() {
        return Err(format!(
            "optimizer {:?}: betas must be in [0, 1), eps > 0",
            o.optimizer
        ));
    }
    Ok(())
}
