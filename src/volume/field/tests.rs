//! Whole-model checks: the gradient of a pixel against central differences, the same
//! bits on 1, 2 and 3 threads, a fit of a small synthetic scene, and the model file.

use glam::Vec3;

use super::hash::F;
use super::model::{FieldKind, Ngp, NgpShape};
use super::render::{Grads, RayTape, RenderSettings, ray_backward, ray_forward, record_len};
use super::*;
use crate::volume::Ray;

fn small_shape() -> NgpShape {
    NgpShape {
        hash: HashShape {
            levels: 4,
            log2_table: 9,
            n_min: 4,
            n_max: 32,
        },
        width: 16,
        density_layers: 1,
        color_layers: 1,
        geo_features: 3,
        occupancy_res: 8,
        frequencies: 0,
    }
}

/// A small NeRF field: 4 octaves, two density layers.
fn small_nerf_shape() -> NgpShape {
    NgpShape {
        hash: HashShape::NONE,
        frequencies: 4,
        density_layers: 2,
        ..small_shape()
    }
}

fn busy_nerf() -> Ngp {
    let mut m = Ngp::new(Vec3::splat(-1.0), Vec3::splat(1.0), small_nerf_shape(), 3);
    let n = m.density.params.len();
    let out = 1 + small_shape().geo_features as usize;
    m.density.params[n - out] = -1.0;
    m
}

/// A model whose features are large enough for every parameter to matter.
fn busy_model() -> Ngp {
    let mut m = Ngp::new(Vec3::splat(-1.0), Vec3::splat(1.0), small_shape(), 3);
    let mut rng = crate::rng::Rng::new(9);
    for p in &mut m.hash.params {
        *p = rng.uniform() * 2.0 - 1.0;
    }
    // A positive bias on the raw density so the ray is neither empty nor opaque.
    let n = m.density.params.len();
    let out = 1 + small_shape().geo_features as usize;
    m.density.params[n - out] = -1.0;
    m
}

/// `Σ G·color` of one ray.
const G: [f32; 3] = [0.8, -0.5, 1.2];

fn pixel_loss(m: &Ngp, ray: &Ray, s: &RenderSettings) -> f64 {
    let c = ray_forward(m, ray, s, 0.5, &mut RayTape::default(), false);
    (0..3).map(|i| (G[i] * c[i]) as f64).sum()
}

/// The whole pixel (hash encoding, both networks, compositing) against central
/// differences: hash entries the ray touches, and weights and biases of both networks.
#[test]
fn pixel_gradient_matches_finite_differences() {
    check_pixel_gradient(busy_model());
}

/// The same for a NeRF field (positional encoding, deeper density network): every
/// weight and bias of both networks.
#[test]
fn nerf_pixel_gradient_matches_finite_differences() {
    check_pixel_gradient(busy_nerf());
}

