//! Optimization: Adam with per-group learning rates and schedules, projection back onto
//! valid scenes after every step, and the image objective (loss, background, pyramid).
//!
//! One step of refinement is: render, [`Objective::eval`] for the loss and `∂L/∂image`,
//! backward pass for `∂L/∂params`, [`Adam::step`] with per-slot learning rates from
//! [`LearningRates::per_slot`] scaled by [`Schedule::factor`], then [`project`].

mod adam;
mod objective;
mod project;
mod schedule;

pub use adam::{Adam, AdamConfig, LearningRates};
pub use objective::Objective;
pub use project::project;
pub use schedule::Schedule;
