//! Checking analytic gradients against central finite differences.
//!
//! ```
//! use diffsvg::{Image, Scene, Sizing, gradcheck, loss::Loss, raster::RenderOptions};
//! let svg = r#"<svg xmlns="http://www.w3.org/2000/svg" width="16" height="16">
//!   <rect x="4" y="4" width="8" height="8" fill="crimson"/></svg>"#;
//! let scene = Scene::from_svg_str(svg, "square.svg", Sizing::Natural)?;
//! let target = Image::filled(16, 16, [0.0, 0.0, 1.0, 1.0]);
//! let (_analytic, _numeric, groups) =
//!     gradcheck::check(&scene, &target, Loss::Mse, &RenderOptions::default(), None, None);
//! assert!(groups.iter().all(|g| g.passes(gradcheck::DEFAULT_TOLERANCE)));
//! # Ok::<(), diffsvg::Error>(())
//! ```

use crate::image_io::Image;
use crate::loss::Loss;
use crate::raster::{RenderOptions, backward_prepared, prepare, render_prepared};
use crate::scene::{ParamGroup, ParamLayout, Scene};

/// Agreement of one parameter group.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroupCheck {
    /// The group.
    pub group: ParamGroup,
    /// Parameters checked.
    pub checked: usize,
    /// Worst `max(|analytic − numeric| − bound, 0) / max(|numeric|, floor)`, where `bound`
    /// is the numeric estimate's own error bound ([`Numeric::error`]) and `floor` is the
    /// larger of 1e-2 of the group's largest numeric gradient and 1e-4 of the largest of any
    /// group checked (so tiny gradients are held to an absolute bound).
    pub worst: f64,
    /// Index (into the parameter vector) of the worst parameter.
    pub worst_index: usize,
    /// Analytic and numeric gradient of the worst parameter.
    pub worst_pair: (f64, f64),
}

impl std::fmt::Display for GroupCheck {
    /// One line: `points: 14 parameters, worst relative error 1.3e-3 (slot 1: analytic …,
    /// numeric …)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{:>9}: {} parameters, worst relative error {:.3e} (slot {}: analytic {:.6e}, numeric {:.6e})",
            self.group.name(),
            self.checked,
            self.worst,
            self.worst_index,
            self.worst_pair.0,
            self.worst_pair.1
        )
    }
}

/// Step used for a central difference on a parameter of `group` with value `v`.
pub fn step(group: ParamGroup, v: f64) -> f64 {
    match group {
        ParamGroup::Points => 1e-3,
        ParamGroup::StopOffset => 1e-4,
        // Never step through zero width, where the stroke vanishes.
        ParamGroup::StrokeWidth => (0.1 * v.abs()).clamp(1e-9, 1e-3),
        ParamGroup::PaintGeometry => 1e-3 * v.abs().max(1.0),
        _ => 1e-3,
    }
}

/// Loss of `scene` against `target` with the chord counts of `counts` held fixed.
fn loss_fixed(
    scene: &Scene,
    target: &Image,
    loss: Loss,
    opts: &RenderOptions,
    counts: &[Vec<u32>],
    background: Option<[f32; 4]>,
) -> f64 {
    let mut p = prepare(scene, opts.tolerance, Some(counts));
    p.set_exact_overlaps(opts.exact_overlaps);
    let mut img = render_prepared(&p);
    if let Some(bg) = background {
        img.over_background(bg);
    }
    loss.value(&img, target)
}

/// Analytic loss gradient of `scene` against `target` (optionally over a straight-RGBA
/// background), and the loss.
pub fn analytic(
    scene: &Scene,
    target: &Image,
    loss: Loss,
    opts: &RenderOptions,
    background: Option<[f32; 4]>,
) -> (f64, Vec<f64>) {
    let mut p = prepare(scene, opts.tolerance, None);
    p.set_exact_overlaps(opts.exact_overlaps);
    let mut img = render_prepared(&p);
    if let Some(bg) = background {
        img.over_background(bg);
    }
    let (l, mut d) = loss.grad(&img, target);
    if let Some(bg) = background {
        d.over_background_backward(bg);
    }
    (l, backward_prepared(scene, &p, &d))
}

/// The tolerance [`GroupCheck::passes`] uses by default: a relative error of 1 %.
pub const DEFAULT_TOLERANCE: f64 = 1e-2;

impl GroupCheck {
    /// Whether the group's worst relative error is within `tolerance` (NaN fails).
    pub fn passes(&self, tolerance: f64) -> bool {
        self.worst <= tolerance
    }
}

/// The interval a parameter of `group` is clamped to when rendered; a finite difference
/// must not step across its ends, where the loss has a kink.
fn bounds(group: ParamGroup) -> (f64, f64) {
    match group {
        ParamGroup::Color | ParamGroup::Opacity | ParamGroup::StopOffset => (0.0, 1.0),
        ParamGroup::StrokeWidth => (0.0, f64::INFINITY),
        // Deviations are clamped at 0 too, but matrix values and offsets are free.
        ParamGroup::Points
        | ParamGroup::PaintGeometry
        | ParamGroup::Transform
        | ParamGroup::Filter => (f64::NEG_INFINITY, f64::INFINITY),
    }
}

