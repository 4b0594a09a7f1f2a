//! 3D reconstruction from posed photos: `recon_voxel`, `recon_splat`, `recon_ngp` and
//! `recon_nerf`, the library's
//! [`diffsvg::volume::recon`] jobs with the GIL released, a progress callback, and the
//! model written atomically to a file as the command line writes it.

use std::path::{Path, PathBuf};

use diffsvg::fit::Control;
use diffsvg::volume::recon::{
    NgpJob, SplatJob, VoxelJob, recon_ngp as lib_ngp, recon_splat as lib_splat,
    recon_voxel as lib_voxel,
};
use diffsvg::volume::{field, splat, voxel};
use numpy::PyArray2;
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::error::{bad, to_py};
use crate::jobs::Progress;

/// The library's output check (extension, not a folder, the folder writable), after
/// refusing a missing folder (which the library would create, as the command line does).
fn check_output(path: &Path, ext: &str) -> PyResult<()> {
    crate::output::check_folder(path)?;
    diffsvg::image_io::check_output(path, ext).map_err(to_py)
}

/// A log as a `(rows, 6)` `float64` array.
fn log_array<'py>(
    py: Python<'py>,
    rows: impl Iterator<Item = [f64; 6]>,
) -> PyResult<Bound<'py, PyArray2<f64>>> {
    let rows: Vec<Vec<f64>> = rows.map(Vec::from).collect();
    if rows.is_empty() {
        return Ok(PyArray2::zeros(py, [0, 6], false));
    }
    PyArray2::from_vec2(py, &rows).map_err(|e| bad(e.to_string()))
}

/// A test PSNR not evaluated is NaN in a log.
fn nan_if_none(t: Option<f64>) -> f64 {
    t.unwrap_or(f64::NAN)
}

/// The keys every reconstruction returns: `output`; `iterations`, `stopped` and
/// `seconds` (how training ended); `load_seconds` and `test_psnr`; the `log` from `rows`.
fn summary<'py>(
    py: Python<'py>,
    output: PathBuf,
    (iterations, stopped, seconds): (usize, bool, f32),
    (load_seconds, test_psnr): (f64, Option<f64>),
    rows: impl Iterator<Item = [f64; 6]>,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("output", output)?;
    d.set_item("iterations", iterations)?;
    d.set_item("stopped", stopped)?;
    d.set_item("seconds", seconds)?;
    d.set_item("load_seconds", load_seconds)?;
    d.set_item("test_psnr", test_psnr)?;
    d.set_item("log", log_array(py, rows)?)?;
    Ok(d)
}

