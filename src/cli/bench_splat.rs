//! `diffsvg bench splat`: time of the 3D Gaussian splatting renderer per view, forward
//! ([`diffsvg::volume::splat::render`]) and backward ([`diffsvg::volume::splat::backward_into`],
//! from one forward rendering and a fixed pseudo-random image gradient), on gsplat's test
//! fixture (the garden points with random Gaussians around them, 3 cameras) and on trained
//! models seen from a dataset's test cameras or from an orbit around them.
//!
//! **The garden.** gsplat's `assets/test_garden.npz` holds COLMAP points of the
//! Mip-NeRF 360 garden (`means3d`, `colors`), three world-to-camera matrices in OpenCV
//! axes (`viewmats`), their intrinsics (`Ks`) and the image size (`height`, `width`).
//! gsplat's tests (`load_test_data`) turn it into Gaussians, and so does [`garden`]: keep
//! the points inside `[-2, 2]³`, color = `colors / 255`, scales uniform in
//! `[1e-4, 0.02]`, orientations normalized 4D normal draws, opacities uniform in
//! `[0, 1]` (drawn from [`Rng`] with seed [`GARDEN_SEED`], so every run times the same
//! model), SH degree 0 with DC `(color − 0.5) / C₀`.

use std::fmt::Write as _;
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use serde::Serialize;

use diffsvg::glam::{Affine3A, DMat4, Mat3A, Vec3A};
use diffsvg::limits::MAX_GAUSSIANS;
use diffsvg::metrics::median;
use diffsvg::scene::random::Rng;
use diffsvg::volume::camera::Camera;
use diffsvg::volume::splat::{self, Gaussians, Gradients, RenderSettings};

/// Seed of the garden's random scales, orientations and opacities.
pub const GARDEN_SEED: u64 = 42;

/// Seed of the image gradient fed to the backward pass.
const D_RGB_SEED: u64 = 7;

/// The garden's points are kept inside `[-CROP, CROP]³` (as gsplat's tests do).
const CROP: f32 = 2.0;

/// Cameras of a trained model: the first this many test views of `--scene`, or this
/// many views on an orbit around it.
const MODEL_VIEWS: usize = 3;

/// Elevation of the orbit around a model without `--scene`, degrees (`view`'s default).
const ORBIT_ELEVATION: f32 = 30.0;

/// `C₀ = 1 / (2√π)`, the degree-0 SH basis constant.
const SH_C0: f32 = 0.282_094_8;

/// Arguments of `diffsvg bench splat`.
#[derive(clap::Args, Debug)]
pub struct SplatBenchArgs {
    /// gsplat's test fixture, timed from its 3 cameras (default:
    /// ../shared/data/scenes/gsplat_test_garden/test_garden.npz; with --model and no
    /// --garden, skipped when absent).
    #[arg(long)]
    garden: Option<PathBuf>,
    /// Time only the --model workloads, not the garden.
    #[arg(long, conflicts_with = "garden", requires = "model")]
    no_garden: bool,
    /// Trained models (PLY) to time as well, from the cameras of --scene, or without it
    /// from 3 views of 200×200 on an orbit around the model's bounding box (those of
    /// `diffsvg view --orbit` without a scene).
    #[arg(long, num_args = 1..)]
    model: Vec<PathBuf>,
    /// Dataset folder whose first 3 test views (train views when it has no test split)
    /// are the cameras of every --model (photos with lens distortion are undistorted).
    #[arg(long, requires = "model")]
    scene: Option<PathBuf>,
    /// Divide the dataset's image sizes by this integer (as in training).
    #[arg(long, default_value_t = 1)]
    downscale: u32,
    /// Timed runs per view and thread count, after one warm-up; the median is reported.
    #[arg(long, default_value_t = 10)]
    runs: usize,
    /// Thread counts.
    #[arg(long, value_delimiter = ',', default_value = "1,2")]
    threads: Vec<usize>,
    /// Print the results as JSON instead of the table.
    #[arg(long)]
    json: bool,
}