/// Finite-difference estimates of a gradient, with their own error estimates.
#[derive(Clone, Debug)]
pub struct Numeric {
    /// The estimates (NaN for parameters not checked).
    pub value: Vec<f64>,
    /// Each estimate's error bound from Ridders' tableau: how far apart the extrapolations
    /// it was chosen from are. Large where the loss has a kink within the steps.
    pub error: Vec<f64>,
}

/// Finite-difference estimates of the loss gradient for the parameters `which` (NaN
/// elsewhere), with chord counts held fixed.
///
/// Steps start a priori per group (a multiple of [`step`]) and shrink by halves under
/// Ridders' extrapolation, which picks its estimate by its own error bound, never by
/// looking at the analytic value. Central differences are used inside a parameter's valid interval; where a
/// central step would cross an end of it (an opacity at 1, a color at 0) the one-sided
/// second-order difference on the inner side is used, which matches the analytic
/// derivative taken from inside.
pub fn numeric(
    scene: &Scene,
    target: &Image,
    loss: Loss,
    opts: &RenderOptions,
    background: Option<[f32; 4]>,
    which: &[usize],
) -> Numeric {
    let counts: Vec<Vec<u32>> = prepare(scene, opts.tolerance, None)
        .geoms
        .into_iter()
        .map(|g| g.counts)
        .collect();
    let layout = ParamLayout::new(scene);
    let params = scene.params();
    let mut out = Numeric {
        value: vec![f64::NAN; params.len()],
        error: vec![f64::NAN; params.len()],
    };
    let mut s = scene.clone();
    let mut at = |i: usize, x: f64| {
        let mut v = params.clone();
        v[i] = x;
        s.set_params(&v);
        loss_fixed(&s, target, loss, opts, &counts, background)
    };
    let mut base = None;
    for &i in which {
        let group = layout.slots[i].group;
        let (lo, hi) = bounds(group);
        let v = params[i];
        // Central differences inside the valid interval; where a central step would cross
        // an end of it, one-sided second-order differences from the inner side.
        let h0 = ridders_start(group) * step(group, v);
        let central = v - h0 >= lo && v + h0 <= hi;
        let dir = if hi - v >= v - lo { 1.0 } else { -1.0 };
        let mut diff = |h: f64| {
            if central {
                (at(i, v + h) - at(i, v - h)) / (2.0 * h)
            } else {
                let f0 = *base.get_or_insert_with(|| {
                    loss_fixed(scene, target, loss, opts, &counts, background)
                });
                let (f1, f2) = (at(i, v + dir * h), at(i, v + dir * 2.0 * h));
                dir * (-3.0 * f0 + 4.0 * f1 - f2) / (2.0 * h)
            }
        };
        (out.value[i], out.error[i]) = ridders(&mut diff, h0);
    }
    out
}

/// Ridders' first step, as a multiple of [`step`]: control points are smooth over several
/// thousandths of a pixel and rounding dominates below; paint geometry lives in gradient
/// space, where [`step`] is already scaled to the value.
fn ridders_start(group: ParamGroup) -> f64 {
    match group {
        ParamGroup::Points => 6.0,
        ParamGroup::PaintGeometry => 1.0,
        _ => 2.0,
    }
}

/// Ridders' extrapolation of difference quotients `diff(h)` towards `h = 0`, from `h0` down
/// by halves: returns the extrapolated value whose own error estimate (the spread between
/// neighbouring entries of the tableau) is smallest, and stops when rounding makes the
/// estimates diverge. It never sees the analytic gradient: the choice among steps is the
/// method's, not the oracle's.
fn ridders(diff: &mut impl FnMut(f64) -> f64, h0: f64) -> (f64, f64) {
    const LEVELS: usize = 7;
    const SAFE: f64 = 2.0;
    let mut table = [[0.0f64; LEVELS]; LEVELS];
    let mut h = h0;
    table[0][0] = diff(h);
    let (mut best, mut err) = (table[0][0], f64::INFINITY);
    for i in 1..LEVELS {
        h *= 0.5;
        table[0][i] = diff(h);
        let mut fac = 4.0;
        for j in 1..=i {
            table[j][i] = (table[j - 1][i] * fac - table[j - 1][i - 1]) / (fac - 1.0);
            fac *= 4.0;
            let e = (table[j][i] - table[j - 1][i])
                .abs()
                .max((table[j][i] - table[j - 1][i - 1]).abs());
            if e <= err {
                err = e;
                best = table[j][i];
            }
        }
        if (table[i][i] - table[i - 1][i - 1]).abs() >= SAFE * err {
            break;
        }
    }
    (best, err)
}

