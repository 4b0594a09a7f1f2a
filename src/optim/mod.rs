//! Optimization: Adam with per-group learning rates, schedules and projection.
