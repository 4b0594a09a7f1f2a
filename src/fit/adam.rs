//! The 2D fitter's optimizer: Adam with bias correction in `f64`, one learning rate per
//! parameter slot from per-group rates.

use crate::optim::{Moments, Rule};
use crate::scene::params::Part;
use crate::scene::{Paint, ParamGroup, ParamLayout, Scene};

/// Adam's constants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AdamConfig {
    /// Decay of the first moment.
    pub beta1: f64,
    /// Decay of the second moment.
    pub beta2: f64,
    /// Added to `√v̂` to keep steps finite.
    pub eps: f64,
}

impl From<AdamConfig> for Rule<f64> {
    fn from(c: AdamConfig) -> Self {
        Rule::Adam {
            beta1: c.beta1,
            beta2: c.beta2,
            eps: c.eps,
        }
    }
}

impl Default for AdamConfig {
    /// β₁ = 0.9, β₂ = 0.999, ε = 1e-8 (the values of the Adam paper and DiffVG).
    fn default() -> Self {
        AdamConfig {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
        }
    }
}

/// Learning rate per parameter group, in the group's own units per step (pixels for
/// points, `[0, 1]` units for colors and opacities, stroke-frame units for widths). A
/// rate of 0 freezes the group.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LearningRates {
    /// Control points, pixels.
    pub points: f64,
    /// Solid colors and stop colors.
    pub color: f64,
    /// Fill, stroke, stop and group opacities.
    pub opacity: f64,
    /// Stroke widths.
    pub width: f64,
    /// Gradient geometry (end points, centers, radii), device pixels: per slot the rate is
    /// divided by the gradient transform's scale, so that a gradient given in
    /// `objectBoundingBox` units (where 1 is the whole shape) moves as fast as one in
    /// user space.
    pub paint: f64,
    /// Gradient stop offsets.
    pub stops: f64,
    /// Transform parameters (a primitive's rotation), in pixels of motion at the shape's
    /// edge: per slot the rate is divided by the shape's radius (half its diagonal for a
    /// rectangle), so that a rotation moves the outline as fast as the points' rate does.
    pub transform: f64,
    /// Filter primitives' numbers, in device pixels for offsets and blur deviations; a
    /// color-matrix value or feComposite's `k` moves by a tenth of it (unitless, like a
    /// color).
    pub filter: f64,
}

impl Default for LearningRates {
    /// Rates that work for drawings of a few hundred pixels: 1 px for points (as DiffVG),
    /// 0.01 for colors and opacities, 0.1 for widths, 0.5 px for gradient geometry, 0.005
    /// for stops, 0.5 px (at the edge) for rotations, 0.1 px for filter offsets and blurs.
    fn default() -> Self {
        LearningRates {
            points: 1.0,
            color: 0.01,
            opacity: 0.01,
            width: 0.1,
            paint: 0.5,
            stops: 0.005,
            transform: 0.5,
            filter: 0.1,
        }
    }
}

impl LearningRates {
    /// The rate of one group.
    pub fn get(&self, g: ParamGroup) -> f64 {
        match g {
            ParamGroup::Points => self.points,
            ParamGroup::Color => self.color,
            ParamGroup::Opacity => self.opacity,
            ParamGroup::StrokeWidth => self.width,
            ParamGroup::PaintGeometry => self.paint,
            ParamGroup::StopOffset => self.stops,
            ParamGroup::Transform => self.transform,
            ParamGroup::Filter => self.filter,
        }
    }

    /// Mutable access to one group's rate.
    pub fn get_mut(&mut self, g: ParamGroup) -> &mut f64 {
        match g {
            ParamGroup::Points => &mut self.points,
            ParamGroup::Color => &mut self.color,
            ParamGroup::Opacity => &mut self.opacity,
            ParamGroup::StrokeWidth => &mut self.width,
            ParamGroup::PaintGeometry => &mut self.paint,
            ParamGroup::StopOffset => &mut self.stops,
            ParamGroup::Transform => &mut self.transform,
            ParamGroup::Filter => &mut self.filter,
        }
    }

    /// Sets the groups in `frozen` to 0.
    pub fn freeze(&mut self, frozen: &[ParamGroup]) {
        for &g in frozen {
            *self.get_mut(g) = 0.0;
        }
    }

