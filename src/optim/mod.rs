//! Optimization over slices of numbers, shared by the 2D fitter and the 3D trainers:
//! update rules, per-group state with dense and lazy steps, schedules. It knows nothing of
//! scenes, images or losses: the 2D scene's Adam, learning rates and image objective are
//! in [`crate::fit`], the projection onto valid scenes in [`crate::scene`].
//!
//! **The optimizer.** A [`Rule`] (Adam or RMSProp, in `f32` or `f64`) says how one slot
//! moves given its gradient; [`Moments`] holds one parameter group's state under that rule
//! (moments per slot, the first only when the rule keeps them, and the step count).
//! Conventions throughout:
//!
//! * Gradients are `∂L/∂x` of a loss being minimized: slots move against them.
//! * A learning rate is in the slot's own units per step (Adam and RMSProp normalize the
//!   gradient, so a step moves a slot by an amount of the order of its rate). Rates are per slot in the dense
//!   step and per call in the lazy one, so each parameter group has its own; a schedule
//!   ([`Schedule::factor`] as a `scale`, or [`exponential`] per group) changes them over
//!   the run.
//! * Steps count from 1 (Adam's bias correction `1 − βᵗ`); a fresh [`Moments`] has taken 0.
//! * A dense step ([`Moments::step`], the 2D fitter's, through `fit::Adam::step`) treats a
//!   non-finite gradient entry as 0 and counts it, and does not move a slot whose rate is
//!   0. A lazy step ([`Moments::lazy_step`], the voxel trainer's) is applied by the caller
//!   to the slots that got a gradient only, and checks nothing; its constants are
//!   computed once per step and it splits into [blocks](LazyStep::blocks) for parallel
//!   updates.
//! * Pruning slots keeps the moments of the rest ([`Moments::retain`], slots of `stride`
//!   entries); new or cloned slots start with zero moments ([`Moments::extend`]).
//!
//! ```
//! use diffsvg::optim::{Moments, Rule, exponential, progress};
//! // Minimize (x − 3)² over two slots: the first densely, with rate 0.1 per step.
//! let rule = Rule::Adam { beta1: 0.9, beta2: 0.999, eps: 1e-8 };
//! let mut state = Moments::new(rule, 2);
//! let mut x = [0.0f64, 0.0];
//! for _ in 0..500 {
//!     let g = [2.0 * (x[0] - 3.0), 2.0 * (x[1] - 3.0)];
//!     state.step(&mut x, &g, &[0.1, 0.0], 1.0); // rate 0 freezes the second slot
//! }
//! assert!((x[0] - 3.0).abs() < 1e-2 && x[1] == 0.0);
//!
//! // The same lazily in f32 with RMSProp, touching only slot 1, at a rate decaying
//! // exponentially from 0.1 to 0.01 over the run.
//! let mut state = Moments::new(Rule::RmsProp { beta: 0.95f32, eps: 1e-8 }, 2);
//! let mut y = [0.0f32, 0.0];
//! for it in 0..500 {
//!     let lr = exponential([0.1, 0.01], progress(it, 500));
//!     let g = 2.0 * (y[1] - 3.0);
//!     state.lazy_step().apply(1, &mut y[1], g, lr);
//! }
//! assert!((y[1] - 3.0).abs() < 0.1 && y[0] == 0.0);
//! ```

mod moments;
mod rule;
mod schedule;

pub use moments::{LazyStep, Moments};
pub use rule::{Rule, Update};
pub use schedule::{Schedule, exponential, progress};
