//! The long 2D jobs: refinement, vectorization, digits and glyphs, with the GIL released and
//! a Python progress callback called after every evaluation.

use diffsvg::fit::digit::{DigitOptions, fit_digit};
use diffsvg::fit::glyph::{GlyphOptions, fit_glyph};
use diffsvg::fit::vectorize::{Event, Mode, VectorizeOptions, vectorize as lib_vectorize};
use diffsvg::fit::{Control, FitOptions, ObjectiveOptions, Step, StopReason, refine};
use diffsvg::fit::{LearningRates, Objective};
use diffsvg::limits::MAX_PATHS;
use diffsvg::loss::Loss;
use diffsvg::optim::Schedule;
use diffsvg::raster::RenderOptions;
use numpy::{PyArray2, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::array::{color_in, image_in};
use crate::error::{bad, to_py};
use crate::render::options as options_for;
use crate::scene::PyScene;

/// A dict of `key => value` pairs (values converted by `set_item`).
macro_rules! dict {
    ($py:expr; $($k:literal => $v:expr),* $(,)?) => {{
        let d = PyDict::new($py);
        $(d.set_item($k, $v)?;)*
        d
    }};
}

/// Calls a Python progress callback (and checks for Ctrl-C) from inside a job that runs
/// without the GIL; the first exception stops the job and is raised once it returns.
pub(crate) struct Progress {
    callback: Option<Py<PyAny>>,
    error: Option<PyErr>,
}

impl Progress {
    pub(crate) fn new(callback: Option<Py<PyAny>>) -> Self {
        Progress {
            callback,
            error: None,
        }
    }

    /// Calls the callback with the dict `fill` builds; `Control::Stop` on an exception
    /// (from the callback, or a pending KeyboardInterrupt) or when the callback returns
    /// `False`.
    pub(crate) fn call(
        &mut self,
        fill: impl FnOnce(&Bound<'_, PyDict>) -> PyResult<()>,
    ) -> Control {
        if self.error.is_some() {
            return Control::Stop;
        }
        let r = Python::attach(|py| -> PyResult<bool> {
            py.check_signals()?;
            let Some(cb) = &self.callback else {
                return Ok(true);
            };
            let d = PyDict::new(py);
            fill(&d)?;
            let r = cb.call1(py, (d,))?;
            // `None` (no return statement) keeps going; `False` stops.
            Ok(r.is_none(py) || r.is_truthy(py)?)
        });
        match r {
            Ok(true) => Control::Continue,
            Ok(false) => Control::Stop,
            Err(e) => {
                self.error = Some(e);
                Control::Stop
            }
        }
    }

    pub(crate) fn finish(self) -> PyResult<()> {
        self.error.map_or(Ok(()), Err)
    }
}

fn step_dict(d: &Bound<'_, PyDict>, s: &Step) -> PyResult<()> {
    d.set_item("iter", s.iter)?;
    d.set_item("loss", s.loss)?;
    d.set_item("psnr", s.psnr)?;
    d.set_item("seconds", s.elapsed.as_secs_f64())?;
    Ok(())
}

/// The options shared by `fit` and `vectorize`, from a dict (unknown keys refused):
/// `lr_points`, `lr_color`, `lr_opacity`, `lr_width`, `lr_paint`, `lr_stops`,
/// `lr_transform`, `lr_filter` (finite, ≥ 0), `exact_filters` and `exact_overlaps`
/// (bools), `schedule`, `loss`, `background` (straight RGBA), `pyramid`, `tolerance`,
/// `fit_background` (bool; `fit` only).
fn fit_setup(
    target: &PyReadonlyArrayDyn<'_, f32>,
    iters: usize,
    until_psnr: Option<f64>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<(Objective, FitOptions)> {
    const KEYS: [&str; 16] = [
        "lr_points",
        "lr_color",
        "lr_opacity",
        "lr_width",
        "lr_paint",
        "lr_stops",
        "lr_transform",
        "lr_filter",
        "exact_filters",
        "exact_overlaps",
        "schedule",
        "loss",
        "background",
        "pyramid",
        "tolerance",
        "fit_background",
    ];
    let get = |k: &str| -> PyResult<Option<Bound<'_, PyAny>>> {
        match options {
            Some(d) => Ok(d.get_item(k)?.filter(|v| !v.is_none())),
            None => Ok(None),
        }
    };
    if let Some(d) = options {
        for k in d.keys() {
            let k: String = k.extract()?;
            if !KEYS.contains(&k.as_str()) {
                return Err(bad(format!(
                    "unknown option {k:?}; expected one of {KEYS:?}"
                )));
            }
        }
    }
    let mut rates = LearningRates::default();
    for (k, r) in KEYS.iter().zip([
        &mut rates.points,
        &mut rates.color,
        &mut rates.opacity,
        &mut rates.width,
        &mut rates.paint,
        &mut rates.stops,
        &mut rates.transform,
        &mut rates.filter,
    ]) {
        if let Some(v) = get(k)? {
            *r = v.extract()?;
        }
    }
    let schedule: String = get("schedule")?.map_or(Ok("constant".into()), |v| v.extract())?;
    let loss: String = get("loss")?.map_or(Ok("mse".into()), |v| v.extract())?;
    let background: Option<[f32; 4]> = get("background")?.map(|v| v.extract()).transpose()?;
    let pyramid: usize = get("pyramid")?.map_or(Ok(1), |v| v.extract())?;
    let tolerance: f64 = get("tolerance")?.map_or(Ok(0.02), |v| v.extract())?;
    let fit_background: bool = get("fit_background")?.map_or(Ok(false), |v| v.extract())?;
    let exact_filters: bool = get("exact_filters")?.map_or(Ok(false), |v| v.extract())?;
    let exact_overlaps: bool = get("exact_overlaps")?.map_or(Ok(false), |v| v.extract())?;
    let target = image_in(target, "target")?;
    if target.width == 0 || target.height == 0 {
        return Err(bad("target: the image is empty"));
    }
    let bg = color_in(background, "background")?;
    let opts = FitOptions {
        iters,
        rates,
        schedule: schedule.parse::<Schedule>().map_err(bad)?,
        until_psnr,
        render: RenderOptions {
            exact_filters,
            ..options_for(tolerance, exact_overlaps)?
        },
        fit_background,
        ..FitOptions::default()
    };
    opts.validate().map_err(to_py)?;
    if fit_background && !bg.is_some_and(|b| b[3] >= 1.0) {
        return Err(bad(
            "fit_background: needs an opaque background, e.g. background=(1, 1, 1)",
        ));
    }
    let objective = ObjectiveOptions {
        loss: loss.parse::<Loss>().map_err(bad)?,
        pyramid,
        background: bg,
    }
    .objective(&target)
    .map_err(to_py)?;
    Ok((objective, opts))
}

/// Refines every parameter of `scene` toward `target` (premultiplied RGBA `float32`,
/// the scene's size) with exact gradients and Adam; `options` as in `fit_setup`.
/// Returns `(best scene, info)`.
#[pyfunction]
#[pyo3(signature = (scene, target, iters=500, until_psnr=None, options=None, progress=None))]
pub(crate) fn fit<'py>(
    py: Python<'py>,
    scene: PyRef<'py, PyScene>,
    target: PyReadonlyArrayDyn<'py, f32>,
    iters: usize,
    until_psnr: Option<f64>,
    options: Option<Bound<'py, PyDict>>,
    progress: Option<Py<PyAny>>,
) -> PyResult<(PyScene, Bound<'py, PyDict>)> {
    let (objective, opts) = fit_setup(&target, iters, until_psnr, options.as_ref())?;
    let t = objective.target();
    let s = scene.inner.clone();
    if (t.width, t.height) != (s.width, s.height) {
        return Err(bad(format!(
            "target: {}x{} (width x height) but the scene is {}x{} (load the scene with \
             width and height of the target)",
            t.width, t.height, s.width, s.height
        )));
    }
    diffsvg::raster::check_backward_memory(&s, &opts.render, std::path::Path::new("scene"))
        .map_err(to_py)?;
    let mut prog = Progress::new(progress);
    let out = py.detach(|| {
        refine(s, &objective, &opts, &mut |step, _| {
            prog.call(|d| step_dict(d, step))
        })
    });
    prog.finish()?;
    let reason = match out.reason {
        StopReason::Finished => "finished",
        StopReason::ReachedPsnr => "reached_psnr",
        StopReason::Interrupted => "stopped",
    };
    let rows: Vec<Vec<f64>> = out
        .history
        .iter()
        .map(|s| vec![s.iter as f64, s.loss, s.psnr, s.elapsed.as_secs_f64()])
        .collect();
    let history = if rows.is_empty() {
        PyArray2::zeros(py, [0, 4], false)
    } else {
        PyArray2::from_vec2(py, &rows).map_err(|e| bad(e.to_string()))?
    };
    let last = out.history.last();
    let info = dict! {py;
        "loss" => out.best_loss,
        "psnr" => out.best_psnr,
        "steps" => out.steps,
        "reason" => reason,
        "step_ms" => out.median_step_ms,
        "final_loss" => last.map(|s| s.loss),
        "seconds" => last.map(|s| s.elapsed.as_secs_f64()),
        "history" => history,
        "background" => out.background.map(|b| b.to_vec()),
    };
    Ok((PyScene::from(out.best), info))
}

/// Builds an SVG scene from a picture: `mode` "adaptive" (paths added where the error is
/// largest), "fixed" (DiffVG's random blobs), "painterly" (random strokes) or "trace"
/// (vtracer, pruned, refined). Returns `(scene, info)`.
#[pyfunction]
#[pyo3(signature = (target, paths=64, mode="adaptive", iters=1000, seed=0, target_psnr=None,
    segments=4, options=None, progress=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn vectorize<'py>(
    py: Python<'py>,
    target: PyReadonlyArrayDyn<'py, f32>,
    paths: usize,
    mode: &str,
    iters: usize,
    seed: u64,
    target_psnr: Option<f64>,
    segments: usize,
    options: Option<Bound<'py, PyDict>>,
    progress: Option<Py<PyAny>>,
) -> PyResult<(PyScene, Bound<'py, PyDict>)> {
    let (objective, fit) = fit_setup(&target, iters, None, options.as_ref())?;
    if fit.fit_background {
        return Err(bad("fit_background is an option of fit, not of vectorize"));
    }
    let mode: Mode = mode.parse().map_err(bad)?;
    let opts = VectorizeOptions {
        mode,
        paths,
        target_psnr,
        segments,
        iters,
        fit,
        seed,
    };
    opts.validate().map_err(to_py)?;
    let mut prog = Progress::new(progress);
    let out = py.detach(|| {
        lib_vectorize(&objective, &opts, &mut |e| match e {
            Event::Round { round, paths } => prog.call(|d| {
                d.set_item("round", round)?;
                d.set_item("paths", paths)
            }),
            Event::Step(step, scene) => prog.call(|d| {
                step_dict(d, step)?;
                d.set_item("paths", scene.path_count())
            }),
        })
    });
    prog.finish()?;
    let out = out.map_err(to_py)?;
    let info = dict! {py;
        "psnr" => out.psnr,
        "mse" => out.mse,
        "steps" => out.steps,
        "rounds" => out.rounds,
        "pruned" => out.pruned,
        "seconds" => out.elapsed.as_secs_f64(),
        "step_ms" => out.median_step_ms,
    };
    Ok((PyScene::from(out.scene), info))
}

