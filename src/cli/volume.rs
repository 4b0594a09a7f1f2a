//! `diffsvg recon voxel` (fit a sparse voxel grid to posed photos) and `diffsvg view`
//! (render a fitted model from held-out cameras or an orbit, with PSNR and SSIM).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use serde_json::json;

use super::choices::choice;
use super::progress::{install_interrupt_handler, interrupted};
use super::recon_report::{
    Reporting, file_stem, psnr_text, sibling, undistortion_note, write_psnr_plot,
};
use super::util::flag_error;
use diffsvg::choice::Choice as _;
use diffsvg::image_io::{Image, contact_sheet, write_atomic};
use diffsvg::volume::depth::save_depth;
use diffsvg::volume::metrics::{psnr, ssim};
use diffsvg::volume::recon::{VoxelJob, recon_voxel};
use diffsvg::volume::view::{Split, check_downscale, orbit_cameras};
use diffsvg::volume::voxel::{self, TrainStep};

/// Arguments of `diffsvg recon`.
#[derive(clap::Args, Debug)]
pub struct ReconArgs {
    #[command(subcommand)]
    model: ReconModel,
}

#[derive(clap::Subcommand, Debug)]
enum ReconModel {
    /// A sparse grid of density and spherical-harmonic color (Plenoxels).
    Voxel(VoxelArgs),
    /// 3D Gaussians rasterized by splatting (Kerbl et al. 2023), written as a PLY.
    Splat(super::splat::SplatArgs),
    /// An Instant-NGP neural field: a multiresolution hash grid and tiny MLPs (.ngp).
    Ngp(super::ngp::NgpArgs),
    /// A NeRF neural field: NeRF's positional encoding and an MLP sized for a CPU
    /// (.nerf); slow, the ladder's first rung.
    Nerf(super::ngp::NerfArgs),
}

/// Arguments of `diffsvg recon voxel`.
#[derive(clap::Args, Debug)]
pub struct VoxelArgs {
    /// Dataset folder: NeRF-synthetic (transforms_train.json), instant-ngp
    /// (transforms.json) or COLMAP (sparse/0/cameras.bin or .txt, photos in images/).
    #[arg(long)]
    scene: PathBuf,
    /// Model file to write (.vox).
    #[arg(short, long)]
    output: PathBuf,
    /// Final grid resolution, cells per axis; training starts coarser and doubles up to it.
    #[arg(long, default_value_t = 128)]
    res: u32,
    /// Optimizer iterations (mini-batches of rays).
    #[arg(long, default_value_t = 3000)]
    iters: usize,
    /// Rays per iteration.
    #[arg(long, default_value_t = 8192)]
    batch: usize,
    /// Divide image sizes by this integer.
    #[arg(long, default_value_t = 1)]
    downscale: u32,
    /// Spherical-harmonic degree of the color, 0 to 3.
    #[arg(long, default_value_t = 2)]
    degree: u32,
    /// Half the box's side, world units (default: the cameras' median distance from
    /// where they look, times 0.4 for objects on white (NeRF-synthetic) or 1 for real
    /// photos (instant-ngp), whose surroundings must fit in the box).
    #[arg(long)]
    bound: Option<f32>,
    /// Sample spacing along rays, in voxels.
    #[arg(long, default_value_t = 0.5)]
    step: f32,
    /// Weight of the total-variation term on densities (default: 0 for objects on white,
    /// 1e-5 for real photos).
    #[arg(long)]
    tv_density: Option<f32>,
    /// Weight of the total-variation term on SH coefficients (default: 0 for objects on
    /// white, 1e-6 for real photos).
    #[arg(long)]
    tv_sh: Option<f32>,
    /// Weight of the sparsity term that removes faint density (default: 0 for objects on
    /// white, 1e-2 for real photos, where it suppresses floaters in front of the cameras).
    #[arg(long)]
    sparsity: Option<f32>,
    /// Random seed of the ray batches.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Instant-ngp and COLMAP folders: hold out the views at positions 0, N, 2N, … (file
    /// order for instant-ngp, sorted by name for COLMAP) as test views; 0: none (default:
    /// every 8th). NeRF-synthetic folders use transforms_test.json.
    #[arg(long, value_name = "N")]
    test_every: Option<usize>,
    /// Instant-ngp and COLMAP folders: the test views are those named in FILE, one a
    /// line (COLMAP: the image's name, such as test/r_0.png; instant-ngp: the frame's
    /// file_path), instead of every N-th; to_colmap writes the source's as DIR/test.txt.
    #[arg(long, value_name = "FILE", conflicts_with = "test_every")]
    test_list: Option<PathBuf>,
    /// After training, also score the test views with each camera aligned to the model
    /// held fixed (test-time pose alignment, as pose-refining reconstructions are
    /// scored): `test_psnr_aligned` in --json. Score the runs you compare alike.
    #[arg(long)]
    align_test_poses: bool,
    #[command(flatten)]
    poses: super::recon_report::PoseArgs,
    #[command(flatten)]
    report: Reporting,
}