/// A model and the cameras to time it from.
struct Workload {
    name: String,
    gaussians: Gaussians,
    settings: RenderSettings,
    views: Vec<(String, Camera)>,
}

/// The JSON report.
#[derive(Serialize)]
struct Report {
    runs: usize,
    /// 1-minute load average before the first run (Linux), for judging the times.
    load_before: Option<f64>,
    workloads: Vec<WorkloadReport>,
}

#[derive(Serialize)]
struct WorkloadReport {
    name: String,
    gaussians: usize,
    sh_degree: u32,
    views: Vec<ViewReport>,
}

#[derive(Serialize)]
struct ViewReport {
    name: String,
    width: u32,
    height: u32,
    /// Gaussians left after culling.
    visible: usize,
    timings: Vec<Timing>,
}

#[derive(Serialize)]
struct Timing {
    threads: usize,
    /// Median forward time, milliseconds.
    forward_ms: f64,
    /// Median backward time, milliseconds (from one forward rendering, not counted).
    backward_ms: f64,
}

/// The garden's default location, beside the checkout.
fn default_garden() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../shared/data/scenes/gsplat_test_garden/test_garden.npz")
}

/// Runs `diffsvg bench splat`.
pub fn run(a: SplatBenchArgs) -> Result<()> {
    if a.runs == 0 || a.downscale == 0 || a.threads.contains(&0) {
        bail!("--runs, --downscale and every --threads entry must be at least 1");
    }
    let mut workloads = Vec::new();
    let garden_path = a.garden.clone().unwrap_or_else(default_garden);
    let wanted = a.garden.is_some() || a.model.is_empty() || garden_path.is_file();
    if a.no_garden {
        // Only the models.
    } else if wanted {
        if !garden_path.exists() {
            bail!(
                "{}: garden file not found (give --garden PATH, or --model)",
                garden_path.display()
            );
        }
        let g = garden(&garden_path)?;
        workloads.push(Workload {
            name: "garden".into(),
            gaussians: g.gaussians,
            settings: RenderSettings::default(),
            views: g
                .cameras
                .into_iter()
                .enumerate()
                .map(|(i, c)| (format!("view {i}"), c))
                .collect(),
        });
    } else {
        eprintln!("note: {}: not found, garden skipped", garden_path.display());
    }
    // The scene's cameras and background, shared by every model.
    let scene = match &a.scene {
        Some(dir) => {
            let data = super::recon_report::load_splat_dataset(dir, a.downscale)?;
            let (views, note) = if data.test.is_empty() {
                (&data.train, " (train)")
            } else {
                (&data.test, "")
            };
            let views: Vec<(String, Camera)> = views
                .iter()
                .take(MODEL_VIEWS)
                .map(|v| (format!("{}{note}", v.name), v.camera))
                .collect();
            Some((views, diffsvg::volume::recon::background(&data)))
        }
        None => None,
    };
    for m in &a.model {
        let gaussians = splat::load(m)?;
        let (views, background) = match &scene {
            Some((views, background)) => (views.clone(), *background),
            None => {
                let cams = diffsvg::volume::view::orbit_cameras(
                    diffsvg::volume::view::splat_bounds(&gaussians),
                    None,
                    MODEL_VIEWS,
                    ORBIT_ELEVATION,
                )
                .with_context(|| m.display().to_string())?;
                let views = cams
                    .into_iter()
                    .enumerate()
                    .map(|(i, c)| (format!("orbit {i}"), c))
                    .collect();
                (views, RenderSettings::default().background)
            }
        };
        workloads.push(Workload {
            name: m.display().to_string(),
            gaussians,
            settings: RenderSettings {
                background,
                ..RenderSettings::default()
            },
            views,
        });
    }
    let report = Report {
        runs: a.runs,
        load_before: load_average(),
        workloads: time_all(&workloads, &a.threads, a.runs)?,
    };
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", table(&report));
    }
    Ok(())
}

