//! `diffsvg mesh render`, `diffsvg mesh fit` and `diffsvg bench mesh`: thin over
//! [`diffsvg::mesh`].

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Result, bail};

use super::progress::{install_interrupt_handler, interrupted, terminal_bar};
use diffsvg::Image;
use diffsvg::image_io::{check_output, side_by_side};
use diffsvg::mesh::fit::{
    FitOptions, Fitted, fit, mse, orbit_cameras, sphere_around, sphere_cameras,
};
use diffsvg::mesh::refine::{Displacement, refine};
use diffsvg::mesh::simplify::{reproject_texture, simplify};
use diffsvg::mesh::{
    DirLight, Lighting, Mesh, MipPyramid, RenderOptions, View, read_mesh, torus_knot, write_mesh,
};
use diffsvg::metrics::{median, psnr_from_mse};
use diffsvg::volume::camera::Camera;

/// Mesh commands.
#[derive(clap::Subcommand, Debug)]
pub enum MeshCommand {
    /// Render a mesh (OBJ or glTF) from orbit cameras around its bounds (exact box-filtered
    /// anti-aliasing); several views are laid out side by side.
    Render(RenderArgs),
    /// Fit an icosphere's vertex positions and vertex colors to renders of a reference
    /// mesh from orbit views; prints held-out PSNR and writes the fitted OBJ.
    Fit(FitArgs),
    /// Build a high-poly reference reproducibly: split every triangle in four `--levels`
    /// times (UVs interpolated) and displace the surface along its normal by smooth
    /// noise (deterministic by `--seed`).
    Refine(RefineArgs),
    /// Simplify a high-poly reference to `--triangles` (quadric-error edge collapse, its
    /// texture reprojected from the reference: the classic baseline), then optimize the
    /// low-poly mesh's vertex positions and texture so that it looks like the reference
    /// from all around; prints both meshes' held-out PSNR and writes OBJ + MTL + PNG.
    Simplify(SimplifyArgs),
}

/// Arguments of `diffsvg mesh`.
#[derive(clap::Args, Debug)]
pub struct MeshArgs {
    #[command(subcommand)]
    command: MeshCommand,
}

/// Shading flags of `mesh render`, `mesh fit` and `view`: Lambert lights (see
/// `diffsvg::mesh::Lighting`; without them meshes render unlit) and mip levels.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct ShadingArgs {
    /// A directional light: world-space direction towards the light, then optionally its
    /// RGB intensity (default 1,1,1); repeatable, at most 4. Shades the mesh (Lambert, smooth
    /// normals): albedo × (ambient + Σ max(0, n·l) · intensity).
    #[arg(long = "light", value_name = "DX,DY,DZ[,R,G,B]", value_parser = parse_light, allow_hyphen_values = true)]
    pub lights: Vec<DirLight>,
    /// Ambient light, RGB (default 0,0,0 with --light; alone it scales the albedo).
    #[arg(long, value_name = "R,G,B", value_parser = parse_rgb, allow_hyphen_values = true)]
    pub ambient: Option<[f64; 3]>,
    /// Sample minified textures from mip levels (2×2 box-filtered, the level nearest the
    /// pixel's footprint) instead of bilinear alone, which aliases.
    #[arg(long)]
    pub mipmaps: bool,
}

impl ShadingArgs {
    /// The lighting these flags ask for (`None`: unlit).
    pub fn lighting(&self) -> Result<Option<Lighting>> {
        if self.lights.is_empty() && self.ambient.is_none() {
            return Ok(None);
        }
        let l = Lighting::new(self.ambient.unwrap_or([0.0; 3]), &self.lights)
            .map_err(|e| anyhow::anyhow!("--light: {e}"))?;
        Ok(Some(l))
    }
}

/// Parses `A,B,C…` into `n` finite numbers.
fn parse_numbers(s: &str, counts: &[usize]) -> std::result::Result<Vec<f64>, String> {
    let v = s
        .split(',')
        .map(|t| {
            t.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("{t:?} is not a finite number"))
        })
        .collect::<std::result::Result<Vec<f64>, String>>()?;
    if !counts.contains(&v.len()) {
        return Err(format!(
            "{} numbers, expected {}",
            v.len(),
            counts
                .iter()
                .map(|c| c.to_string())
                .collect::<Vec<_>>()
                .join(" or ")
        ));
    }
    Ok(v)
}

/// A clap value parser for `R,G,B`.
fn parse_rgb(s: &str) -> std::result::Result<[f64; 3], String> {
    let v = parse_numbers(s, &[3])?;
    Ok([v[0], v[1], v[2]])
}

/// A clap value parser for `DX,DY,DZ[,R,G,B]`.
fn parse_light(s: &str) -> std::result::Result<DirLight, String> {
    let v = parse_numbers(s, &[3, 6])?;
    let direction = [v[0], v[1], v[2]];
    if direction == [0.0; 3] {
        return Err("the direction is zero".into());
    }
    let intensity = if v.len() == 6 {
        [v[3], v[4], v[5]]
    } else {
        [1.0; 3]
    };
    Ok(DirLight {
        direction,
        intensity,
    })
}