    /// One rate per slot of `scene`'s parameter vector (see [`ParamLayout`]); 0 for the
    /// points of an image's rectangle, which fits keep fixed.
    pub fn per_slot(&self, scene: &Scene) -> Vec<f64> {
        let layout = ParamLayout::new(scene);
        let mut rates: Vec<f64> = layout.slots.iter().map(|s| self.get(s.group)).collect();
        // A unitless filter number (a color-matrix value, feComposite's k) moves by a
        // tenth of the rate of pixel quantities.
        let mut slot = 0;
        crate::scene::params::walk(&mut scene.clone(), &mut |_, _, part, _| {
            if part == (Part::Filter { unitless: true }) {
                rates[slot] *= 0.1;
            }
            slot += 1;
        });
        let mut i = 0;
        scene.for_each_path(|p| {
            let offsets = &layout.paths[i];
            i += 1;
            let paints = [
                (p.fill.as_ref().map(|f| &f.paint), offsets.fill),
                (p.stroke.as_ref().map(|s| &s.paint), offsets.stroke),
            ];
            // An image's rectangle stays where it is: the writer puts an image only at its
            // own rectangle (its pixels have no slots at all).
            if let Some(Paint::Image(_)) = paints[0].0 {
                for r in &mut rates[offsets.points..offsets.points + 2 * p.points.len()] {
                    *r = 0.0;
                }
            }
            // A rotation's rate is the edge's motion over the shape's radius.
            if let Some(prim) = &p.primitive {
                let radius = prim.radius();
                let last = offsets.points + prim.slot_count() - 1;
                if layout.slots[last].group == ParamGroup::Transform {
                    rates[last] = if radius > 0.0 {
                        rates[last] / radius
                    } else {
                        0.0
                    };
                }
            }
            for (paint, at) in paints {
                let (Some(Paint::Gradient(g)), Some(at)) = (paint, at) else {
                    continue;
                };
                let t = &g.transform;
                let scale = (t[0] * t[3] - t[1] * t[2]).abs().sqrt();
                if scale.is_finite() && scale > 0.0 {
                    for r in &mut rates[at.base..at.stops] {
                        *r /= scale;
                    }
                }
            }
        });
        // A group transform's angle and scale move its content's edge by the reach
        // times the change (the scale's by the reach over the scale).
        let reaches = crate::scene::transform::reaches(&scene.nodes);
        // A general map's linear entries move it by the reach over the mean scale.
        for (&at, (reach, s, n)) in layout.transforms.iter().zip(reaches) {
            let per = |r: f64| if reach > 0.0 { r / reach } else { 0.0 };
            if n == 4 {
                rates[at + 2] = per(rates[at + 2]);
                rates[at + 3] = per(rates[at + 3]) * s;
            } else {
                for r in &mut rates[at + 2..at + n] {
                    *r = per(*r) * s;
                }
            }
        }
        rates
    }
}

/// Adam's state for a parameter vector of fixed length: [`Moments`] with the rule
/// [`Rule::Adam`] in `f64`, stepped densely.
#[derive(Clone, Debug)]
pub struct Adam {
    moments: Moments<f64>,
}

impl Adam {
    /// Fresh state (zero moments) for `len` parameters.
    pub fn new(len: usize, config: AdamConfig) -> Self {
        Adam {
            moments: Moments::new(config.into(), len),
        }
    }

    /// Steps taken so far.
    pub fn steps(&self) -> i32 {
        self.moments.steps()
    }

    /// One bias-corrected step: `params[i] -= lr[i] · m̂ᵢ / (√v̂ᵢ + ε)`, every rate multiplied
    /// by `scale` (the schedule). A non-finite gradient entry counts as 0, so one bad pixel
    /// cannot poison the state; slots with rate 0 do not move. Returns how many gradient
    /// entries were not finite. (See [`Moments::step`].)
    pub fn step(&mut self, params: &mut [f64], grads: &[f64], lr: &[f64], scale: f64) -> usize {
        self.moments.step(params, grads, lr, scale)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn first_step_moves_by_the_learning_rate() {
        // With bias correction, the first step is lr · sign(g) whatever |g| is.
        let mut a = Adam::new(3, AdamConfig::default());
        let mut p = [1.0, 1.0, 1.0];
        a.step(&mut p, &[1e-3, -50.0, 0.0], &[0.1, 0.1, 0.1], 1.0);
        assert!((p[0] - 0.9).abs() < 1e-6, "{p:?}");
        assert!((p[1] - 1.1).abs() < 1e-6, "{p:?}");
        assert_eq!(p[2], 1.0);
    }

    #[test]
    fn minimizes_a_quadratic_and_respects_frozen_slots() {
        let mut a = Adam::new(2, AdamConfig::default());
        let mut p = [5.0, 5.0];
        for _ in 0..2000 {
            let g = [2.0 * (p[0] - 2.0), 2.0 * (p[1] + 1.0)];
            a.step(&mut p, &g, &[0.05, 0.0], 1.0);
        }
        assert!((p[0] - 2.0).abs() < 1e-3, "{p:?}");
        assert_eq!(p[1], 5.0);
    }

    #[test]
    fn non_finite_gradients_are_ignored() {
        let mut a = Adam::new(2, AdamConfig::default());
        let mut p = [0.0, 0.0];
        let bad = a.step(&mut p, &[f64::NAN, f64::INFINITY], &[1.0, 1.0], 1.0);
        assert_eq!(bad, 2);
        assert_eq!(p, [0.0, 0.0]);
        a.step(&mut p, &[1.0, 1.0], &[1.0, 1.0], 1.0);
        assert!(p.iter().all(|v| v.is_finite() && *v < 0.0));
    }
}