/// Fits a sparse voxel grid (Plenoxels) to a posed-photo folder and writes it to
/// `output` (`.vox`). Options as `diffsvg recon voxel`'s flags. Returns a dict.
#[pyfunction]
#[pyo3(signature = (scene, output, res=128, iters=3000, batch=8192, downscale=1, degree=2,
    bound=None, step=0.5, tv_density=None, tv_sh=None, sparsity=None, seed=0, eval_every=0,
    test_every=None, test_list=None, refine_poses=false, perturb_poses=None,
    align_test_poses=false, progress=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn recon_voxel<'py>(
    py: Python<'py>,
    scene: PathBuf,
    output: PathBuf,
    res: u32,
    iters: usize,
    batch: usize,
    downscale: u32,
    degree: u32,
    bound: Option<f32>,
    step: f32,
    tv_density: Option<f32>,
    tv_sh: Option<f32>,
    sparsity: Option<f32>,
    seed: u64,
    eval_every: usize,
    test_every: Option<usize>,
    test_list: Option<PathBuf>,
    refine_poses: bool,
    perturb_poses: Option<(f32, f32)>,
    align_test_poses: bool,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    check_output(&output, "vox")?;
    let job = VoxelJob {
        res,
        iters,
        batch,
        downscale,
        degree,
        bound,
        step,
        tv_density,
        tv_sh,
        sparsity,
        seed,
        eval_every,
        test_every,
        test_list,
        refine_poses,
        perturb_poses: perturb_poses.map(|(d, u)| [d, u]),
        align_test_poses,
    };
    job.validate().map_err(to_py)?;
    let mut prog = Progress::new(progress);
    let out = py.detach(|| {
        lib_voxel(&scene, &job, &mut |s, test| {
            prog.call(|d| {
                d.set_item("iteration", s.iteration)?;
                d.set_item("loss", s.loss)?;
                d.set_item("psnr", s.psnr)?;
                d.set_item("rays_per_second", s.rays_per_second)?;
                d.set_item("res", s.res)?;
                d.set_item("allocated", s.allocated)?;
                d.set_item("seconds", s.elapsed)?;
                d.set_item("test_psnr", test)
            }) == Control::Continue
        })
    });
    prog.finish()?;
    let out = out.map_err(to_py)?;
    py.detach(|| voxel::save(&out.grid, &output))
        .map_err(to_py)?;
    let rows = out.log.iter().map(|(s, t)| {
        let (res, allocated) = (s.res as f64, s.allocated as f64);
        [
            s.iteration as f64,
            s.elapsed as f64,
            res,
            allocated,
            s.psnr as f64,
            nan_if_none(*t),
        ]
    });
    let o = &out.outcome;
    let ended = (o.iterations, o.stopped, o.seconds);
    let d = summary(py, output, ended, (out.load_seconds, out.test_psnr), rows)?;
    d.set_item("res", out.grid.res())?;
    d.set_item("allocated", out.grid.allocated())?;
    d.set_item("batch", out.batch)?;
    set_pose_error(&d, &out.pose_error)?;
    d.set_item("test_psnr_in_frame", out.test_psnr_in_frame)?;
    d.set_item("test_psnr_aligned", out.test_psnr_aligned.map(|a| a.0))?;
    d.set_item("test_pose_turn", out.test_psnr_aligned.map(|a| a.1))?;
    Ok(d)
}

/// Fits 3D Gaussians to a posed-photo folder and writes them to `output` (`.ply`, the
/// layout Gaussian-splatting viewers read). Options as `diffsvg recon splat`'s flags.
/// Returns a dict.
#[pyfunction]
#[pyo3(signature = (scene, output, iters=5000, downscale=1, max_gaussians=300_000,
    initial=50_000, degree=3, bound=None, seed=0, eval_every=0, test_every=None,
    test_list=None, antialias=false, exposure=false, mcmc=false, refine_poses=false, perturb_poses=None,
    progress=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn recon_splat<'py>(
    py: Python<'py>,
    scene: PathBuf,
    output: PathBuf,
    iters: usize,
    downscale: u32,
    max_gaussians: usize,
    initial: usize,
    degree: u32,
    bound: Option<f32>,
    seed: u64,
    eval_every: usize,
    test_every: Option<usize>,
    test_list: Option<PathBuf>,
    antialias: bool,
    exposure: bool,
    mcmc: bool,
    refine_poses: bool,
    perturb_poses: Option<(f32, f32)>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    check_output(&output, "ply")?;
    let job = SplatJob {
        iters,
        downscale,
        max_gaussians,
        initial,
        degree,
        bound,
        seed,
        eval_every,
        test_every,
        test_list,
        antialias,
        exposure,
        mcmc,
        refine_poses,
        perturb_poses: perturb_poses.map(|(d, u)| [d, u]),
    };
    job.validate().map_err(to_py)?;
    let mut prog = Progress::new(progress);
    let out = py.detach(|| {
        lib_splat(&scene, &job, &mut |s, test| {
            prog.call(|d| {
                d.set_item("iteration", s.iteration)?;
                d.set_item("loss", s.loss)?;
                d.set_item("psnr", s.psnr)?;
                d.set_item("gaussians", s.gaussians)?;
                d.set_item("sh_degree", s.sh_degree)?;
                d.set_item("seconds", s.elapsed)?;
                d.set_item("test_psnr", test)
            }) == Control::Continue
        })
    });
    prog.finish()?;
    let out = out.map_err(to_py)?;
    py.detach(|| splat::save(&out.model, &output))
        .map_err(to_py)?;
    let rows = out.log.iter().map(|(s, t)| {
        let (gaussians, degree) = (s.gaussians as f64, s.sh_degree as f64);
        [
            s.iteration as f64,
            s.elapsed as f64,
            gaussians,
            degree,
            s.psnr as f64,
            nan_if_none(*t),
        ]
    });
    let o = &out.outcome;
    let ended = (o.iterations, o.stopped, o.seconds);
    let d = summary(py, output, ended, (out.load_seconds, out.test_psnr), rows)?;
    d.set_item("gaussians", out.model.len())?;
    d.set_item("undistorted", out.undistorted)?;
    set_pose_error(&d, &out.pose_error)?;
    d.set_item("test_psnr_in_frame", out.test_psnr_in_frame)?;
    Ok(d)
}