/// Compares an analytic gradient with numeric estimates on the parameters `which`, per
/// parameter group present.
pub fn compare(
    layout: &ParamLayout,
    which: &[usize],
    analytic: &[f64],
    numeric: &Numeric,
) -> Vec<GroupCheck> {
    let (est, bound) = (&numeric.value, &numeric.error);
    // A group whose gradient is all but zero (a rectangle's rotation on a symmetric
    // picture) is compared in absolute terms, against the largest estimate of any group.
    let overall = which.iter().map(|&i| est[i].abs()).fold(0.0, f64::max);
    let mut out = Vec::new();
    for group in ParamGroup::ALL {
        let ids: Vec<usize> = which
            .iter()
            .copied()
            .filter(|&i| layout.slots[i].group == group)
            .collect();
        if ids.is_empty() {
            continue;
        }
        let scale = ids.iter().map(|&i| est[i].abs()).fold(0.0, f64::max);
        let floor = (1e-2 * scale).max(1e-4 * overall).max(1e-12);
        let mut gc = GroupCheck {
            group,
            checked: ids.len(),
            worst: 0.0,
            worst_index: ids[0],
            worst_pair: (analytic[ids[0]], est[ids[0]]),
        };
        for &i in &ids {
            // The part of the disagreement the estimate's own error bound cannot explain.
            let off = ((analytic[i] - est[i]).abs() - bound[i]).max(0.0);
            let e = off / est[i].abs().max(floor);
            if !(e <= gc.worst) {
                gc.worst = e;
                gc.worst_index = i;
                gc.worst_pair = (analytic[i], est[i]);
            }
        }
        out.push(gc);
    }
    out
}

/// Compares the analytic gradient with finite differences ([`numeric`]) on the parameters
/// `which` (all when `None`). Returns the analytic and numeric gradients and one entry per
/// group present.
pub fn check(
    scene: &Scene,
    target: &Image,
    loss: Loss,
    opts: &RenderOptions,
    background: Option<[f32; 4]>,
    which: Option<&[usize]>,
) -> (Vec<f64>, Vec<f64>, Vec<GroupCheck>) {
    let (_, grad) = analytic(scene, target, loss, opts, background);
    let all: Vec<usize> = (0..grad.len()).collect();
    let which = which.unwrap_or(&all);
    let num = numeric(scene, target, loss, opts, background, which);
    let groups = compare(&ParamLayout::new(scene), which, &grad, &num);
    (grad, num.value, groups)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Sizing;
    use crate::raster::render;

    /// A filled and stroked curve at full opacity and a color channel at 0, over a target
    /// that differs, so that every group has a gradient and several parameters sit on the
    /// ends of their intervals.
    fn scene_at_bounds() -> (Scene, Image) {
        let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="24" height="20">
            <path id="c" d="M3.3 4.1 C 9 1, 15 17.2, 20.6 6.4 L 17.2 16.3 Z" fill="#f08000"
                  fill-opacity="1" stroke="#0000ff" stroke-width="2.3" stroke-opacity="1"/></svg>"##;
        let scene = Scene::from_svg_str(svg, "bounds.svg", Sizing::Natural).unwrap();
        let mut moved = scene.clone();
        let mut p = moved.params();
        for (k, v) in p.iter_mut().enumerate() {
            *v += 0.37 * ((k as f64 * 1.7).sin());
        }
        moved.set_params(&p);
        let target = render(&moved, &RenderOptions::default());
        (scene, target)
    }

    #[test]
    fn opacity_at_one_is_no_false_alarm() {
        let (scene, target) = scene_at_bounds();
        let (_, _, groups) = check(
            &scene,
            &target,
            Loss::Mse,
            &RenderOptions::default(),
            None,
            None,
        );
        assert!(groups.iter().any(|g| g.group == ParamGroup::Opacity));
        for g in &groups {
            assert!(g.passes(DEFAULT_TOLERANCE), "{g}");
        }
    }

    #[test]
    fn a_flipped_sign_fails_the_check() {
        let (scene, target) = scene_at_bounds();
        let opts = RenderOptions::default();
        let (_, mut grad) = analytic(&scene, &target, Loss::Mse, &opts, None);
        let all: Vec<usize> = (0..grad.len()).collect();
        let num = numeric(&scene, &target, Loss::Mse, &opts, None, &all);
        let layout = ParamLayout::new(&scene);
        // The largest point gradient, negated.
        let i = (0..grad.len())
            .filter(|&i| layout.slots[i].group == ParamGroup::Points)
            .max_by(|&a, &b| grad[a].abs().total_cmp(&grad[b].abs()))
            .unwrap();
        grad[i] = -grad[i];
        let groups = compare(&layout, &all, &grad, &num);
        let points = groups
            .iter()
            .find(|g| g.group == ParamGroup::Points)
            .unwrap();
        assert!(!points.passes(DEFAULT_TOLERANCE), "{points}");
        assert_eq!(points.worst_index, i);
    }
}