/// Arguments of `diffsvg mesh render`.
#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// Mesh file: OBJ (with its MTL and texture), or glTF 2.0 (`.gltf` with its buffers and
    /// images, `.glb`).
    mesh: PathBuf,
    /// Number of orbit views.
    #[arg(long, default_value_t = 1)]
    orbit: usize,
    /// Image side, pixels.
    #[arg(long, default_value_t = 256)]
    size: u32,
    /// Output PNG.
    #[arg(short, long)]
    output: PathBuf,
    /// Keep back faces (slower; the same image for closed meshes).
    #[arg(long)]
    no_cull: bool,
    /// Transparent background instead of white.
    #[arg(long)]
    transparent: bool,
    #[command(flatten)]
    light: ShadingArgs,
}

/// Arguments of `diffsvg mesh fit`.
#[derive(clap::Args, Debug)]
pub struct FitArgs {
    /// Reference mesh (OBJ, `.gltf` or `.glb`), rendered from the training and held-out views.
    #[arg(required_unless_present = "scene", conflicts_with = "scene")]
    reference: Option<PathBuf>,
    /// Fit to a dataset's photos instead (NeRF-synthetic, instant-ngp or COLMAP folder,
    /// pinhole cameras): its training views, and up to `--test-views` of its test views
    /// held out; photos on white are fitted over white, others over black.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Divide the dataset's image sizes by this integer (with `--scene`).
    #[arg(long, default_value_t = 1)]
    downscale: u32,
    /// Start from this mesh instead of an icosphere (around the reference's bounds, or
    /// with `--scene` at the point the cameras look at, 0.3 times their distance across).
    #[arg(long)]
    start: Option<PathBuf>,
    /// Training views on an orbit (with a reference mesh).
    #[arg(long, default_value_t = 20)]
    views: usize,
    /// Held-out views, between the training ones (with `--scene`: at most this many of
    /// its test views, evenly spaced).
    #[arg(long, default_value_t = 5)]
    test_views: usize,
    /// Image side, pixels.
    #[arg(long, default_value_t = 128)]
    size: u32,
    /// Optimizer steps (each renders every training view).
    #[arg(long, default_value_t = 200)]
    iters: usize,
    /// Subdivisions of the starting icosphere (20·4ⁿ triangles).
    #[arg(long, default_value_t = 3)]
    subdivisions: u32,
    /// Learning rate of vertex positions, world units per step.
    #[arg(long, default_value_t = 2e-3)]
    lr_positions: f64,
    /// Learning rate of vertex colors.
    #[arg(long, default_value_t = 1e-2)]
    lr_colors: f64,
    /// Weight of the edge-length smoothness term.
    #[arg(long, default_value_t = 1e-3)]
    smoothness: f64,
    /// Output mesh: OBJ (with MTL), or glTF (`.glb`, `.gltf`), by the extension. Beside
    /// it: `.log.csv` (held-out and training PSNR against training seconds) and the plot
    /// `.psnr.png` / `.psnr.svg`.
    #[arg(short, long)]
    output: PathBuf,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
    /// Every this many steps, render the held-out views and log their mean PSNR (the time
    /// this takes is not counted as training time); always before the first step and at
    /// the end. 0: only those two.
    #[arg(long, default_value_t = 10)]
    eval_every: usize,
    /// Print one JSON object per held-out evaluation and a JSON summary instead of a
    /// progress bar.
    #[arg(long)]
    json: bool,
    /// Lights for the reference's and the model's renders (the fitted colors are albedo);
    /// fixed unless --fit-lights.
    #[command(flatten)]
    light: ShadingArgs,
    /// Fit the model's lights too, starting from --light/--ambient (which must be given);
    /// with a reference mesh, the reference is rendered with --reference-light instead,
    /// when given.
    #[arg(long)]
    fit_lights: bool,
    /// Learning rate of the lights (ambient and intensities; directions as unit vectors).
    #[arg(long, default_value_t = 1e-2)]
    lr_lights: f64,
    /// The reference's lights when they differ from the model's start (with a reference
    /// mesh and --fit-lights): a directional light as --light, repeatable.
    #[arg(long = "reference-light", value_name = "DX,DY,DZ[,R,G,B]", value_parser = parse_light, allow_hyphen_values = true)]
    reference_lights: Vec<DirLight>,
    /// Learning rate of the UVs, per step (a textured --start mesh); 0 keeps them.
    #[arg(long, default_value_t = 0.0)]
    lr_uvs: f64,
    /// Learn a pose correction of each training camera; held-out views keep theirs.
    #[command(flatten)]
    poses: super::recon_report::PoseArgs,
    /// Learning rate of the pose corrections' rotation, radians per step; their
    /// translation's is this times the start mesh's bounding radius.
    #[arg(long, default_value_t = 1e-3)]
    lr_pose: f64,
    /// Seed of --perturb-poses.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

/// Arguments of `diffsvg mesh refine`.
#[derive(clap::Args, Debug)]
pub struct RefineArgs {
    /// Mesh to refine (OBJ or glTF).
    mesh: PathBuf,
    /// Times every triangle is split in four (4ⁿ times the triangles).
    #[arg(long, default_value_t = 4)]
    levels: u32,
    /// Largest displacement along the normal, fraction of the bounding radius (0: none).
    #[arg(long, default_value_t = 0.03)]
    displace: f64,
    /// Noise frequency of the first octave, cycles per bounding radius.
    #[arg(long, default_value_t = 16.0)]
    frequency: f64,
    /// Octaves of noise (1 to 8).
    #[arg(long, default_value_t = 3)]
    octaves: u32,
    /// Seed of the noise.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output mesh: OBJ (with MTL and PNG when textured), or glTF (`.glb`, `.gltf`: the
    /// texture inside), by the extension.
    #[arg(short, long)]
    output: PathBuf,
}

/// Arguments of `diffsvg mesh simplify`.
#[derive(clap::Args, Debug)]
pub struct SimplifyArgs {
    /// High-poly reference mesh (OBJ or glTF).
    reference: PathBuf,
    /// Target triangle count.
    #[arg(long, default_value_t = 6500)]
    triangles: usize,
    /// Training views, from all around (a Fibonacci sphere).
    #[arg(long, default_value_t = 40)]
    views: usize,
    /// Held-out views (another Fibonacci sphere, turned: none is a training view).
    #[arg(long, default_value_t = 50)]
    test_views: usize,
    /// Image side of every view, pixels.
    #[arg(long, default_value_t = 256)]
    size: u32,
    /// Optimizer steps (each renders every training view).
    #[arg(long, default_value_t = 60)]
    iters: usize,
    /// Side of the low-poly mesh's texture, texels.
    #[arg(long, default_value_t = 512)]
    texture_size: u32,
    /// Learning rate of vertex positions, world units per step.
    #[arg(long, default_value_t = 2e-3)]
    lr_positions: f64,
    /// Learning rate of texels.
    #[arg(long, default_value_t = 1e-2)]
    lr_colors: f64,
    /// Weight of the edge-length smoothness term.
    #[arg(long, default_value_t = 0.0)]
    smoothness: f64,
    /// Also write the classic simplification (with its reprojected texture) here.
    #[arg(long)]
    classic: Option<PathBuf>,
    /// Output mesh of the optimized low-poly mesh: OBJ (with MTL and PNG), or glTF (`.glb`,
    /// `.gltf`), by the extension.
    #[arg(short, long)]
    output: PathBuf,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

/// Arguments of `diffsvg bench mesh`.
#[derive(clap::Args, Debug)]
pub struct MeshBenchArgs {
    /// Mesh file, OBJ or glTF (default: ../shared/data/meshes/spot/spot.obj).
    mesh: Option<PathBuf>,
    /// Image side, pixels.
    #[arg(long, default_value_t = 256)]
    size: u32,
    /// Timed runs; medians are reported.
    #[arg(long, default_value_t = 9)]
    runs: usize,
    /// Thread counts.
    #[arg(long, value_delimiter = ',', default_value = "1,2")]
    threads: Vec<usize>,
    /// Sample the texture from mip levels (trilinear); the pyramid is built once, before
    /// the timed runs, as a fit step or a render of many views shares it (its build
    /// time is printed).
    #[arg(long)]
    mipmaps: bool,
    /// PyTorch3D's camera-position tutorial rebuilt instead: a generated torus knot of
    /// 2,560 triangles (a teapot's size; the mesh argument is ignored), silhouette loss
    /// (squared alpha difference to the silhouette from another orbit position), one
    /// iteration = forward + backward, giving the gradient of the camera pose (its
    /// translation is printed).
    #[arg(long)]
    tutorial: bool,
}

/// Runs `diffsvg mesh …`.
pub fn run(a: MeshArgs) -> Result<()> {
    match a.command {
        MeshCommand::Render(r) => run_render(r),
        MeshCommand::Fit(f) => run_fit(f),
        MeshCommand::Refine(r) => run_refine(r),
        MeshCommand::Simplify(s) => run_simplify(s),
    }
}

fn check_size(size: u32, views: usize) -> Result<()> {
    if size == 0 || size > 4096 {
        bail!("--size {size} must be between 1 and 4096");
    }
    if views == 0 || views > 1000 {
        bail!("the number of views {views} must be between 1 and 1000");
    }
    Ok(())
}

fn run_render(a: RenderArgs) -> Result<()> {
    check_size(a.size, a.orbit)?;
    check_output(&a.output, "png")?;
    let mesh = read_mesh(&a.mesh)?;
    let opts = RenderOptions {
        background: (!a.transparent).then_some([1.0; 3]),
        cull_back_faces: !a.no_cull,
        lighting: a.light.lighting()?,
        mipmaps: a.light.mipmaps,
        ..RenderOptions::default()
    };
    let cams = orbit_cameras(&mesh, a.orbit, a.size, 0.0)?;
    let t = Instant::now();
    let pyramid = MipPyramid::for_mesh(&mesh, &opts);
    let imgs: Vec<Image> = cams
        .iter()
        .map(|c| Ok(View::with_pyramid(&mesh, c, opts, pyramid.as_ref())?.render()))
        .collect::<diffsvg::Result<_>>()?;
    let ms = t.elapsed().as_secs_f64() * 1e3 / imgs.len() as f64;
    let out = if imgs.len() == 1 {
        imgs.into_iter().next().expect("one image")
    } else {
        let refs: Vec<&Image> = imgs.iter().collect();
        side_by_side(&refs)
    };
    out.save_png(&a.output)?;
    println!(
        "{}: {} triangles, {} view(s) at {}², {ms:.1} ms per view → {}",
        a.mesh.display(),
        mesh.triangles.len(),
        cams.len(),
        a.size,
        a.output.display()
    );
    Ok(())
}

/// Checks a mesh output path: OBJ (with its MTL and PNG beside it), or glTF (`.gltf`,
/// `.glb`: one file), chosen by the extension.
fn check_mesh_output(path: &Path) -> Result<()> {
    match diffsvg::mesh::MeshFormat::of(path) {
        Some(f) => Ok(check_output(path, f.extension())?),
        None => bail!(
            "{}: output must be a .obj, .gltf or .glb file",
            path.display()
        ),
    }
}

fn run_fit(a: FitArgs) -> Result<()> {
    check_size(a.size, a.views)?;
    check_size(a.size, a.test_views)?;
    if a.subdivisions > 6 {
        bail!("--subdivisions {} must be at most 6", a.subdivisions);
    }
    for (flag, v) in [
        ("--lr-lights", a.lr_lights),
        ("--lr-uvs", a.lr_uvs),
        ("--lr-pose", a.lr_pose),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            bail!("{flag} {v} must be finite and not negative");
        }
    }
    diffsvg::volume::recon::check_perturbation(a.poses.perturb_poses)
        .map_err(|e| anyhow::anyhow!("--perturb-poses: {e}"))?;
    check_mesh_output(&a.output)?;
    let mut opts = FitOptions {
        iters: a.iters,
        lr_positions: a.lr_positions,
        lr_colors: a.lr_colors,
        smoothness: a.smoothness,
        lr_uvs: a.lr_uvs,
        ..FitOptions::default()
    };
    opts.render.lighting = a.light.lighting()?;
    opts.render.mipmaps = a.light.mipmaps;
    if a.fit_lights {
        if opts.render.lighting.is_none() {
            bail!("--fit-lights: give the lights to start from with --light or --ambient");
        }
        opts.lr_lights = a.lr_lights;
    } else if !a.reference_lights.is_empty() {
        bail!("--reference-light: only with --fit-lights");
    }
    if a.scene.is_some() && !a.reference_lights.is_empty() {
        bail!("--reference-light: only with a reference mesh (photos have their own lights)");
    }
    let (mut train, test, sphere) = match (&a.reference, &a.scene) {
        (Some(r), _) => {
            let reference = read_mesh(r)?;
            let mut ref_opts = opts;
            if !a.reference_lights.is_empty() {
                let ambient = opts.render.lighting.map_or([0.0; 3], |l| l.ambient);
                ref_opts.render.lighting = Some(
                    Lighting::new(ambient, &a.reference_lights)
                        .map_err(|e| anyhow::anyhow!("--reference-light: {e}"))?,
                );
            }
            let render_all = |cams: &[Camera]| render_views(&reference, cams, &ref_opts);
            let train = render_all(&orbit_cameras(&reference, a.views, a.size, 0.0)?)?;
            let test = render_all(&orbit_cameras(&reference, a.test_views, a.size, 0.5)?)?;
            (train, test, sphere_around(&reference, a.subdivisions))
        }
        (None, Some(dir)) => {
            dataset_views(dir, a.downscale, a.test_views, a.subdivisions, &mut opts)?
        }
        (None, None) => bail!("give a reference mesh or --scene DIR"),
    };
    let mut model = match &a.start {
        Some(p) => {
            let mut m = read_mesh(p)?;
            if m.colors.is_none() && m.texture.is_none() {
                m.colors = Some(vec![[0.5; 3]; m.positions.len()]);
            }
            m
        }
        None => sphere,
    };
    if a.lr_uvs > 0.0 && (model.texture.is_none() || model.uvs.is_none()) {
        bail!("--lr-uvs: the start mesh has no texture and UVs (give a textured --start)");
    }
    // Pose refinement: the training cameras (perturbed on request); held-out views keep
    // theirs.
    let loaded: Vec<Camera> = train.iter().map(|(c, _)| *c).collect();
    if let Some([deg, dist]) = a.poses.perturb_poses {
        let mut cams = loaded.clone();
        diffsvg::volume::pose::perturb_cameras(&mut cams, deg, dist, a.seed);
        for ((c, _), p) in train.iter_mut().zip(cams) {
            *c = p;
        }
    }
    if a.poses.refine_poses {
        let (lo, hi) = model.bounds();
        let r = 0.5 * (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
        opts.lr_poses = [a.lr_pose, a.lr_pose * r];
    }
    let eval = Eval {
        test: &test,
        every: a.eval_every,
        json: a.json,
    };
    let run = fit_with_progress(&mut model, &train, &opts, a.quiet || a.json, Some(eval))?;
    let pose_error = a.poses.perturb_poses.map(|_| {
        let given: Vec<Camera> = train.iter().map(|(c, _)| *c).collect();
        let (lo, hi) = model.bounds();
        let corner = |p: [f64; 3]| glam::Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32);
        let points = diffsvg::volume::pose::lattice(corner(lo), corner(hi), 5);
        diffsvg::volume::recon::mean_pose_error(&loaded, &given, &run.fitted.poses, &points)
    });
    write_mesh(&model, &a.output)?;
    run.write_log(&a.output)?;
    let (start_psnr, end_psnr) = (run.tests[0].2, run.tests.last().map_or(f64::NAN, |t| t.2));
    let lights = run
        .fitted
        .lighting
        .filter(|_| a.fit_lights)
        .map(|l| {
            let dirs: Vec<String> = l
                .lights()
                .iter()
                .map(|d| {
                    format!(
                        "({:.3}, {:.3}, {:.3})",
                        d.direction[0], d.direction[1], d.direction[2]
                    )
                })
                .collect();
            format!("; fitted light directions {}", dirs.join(", "))
        })
        .unwrap_or_default();
    if a.json {
        println!(
            "{}",
            serde_json::json!({"done": true, "output": a.output, "triangles": model.triangles.len(),
                "steps": run.steps, "seconds": run.seconds, "train_psnr": psnr_from_mse(run.fitted.mse),
                "test_psnr_start": start_psnr, "test_psnr": end_psnr, "test_views": test.len(),
                "lighting": run.fitted.lighting.filter(|_| a.fit_lights).map(|l| serde_json::json!({
                    "ambient": l.ambient,
                    "lights": l.lights().iter().map(|d| serde_json::json!({
                        "direction": d.direction, "intensity": d.intensity})).collect::<Vec<_>>()})),
                "pose_corrections": if opts.fits_poses() { run.fitted.poses.len() } else { 0 },
                "pose_error": super::recon_report::pose_error_json(&pose_error)})
        );
    } else {
        println!(
            "fitted {} triangles to {} views at {}² in {:.1} s ({} steps): train PSNR {:.2} dB, \
             held-out PSNR {start_psnr:.2} → {end_psnr:.2} dB over {} views{lights}{} → {}",
            model.triangles.len(),
            train.len(),
            train[0].0.width,
            run.seconds,
            run.steps,
            psnr_from_mse(run.fitted.mse),
            test.len(),
            super::recon_report::pose_error_text(&pose_error, None),
            a.output.display()
        );
    }
    Ok(())
}

/// Held-out evaluation during a fit: the views, every how many steps, JSON rows or not.
#[derive(Clone, Copy)]
struct Eval<'a> {
    test: &'a [(Camera, Image)],
    every: usize,
    json: bool,
}