/// Arguments of `diffsvg view`.
#[derive(clap::Args, Debug)]
pub struct ViewArgs {
    /// Model file written by `diffsvg recon voxel` (.vox), `diffsvg recon splat` (a
    /// Gaussian-splatting PLY or SPZ), `diffsvg recon ngp` (.ngp) or `recon nerf` (.nerf); the kind is read
    /// from the file's header. A triangle mesh (`.obj` with its MTL and texture, `.gltf`,
    /// `.glb`; `mesh fit` writes OBJ) renders with the exact mesh renderer.
    model: PathBuf,
    /// Dataset folder whose cameras to render from.
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Which views.
    #[arg(long, ignore_case = true, value_parser = choice::<Split>(), default_value = Split::default().name())]
    split: Split,
    /// Output folder: one PNG per view (rendering | photo), metrics.csv, and orbit frames.
    #[arg(short, long)]
    output: PathBuf,
    /// Divide image sizes by this integer (as in training).
    #[arg(long, default_value_t = 1)]
    downscale: u32,
    /// Which views are test views (as in training): see `recon splat --help`.
    #[arg(long, value_name = "N")]
    test_every: Option<usize>,
    /// Which views are test views (as in training): see `recon splat --help`.
    #[arg(long, value_name = "FILE", conflicts_with = "test_every")]
    test_list: Option<PathBuf>,
    /// Also render this many views on a circle around the model: orbit-NNN.png,
    /// orbit.gif and (from 2 views) orbit.png, a contact sheet of the first half of the
    /// circle above the second.
    #[arg(long, default_value_t = 0)]
    orbit: usize,
    /// Elevation of the orbit, degrees above the horizontal plane (objects on white; real
    /// photos are orbited along the arc and at the elevation of their cameras, since the
    /// far side was never seen).
    #[arg(long, default_value_t = 30.0)]
    elevation: f32,
    /// Sample spacing along rays, in voxels (voxel models).
    #[arg(long, default_value_t = 0.5)]
    step: f32,
    /// Also write depth images of every view (Gaussian and voxel models): NAME.depth-expected and
    /// NAME.depth-median, each as a 16-bit PNG (level × units_per_level = depth, the
    /// scale in depth.csv) and a float32 .npy; depths along the viewing axis, world
    /// units, 0 where none.
    #[arg(long)]
    depth: bool,
    /// Print a JSON summary instead of a table.
    #[arg(long)]
    json: bool,
    /// Lambert shading and mip levels of meshes (refused for other models).
    #[command(flatten)]
    light: super::mesh::ShadingArgs,
}

/// Runs `diffsvg recon`.
pub fn run_recon(a: ReconArgs) -> Result<()> {
    match a.model {
        ReconModel::Voxel(v) => run_voxel(v),
        ReconModel::Splat(v) => super::splat::run(v),
        ReconModel::Ngp(v) => super::ngp::run(v),
        ReconModel::Nerf(v) => super::ngp::run_nerf(v),
    }
}

fn check_model_path(path: &Path) -> Result<()> {
    super::util::check_output(path, "vox")
}