fn check_pixel_gradient(m: Ngp) {
    let s = RenderSettings {
        steps: 48,
        background: [0.3, 0.9, 0.6],
        early_stop: 0.0,
    };
    let ray = Ray {
        origin: Vec3::new(-2.0, -0.7, 1.9),
        dir: Vec3::new(0.7, 0.3, -0.65).normalize(),
    };
    let mut tape = RayTape::default();
    let c = ray_forward(&m, &ray, &s, 0.5, &mut tape, true);
    assert!(tape.samples() > 20, "{} samples", tape.samples());
    let mut grads = Grads::new(&m);
    ray_backward(&m, &s, &mut tape, c, G, &mut grads);
    // The hash gradient from the records, as the trainer scatters it.
    let ll = m.hash.level_len();
    let mut hg = vec![0.0f32; m.hash.params.len()];
    let rl = record_len(&m);
    for l in 0..m.hash.levels() {
        let mut flags = vec![false; ll / F];
        let mut list = Vec::new();
        for r in grads.records.chunks_exact(rl) {
            let x = Vec3::new(r[0], r[1], r[2]);
            m.hash.scatter_level(
                l,
                x,
                &r[3 + l * F..3 + (l + 1) * F],
                &mut hg[l * ll..(l + 1) * ll],
                &mut flags,
                &mut list,
            );
        }
    }
    let scale = hg
        .iter()
        .chain(&grads.density)
        .chain(&grads.color)
        .fold(0.0f32, |a, g| a.max(g.abs())) as f64;
    assert!(scale > 1e-3);
    let hashed = m.shape().kind() == FieldKind::Ngp;
    // Central differences in f32 with a step where rounding (~1e-7 relative) and
    // curvature stay below the tolerance (smaller for the NeRF field, whose density
    // varies faster; below 1e-3 its f32 rounding dominates).
    let h = if hashed { 2e-3f32 } else { 1e-3 };
    let check = |which: usize, i: usize, an: f32| {
        let mut p = m.clone();
        let v = get(&m, which, i);
        set(&mut p, which, i, v + h);
        let lp = pixel_loss(&p, &ray, &s);
        set(&mut p, which, i, v - h);
        let lm = pixel_loss(&p, &ray, &s);
        let fd = (lp - lm) / (2.0 * h as f64);
        let tol = 2e-3 * scale + 2e-2 * fd.abs();
        assert!(
            (fd - an as f64).abs() <= tol,
            "{} parameter {i}: analytic {an}, central difference {fd}",
            ["hash", "density", "color"][which]
        );
    };
    let touched: Vec<usize> = (0..hg.len()).filter(|&i| hg[i] != 0.0).collect();
    assert!(
        touched.len() > 50 || !hashed,
        "{} hash entries touched",
        touched.len()
    );
    for &i in touched.iter().step_by(7) {
        check(0, i, hg[i]);
    }
    for i in (0..m.density.params.len()).step_by(5) {
        check(1, i, grads.density[i]);
    }
    for i in (0..m.color.params.len()).step_by(5) {
        check(2, i, grads.color[i]);
    }
    // Untouched entries get exactly nothing.
    assert!(hg.iter().filter(|g| **g == 0.0).count() >= hg.len() / 2);
    // Both networks' first layers got gradients (through the encoding).
    let n_in = m.density.dims()[0];
    let first = &grads.density[..n_in * m.density.dims()[1]];
    assert!(first.iter().filter(|g| **g != 0.0).count() > first.len() / 3);
}

fn get(m: &Ngp, which: usize, i: usize) -> f32 {
    match which {
        0 => m.hash.params[i],
        1 => m.density.params[i],
        _ => m.color.params[i],
    }
}

fn set(m: &mut Ngp, which: usize, i: usize, v: f32) {
    match which {
        0 => m.hash.params[i] = v,
        1 => m.density.params[i] = v,
        _ => m.color.params[i] = v,
    }
}

/// A red ball of radius 0.5 at the origin on white, seen by cameras around it: rays
/// and colors (the ball's color or white).
fn ball_scene(views: usize, size: u32) -> (Vec<Ray>, Vec<[f32; 3]>) {
    let mut rays = Vec::new();
    let mut colors = Vec::new();
    for v in 0..views {
        let a = v as f32 * std::f32::consts::TAU / views as f32;
        let eye = Vec3::new(3.0 * a.cos(), 3.0 * a.sin(), 0.8 + 0.3 * (v % 3) as f32);
        let fwd = (-eye).normalize();
        let right = fwd.cross(Vec3::Z).normalize();
        let up = right.cross(fwd);
        for y in 0..size {
            for x in 0..size {
                let u = (x as f32 + 0.5) / size as f32 * 2.0 - 1.0;
                let w = (y as f32 + 0.5) / size as f32 * 2.0 - 1.0;
                let dir = (fwd + 0.5 * (u * right - w * up)).normalize();
                let b = eye.dot(dir);
                let disc = b * b - (eye.length_squared() - 0.25);
                let c = if disc > 0.0 {
                    let n = (eye + dir * (-b - disc.sqrt())).normalize();
                    let shade = 0.4 + 0.6 * n.dot(Vec3::new(0.3, 0.4, 0.87)).max(0.0);
                    [0.9 * shade, 0.2 * shade, 0.1 * shade]
                } else {
                    [1.0; 3]
                };
                rays.push(Ray { origin: eye, dir });
                colors.push(c);
            }
        }
    }
    (rays, colors)
}

