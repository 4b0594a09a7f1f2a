//! The sparse voxel grid (Plenoxels) end to end: hard rays for the renderer and its
//! gradient, and recovery of a synthetic scene of colored spheres from posed views.
//!
//! Run in release (`cargo test --release --test voxel`); the recovery test trains for
//! about 10 s on 2 cores there. `-- --ignored --nocapture bench` prints timings at 128³.

use std::time::Instant;

use diffsvg::glam::Vec3;
use diffsvg::optim::Rule;
use diffsvg::volume::Ray;
use diffsvg::volume::voxel::{
    Grads, Grid, RenderSettings, TrainOptions, load, max_weights, ray_backward, render_ray,
    render_rays, save, train,
};

// ---------------------------------------------------------------------------------------
// Hard cases

/// A 8³ grid over `[−1, 1]³` with smoothly varying positive density and SH of degree 2.
fn smooth_grid(density_scale: f32) -> Grid {
    let mut g = Grid::dense(Vec3::splat(-1.0), Vec3::splat(1.0), 8, 2, 0.0);
    for s in 0..g.allocated() {
        let p = g.position(s);
        g.density_mut()[s] =
            density_scale * (1.0 + 0.5 * (2.0 * p.x).sin() * (1.5 * p.y + p.z).cos());
        let stride = g.sh_stride();
        for j in 0..stride {
            g.sh_mut()[s * stride + j] =
                0.6 * ((j as f32 + 1.0) * p.x + 0.7 * p.y - p.z * j as f32 * 0.3).sin();
        }
    }
    g
}

fn ray(origin: Vec3, dir: Vec3) -> Ray {
    Ray {
        origin,
        dir: dir.normalize(),
    }
}

fn all_finite(v: &[f32]) -> bool {
    v.iter().all(|x| x.is_finite())
}

fn close(a: [f32; 3], b: [f32; 3], tol: f32) -> bool {
    (0..3).all(|i| (a[i] - b[i]).abs() <= tol)
}

#[test]
fn a_ray_that_misses_the_box_shows_the_background_and_has_no_gradient() {
    let g = smooth_grid(2.0);
    let s = RenderSettings {
        background: [0.1, 0.2, 0.3],
        ..RenderSettings::default()
    };
    let misses = [
        ray(Vec3::new(0.0, 3.0, 5.0), Vec3::NEG_Z), // passes above the box
        ray(Vec3::new(0.0, 0.0, 5.0), Vec3::Z),     // points away from it
        ray(Vec3::new(-3.0, 1.5, 0.0), Vec3::new(1.0, 0.0, 0.0)), // parallel to a face, outside
        ray(Vec3::new(5.0, 5.0, 5.0), Vec3::new(1.0, -1.0, 0.0)), // skew
    ];
    for r in misses {
        assert_eq!(render_ray(&g, &r, &s), s.background, "{r:?}");
        let mut grads = Grads::new(&g);
        let c = ray_backward(&g, &r, &s, [1.0, -1.0, 0.5], &mut grads);
        assert_eq!(c, s.background);
        assert!(
            grads.density.iter().chain(&grads.sh).all(|&v| v == 0.0),
            "{r:?}"
        );
    }
    // A near plane beyond the box is a miss too.
    let r = ray(Vec3::new(0.0, 0.0, 5.0), Vec3::NEG_Z);
    let far = RenderSettings { t_min: 7.0, ..s };
    assert_eq!(render_ray(&g, &r, &far), s.background);
}