fn run_voxel(a: VoxelArgs) -> Result<()> {
    check_model_path(&a.output)?;
    let job = VoxelJob {
        res: a.res,
        iters: a.iters,
        batch: a.batch,
        downscale: a.downscale,
        degree: a.degree,
        bound: a.bound,
        step: a.step,
        tv_density: a.tv_density,
        tv_sh: a.tv_sh,
        sparsity: a.sparsity,
        seed: a.seed,
        eval_every: a.report.eval_every,
        test_every: a.test_every,
        test_list: a.test_list,
        refine_poses: a.poses.refine_poses,
        perturb_poses: a.poses.perturb_poses,
        align_test_poses: a.align_test_poses,
    };
    job.validate().map_err(flag_error)?;
    install_interrupt_handler();
    let bar = super::progress::terminal_bar(a.report.json || a.report.quiet, a.iters, "");
    let out = recon_voxel(&a.scene, &job, &mut |s, test| {
        if let Some(b) = &bar {
            b.set_position(s.iteration as u64);
            b.set_message(format!(
                "loss {:.2e}  PSNR {:.2} dB  {:.0}k rays/s  {}³  {} voxels",
                s.loss,
                s.psnr,
                s.rays_per_second / 1e3,
                s.res,
                s.allocated
            ));
            if let Some(p) = test {
                b.println(format!(
                    "iteration {}: test PSNR {p:.2} dB after {:.0} s",
                    s.iteration, s.elapsed
                ));
            }
        }
        if a.report.json && (s.iteration % 50 == 0 || test.is_some()) {
            println!(
                "{}",
                json!({"iteration": s.iteration, "loss": s.loss, "psnr": s.psnr,
                    "rays_per_second": s.rays_per_second, "res": s.res, "allocated": s.allocated,
                    "elapsed": s.elapsed, "test_psnr": test})
            );
        }
        !interrupted()
    })
    .map_err(flag_error)?;
    if let Some(b) = bar {
        b.finish_and_clear();
    }
    if out.batch < a.batch {
        eprintln!(
            "note: --batch {} is more than the {} training pixels; used {}",
            a.batch, out.batch, out.batch
        );
    }
    super::util::print_warnings(&out.warnings);
    let grid = &out.grid;
    voxel::save(grid, &a.output)?;
    write_log(&a.output, &out.log)?;
    let dense = (a.res as u64 + 1).pow(3);
    let outcome = out.outcome;
    if a.report.json {
        println!(
            "{}",
            json!({"done": true, "output": a.output, "iterations": outcome.iterations,
                "seconds": outcome.seconds, "load_seconds": out.load_seconds,
                "test_psnr": out.test_psnr, "test_psnr_in_frame": out.test_psnr_in_frame,
                "test_psnr_aligned": out.test_psnr_aligned.map(|a| a.0),
                "test_pose_turn": out.test_psnr_aligned.map(|a| a.1),
                "allocated": grid.allocated(), "dense": dense,
                "res": grid.res(), "stopped": outcome.stopped,
                "pose_error": super::recon_report::pose_error_json(&out.pose_error)})
        );
    } else {
        println!(
            "recon voxel: {} iterations in {:.1} s, {}³ grid with {} of {} voxels allocated ({:.1}%), \
             test PSNR {}{}{}; wrote {}",
            outcome.iterations,
            outcome.seconds,
            grid.res(),
            grid.allocated(),
            dense,
            100.0 * grid.allocated() as f64 / dense as f64,
            psnr_text(out.test_psnr),
            out.test_psnr_aligned
                .map(|(p, t)| format!(" ({p:.2} dB with the test cameras aligned, turned {t:.3}°)"))
                .unwrap_or_default(),
            super::recon_report::pose_error_text(&out.pose_error, out.test_psnr_in_frame),
            a.output.display()
        );
    }
    if outcome.stopped {
        eprintln!("interrupted: the model so far was written");
    }
    Ok(())
}

/// Writes `<model>.log.csv` (iteration, training seconds, resolution, allocated slots,
/// batch PSNR, test PSNR where evaluated) and, when the test views were evaluated more
/// than once, `<model>.psnr.png` and `.psnr.svg`: PSNR against training time.
pub(super) fn write_log_rows(
    model: &Path,
    header: &str,
    rows: &[String],
    tests: Vec<(f64, f64)>,
    batches: Vec<(f64, f64)>,
) -> Result<()> {
    let mut csv = String::from(header);
    for r in rows {
        csv.push_str(r);
        csv.push('\n');
    }
    write_atomic(&sibling(model, ".log.csv"), csv.as_bytes())?;
    write_psnr_plot(model, tests, batches, "training batches")
}