/// A fit as run by [`fit_with_progress`].
struct FitRun {
    fitted: Fitted,
    /// Steps taken.
    steps: usize,
    /// Training seconds (held-out evaluations excluded).
    seconds: f64,
    /// `(step, training seconds, training PSNR)` of every step.
    train: Vec<(usize, f64, f64)>,
    /// `(step, training seconds, held-out PSNR)` of every evaluation, the start first
    /// and the end last.
    tests: Vec<(usize, f64, f64)>,
}

impl FitRun {
    /// Writes `<model>.log.csv` (step, training seconds, training PSNR, held-out PSNR
    /// where evaluated; a last row for the end) and the PSNR plot beside `model`.
    fn write_log(&self, model: &Path) -> Result<()> {
        use std::fmt::Write as _;
        let mut csv = String::from("iteration,seconds,train_psnr,test_psnr\n");
        let test_at = |i: usize| self.tests.iter().find(|t| t.0 == i).map(|t| t.2);
        for &(i, secs, p) in &self.train {
            let cell = test_at(i).map(|t| format!("{t:.3}")).unwrap_or_default();
            let _ = writeln!(csv, "{i},{secs:.3},{p:.3},{cell}");
        }
        if let Some(&(i, secs, p)) = self.tests.last().filter(|t| t.0 == self.steps) {
            let _ = writeln!(csv, "{i},{secs:.3},,{p:.3}");
        }
        diffsvg::image_io::write_atomic(
            &super::recon_report::sibling(model, ".log.csv"),
            csv.as_bytes(),
        )?;
        super::recon_report::write_psnr_plot(
            model,
            self.tests.iter().map(|t| (t.1, t.2)).collect(),
            self.train.iter().map(|t| (t.1, t.2)).collect(),
            "training views",
        )
    }
}