#[test]
fn rays_along_grid_planes_and_edges_match_slightly_offset_rays() {
    let g = smooth_grid(1.5);
    let s = RenderSettings::default();
    let h = g.voxel_size().x; // 0.25
    let cases = [
        // In the plane y = one vertex layer, oblique within it.
        (
            Vec3::new(-3.0, 2.0 * h, -0.4),
            Vec3::new(1.0, 0.0, 0.35),
            Vec3::Y,
        ),
        // Along a grid edge (y and z on vertex layers), parallel to x.
        (
            Vec3::new(-3.0, -h, 3.0 * h),
            Vec3::X,
            Vec3::new(0.0, 1.0, 1.0),
        ),
        // Along an edge of the box itself (y = z = max).
        (
            Vec3::new(-3.0, 1.0, 1.0),
            Vec3::X,
            Vec3::new(0.0, -1.0, -1.0),
        ),
        // On a face of the box (z = min), oblique.
        (
            Vec3::new(-3.0, -0.3, -1.0),
            Vec3::new(1.0, 0.4, 0.0),
            Vec3::Z,
        ),
        // Along the diagonal through vertices.
        (Vec3::splat(-3.0), Vec3::ONE, Vec3::new(1.0, -1.0, 0.0)),
    ];
    for (o, d, off) in cases {
        let on = ray(o, d);
        let c_on = render_ray(&g, &on, &s);
        let mut grads = Grads::new(&g);
        ray_backward(&g, &on, &s, [1.0, 0.5, -0.7], &mut grads);
        assert!(
            all_finite(&c_on) && all_finite(&grads.density) && all_finite(&grads.sh),
            "{on:?}"
        );
        assert!(
            grads.density.iter().any(|&v| v != 0.0),
            "the ray sees the grid: {on:?}"
        );
        let nudged = ray(o + off.normalize() * 1e-4 * h, d);
        let c_off = render_ray(&g, &nudged, &s);
        assert!(
            close(c_on, c_off, 2e-3),
            "{on:?}: {c_on:?} vs offset {c_off:?}"
        );
        let mut g2 = Grads::new(&g);
        ray_backward(&g, &nudged, &s, [1.0, 0.5, -0.7], &mut g2);
        let diff = grads
            .density
            .iter()
            .zip(&g2.density)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f32::max);
        let size = grads.density.iter().map(|a| a.abs()).fold(0.0, f32::max);
        assert!(
            diff <= 0.05 * size + 1e-5,
            "density gradient moves by {diff} (max {size})"
        );
    }
}

#[test]
fn zero_density_shows_the_background() {
    let mut g = smooth_grid(1.0);
    g.density_mut().fill(0.0);
    let s = RenderSettings {
        background: [0.25, 0.5, 0.75],
        ..RenderSettings::default()
    };
    let r = ray(Vec3::new(0.2, -0.1, 4.0), Vec3::new(-0.1, 0.05, -1.0));
    assert_eq!(render_ray(&g, &r, &s), s.background);
    // Negative raw density is clipped by the ReLU: still the background, and at or below
    // the kink the density gradient is 0 by convention.
    g.density_mut().fill(-3.0);
    let mut grads = Grads::new(&g);
    assert_eq!(ray_backward(&g, &r, &s, [1.0; 3], &mut grads), s.background);
    assert!(grads.density.iter().chain(&grads.sh).all(|&v| v == 0.0));
}

#[test]
fn saturating_density_stays_finite() {
    for scale in [1e4f32, 1e12, 1e30] {
        let g = smooth_grid(scale);
        for early_stop in [0.0, 1e-3] {
            let s = RenderSettings {
                early_stop,
                ..RenderSettings::default()
            };
            let r = ray(Vec3::new(-0.3, 0.2, 4.0), Vec3::new(0.1, -0.05, -1.0));
            let mut grads = Grads::new(&g);
            let c = ray_backward(&g, &r, &s, [1.0, -2.0, 0.5], &mut grads);
            assert!(
                all_finite(&c) && all_finite(&grads.density) && all_finite(&grads.sh),
                "scale {scale}"
            );
            assert!(c.iter().all(|v| (0.0..=1.0).contains(v)));
            // Opaque at the first sample: the color is that sample's color and only the
            // first cell's corners get SH gradients.
            let touched = (0..g.allocated())
                .filter(|&i| grads.sh[i * 27..(i + 1) * 27].iter().any(|&v| v != 0.0))
                .count();
            assert!(touched <= 8, "{touched} slots behind an opaque sample");
        }
    }
}

#[test]
fn a_camera_inside_the_grid_sees_from_where_it_stands() {
    let g = smooth_grid(2.0);
    let s = RenderSettings::default();
    for (o, d) in [
        (Vec3::new(0.1, -0.2, 0.3), Vec3::new(0.3, 0.2, -1.0)),
        (Vec3::new(-0.9, 0.95, 0.0), Vec3::new(1.0, -0.6, 0.2)),
        (Vec3::ZERO, Vec3::X),
    ] {
        let inside = ray(o, d);
        // The same line, started 5 units back, with a near plane at the inside origin.
        let behind = ray(o - inside.dir * 5.0, d);
        let near = RenderSettings { t_min: 5.0, ..s };
        let (a, b) = (render_ray(&g, &inside, &s), render_ray(&g, &behind, &near));
        assert!(close(a, b, 1e-3), "{a:?} vs {b:?}");
        // And it sees less than a camera outside on the same line (which also sees the
        // part behind the inside origin): the colors differ.
        let whole = render_ray(&g, &behind, &s);
        assert!(
            !close(a, whole, 1e-3),
            "the part behind the camera counts: {a:?} {whole:?}"
        );
        let mut grads = Grads::new(&g);
        ray_backward(&g, &inside, &s, [1.0; 3], &mut grads);
        assert!(all_finite(&grads.density) && grads.density.iter().any(|&v| v != 0.0));
    }
}