/// Trains a neural field (`job` of either kind) and writes it to `output` as the command
/// line does; the dict adds `samples`, `samples_per_second`, `parameters` and
/// `occupied`, and the log's columns are iteration, seconds, samples, samples per
/// second, batch PSNR and test PSNR.
fn run_field<'py>(
    py: Python<'py>,
    scene: PathBuf,
    output: PathBuf,
    job: NgpJob,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    job.validate().map_err(to_py)?;
    let mut prog = Progress::new(progress);
    let out = py.detach(|| {
        lib_ngp(&scene, &job, &mut |s, test| {
            prog.call(|d| {
                d.set_item("iteration", s.iteration)?;
                d.set_item("loss", s.loss)?;
                d.set_item("psnr", s.psnr)?;
                d.set_item("samples_per_second", s.samples_per_second)?;
                d.set_item("occupied", s.occupied)?;
                d.set_item("seconds", s.elapsed)?;
                d.set_item("test_psnr", test)
            }) == Control::Continue
        })
    });
    prog.finish()?;
    let out = out.map_err(to_py)?;
    py.detach(|| field::save(&out.model, &output))
        .map_err(to_py)?;
    let rows = out.log.iter().map(|(s, t)| {
        [
            s.iteration as f64,
            s.elapsed as f64,
            s.samples as f64,
            s.samples_per_second as f64,
            s.psnr as f64,
            nan_if_none(*t),
        ]
    });
    let o = &out.outcome;
    let ended = (o.iterations, o.stopped, o.seconds);
    let d = summary(py, output, ended, (out.load_seconds, out.test_psnr), rows)?;
    d.set_item("samples", o.samples)?;
    d.set_item(
        "samples_per_second",
        o.samples as f64 / (o.seconds as f64).max(1e-9),
    )?;
    d.set_item("parameters", out.model.param_count())?;
    d.set_item("occupied", out.model.occupied_fraction())?;
    d.set_item("pose_error", py.None())?;
    Ok(d)
}

/// Fits an Instant-NGP neural field (hash grid and tiny MLPs) to a posed-photo folder
/// and writes it to `output` (`.ngp`). Options as `diffsvg recon ngp`'s flags
/// (`lr` is `(start, end)`). Returns a dict.
#[pyfunction]
#[pyo3(signature = (scene, output, iters=2000, seconds=0.0, batch=8192, samples=65536,
    downscale=1, bound=None, steps=512, levels=16, log2_table=16, min_res=16, max_res=1024,
    width=64, lr=(1e-2, 1e-3), seed=0, eval_every=0, test_every=None, test_list=None,
    progress=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn recon_ngp<'py>(
    py: Python<'py>,
    scene: PathBuf,
    output: PathBuf,
    iters: usize,
    seconds: f32,
    batch: usize,
    samples: usize,
    downscale: u32,
    bound: Option<f32>,
    steps: u32,
    levels: u32,
    log2_table: u32,
    min_res: u32,
    max_res: u32,
    width: u32,
    lr: (f32, f32),
    seed: u64,
    eval_every: usize,
    test_every: Option<usize>,
    test_list: Option<PathBuf>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    check_output(&output, "ngp")?;
    let job = NgpJob {
        iters,
        seconds,
        batch,
        samples,
        downscale,
        bound,
        steps,
        levels,
        log2_table,
        min_res,
        max_res,
        width,
        lr: [lr.0, lr.1],
        seed,
        eval_every,
        test_every,
        test_list,
        ..NgpJob::default()
    };
    run_field(py, scene, output, job, progress)
}