fn canvas(n: usize, width: u32, height: u32) -> PyResult<()> {
    if n > MAX_PATHS {
        return Err(bad(format!("{n} paths: at most {MAX_PATHS}")));
    }
    diffsvg::image_io::check_image_size(width, height, "canvas".as_ref()).map_err(to_py)
}

/// DiffVG's painterly blobs: `n` closed random-walk paths of 3–5 cubics with random
/// straight RGBA fills, even-odd, no stroke (the same scene as `diffsvg bench painterly`
/// for the same seed).
#[pyfunction]
#[pyo3(signature = (n, width, height, seed=0))]
pub(crate) fn random_blobs(n: usize, width: u32, height: u32, seed: u64) -> PyResult<PyScene> {
    canvas(n, width, height)?;
    Ok(PyScene::from(diffsvg::fit::random_blobs(
        n, width, height, seed,
    )))
}

/// DiffVG's painterly strokes: `n` open random-walk paths of 1–3 cubics, 1 px wide.
#[pyfunction]
#[pyo3(signature = (n, width, height, seed=0))]
pub(crate) fn random_strokes(n: usize, width: u32, height: u32, seed: u64) -> PyResult<PyScene> {
    canvas(n, width, height)?;
    Ok(PyScene::from(diffsvg::fit::random_strokes(
        n, width, height, seed,
    )))
}