#[test]
fn early_termination_changes_the_color_by_at_most_the_threshold() {
    let g = smooth_grid(6.0);
    let exact = RenderSettings {
        early_stop: 0.0,
        ..RenderSettings::default()
    };
    let early = RenderSettings {
        early_stop: 1e-2,
        ..exact
    };
    for i in 0..20 {
        let a = i as f32 * 0.3;
        let r = ray(
            Vec3::new(3.0 * a.cos(), 0.4 * a.sin(), 3.0 * a.sin()),
            Vec3::new(-a.cos(), 0.1, -a.sin()),
        );
        let (c0, c1) = (render_ray(&g, &r, &exact), render_ray(&g, &r, &early));
        assert!(close(c0, c1, 1e-2), "{c0:?} vs {c1:?}");
    }
}

// ---------------------------------------------------------------------------------------
// Synthetic scene: colored spheres seen from posed cameras

/// An opaque, Lambert-shaded sphere.
struct Sphere {
    center: Vec3,
    radius: f32,
    albedo: [f32; 3],
}

fn spheres() -> Vec<Sphere> {
    vec![
        Sphere {
            center: Vec3::new(-0.4, -0.2, 0.1),
            radius: 0.36,
            albedo: [0.9, 0.15, 0.1],
        },
        Sphere {
            center: Vec3::new(0.38, 0.25, -0.2),
            radius: 0.3,
            albedo: [0.1, 0.75, 0.2],
        },
        Sphere {
            center: Vec3::new(0.15, -0.3, 0.5),
            radius: 0.25,
            albedo: [0.15, 0.3, 0.95],
        },
        Sphere {
            center: Vec3::new(-0.05, 0.5, 0.35),
            radius: 0.2,
            albedo: [0.95, 0.8, 0.1],
        },
    ]
}

/// The color seen along `r`: nearest sphere hit, shaded `albedo · (0.35 + 0.65·max(n·l, 0))`
/// with a fixed light direction, or the white background.
fn trace(scene: &[Sphere], r: &Ray) -> [f32; 3] {
    let light = Vec3::new(0.4, 0.8, 0.45).normalize();
    let mut best: Option<(f32, &Sphere)> = None;
    for sp in scene {
        let oc = r.origin - sp.center;
        let b = oc.dot(r.dir);
        let c = oc.length_squared() - sp.radius * sp.radius;
        let disc = b * b - c;
        if disc < 0.0 {
            continue;
        }
        let t = -b - disc.sqrt();
        if t > 0.0 && best.is_none_or(|(bt, _)| t < bt) {
            best = Some((t, sp));
        }
    }
    match best {
        None => [1.0; 3],
        Some((t, sp)) => {
            let n = (r.at(t) - sp.center).normalize();
            let shade = 0.35 + 0.65 * n.dot(light).max(0.0);
            sp.albedo.map(|a| a * shade)
        }
    }
}

/// A look-at pinhole camera: `width²` pixels, horizontal field of view `fov` (radians),
/// OpenGL axes (looking down −Z, +Y up), pixel centers at `+0.5`, y down.
struct Cam {
    pos: Vec3,
    right: Vec3,
    up: Vec3,
    fwd: Vec3,
    focal: f32,
    width: u32,
}

impl Cam {
    fn look_at(pos: Vec3, target: Vec3, width: u32, fov: f32) -> Cam {
        let fwd = (target - pos).normalize();
        let up0 = if fwd.y.abs() > 0.99 { Vec3::X } else { Vec3::Y };
        let right = fwd.cross(up0).normalize();
        let up = right.cross(fwd);
        Cam {
            pos,
            right,
            up,
            fwd,
            focal: 0.5 * width as f32 / (0.5 * fov).tan(),
            width,
        }
    }

    /// The ray through image point `(u, v)` (pixels).
    fn ray(&self, u: f32, v: f32) -> Ray {
        let half = 0.5 * self.width as f32;
        let d =
            self.right * ((u - half) / self.focal) - self.up * ((v - half) / self.focal) + self.fwd;
        ray(self.pos, d)
    }