/// [`fit`] with a progress bar (or a line every 25 steps without a terminal, nothing when
/// `quiet`), stopped by Ctrl-C; with `eval`, the held-out views' PSNR before the first
/// step, every `eval.every` steps and at the end (their time excluded from the training
/// seconds).
fn fit_with_progress(
    model: &mut Mesh,
    train: &[(Camera, Image)],
    opts: &FitOptions,
    quiet: bool,
    eval: Option<Eval>,
) -> diffsvg::Result<FitRun> {
    install_interrupt_handler();
    let bar = terminal_bar(quiet, opts.iters, "steps");
    let start = Instant::now();
    let mut eval_secs = 0.0;
    let mut tests = Vec::new();
    let mut rows = Vec::new();
    let mut failed = None;
    let mut evaluate = |step: usize, m: &Mesh, render: RenderOptions, secs: f64| {
        let Some(e) = eval else { return Ok(0.0) };
        let t = Instant::now();
        let p = held_out_psnr(m, e.test, &FitOptions { render, ..*opts })?;
        tests.push((step, secs, p));
        if e.json {
            println!(
                "{}",
                serde_json::json!({"iteration": step, "seconds": secs, "test_psnr": p})
            );
        }
        Ok::<f64, diffsvg::Error>(t.elapsed().as_secs_f64())
    };
    let mut stopped = false;
    let fitted = fit(model, train, opts, |s, snap| {
        let secs = start.elapsed().as_secs_f64() - eval_secs;
        rows.push((s.iter, secs, psnr_from_mse(s.mse)));
        if let Some(e) = eval
            && (s.iter == 0 || (e.every > 0 && s.iter % e.every == 0))
        {
            match evaluate(s.iter, snap.mesh, snap.render, secs) {
                Ok(dt) => eval_secs += dt,
                Err(err) => {
                    failed = Some(err);
                    return false;
                }
            }
        }
        if let Some(b) = &bar {
            b.set_position(s.iter as u64);
            b.set_message(format!("train PSNR {:.2} dB", psnr_from_mse(s.mse)));
        } else if !quiet && (s.iter % 25 == 0) {
            println!(
                "step {:4}  train PSNR {:.2} dB",
                s.iter,
                psnr_from_mse(s.mse)
            );
        }
        stopped = interrupted();
        !stopped
    })?;
    if let Some(err) = failed {
        return Err(err);
    }
    let seconds = start.elapsed().as_secs_f64() - eval_secs;
    // A stop comes before its step.
    let steps = rows.len() - usize::from(stopped);
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    let render = RenderOptions {
        lighting: fitted.lighting,
        ..opts.render
    };
    evaluate(steps, model, render, seconds)?;
    Ok(FitRun {
        fitted,
        steps,
        seconds,
        train: rows,
        tests,
    })
}