/// Fits white strokes to one grayscale digit (`(h, w)` intensities in `[0, 1]`, ink
/// bright, e.g. MNIST / 255): the fewest curves that reach `target_iou`. Returns
/// `(scene, info)`; draw the scene over black to compare.
#[pyfunction]
#[pyo3(signature = (pixels, target_iou=0.85, max_strokes=2, max_segments=3, scale=2))]
pub(crate) fn digit<'py>(
    py: Python<'py>,
    pixels: PyReadonlyArrayDyn<'py, f32>,
    target_iou: f64,
    max_strokes: usize,
    max_segments: usize,
    scale: u32,
) -> PyResult<(PyScene, Bound<'py, PyDict>)> {
    let shape = pixels.shape().to_vec();
    if shape.len() != 2 || shape[0] == 0 || shape[1] == 0 || shape[0] > 1024 || shape[1] > 1024 {
        return Err(bad(format!(
            "pixels: expected a (height, width) array of at most 1024 x 1024, got {shape:?}"
        )));
    }
    let v: Vec<f32> = pixels.as_array().iter().copied().collect();
    if let Some(i) = v.iter().position(|x| !(0.0..=1.0).contains(x)) {
        return Err(bad(format!(
            "pixels: value {i} is {} (intensities must be in [0, 1])",
            v[i]
        )));
    }
    let opts = DigitOptions {
        scale,
        target_iou,
        max_strokes,
        max_segments,
        ..DigitOptions::default()
    };
    opts.validate().map_err(to_py)?;
    let (h, w) = (shape[0], shape[1]);
    let f = py.detach(|| crate::on_pool(|| fit_digit(&v, w, h, &opts)));
    let info = dict! {py;
        "iou" => f.iou,
        "mse" => f.mse,
        "segments" => f.segments.clone(),
        "steps" => f.steps,
    };
    Ok((PyScene::from(f.scene), info))
}

/// Fits one closed black outline (one cubic subpath per contour) to a rendered glyph
/// (premultiplied RGBA `float32`, dark ink), with the fewest segments that reach
/// `iou`. Returns `(scene, info)`; draw the scene over white to compare.
#[pyfunction]
#[pyo3(signature = (target, iou=0.99, max_segments=64, iters=150))]
pub(crate) fn glyph<'py>(
    py: Python<'py>,
    target: PyReadonlyArrayDyn<'py, f32>,
    iou: f64,
    max_segments: usize,
    iters: usize,
) -> PyResult<(PyScene, Bound<'py, PyDict>)> {
    let t = image_in(&target, "target")?;
    let opts = GlyphOptions {
        iou_goal: iou,
        max_segments,
        iters,
        ..GlyphOptions::default()
    };
    opts.validate().map_err(to_py)?;
    let out = py.detach(|| crate::on_pool(|| fit_glyph(&t, &opts)));
    let info = dict! {py;
        "iou" => out.iou,
        "mse" => out.mse,
        "segments" => out.segments,
        "reached" => out.reached,
        "steps" => out.steps,
        "seconds" => out.elapsed.as_secs_f64(),
    };
    Ok((PyScene::from(out.scene), info))
}