    fn pixel_rays(&self) -> Vec<Ray> {
        let w = self.width;
        (0..w * w)
            .map(|i| self.ray((i % w) as f32 + 0.5, (i / w) as f32 + 0.5))
            .collect()
    }

    /// The scene's picture, each pixel the mean of `ss × ss` rays (anti-aliased).
    fn picture(&self, scene: &[Sphere], ss: u32) -> Vec<[f32; 3]> {
        let w = self.width;
        (0..w * w)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let mut acc = [0.0f32; 3];
                for k in 0..ss * ss {
                    let u = x + ((k % ss) as f32 + 0.5) / ss as f32;
                    let v = y + ((k / ss) as f32 + 0.5) / ss as f32;
                    let c = trace(scene, &self.ray(u, v));
                    (0..3).for_each(|ch| acc[ch] += c[ch]);
                }
                acc.map(|a| a / (ss * ss) as f32)
            })
            .collect()
    }
}

/// `n` cameras at distance `dist` on a Fibonacci sphere (shifted by `phase`) looking at
/// the origin.
fn ring(n: usize, dist: f32, phase: f32, width: u32) -> Vec<Cam> {
    let golden = std::f32::consts::PI * (3.0 - 5.0f32.sqrt());
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
            let r = (1.0 - y * y).sqrt();
            let a = golden * i as f32 + phase;
            Cam::look_at(
                Vec3::new(r * a.cos(), y, r * a.sin()) * dist,
                Vec3::ZERO,
                width,
                0.7,
            )
        })
        .collect()
}

fn psnr(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    let se: f64 = a
        .iter()
        .zip(b)
        .flat_map(|(p, q)| (0..3).map(move |i| (p[i] - q[i]) as f64))
        .map(|e| e * e)
        .sum();
    -10.0 * (se / (3 * a.len()) as f64).log10()
}

/// Training views and held-out views of the sphere scene, and the options of the CI run.
fn scene_setup() -> (Vec<Ray>, Vec<[f32; 3]>, Vec<Cam>, TrainOptions) {
    let scene = spheres();
    let train_cams = ring(32, 3.2, 0.0, 40);
    let mut rays = Vec::new();
    let mut colors = Vec::new();
    for c in &train_cams {
        rays.extend(c.pixel_rays());
        colors.extend(c.picture(&scene, 3));
    }
    let test_cams = ring(6, 3.2, 1.1, 40);
    // Light density TV frees the haze that pruning would otherwise keep (without it
    // the held-out PSNR is about the same but the 64³ grid stays nearly dense).
    let opts = TrainOptions {
        iterations: 1200,
        batch_size: 4096,
        upsample: vec![(300, 64)],
        tv_density: 1e-6,
        ..TrainOptions::default()
    };
    (rays, colors, test_cams, opts)
}

fn box_grid() -> Grid {
    Grid::dense(Vec3::splat(-1.0), Vec3::splat(1.0), 32, 1, 0.1)
}

/// A small scene recovered to ≥ 30 dB on held-out views: 4 spheres, 32 training views of
/// 40×40 (anti-aliased ground truth), 32³ → 64³ with pruning, SH degree 1.
#[test]
fn synthetic_spheres_are_recovered_on_held_out_views() {
    let (rays, colors, test_cams, opts) = scene_setup();
    let mut grid = box_grid();
    let t0 = Instant::now();
    let mut last = None;
    let outcome = train(&mut grid, &rays, &colors, &opts, &mut |s, _| {
        if s.iteration % 100 == 0 {
            eprintln!(
                "it {:5}  res {:3}  loss {:.5}  psnr {:5.2}  {:7.0} rays/s  {} slots",
                s.iteration, s.res, s.loss, s.psnr, s.rays_per_second, s.allocated
            );
        }
        last = Some(*s);
        true
    })
    .unwrap();
    let secs = t0.elapsed().as_secs_f32();
    assert_eq!(outcome.iterations, opts.iterations);
    assert_eq!(grid.res(), 64);
    let dense_64 = 65usize.pow(3);
    assert!(
        grid.allocated() < dense_64 / 3,
        "pruned: {} of {dense_64}",
        grid.allocated()
    );
    let scene = spheres();
    let mut worst = f64::INFINITY;
    for (i, cam) in test_cams.iter().enumerate() {
        let got = render_rays(&grid, &cam.pixel_rays(), &opts.render);
        let want = cam.picture(&scene, 3);
        let p = psnr(&got, &want);
        eprintln!("held-out view {i}: {p:.2} dB");
        worst = worst.min(p);
    }
    eprintln!(
        "trained in {secs:.1} s; last batch {:?}; worst held-out view {worst:.2} dB",
        last.unwrap()
    );
    assert!(worst >= 30.0, "held-out PSNR {worst:.2} dB < 30 dB");
}