fn write_log(model: &Path, rows: &[(TrainStep, Option<f64>)]) -> Result<()> {
    let mut csv = String::from("iteration,seconds,res,allocated,batch_psnr,test_psnr\n");
    for (s, test) in rows {
        let _ = writeln!(
            csv,
            "{},{:.3},{},{},{:.3},{}",
            s.iteration,
            s.elapsed,
            s.res,
            s.allocated,
            s.psnr,
            test.map(|p| format!("{p:.3}")).unwrap_or_default()
        );
    }
    write_atomic(&sibling(model, ".log.csv"), csv.as_bytes())?;
    let tests: Vec<(f64, f64)> = rows
        .iter()
        .filter_map(|(s, t)| t.map(|p| (s.elapsed as f64, p)))
        .collect();
    let batches = rows
        .iter()
        .map(|(s, _)| (s.elapsed as f64, s.psnr as f64))
        .collect();
    write_psnr_plot(model, tests, batches, "training batches")
}

fn to_image(rgb: &[[f32; 3]], w: u32, h: u32) -> Image {
    let mut img = Image::new(w, h);
    for (d, c) in img.data.iter_mut().zip(rgb) {
        *d = [
            c[0].clamp(0.0, 1.0),
            c[1].clamp(0.0, 1.0),
            c[2].clamp(0.0, 1.0),
            1.0,
        ];
    }
    img
}