/// Images with the cameras they are seen from.
type Posed = Vec<(Camera, Image)>;

/// A dataset's training views and up to `max_test` of its test views (evenly spaced) as
/// `(camera, photo)` pairs, and an icosphere at the point the training cameras look at
/// (0.3 times their median distance in radius, gray). Sets the fit's background to the
/// dataset's: white for objects on white, else black.
fn dataset_views(
    dir: &Path,
    downscale: u32,
    max_test: usize,
    subdivisions: u32,
    opts: &mut FitOptions,
) -> Result<(Posed, Posed, Mesh)> {
    use diffsvg::volume::dataset::{Dataset, Loading};
    diffsvg::volume::view::check_downscale(downscale)?;
    let data = Dataset::load_with(
        dir,
        &Loading {
            downscale,
            ..Loading::default()
        },
    )?;
    if data.train.is_empty() {
        bail!("{}: no training views", dir.display());
    }
    let bg = if data.white_background { 1.0 } else { 0.0 };
    opts.render.background = Some([bg; 3]);
    let pair = |v: &diffsvg::volume::dataset::View| {
        let img = Image {
            width: v.width,
            height: v.height,
            data: v.rgb.iter().map(|c| [c[0], c[1], c[2], 1.0]).collect(),
        };
        (v.camera, img)
    };
    let train: Vec<_> = data.train.iter().map(pair).collect();
    let n = data.test.len();
    let k = max_test.min(n);
    let test: Vec<_> = (0..k).map(|i| pair(&data.test[i * n / k])).collect();
    let (center, dist) = data.focus();
    let mut sphere = diffsvg::mesh::icosphere(subdivisions, 0.3 * dist as f64);
    for p in &mut sphere.positions {
        for (q, c) in p.iter_mut().zip(center.to_array()) {
            *q += c as f64;
        }
    }
    sphere.colors = Some(vec![[0.5; 3]; sphere.positions.len()]);
    Ok((train, test, sphere))
}