/// Fits a NeRF field (NeRF's positional encoding and an MLP sized for a CPU) to a
/// posed-photo folder and writes it to `output` (`.nerf`). Options as `diffsvg recon
/// nerf`'s flags (`lr` is `(start, end)`). Returns a dict as `recon_ngp`'s.
#[pyfunction]
#[pyo3(signature = (scene, output, iters=2000, seconds=0.0, batch=8192, samples=16384,
    downscale=1, bound=None, steps=256, frequencies=10, width=64, density_layers=4,
    color_layers=1, lr=(2e-3, 2e-4), seed=0, eval_every=0, test_every=None, test_list=None,
    progress=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn recon_nerf<'py>(
    py: Python<'py>,
    scene: PathBuf,
    output: PathBuf,
    iters: usize,
    seconds: f32,
    batch: usize,
    samples: usize,
    downscale: u32,
    bound: Option<f32>,
    steps: u32,
    frequencies: u32,
    width: u32,
    density_layers: u32,
    color_layers: u32,
    lr: (f32, f32),
    seed: u64,
    eval_every: usize,
    test_every: Option<usize>,
    test_list: Option<PathBuf>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    check_output(&output, "nerf")?;
    if frequencies == 0 {
        return Err(to_py(diffsvg::Error::Setting {
            name: "frequencies".into(),
            message: "0 must be 1 to 16".into(),
        }));
    }
    let job = NgpJob {
        iters,
        seconds,
        batch,
        samples,
        downscale,
        bound,
        steps,
        frequencies,
        width,
        density_layers,
        color_layers,
        lr: [lr.0, lr.1],
        seed,
        eval_every,
        test_every,
        test_list,
        ..NgpJob::nerf()
    };
    run_field(py, scene, output, job, progress)
}

/// `d["pose_error"]`: `None`, or `{"before": (degrees, units), "after": (…)}` when the
/// training poses were perturbed.
fn set_pose_error(
    d: &Bound<'_, PyDict>,
    e: &Option<diffsvg::volume::recon::PoseError>,
) -> PyResult<()> {
    match e {
        Some(e) => {
            let inner = PyDict::new(d.py());
            inner.set_item("before", (e.before[0], e.before[1]))?;
            inner.set_item("after", (e.after[0], e.after[1]))?;
            inner.set_item("after_in_frame", (e.after_in_frame[0], e.after_in_frame[1]))?;
            inner.set_item("frame", (e.frame[0], e.frame[1]))?;
            d.set_item("pose_error", inner)
        }
        None => d.set_item("pose_error", d.py().None()),
    }
}

/// Renders a trained model (`.vox` or Gaussian PLY, told apart by its header) as
/// `diffsvg view` does: from the cameras of the `split` ("test" or "train") views of the
/// dataset `scene` (when given), and from `orbit` new cameras around the model raised by
/// `elevation` degrees. Returns a dict: `views`, a list of `(name, rendering, photo)`
/// with `(h, w, 3)` `float32` linear RGB arrays (unclamped), and `orbit`, a list of
/// `(h, w, 3)` renderings. With `depth`, also `depth` and `orbit_depth`: per view (and per
/// orbit camera) a dict of `expected` and `median` `(h, w)` `float32` depth images (world
/// units along the viewing axis, as `diffsvg view --depth` writes them; Gaussian and voxel
/// models only). `test_every` and `test_list` choose an instant-ngp or COLMAP folder's
/// held-out views as `recon` did (`diffsvg view --test-every/--test-list`). The GIL is
/// released while it renders.
#[pyfunction]
#[pyo3(signature = (model, scene=None, split="test", orbit=0, elevation=30.0, downscale=1,
    step=0.5, depth=false, test_every=None, test_list=None))]