/// Pruning at the working resolution (`prune_every`) frees the empty space training has
/// cleared, and the final prune leaves the rendered training views as they were.
#[test]
fn pruning_between_resamplings_frees_space_without_changing_the_picture() {
    let (rays, colors, _, base) = scene_setup();
    let opts = TrainOptions {
        iterations: 400,
        upsample: Vec::new(),
        prune_every: 100,
        prune_rays: 0,
        ..base
    };
    let mut grid = box_grid();
    let dense = grid.allocated();
    let mut before_final = None;
    let mut counts = Vec::new();
    let outcome = train(&mut grid, &rays, &colors, &opts, &mut |s, g| {
        counts.push(s.allocated);
        if s.iteration == opts.iterations {
            before_final = Some(render_rays(g, &rays, &opts.render));
        }
        true
    })
    .unwrap();
    assert_eq!(outcome.iterations, 400);
    // Pruned at iterations 100, 200 and 300 (never growing), and once more at the end.
    assert!(counts.windows(2).all(|w| w[1] <= w[0]), "{counts:?}");
    assert!(
        counts[150] < dense,
        "nothing pruned: {} of {dense}",
        counts[150]
    );
    assert!(grid.allocated() <= counts[399]);
    assert!(
        grid.allocated() < dense / 3,
        "{} of {dense}",
        grid.allocated()
    );
    let after = render_rays(&grid, &rays, &opts.render);
    let worst = before_final
        .unwrap()
        .iter()
        .zip(&after)
        .flat_map(|(a, b)| (0..3).map(move |c| (a[c] - b[c]).abs()))
        .fold(0.0f32, f32::max);
    eprintln!(
        "allocated {dense} → {} → {} → {}; worst change {worst}",
        counts[150],
        counts[399],
        grid.allocated()
    );
    assert!(worst < 0.01, "the final prune changed a pixel by {worst}");
    assert!(psnr(&after, &colors) > 28.0, "{:.2}", psnr(&after, &colors));
}

#[test]
fn saved_models_load_and_render_the_same() {
    let mut g = smooth_grid(2.0);
    let w = max_weights(
        &g,
        &[ray(Vec3::new(0.0, 0.0, 4.0), Vec3::NEG_Z)],
        &RenderSettings::default(),
    );
    g.prune_by_weight(&w, 1e-4, 1);
    let dir = std::env::temp_dir().join(format!("diffsvg-voxel-test-{}", std::process::id()));
    let path = dir.join("sub/model.dsvox");
    save(&g, &path).unwrap();
    let h = load(&path).unwrap();
    std::fs::remove_dir_all(&dir).ok();
    let s = RenderSettings::default();
    for i in 0..10 {
        let r = ray(
            Vec3::new(0.1 * i as f32 - 0.5, 0.2, 4.0),
            Vec3::new(0.0, -0.05, -1.0),
        );
        assert_eq!(render_ray(&g, &r, &s), render_ray(&h, &r, &s));
    }
}

#[test]
fn training_rejects_bad_input_with_reasons() {
    let mut g = box_grid();
    let r = [ray(Vec3::new(0.0, 0.0, 3.0), Vec3::NEG_Z)];
    let opts = TrainOptions::default();
    let err = train(&mut g, &r, &[], &opts, &mut |_, _| true)
        .unwrap_err()
        .to_string();
    assert!(err.contains("1 rays and 0 colors"), "{err}");
    let err = train(&mut g, &r, &[[f32::NAN, 0.0, 0.0]], &opts, &mut |_, _| true)
        .unwrap_err()
        .to_string();
    assert!(err.contains("color 0 is not finite"), "{err}");
    let bad = TrainOptions {
        density_optimizer: Rule::Adam {
            beta1: 1.0,
            beta2: 0.99,
            eps: 1e-8,
        },
        ..TrainOptions::default()
    };
    let err = train(&mut g, &r, &[[0.5; 3]], &bad, &mut |_, _| true)
        .unwrap_err()
        .to_string();
    assert!(err.contains("betas"), "{err}");
    // The observer can stop training.
    let mut seen = 0;
    let out = train(&mut g, &r, &[[0.5; 3]], &opts, &mut |_, _| {
        seen += 1;
        seen < 3
    })
    .unwrap();
    assert!(out.stopped && out.iterations == 3 && seen == 3);
}
