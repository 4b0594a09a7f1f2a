//! Checking analytic gradients against central finite differences.

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
    /// Worst `|analytic − numeric| / max(|numeric|, floor)`, where `floor` is 1e-2 of the
    /// group's largest numeric gradient (so tiny gradients are held to an absolute bound).
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
    let mut img = render_prepared(&prepare(scene, opts.tolerance, Some(counts)));
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
    let p = prepare(scene, opts.tolerance, None);
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

/// Compares the analytic gradient with central differences on the parameters `which` (all
/// when `None`), chord counts held fixed. Returns one entry per group present.
pub fn check(
    scene: &Scene,
    target: &Image,
    loss: Loss,
    opts: &RenderOptions,
    background: Option<[f32; 4]>,
    which: Option<&[usize]>,
) -> (Vec<f64>, Vec<f64>, Vec<GroupCheck>) {
    let (_, grad) = analytic(scene, target, loss, opts, background);
    let counts: Vec<Vec<u32>> = prepare(scene, opts.tolerance, None)
        .geoms
        .into_iter()
        .map(|g| g.counts)
        .collect();
    let layout = ParamLayout::new(scene);
    let params = scene.params();
    let all: Vec<usize> = (0..params.len()).collect();
    let which = which.unwrap_or(&all);
    let mut numeric = vec![f64::NAN; params.len()];
    let mut s = scene.clone();
    for &i in which {
        let group = layout.slots[i].group;
        // Rendering is f32: a small step drowns tiny gradients in rounding, a large one
        // straddles pixel-boundary kinks. Three steps a factor 3 apart; keep the estimate
        // nearest the analytic value (all three are estimates of the same derivative).
        for scale in [1.0, 1.0 / 3.0, 3.0] {
            let h = step(group, params[i]) * scale;
            let mut v = params.clone();
            v[i] = params[i] + h;
            s.set_params(&v);
            let up = loss_fixed(&s, target, loss, opts, &counts, background);
            v[i] = params[i] - h;
            s.set_params(&v);
            let down = loss_fixed(&s, target, loss, opts, &counts, background);
            let n = (up - down) / (2.0 * h);
            if !((numeric[i] - grad[i]).abs() <= (n - grad[i]).abs()) {
                numeric[i] = n;
            }
        }
    }
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
        let scale = ids.iter().map(|&i| numeric[i].abs()).fold(0.0, f64::max);
        let floor = (1e-2 * scale).max(1e-12);
        let mut gc = GroupCheck {
            group,
            checked: ids.len(),
            worst: 0.0,
            worst_index: ids[0],
            worst_pair: (grad[ids[0]], numeric[ids[0]]),
        };
        for &i in &ids {
            let e = (grad[i] - numeric[i]).abs() / numeric[i].abs().max(floor);
            if !(e <= gc.worst) {
                gc.worst = e;
                gc.worst_index = i;
                gc.worst_pair = (grad[i], numeric[i]);
            }
        }
        out.push(gc);
    }
    (grad, numeric, out)
}