#[allow(clippy::too_many_arguments, clippy::type_complexity)]
pub(crate) fn view<'py>(
    py: Python<'py>,
    model: PathBuf,
    scene: Option<PathBuf>,
    split: &str,
    orbit: usize,
    elevation: f32,
    downscale: u32,
    step: f32,
    depth: bool,
    test_every: Option<usize>,
    test_list: Option<PathBuf>,
) -> PyResult<Bound<'py, PyDict>> {
    use diffsvg::volume::view::{Model, Split, check_downscale, orbit_cameras};
    use numpy::PyArrayMethods as _;
    let split: Split = split.parse().map_err(bad)?;
    check_downscale(downscale).map_err(to_py)?;
    if scene.is_none() && orbit == 0 {
        return Err(bad("nothing to render: give scene and/or orbit"));
    }
    type Rgb = (u32, u32, Vec<[f32; 3]>);
    // The depth images of a camera, when asked for.
    let depth_of = |m: &Model, c: &diffsvg::volume::camera::Camera| {
        depth.then(|| m.render_depth(c)).transpose()
    };
    let mut depths = Vec::new();
    let mut orbit_depths = Vec::new();
    let (views, orbits) = py
        .detach(|| -> diffsvg::Result<(Vec<(String, Rgb, Rgb)>, Vec<Rgb>)> {
            crate::on_pool(|| {
                let mut m = Model::load(&model, step)?;
                let data = match &scene {
                    Some(d) => {
                        let loading = diffsvg::volume::dataset::Loading {
                            downscale,
                            test_every,
                            test_list: test_list.clone(),
                        };
                        Some(m.load_dataset(d, &loading)?.0)
                    }
                    None => None,
                };
                let mut views = Vec::new();
                if let Some(d) = &data {
                    for v in split.views(d) {
                        depths.extend(depth_of(&m, &v.camera)?);
                        let out = m.render(&v.camera)?;
                        views.push((
                            v.name.clone(),
                            (v.width, v.height, out),
                            (v.width, v.height, v.rgb.clone()),
                        ));
                    }
                }
                let cams = if orbit > 0 {
                    orbit_cameras(m.bounds(), data.as_ref(), orbit, elevation)?
                } else {
                    Vec::new()
                };
                let mut orbits = Vec::new();
                for c in &cams {
                    orbit_depths.extend(depth_of(&m, c)?);
                    orbits.push((c.width, c.height, m.render(c)?));
                }
                Ok((views, orbits))
            })
        })
        .map_err(to_py)?;
    let array = |(w, h, rgb): Rgb| -> PyResult<Bound<'py, numpy::PyArray3<f32>>> {
        let flat: Vec<f32> = rgb.into_iter().flatten().collect();
        numpy::PyArray1::from_vec(py, flat)
            .reshape([h as usize, w as usize, 3])
            .map_err(|e| bad(e.to_string()))
    };
    let out = PyDict::new(py);
    let list = pyo3::types::PyList::empty(py);
    for (name, a, b) in views {
        list.append((name, array(a)?, array(b)?))?;
    }
    out.set_item("views", list)?;
    let list = pyo3::types::PyList::empty(py);
    for o in orbits {
        list.append(array(o)?)?;
    }
    out.set_item("orbit", list)?;
    if depth {
        let image = |w: u32, h: u32, v: Vec<f32>| {
            numpy::PyArray1::from_vec(py, v)
                .reshape([h as usize, w as usize])
                .map_err(|e| bad(e.to_string()))
        };
        for (key, ds) in [("depth", depths), ("orbit_depth", orbit_depths)] {
            let list = pyo3::types::PyList::empty(py);
            for d in ds {
                let entry = PyDict::new(py);
                entry.set_item("expected", image(d.width, d.height, d.expected)?)?;
                entry.set_item("median", image(d.width, d.height, d.median)?)?;
                list.append(entry)?;
            }
            out.set_item(key, list)?;
        }
    }
    Ok(out)
}