/// Times every view of every workload with each thread count.
fn time_all(workloads: &[Workload], threads: &[usize], runs: usize) -> Result<Vec<WorkloadReport>> {
    let pools = threads
        .iter()
        .map(|&n| Ok((n, rayon::ThreadPoolBuilder::new().num_threads(n).build()?)))
        .collect::<Result<Vec<_>>>()?;
    let context = |w: &Workload, view: &str| format!("{}, {view}", w.name);
    // Every view rendered once before any is timed, so that a view the renderer refuses
    // (a camera with distortion, too many tiles) fails at once; the culling count is
    // the same for every thread count.
    let mut visible = Vec::new();
    for w in workloads {
        for (name, cam) in &w.views {
            let first = splat::render(&w.gaussians, cam, &w.settings)
                .map_err(anyhow::Error::msg)
                .with_context(|| context(w, name))?;
            visible.push(first.visible());
        }
    }
    let mut visible = visible.into_iter();
    let mut out = Vec::new();
    for w in workloads {
        let mut views = Vec::new();
        let mut grads = Gradients::zeros(&w.gaussians);
        for (name, cam) in &w.views {
            let d_rgb = image_gradient(cam.width as usize * cam.height as usize);
            let mut timings = Vec::new();
            for (n, pool) in &pools {
                let times = pool.install(|| {
                    let forward_ms = median_ms(runs, || {
                        std::hint::black_box(splat::render(&w.gaussians, cam, &w.settings))
                            .map(|_| ())
                    })?;
                    let rendered = splat::render(&w.gaussians, cam, &w.settings)?;
                    let backward_ms = median_ms(runs, || {
                        splat::backward_into(
                            &w.gaussians,
                            cam,
                            &w.settings,
                            &rendered,
                            &d_rgb,
                            &mut grads,
                        )
                    })?;
                    std::hint::black_box(&grads);
                    Ok::<_, String>((forward_ms, backward_ms))
                });
                let (forward_ms, backward_ms) = times
                    .map_err(anyhow::Error::msg)
                    .with_context(|| context(w, name))?;
                timings.push(Timing {
                    threads: *n,
                    forward_ms,
                    backward_ms,
                });
            }
            views.push(ViewReport {
                name: name.clone(),
                width: cam.width,
                height: cam.height,
                visible: visible.next().unwrap_or(0),
                timings,
            });
        }
        out.push(WorkloadReport {
            name: w.name.clone(),
            gaussians: w.gaussians.len(),
            sh_degree: w.gaussians.sh_degree,
            views,
        });
    }
    Ok(out)
}

/// The image gradient fed to the backward pass for `pixels` pixels: each channel uniform
/// in `±1 / (3·pixels)`, the size of a mean L1 loss's gradient, from [`D_RGB_SEED`] (the
/// same for every view of that size and every thread count).
fn image_gradient(pixels: usize) -> Vec<[f32; 3]> {
    let mut rng = Rng::new(D_RGB_SEED);
    let scale = 1.0 / (3 * pixels.max(1)) as f64;
    (0..pixels)
        .map(|_| [0; 3].map(|_| rng.range(-scale, scale) as f32))
        .collect()
}

/// Median wall time of `f` over `runs` calls after one warm-up call, milliseconds; the
/// first error stops the timing.
fn median_ms(runs: usize, mut f: impl FnMut() -> Result<(), String>) -> Result<f64, String> {
    f()?;
    let mut t = Vec::with_capacity(runs);
    for _ in 0..runs {
        let s = Instant::now();
        f()?;
        t.push(s.elapsed().as_secs_f64() * 1e3);
    }
    Ok(median(&mut t))
}

/// The 1-minute load average from `/proc/loadavg`, where there is one.
fn load_average() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/loadavg").ok()?;
    s.split_whitespace().next()?.parse().ok()
}