/// `mesh`'s renders from `cams`, paired with them.
fn render_views(
    mesh: &Mesh,
    cams: &[Camera],
    opts: &FitOptions,
) -> diffsvg::Result<Vec<(Camera, Image)>> {
    let pyramid = MipPyramid::for_mesh(mesh, &opts.render);
    cams.iter()
        .map(|c| {
            let view = View::with_pyramid(mesh, c, opts.render, pyramid.as_ref())?;
            Ok((*c, view.render()))
        })
        .collect()
}

/// Mean PSNR (dB, of the mean MSE) of `m`'s renders against held-out `(camera, image)`s.
fn held_out_psnr(m: &Mesh, test: &[(Camera, Image)], opts: &FitOptions) -> diffsvg::Result<f64> {
    let mut e = 0.0;
    let pyramid = MipPyramid::for_mesh(m, &opts.render);
    for (c, t) in test {
        e += mse(
            &View::with_pyramid(m, c, opts.render, pyramid.as_ref())?.render(),
            t,
        );
    }
    Ok(psnr_from_mse(e / test.len().max(1) as f64))
}

fn run_refine(a: RefineArgs) -> Result<()> {
    for (flag, v) in [("--displace", a.displace), ("--frequency", a.frequency)] {
        if !(v.is_finite() && v >= 0.0) {
            bail!("{flag} {v} must be finite and not negative");
        }
    }
    if !(1..=8).contains(&a.octaves) {
        bail!("--octaves {} must be between 1 and 8", a.octaves);
    }
    if a.levels > 8 {
        bail!(
            "--levels {} must be at most 8 (4⁸ = 65,536 times the triangles)",
            a.levels
        );
    }
    check_mesh_output(&a.output)?;
    let mesh = read_mesh(&a.mesh)?;
    let d = Displacement {
        amplitude: a.displace,
        frequency: a.frequency,
        octaves: a.octaves,
        seed: a.seed,
    };
    let t = Instant::now();
    let out = refine(&mesh, a.levels, &d)?;
    let secs = t.elapsed().as_secs_f64();
    write_mesh(&out, &a.output)?;
    println!(
        "{}: {} → {} triangles ({} levels, displacement {} of the bounding radius, seed {}) \
         in {secs:.1} s → {}",
        a.mesh.display(),
        mesh.triangles.len(),
        out.triangles.len(),
        a.levels,
        a.displace,
        a.seed,
        a.output.display()
    );
    Ok(())
}