/// Runs `diffsvg view`.
pub fn run_view(a: ViewArgs) -> Result<()> {
    let mut model = super::viewed::Viewed::load(&a.model, a.step).map_err(flag_error)?;
    let lighting = a.light.lighting()?;
    if lighting.is_some() || a.light.mipmaps {
        match &mut model {
            super::viewed::Viewed::Mesh(_, opts, _) => {
                opts.lighting = lighting;
                opts.mipmaps = a.light.mipmaps;
            }
            _ => bail!("--light/--ambient/--mipmaps: only meshes (.obj, .gltf, .glb) are shaded"),
        }
    }
    if a.scene.is_none() && a.orbit == 0 {
        bail!("nothing to render: give --scene DIR and/or --orbit N");
    }
    if a.depth && !model.has_depth() {
        bail!(
            "--depth: depth images are drawn for Gaussian (.ply, .spz) and voxel (.vox) models only"
        );
    }
    check_downscale(a.downscale).map_err(flag_error)?;
    let data = match &a.scene {
        Some(d) => {
            let loading = diffsvg::volume::dataset::Loading {
                downscale: a.downscale,
                test_every: a.test_every,
                test_list: a.test_list.clone(),
            };
            let (data, undistorted) = model.load_dataset(d, &loading).map_err(flag_error)?;
            super::util::print_warnings(&data.warnings);
            if let Some(outside) = undistorted {
                undistortion_note(d, outside);
            }
            Some(data)
        }
        None => None,
    };
    // Cameras first, so that a bad orbit fails before anything is written.
    let orbit_cams = if a.orbit > 0 {
        orbit_cameras(model.bounds(), data.as_ref(), a.orbit, a.elevation).map_err(flag_error)?
    } else {
        Vec::new()
    };
    std::fs::create_dir_all(&a.output)
        .with_context(|| format!("{}: cannot create the output folder", a.output.display()))?;
    let mut depth_csv = String::from("file,units_per_level,max_depth\n");
    let mut write_depth = |cam: &diffsvg::volume::camera::Camera, stem: &str| -> Result<()> {
        if !a.depth {
            return Ok(());
        }
        let d = model.render_depth(cam)?;
        for (kind, values) in [("expected", &d.expected), ("median", &d.median)] {
            let name = format!("{stem}.depth-{kind}");
            let unit = save_depth(values, d.width, d.height, &a.output.join(&name))?;
            let _ = writeln!(depth_csv, "{name}.png,{unit:e},{:e}", unit * 65535.0);
        }
        Ok(())
    };
    let mut summary = serde_json::Map::new();
    if let Some(data) = &data {
        let views = a.split.views(data);
        if views.is_empty() {
            bail!(
                "{}: no {} views",
                a.scene.as_ref().unwrap().display(),
                a.split.name()
            );
        }
        let mut csv = String::from("view,psnr,ssim,ms\n");
        let (mut sp, mut ss) = (0.0, 0.0);
        for v in views {
            let t0 = Instant::now();
            let out = model.render(&v.camera)?;
            let ms = t0.elapsed().as_secs_f64() * 1e3;
            let p = psnr(&out, &v.rgb);
            let s = ssim(&out, &v.rgb, v.width as usize, v.height as usize);
            sp += p.min(99.0);
            ss += s;
            let _ = writeln!(csv, "{},{p:.3},{s:.4},{ms:.1}", v.name);
            let pair = diffsvg::image_io::side_by_side(&[
                &to_image(&out, v.width, v.height),
                &to_image(&v.rgb, v.width, v.height),
            ]);
            pair.save_png(a.output.join(format!("{}.png", file_stem(&v.name))))?;
            write_depth(&v.camera, &file_stem(&v.name))?;
        }
        let n = views.len() as f64;
        let _ = writeln!(csv, "mean,{:.3},{:.4},", sp / n, ss / n);
        write_atomic(&a.output.join("metrics.csv"), csv.as_bytes())?;
        summary.insert("views".into(), json!(views.len()));
        summary.insert("psnr".into(), json!(sp / n));
        summary.insert("ssim".into(), json!(ss / n));
        if !a.json {
            println!(
                "view: {} {} views, mean PSNR {:.2} dB, SSIM {:.4}; wrote {}",
                views.len(),
                a.split.name(),
                sp / n,
                ss / n,
                a.output.join("metrics.csv").display()
            );
        }
    }
    if !orbit_cams.is_empty() {
        let mut frames = Vec::new();
        for (i, cam) in orbit_cams.iter().enumerate() {
            let out = model.render(cam)?;
            let img = to_image(&out, cam.width, cam.height);
            img.save_png(a.output.join(format!("orbit-{i:03}.png")))?;
            write_depth(cam, &format!("orbit-{i:03}"))?;
            frames.push(img);
        }
        write_gif(&frames, &a.output.join("orbit.gif"))?;
        // The sheet stacks pairs: first half of the orbit above, second half below, so
        // that frames read in order along each row.
        let half = frames.len() / 2;
        let pairs: Vec<(&Image, &Image)> =
            (0..half).map(|i| (&frames[i], &frames[i + half])).collect();
        if !pairs.is_empty() {
            contact_sheet(&pairs, half.min(8), 2, [1.0; 4]).save_png(a.output.join("orbit.png"))?;
        }
        summary.insert("orbit".into(), json!(frames.len()));
        if !a.json {
            println!(
                "view: {} orbit frames, orbit.gif and orbit.png in {}",
                frames.len(),
                a.output.display()
            );
        }
    }
    if a.depth {
        let path = a.output.join("depth.csv");
        write_atomic(&path, depth_csv.as_bytes())?;
        summary.insert("depth".into(), json!(path));
        if !a.json {
            println!(
                "view: depth images (16-bit PNG and float32 .npy), their scales in {}",
                path.display()
            );
        }
    }
    if a.json {
        summary.insert("done".into(), json!(true));
        summary.insert("output".into(), json!(a.output));
        println!("{}", serde_json::Value::Object(summary));
    }
    Ok(())
}

fn write_gif(frames: &[Image], path: &Path) -> Result<()> {
    use image::codecs::gif::{GifEncoder, Repeat};
    let mut buf = Vec::new();
    {
        let mut enc = GifEncoder::new_with_speed(&mut buf, 10);
        enc.set_repeat(Repeat::Infinite)
            .with_context(|| format!("{}: cannot encode GIF", path.display()))?;
        for f in frames {
            let rgba =
                image::RgbaImage::from_raw(f.width, f.height, f.to_rgba8()).expect("sizes match");
            let frame =
                image::Frame::from_parts(rgba, 0, 0, image::Delay::from_numer_denom_ms(80, 1));
            enc.encode_frame(frame)
                .with_context(|| format!("{}: cannot encode GIF", path.display()))?;
        }
    }
    write_atomic(path, &buf)?;
    Ok(())
}