/// The report as a Markdown table, one row per view and thread count.
fn table(r: &Report) -> String {
    let mut s = format!(
        "3D Gaussian splatting on the CPU, medians of {} runs",
        r.runs
    );
    if let Some(l) = r.load_before {
        let _ = write!(s, " (load average {l:.2} before the first)");
    }
    s += ".\n\n| model | view | size | Gaussians | visible | threads | forward (ms) \
          | backward (ms) |\n|---|---|---|---:|---:|---:|---:|---:|\n";
    for w in &r.workloads {
        for v in &w.views {
            for t in &v.timings {
                let _ = writeln!(
                    s,
                    "| {} | {} | {}×{} | {} | {} | {} | {:.1} | {:.1} |",
                    w.name,
                    v.name,
                    v.width,
                    v.height,
                    w.gaussians,
                    v.visible,
                    t.threads,
                    t.forward_ms,
                    t.backward_ms
                );
            }
        }
    }
    s
}

/// gsplat's test fixture as Gaussians and cameras (see the module documentation).
pub struct Garden {
    /// The points inside `[-2, 2]³` with random shapes and opacities.
    pub gaussians: Gaussians,
    /// The fixture's cameras (OpenGL axes, as everywhere in `diffsvg::volume`).
    pub cameras: Vec<Camera>,
}

/// Reads gsplat's `test_garden.npz` and builds the Gaussians of its tests and our
/// cameras from its view matrices. Errors name the file and the array.
pub fn garden(path: &Path) -> Result<Garden> {
    let file = File::open(path).with_context(|| format!("{}: cannot open", path.display()))?;
    let mut zip = zip::ZipArchive::new(BufReader::new(file))
        .with_context(|| format!("{}: not an .npz (zip) archive", path.display()))?;
    let mut npz = Npz {
        path,
        zip: &mut zip,
    };
    let (shape, means) = npz.array::<f32>("means3d", &[None, Some(3)])?;
    let n = shape[0] as usize;
    let (_, colors) = npz.array::<u8>("colors", &[Some(n as u64), Some(3)])?;
    let (shape, viewmats) = npz.array::<f32>("viewmats", &[None, Some(4), Some(4)])?;
    let views = shape[0] as usize;
    let (_, ks) = npz.array::<f32>("Ks", &[Some(views as u64), Some(3), Some(3)])?;
    let height = npz.size("height")?;
    let width = npz.size("width")?;
    let cameras = (0..views)
        .map(|v| {
            let m: [f32; 16] = viewmats[16 * v..16 * (v + 1)].try_into().unwrap();
            let k: [f32; 9] = ks[9 * v..9 * (v + 1)].try_into().unwrap();
            camera_from_opencv(&m, &k, width, height)
                .with_context(|| format!("{}: camera {v}", path.display()))
        })
        .collect::<Result<Vec<_>>>()?;
    let mut rng = Rng::new(GARDEN_SEED);
    let mut g = Gaussians::new(0);
    for i in 0..n {
        let p: [f32; 3] = means[3 * i..3 * i + 3].try_into().unwrap();
        if !p.iter().all(|v| (-CROP..=CROP).contains(v)) {
            continue;
        }
        let sh = [0, 1, 2].map(|c| (colors[3 * i + c] as f32 / 255.0 - 0.5) / SH_C0);
        let log_scale = [0; 3].map(|_| (rng.range(1e-4, 0.02) as f32).ln());
        let mut q = [0; 4].map(|_| normal(&mut rng));
        let norm = q.iter().map(|v| v * v).sum::<f32>().sqrt();
        if norm > 0.0 {
            q = q.map(|v| v / norm);
        } else {
            q = [1.0, 0.0, 0.0, 0.0];
        }
        // Opacity in the open interval, so that its logit is finite.
        let o = rng.range(0.0, 1.0).clamp(1e-6, 1.0 - 1e-6);
        let logit = (o / (1.0 - o)).ln() as f32;
        g.push(p, log_scale, q, logit, &sh);
    }
    g.validate()
        .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
    Ok(Garden {
        gaussians: g,
        cameras,
    })
}