fn quick_opts(iterations: usize) -> TrainOptions {
    TrainOptions {
        iterations,
        batch_size: 300,
        batch_samples: 4000,
        render: RenderSettings {
            steps: 64,
            ..RenderSettings::default()
        },
        occupancy_every: 8,
        occupancy_warmup: 16,
        ..TrainOptions::default()
    }
}

/// Training in pools of 1, 2 and 3 threads gives the same model, bit for bit
/// (occupancy updates included).
#[test]
fn same_bits_on_one_two_and_three_threads() {
    same_bits_for(small_shape());
}

/// The same for a NeRF field.
#[test]
fn nerf_same_bits_on_one_two_and_three_threads() {
    same_bits_for(small_nerf_shape());
}

fn same_bits_for(shape: NgpShape) {
    let (rays, colors) = ball_scene(6, 12);
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut m = Ngp::new(Vec3::splat(-1.0), Vec3::splat(1.0), shape, 1);
            let out = train(&mut m, &rays, &colors, &quick_opts(20), &mut |_, _| true).unwrap();
            assert_eq!(out.iterations, 20);
            m
        })
    };
    let one = run(1);
    let fresh = Ngp::new(Vec3::splat(-1.0), Vec3::splat(1.0), shape, 1);
    assert_ne!(
        (&one.hash.params, &one.density.params),
        (&fresh.hash.params, &fresh.density.params),
        "training moved the model"
    );
    for t in [2, 3] {
        let other = run(t);
        let bits = |m: &Ngp| {
            m.hash
                .params
                .iter()
                .chain(&m.density.params)
                .chain(&m.color.params)
                .map(|v| v.to_bits())
                .collect::<Vec<u32>>()
        };
        assert!(bits(&one) == bits(&other), "{t} threads differ from 1");
        assert_eq!(one.occupancy.bits, other.occupancy.bits);
    }
}

/// A short fit learns the ball: the batch error falls tenfold, the views reach 22 dB,
/// and the occupancy grid skips only space without density.
#[test]
fn a_short_fit_learns_a_ball() {
    let (rays, colors) = ball_scene(8, 16);
    let mut m = Ngp::new(Vec3::splat(-1.0), Vec3::splat(1.0), small_shape(), 2);
    let mut first = None;
    let mut last = 0.0;
    let out = train(&mut m, &rays, &colors, &quick_opts(150), &mut |s, _| {
        first.get_or_insert(s.loss);
        last = s.loss;
        true
    })
    .unwrap();
    assert_eq!(out.iterations, 150);
    let first = first.unwrap();
    assert!(last < first / 10.0, "loss {first} → {last}");
    let rendered = render_rays(
        &m,
        &rays,
        &RenderSettings {
            steps: 64,
            ..RenderSettings::default()
        },
    );
    let psnr = crate::volume::metrics::psnr(&rendered, &colors);
    assert!(psnr > 22.0, "PSNR {psnr}");
    // Skipping cells the occupancy grid marks empty changes the picture little: they
    // hold next to no density.
    let mut all = m.clone();
    all.occupancy.bits.fill(true);
    let unskipped = render_rays(
        &all,
        &rays,
        &RenderSettings {
            steps: 64,
            ..RenderSettings::default()
        },
    );
    let agree = crate::volume::metrics::psnr(&rendered, &unskipped);
    assert!(
        agree > 35.0,
        "skipping empty cells: {agree} dB from the full march"
    );
}