fn run_simplify(a: SimplifyArgs) -> Result<()> {
    check_size(a.size, a.views)?;
    check_size(a.size, a.test_views)?;
    if a.texture_size == 0 || a.texture_size > 4096 {
        bail!(
            "--texture-size {} must be between 1 and 8192",
            a.texture_size
        );
    }
    if a.triangles == 0 || a.triangles > diffsvg::limits::MAX_MESH_TRIANGLES {
        bail!(
            "--triangles {} must be between 1 and {}",
            a.triangles,
            diffsvg::limits::MAX_MESH_TRIANGLES
        );
    }
    check_mesh_output(&a.output)?;
    if let Some(c) = &a.classic {
        check_mesh_output(c)?;
    }
    let start = Instant::now();
    let reference = read_mesh(&a.reference)?;
    if reference.uvs.is_none() {
        bail!(
            "{}: the reference has no UVs (the low-poly texture lives in its UV chart)",
            a.reference.display()
        );
    }
    let opts = FitOptions {
        iters: a.iters,
        lr_positions: a.lr_positions,
        lr_colors: a.lr_colors,
        smoothness: a.smoothness,
        ..FitOptions::default()
    };
    let say = |what: String| {
        if !a.quiet {
            println!("[{:6.1} s] {what}", start.elapsed().as_secs_f64());
        }
    };
    say(format!(
        "read {}: {} triangles",
        a.reference.display(),
        reference.triangles.len()
    ));
    let render_all = |cams: &[Camera]| render_views(&reference, cams, &opts);
    let t = Instant::now();
    let train = render_all(&sphere_cameras(&reference, a.views, a.size, 0.0)?)?;
    let test = render_all(&sphere_cameras(&reference, a.test_views, a.size, 0.5)?)?;
    say(format!(
        "rendered the reference from {} training and {} held-out views at {}² ({:.0} ms a view)",
        a.views,
        a.test_views,
        a.size,
        t.elapsed().as_secs_f64() * 1e3 / (a.views + a.test_views) as f64
    ));
    let t = Instant::now();
    let mut model = simplify(&reference, a.triangles)?;
    say(format!(
        "simplified to {} triangles in {:.1} s",
        model.triangles.len(),
        t.elapsed().as_secs_f64()
    ));
    let t = Instant::now();
    model.texture = Some(reproject_texture(&model, &reference, a.texture_size)?);
    model.colors = None;
    say(format!(
        "reprojected a {0}×{0} texture in {1:.1} s",
        a.texture_size,
        t.elapsed().as_secs_f64()
    ));
    let classic_psnr = held_out_psnr(&model, &test, &opts)?;
    say(format!("classic: held-out PSNR {classic_psnr:.2} dB"));
    if let Some(c) = &a.classic {
        write_mesh(&model, c)?;
    }
    let t = Instant::now();
    let train_mse = fit_with_progress(&mut model, &train, &opts, a.quiet, None)?
        .fitted
        .mse;
    let fit_secs = t.elapsed().as_secs_f64();
    let end_psnr = held_out_psnr(&model, &test, &opts)?;
    write_mesh(&model, &a.output)?;
    println!(
        "simplified {} → {} triangles in {:.1} s (fit {fit_secs:.1} s, {} steps, {} views at {}², \
         train PSNR {:.2} dB): held-out PSNR over {} views: classic {classic_psnr:.2} dB, \
         optimized {end_psnr:.2} dB ({:+.2} dB) → {}",
        reference.triangles.len(),
        model.triangles.len(),
        start.elapsed().as_secs_f64(),
        a.iters,
        a.views,
        a.size,
        psnr_from_mse(train_mse),
        a.test_views,
        end_psnr - classic_psnr,
        a.output.display()
    );
    Ok(())
}