/// A standard normal draw (Box–Muller).
fn normal(rng: &mut Rng) -> f32 {
    let u = rng.range(f64::MIN_POSITIVE, 1.0);
    let v = rng.range(0.0, 1.0);
    ((-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()) as f32
}

/// Our camera for an OpenCV one: `viewmat` a row-major 4×4 world-to-camera matrix with
/// camera axes +X right, +Y down, +Z forward, `k` a row-major 3×3 pinhole matrix. Pixel
/// coordinates are those of gsplat and of [`Camera`] alike (pixel `(x, y)` spans
/// `[x, x + 1) × [y, y + 1)`), so the intrinsics carry over unchanged; the pose is the
/// inverse of `viewmat` with its camera y and z axes negated (OpenCV to OpenGL axes).
pub fn camera_from_opencv(
    viewmat: &[f32; 16],
    k: &[f32; 9],
    width: u32,
    height: u32,
) -> Result<Camera> {
    if k[1].abs() > 1e-6 * k[0].abs() || k[3] != 0.0 || k[6..] != [0.0, 0.0, 1.0] {
        bail!("intrinsics {k:?} are not a pinhole matrix without skew");
    }
    let w2c = DMat4::from_cols_array(&viewmat.map(f64::from)).transpose();
    let bottom = w2c.row(3).to_array();
    if bottom
        .iter()
        .zip([0.0, 0.0, 0.0, 1.0])
        .any(|(a, b)| (a - b).abs() > 1e-6)
    {
        bail!("view matrix's last row must be 0 0 0 1, got {bottom:?}");
    }
    let c2w = w2c.inverse();
    if !c2w.is_finite() {
        bail!("view matrix is singular");
    }
    let col = |c: usize, sign: f64| Vec3A::from((c2w.col(c).truncate() * sign).as_vec3());
    let pose = Affine3A {
        matrix3: Mat3A::from_cols(col(0, 1.0), col(1, -1.0), col(2, -1.0)),
        translation: col(3, 1.0),
    };
    Ok(Camera::new(width, height, k[0], k[4], k[2], k[5], pose)?)
}

/// An open `.npz` archive, for reading arrays with checked shapes.
struct Npz<'a> {
    path: &'a Path,
    zip: &'a mut zip::ZipArchive<BufReader<File>>,
}