/// `m`'s file image, after checking that it has the size its header implies and loads
/// back to the same bytes and pixels.
fn round_trip(m: &Ngp, name: &str) -> Vec<u8> {
    let bytes = io::to_bytes(m);
    assert_eq!(bytes.len() as u64, io::file_size(&m.shape()));
    let back = io::from_bytes(&bytes, name.as_ref()).unwrap();
    assert_eq!(back.shape(), m.shape());
    assert_eq!(io::to_bytes(&back), bytes);
    let ray = Ray {
        origin: Vec3::new(0.1, 0.2, 3.0),
        dir: Vec3::NEG_Z,
    };
    let s = RenderSettings::default();
    assert_eq!(render_ray(m, &ray, &s), render_ray(&back, &ray, &s));
    bytes
}

#[test]
fn files_round_trip_and_bad_files_are_named() {
    let bytes = round_trip(&busy_model(), "m.ngp");
    let err = |b: &[u8]| io::from_bytes(b, "m.ngp".as_ref()).unwrap_err().to_string();
    assert!(err(&bytes[..bytes.len() - 1]).contains("header implies"));
    assert!(err(b"DSVOXGRD\x01\0\0\0").contains("bad magic"));
    let mut v2 = bytes.clone();
    v2[8] = 2;
    assert!(err(&v2).contains("version 2"));
    let mut huge = bytes.clone();
    huge[40..44].copy_from_slice(&30u32.to_le_bytes()); // log2 table 30
    assert!(err(&huge).contains("log2 table size 30"));
    let mut nan = bytes.clone();
    nan[80..84].copy_from_slice(&f32::NAN.to_le_bytes());
    let e = err(&nan);
    assert!(e.contains("m.ngp") && e.contains("not finite"), "{e}");
}

/// A short fit of the ball by a NeRF field: the batch error falls fivefold and the
/// views reach 15 dB (the positional encoding learns slower than the hash grid: 16.9 dB
/// where the hash grid reaches 22).
#[test]
fn a_short_nerf_fit_learns_a_ball() {
    let (rays, colors) = ball_scene(8, 16);
    let mut m = Ngp::new(Vec3::splat(-1.0), Vec3::splat(1.0), small_nerf_shape(), 2);
    let mut first = None;
    let mut last = 0.0;
    let opts = TrainOptions {
        lr: [5e-3, 5e-4],
        ..quick_opts(150)
    };
    train(&mut m, &rays, &colors, &opts, &mut |s, _| {
        first.get_or_insert(s.loss);
        last = s.loss;
        true
    })
    .unwrap();
    let first = first.unwrap();
    assert!(last < first / 5.0, "loss {first} → {last}");
    let s = RenderSettings {
        steps: 64,
        ..RenderSettings::default()
    };
    let psnr = crate::volume::metrics::psnr(&render_rays(&m, &rays, &s), &colors);
    assert!(psnr > 15.0, "PSNR {psnr}");
}

#[test]
fn nerf_files_round_trip_and_bad_files_are_named() {
    let bytes = round_trip(&busy_nerf(), "m.nerf");
    assert_eq!(&bytes[..8], b"DSNERFLD");
    let err = |b: &[u8]| {
        io::from_bytes(b, "m.nerf".as_ref())
            .unwrap_err()
            .to_string()
    };
    assert!(err(&bytes[..bytes.len() - 1]).contains("header implies"));
    assert!(err(&bytes[..50]).contains("shorter than the 60-byte header"));
    let mut v2 = bytes.clone();
    v2[8] = 2;
    assert!(err(&v2).contains("version 2"));
    for (at, v, want) in [
        (36, 0u32, "frequencies 0"),
        (36, 40, "frequencies 40"),
        (40, 100_000, "width 100000"),
        (44, 9, "density_layers 9"),
    ] {
        let mut b = bytes.clone();
        b[at..at + 4].copy_from_slice(&v.to_le_bytes());
        let e = err(&b);
        assert!(e.contains(want) && e.contains("m.nerf"), "{e}");
    }
    let mut nan = bytes.clone();
    nan[64..68].copy_from_slice(&f32::NAN.to_le_bytes());
    assert!(err(&nan).contains("not finite"));
}