/// Runs `diffsvg bench mesh`: forward, and forward + backward, medians per thread count.
pub fn run_bench(a: MeshBenchArgs) -> Result<()> {
    check_size(a.size, 1)?;
    if a.runs == 0 || a.runs > 1000 {
        bail!("--runs {} must be between 1 and 1000", a.runs);
    }
    if a.tutorial {
        return run_bench_tutorial(a);
    }
    let path = a
        .mesh
        .clone()
        .unwrap_or_else(|| PathBuf::from("../shared/data/meshes/spot/spot.obj"));
    let mesh = read_mesh(&path)?;
    let cam = orbit_cameras(&mesh, 8, a.size, 0.0)?[1];
    let opts = RenderOptions {
        background: Some([1.0; 3]),
        mipmaps: a.mipmaps,
        ..RenderOptions::default()
    };
    let t = Instant::now();
    let pyramid = MipPyramid::for_mesh(&mesh, &opts);
    let pyramid_ms = t.elapsed().as_secs_f64() * 1e3;
    println!(
        "{}: {} triangles, {}² (median of {} runs){}",
        path.display(),
        mesh.triangles.len(),
        a.size,
        a.runs,
        match &pyramid {
            Some(p) => format!(
                ", mip levels ({} above the texture) built once in {pyramid_ms:.2} ms",
                p.len()
            ),
            None => String::new(),
        }
    );
    println!("| threads | forward ms | forward + backward ms |\n|---|---|---|");
    for &n in &a.threads {
        if n == 0 || n > 256 {
            bail!("--threads {n} must be between 1 and 256");
        }
        let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build()?;
        let (mut fwd, mut both) = (Vec::new(), Vec::new());
        pool.install(|| -> Result<()> {
            for _ in 0..a.runs + 1 {
                let t = Instant::now();
                let img = View::with_pyramid(&mesh, &cam, opts, pyramid.as_ref())?.render();
                let f = t.elapsed().as_secs_f64() * 1e3;
                let mut d = img.clone();
                for p in &mut d.data {
                    *p = p.map(|v| v - 0.5);
                }
                let t = Instant::now();
                let view = View::with_pyramid(&mesh, &cam, opts, pyramid.as_ref())?;
                let img2 = view.render();
                let g = view.backward(&d, true)?;
                let b = t.elapsed().as_secs_f64() * 1e3;
                std::hint::black_box((&img2, &g));
                fwd.push(f);
                both.push(b);
            }
            Ok(())
        })?;
        // The first run warms the caches and the pool; it is left out.
        println!(
            "| {n} | {:.2} | {:.2} |",
            median(&mut fwd[1..]),
            median(&mut both[1..])
        );
    }
    Ok(())
}

/// `bench mesh --tutorial`: PyTorch3D's camera-position tutorial scene (silhouette loss,
/// gradient of the camera pose, `MeshGrad::pose`), timed per iteration.
fn run_bench_tutorial(a: MeshBenchArgs) -> Result<()> {
    let mesh = torus_knot(128, 10);
    let cams = orbit_cameras(&mesh, 8, a.size, 0.0)?;
    let (cam, target_cam) = (cams[1], cams[2]);
    let opts = RenderOptions::default();
    let target = View::new(&mesh, &target_cam, opts)?.render();
    println!(
        "torus knot: {} triangles, {}², silhouette loss (median of {} runs)",
        mesh.triangles.len(),
        a.size,
        a.runs
    );
    println!("| threads | iteration ms | loss | camera gradient |\n|---|---|---|---|");
    for &n in &a.threads {
        if n == 0 || n > 256 {
            bail!("--threads {n} must be between 1 and 256");
        }
        let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build()?;
        let mut times = Vec::new();
        let mut last = (0.0, [0.0; 3]);
        pool.install(|| -> Result<()> {
            for _ in 0..a.runs + 1 {
                let t = Instant::now();
                let view = View::new(&mesh, &cam, opts)?;
                let img = view.render();
                // L = Σ (α − α_target)², on the alpha channel only.
                let mut d = img.clone();
                let mut loss = 0.0f64;
                for (p, q) in d.data.iter_mut().zip(&target.data) {
                    let e = p[3] - q[3];
                    loss += (e as f64).powi(2);
                    *p = [0.0, 0.0, 0.0, 2.0 * e];
                }
                let g = view.backward(&d, false)?;
                // The camera pose gradient: its translation part.
                let gc = [g.pose[3], g.pose[4], g.pose[5]];
                times.push(t.elapsed().as_secs_f64() * 1e3);
                last = (loss, gc);
            }
            Ok(())
        })?;
        println!(
            "| {n} | {:.2} | {:.1} | ({:.3}, {:.3}, {:.3}) |",
            median(&mut times[1..]),
            last.0,
            last.1[0],
            last.1[1],
            last.1[2]
        );
    }
    Ok(())
}