impl Npz<'_> {
    /// Opens array `name`, C order, not pickled.
    fn open(
        &mut self,
        name: &str,
    ) -> Result<npyz::NpyFile<zip::read::ZipFile<'_, BufReader<File>>>> {
        let path = self.path.display().to_string();
        let entry = self
            .zip
            .by_name(&format!("{name}.npy"))
            .map_err(|e| anyhow::anyhow!("{path}: no array {name} ({e})"))?;
        let npy =
            npyz::NpyFile::new(entry).map_err(|e| anyhow::anyhow!("{path}: array {name}: {e}"))?;
        if npy.order() != npyz::Order::C && npy.shape().len() > 1 {
            bail!("{path}: array {name} is in Fortran order (C order expected)");
        }
        Ok(npy)
    }

    /// Array `name` of element type `T`, flattened in C order, after checking that its
    /// shape matches `want` (`None` dimensions are free, up to [`MAX_GAUSSIANS`]).
    fn array<T: npyz::Deserialize>(
        &mut self,
        name: &str,
        want: &[Option<u64>],
    ) -> Result<(Vec<u64>, Vec<T>)> {
        let path = self.path.display().to_string();
        let npy = self.open(name)?;
        let shape = npy.shape().to_vec();
        let fits = shape.len() == want.len()
            && shape.iter().zip(want).all(|(&s, w)| match w {
                Some(w) => s == *w,
                None => s <= MAX_GAUSSIANS as u64,
            });
        if !fits {
            let want: Vec<String> = want
                .iter()
                .map(|w| w.map_or("N".to_string(), |w| w.to_string()))
                .collect();
            bail!(
                "{path}: array {name} has shape {shape:?}, expected [{}]",
                want.join(", ")
            );
        }
        let descr = npy.dtype().descr();
        let data = npy
            .into_vec::<T>()
            .map_err(|e| anyhow::anyhow!("{path}: array {name} (dtype {descr}): {e}"))?;
        Ok((shape, data))
    }

    /// The integer scalar `name` (an image side: 1 to `limits::MAX_SIDE`).
    fn size(&mut self, name: &str) -> Result<u32> {
        let path = self.path.display().to_string();
        let npy = self.open(name)?;
        if !npy.shape().is_empty() {
            bail!(
                "{path}: array {name} has shape {:?}, expected a scalar",
                npy.shape()
            );
        }
        let descr = npy.dtype().descr();
        let value: i64 = match npy.try_data::<i64>() {
            Ok(mut r) => r.next().transpose()?.unwrap_or(0),
            Err(npy) => match npy.try_data::<i32>() {
                Ok(mut r) => r.next().transpose()?.unwrap_or(0) as i64,
                Err(_) => bail!("{path}: array {name} has dtype {descr}, expected an integer"),
            },
        };
        if !(1..=diffsvg::limits::MAX_SIDE as i64).contains(&value) {
            bail!("{path}: {name} is {value}, not an image side");
        }
        Ok(value as u32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use diffsvg::glam::{Mat3, Quat, Vec2, Vec3};

    /// An OpenCV world-to-camera matrix, row-major, from a rotation and translation.
    fn viewmat(rot: Mat3, t: Vec3) -> [f32; 16] {
        let mut m = [0.0; 16];
        for r in 0..3 {
            for c in 0..3 {
                m[4 * r + c] = rot.col(c)[r];
            }
            m[4 * r + 3] = t[r];
        }
        m[15] = 1.0;
        m
    }

    #[test]
    fn opencv_camera_projects_to_the_same_pixel() {
        let rot = Mat3::from_quat(Quat::from_euler(
            diffsvg::glam::EulerRot::YXZ,
            0.7,
            -0.4,
            0.2,
        ));
        let t = Vec3::new(0.3, -1.2, 2.5);
        let k = [480.6, 0.0, 324.2, 0.0, 481.5, 210.1, 0.0, 0.0, 1.0];
        let cam = camera_from_opencv(&viewmat(rot, t), &k, 648, 420).unwrap();
        // Points in front of the OpenCV camera (+Z forward, +Y down), in its own axes.
        for pc in [
            Vec3::new(0.0, 0.0, 3.0),
            Vec3::new(0.5, -0.3, 2.0),
            Vec3::new(-1.0, 0.6, 4.0),
        ] {
            let want = Vec2::new(k[0] * pc.x / pc.z + k[2], k[4] * pc.y / pc.z + k[5]);
            // World point: invert p_cam = R p_world + t.
            let pw = rot.transpose() * (pc - t);
            let got = cam.project(pw).expect("in front of the camera");
            assert!((got - want).length() < 1e-3, "{pc}: {got} vs {want}");
        }
        // Behind the OpenCV camera is behind ours.
        let behind = rot.transpose() * (Vec3::new(0.0, 0.0, -1.0) - t);
        assert!(cam.project(behind).is_none());
        assert_eq!((cam.width, cam.height), (648, 420));
    }

    #[test]
    fn opencv_camera_refuses_bad_matrices() {
        let k = [100.0, 0.0, 50.0, 0.0, 100.0, 50.0, 0.0, 0.0, 1.0];
        let mut m = viewmat(Mat3::IDENTITY, Vec3::ZERO);
        m[12] = 0.5;
        assert!(camera_from_opencv(&m, &k, 100, 100).is_err());
        let mut skew = k;
        skew[1] = 3.0;
        let m = viewmat(Mat3::IDENTITY, Vec3::ZERO);
        assert!(camera_from_opencv(&m, &skew, 100, 100).is_err());
        // A reflection is no pose.
        let m = viewmat(Mat3::from_diagonal(Vec3::new(1.0, 1.0, -1.0)), Vec3::ZERO);
        assert!(camera_from_opencv(&m, &k, 100, 100).is_err());
    }

    /// gsplat's fixture beside the checkout (or under `$DIFFSVG_DATA`); `None` with a
    /// printed reason when absent, a panic then under `DIFFSVG_REQUIRE_DATA=1`.
    fn garden_file(test: &str) -> Option<PathBuf> {
        let data = std::env::var_os("DIFFSVG_DATA")
            .map(PathBuf::from)
            .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
        let f = data.join("scenes/gsplat_test_garden/test_garden.npz");
        if f.is_file() {
            return Some(f);
        }
        let reason = format!("{} not found", f.display());
        if std::env::var_os("DIFFSVG_REQUIRE_DATA").is_some_and(|v| v == "1") {
            panic!("{test}: {reason}, and DIFFSVG_REQUIRE_DATA=1 forbids skipping");
        }
        eprintln!("SKIPPED {test}: {reason} (set DIFFSVG_DATA)");
        None
    }

    #[test]
    fn garden_loads_and_its_points_are_in_view() {
        let Some(f) = garden_file("garden_loads_and_its_points_are_in_view") else {
            return;
        };
        let g = garden(&f).unwrap();
        let n = g.gaussians.len();
        assert!(n > 100_000 && n < 138_766, "{n} points kept");
        assert_eq!(g.gaussians.sh_degree, 0);
        assert_eq!(g.cameras.len(), 3);
        let in_image = |cam: &Camera| {
            let inside = g
                .gaussians
                .means
                .iter()
                .filter_map(|&p| cam.project(Vec3::from(p)))
                .filter(|uv| uv.x >= 0.0 && uv.y >= 0.0 && uv.x < 648.0 && uv.y < 420.0)
                .count();
            inside as f64 / n as f64
        };
        for (i, cam) in g.cameras.iter().enumerate() {
            assert_eq!((cam.width, cam.height), (648, 420));
            assert!((cam.fx - 480.61).abs() < 0.01 && (cam.cy - 210.06).abs() < 0.01);
            // The cameras look at the garden: about half to two thirds of the cropped
            // points fall inside each image (0.49 to 0.64 when this was written).
            let fraction = in_image(cam);
            assert!(
                fraction > 0.4,
                "camera {i}: {fraction:.3} of the points in the image"
            );
            // Left in OpenCV axes (no y, z flip), the camera would look away from them.
            let flip = Affine3A::from_mat3(Mat3::from_diagonal(Vec3::new(1.0, -1.0, -1.0)));
            let unflipped = Camera {
                c2w: cam.c2w * flip,
                ..*cam
            };
            let fraction = in_image(&unflipped);
            assert!(fraction < 0.05, "camera {i} unflipped: {fraction:.3}");
        }
        // The same seed, the same model.
        assert_eq!(garden(&f).unwrap().gaussians, g.gaussians);
        // Scales and opacities as drawn.
        let s = g.gaussians.scale(7);
        assert!(
            s.min_element() >= 0.999e-4 && s.max_element() <= 0.02001,
            "{s}"
        );
        let o = g.gaussians.opacity(7);
        assert!(o > 0.0 && o < 1.0);
    }

    #[test]
    fn npz_arrays_of_the_wrong_shape_are_refused() {
        let Some(f) = garden_file("npz_arrays_of_the_wrong_shape_are_refused") else {
            return;
        };
        let mut zip = zip::ZipArchive::new(BufReader::new(File::open(&f).unwrap())).unwrap();
        let mut npz = Npz {
            path: &f,
            zip: &mut zip,
        };
        let e = npz
            .array::<f32>("viewmats", &[None, Some(3), Some(4)])
            .unwrap_err();
        let e = e.to_string();
        assert!(
            e.contains("test_garden.npz") && e.contains("viewmats"),
            "{e}"
        );
        assert!(e.contains("[3, 4, 4]") && e.contains("[N, 3, 4]"), "{e}");
        let e = npz
            .array::<f32>("colors", &[None, Some(3)])
            .unwrap_err()
            .to_string();
        assert!(e.contains("colors") && e.contains("u1"), "{e}");
        let e = npz
            .array::<f32>("nothing", &[None])
            .unwrap_err()
            .to_string();
        assert!(e.contains("no array nothing"), "{e}");
        assert_eq!(npz.size("width").unwrap(), 648);
    }
}
