//! Numerically hard inputs of the Gaussian-splatting renderer and its backward pass: the
//! image and every gradient stay finite, culled Gaussians get exactly zero gradient, and
//! where the rendering is a smooth function of a parameter the gradient agrees with
//! central finite differences.

use std::f32::consts::FRAC_1_SQRT_2;

use diffsvg::glam::Affine3A;
use diffsvg::volume::camera::Camera;
use diffsvg::volume::splat::{Gaussians, Gradients, RenderSettings, backward, render};

/// A 32 × 24 camera at the origin looking down −Z, fx = fy = 40.
fn camera() -> Camera {
    Camera::new(32, 24, 40.0, 40.0, 16.0, 12.0, Affine3A::IDENTITY).unwrap()
}

fn settings() -> RenderSettings {
    RenderSettings {
        background: [0.3, 0.6, 0.9],
        ..RenderSettings::default()
    }
}

/// SH DC (degree 0) of linear color `c`.
fn dc(c: [f32; 3]) -> [f32; 3] {
    c.map(|v| (v - 0.5) / 0.282_094_8)
}

/// Fixed pseudo-random weights: `L = Σ wᵢ·rgbᵢ` and `∂L/∂rgb = w`.
fn weights(n: usize) -> Vec<[f32; 3]> {
    let mut s = 0x9e37_79b9u32;
    (0..n)
        .map(|_| {
            [0.0; 3].map(|_: f32| {
                s ^= s << 13;
                s ^= s >> 17;
                s ^= s << 5;
                (s >> 8) as f32 / (1u32 << 24) as f32 - 0.5
            })
        })
        .collect()
}

fn loss(g: &Gaussians, w: &[[f32; 3]]) -> f64 {
    let out = render(g, &camera(), &settings()).unwrap();
    out.rgb
        .iter()
        .zip(w)
        .map(|(p, q)| (0..3).map(|c| p[c] as f64 * q[c] as f64).sum::<f64>())
        .sum()
}

/// Renders and differentiates `g`; asserts everything is finite.
fn run(g: &Gaussians) -> (Vec<[f32; 3]>, Gradients) {
    let cam = camera();
    let s = settings();
    let out = render(g, &cam, &s).unwrap();
    assert!(out.rgb.iter().flatten().all(|v| v.is_finite()), "image");
    assert!(out.transmittance.iter().all(|t| (0.0..=1.0).contains(t)));
    let w = weights(out.rgb.len());
    let grads = backward(g, &cam, &s, &out, &w).unwrap();
    let all = grads
        .means
        .as_flattened()
        .iter()
        .chain(grads.log_scales.as_flattened())
        .chain(grads.rotations.as_flattened())
        .chain(&grads.logit_opacities)
        .chain(&grads.sh)
        .chain(grads.mean2d.as_flattened());
    for v in all {
        assert!(v.is_finite(), "gradient {v}");
    }
    (out.rgb, grads)
}

/// Which parameter of Gaussian `i` a finite-difference check moves.
#[derive(Clone, Copy, Debug)]
enum P {
    Mean(usize),
    LogScale(usize),
    Rot(usize),
    Opacity,
    Sh(usize),
}

fn slot(g: &mut Gaussians, i: usize, p: P) -> &mut f32 {
    let k3 = 3 * g.coeffs_per_channel();
    match p {
        P::Mean(a) => &mut g.means[i][a],
        P::LogScale(a) => &mut g.log_scales[i][a],
        P::Rot(a) => &mut g.rotations[i][a],
        P::Opacity => &mut g.logit_opacities[i],
        P::Sh(j) => &mut g.sh[i * k3 + j],
    }
}

fn analytic(gr: &Gradients, g: &Gaussians, i: usize, p: P) -> f32 {
    let k3 = 3 * g.coeffs_per_channel();
    match p {
        P::Mean(a) => gr.means[i][a],
        P::LogScale(a) => gr.log_scales[i][a],
        P::Rot(a) => gr.rotations[i][a],
        P::Opacity => gr.logit_opacities[i],
        P::Sh(j) => gr.sh[i * k3 + j],
    }
}

/// Central differences of `L` in each listed parameter of Gaussian `i` agree with the
/// backward pass within 2 % (plus a small absolute floor for f32 rounding).
fn check(g: &Gaussians, i: usize, params: &[P]) {
    let (_, gr) = run(g);
    let w = weights(32 * 24);
    let h = 2e-3f32;
    for &p in params {
        let (mut plus, mut minus) = (g.clone(), g.clone());
        *slot(&mut plus, i, p) += h;
        *slot(&mut minus, i, p) -= h;
        let fd = (loss(&plus, &w) - loss(&minus, &w)) / (2.0 * h as f64);
        let an = analytic(&gr, g, i, p) as f64;
        assert!(
            (fd - an).abs() <= 0.02 * fd.abs().max(an.abs()) + 2e-3,
            "Gaussian {i} {p:?}: analytic {an} vs central difference {fd}"
        );
    }
}

const ALL: [P; 12] = [
    P::Mean(0),
    P::Mean(1),
    P::Mean(2),
    P::LogScale(0),
    P::LogScale(1),
    P::LogScale(2),
    P::Rot(0),
    P::Rot(1),
    P::Rot(3),
    P::Opacity,
    P::Sh(0),
    P::Sh(2),
];

#[test]
fn behind_the_camera_and_across_the_near_plane_get_zero_gradient() {
    let mut g = Gaussians::new(0);
    // In view, large and smooth.
    g.push(
        [0.1, 0.0, -6.0],
        [0.9; 3],
        [1.0, 0.0, 0.0, 0.0],
        -0.5,
        &dc([0.8, 0.3, 0.2]),
    );
    // Behind the camera, huge (it would cover everything if projected).
    g.push(
        [0.0, 0.0, 3.0],
        [2.0; 3],
        [1.0, 0.0, 0.0, 0.0],
        4.0,
        &dc([0.0; 3]),
    );
    // Center just in front of the camera but inside the near distance; its extent
    // straddles the plane.
    g.push(
        [0.0, 0.0, -0.005],
        [0.0; 3],
        [1.0, 0.0, 0.0, 0.0],
        4.0,
        &dc([0.0; 3]),
    );
    let (_, gr) = run(&g);
    assert_eq!(gr.visible, vec![true, false, false]);
    for i in 1..3 {
        assert_eq!(gr.means[i], [0.0; 3]);
        assert_eq!(gr.logit_opacities[i], 0.0);
        assert_eq!(gr.mean2d[i], [0.0; 2]);
    }
    check(&g, 0, &ALL);
}

#[test]
fn a_gaussian_on_the_image_border() {
    let mut g = Gaussians::new(0);
    // Centered on the left edge (x/z = −cx/fx at depth 5).
    g.push(
        [-2.0, 0.3, -5.0],
        [0.8, 0.6, 0.7],
        [0.9, 0.1, -0.2, 0.3],
        -0.3,
        &dc([0.2, 0.7, 0.4]),
    );
    // And one centered just outside the top-right corner, a little further away (at the
    // same depth a finite difference of the depth would swap their order).
    g.push(
        [2.42, 1.76, -5.5],
        [0.9; 3],
        [1.0, 0.0, 0.0, 0.0],
        -0.8,
        &dc([0.9, 0.9, 0.1]),
    );
    let (_, gr) = run(&g);
    assert!(gr.visible.iter().all(|&v| v));
    check(&g, 0, &ALL);
    check(&g, 1, &ALL);
}

#[test]
fn a_nearly_flat_gaussian() {
    let mut g = Gaussians::new(0);
    // A disk of radius ~1.8 and thickness 1e-6, seen at an angle. Its 1/255 contour,
    // where the renderer stops drawing it (a true discontinuity that finite differences
    // would see), lies outside the image.
    g.push(
        [0.0, 0.0, -5.0],
        [1e-6f32.ln(), 0.6, 0.5],
        [0.9, 0.3, 0.2, 0.0],
        2.0,
        &dc([0.6, 0.2, 0.5]),
    );
    let (rgb, gr) = run(&g);
    assert!(gr.visible[0]);
    assert!(rgb[12 * 32 + 16][2] < 0.6, "the disk is drawn");
    // The thin axis barely matters; the others are smooth.
    check(
        &g,
        0,
        &[
            P::Mean(0),
            P::Mean(1),
            P::LogScale(1),
            P::LogScale(2),
            P::Opacity,
            P::Sh(1),
        ],
    );
    // Seen exactly edge-on, the dilation keeps the splat finite.
    let mut edge = Gaussians::new(0);
    edge.push(
        [0.0, 0.0, -5.0],
        [0.0, 0.0, 1e-6f32.ln()],
        [0.0, 1.0, 0.0, 0.0],
        2.0,
        &dc([0.0; 3]),
    );
    edge.rotations[0] = [FRAC_1_SQRT_2, FRAC_1_SQRT_2, 0.0, 0.0]; // thin axis along the view
    run(&edge);
}

#[test]
fn a_huge_gaussian_covering_the_image() {
    let mut g = Gaussians::new(1);
    let mut sh = [0.0f32; 12];
    sh[0] = 0.4;
    sh[5] = -0.3;
    sh[11] = 0.2;
    g.push(
        [0.5, -0.2, -4.0],
        [3.0, 2.5, 3.5],
        [0.8, 0.0, 0.5, 0.1],
        -0.2,
        &sh,
    );
    let (rgb, gr) = run(&g);
    assert!(gr.visible[0]);
    assert!(
        rgb.iter().all(|c| (c[0] - 0.3).abs() > 0.01),
        "every pixel is covered"
    );
    check(&g, 0, &[ALL.as_slice(), &[P::Sh(5), P::Sh(11)]].concat());
}

#[test]
fn a_fully_opaque_stack() {
    // Twenty opaque Gaussians stacked along the view axis: the front one saturates the
    // clamp at 0.99, blending stops early, and those behind get no gradient at the center.
    let mut g = Gaussians::new(0);
    for k in 0..20 {
        // Colors stay clear of 0 and 1, where the color clamp has a kink.
        let c = [
            0.03 + 0.9 * k as f32 / 20.0,
            0.5,
            0.97 - 0.9 * k as f32 / 20.0,
        ];
        g.push(
            [0.0, 0.0, -3.0 - 0.1 * k as f32],
            [0.5; 3],
            [1.0, 0.0, 0.0, 0.0],
            9.0,
            &dc(c),
        );
    }
    let (rgb, gr) = run(&g);
    let center = rgb[12 * 32 + 16];
    assert!(
        center[0] < 0.05 && center[2] > 0.95,
        "the front one shows: {center:?}"
    );
    assert!(gr.visible.iter().all(|&v| v));
    // The back of the stack is hidden everywhere.
    assert_eq!(gr.sh[19 * 3..20 * 3], [0.0; 3]);
    // The colors are smooth even where the opacity is clamped.
    check(&g, 0, &[P::Sh(0), P::Sh(1), P::Sh(2)]);
}

#[test]
fn identical_depths_blend_in_index_order() {
    let red = dc([1.0, 0.0, 0.0]);
    let blue = dc([0.0, 0.0, 1.0]);
    let build = |first: [f32; 3], second: [f32; 3]| {
        let mut g = Gaussians::new(0);
        g.push(
            [0.0, 0.0, -4.0],
            [0.6; 3],
            [1.0, 0.0, 0.0, 0.0],
            1.0,
            &first,
        );
        g.push(
            [0.0, 0.0, -4.0],
            [0.6; 3],
            [1.0, 0.0, 0.0, 0.0],
            1.0,
            &second,
        );
        g
    };
    let (a, ga) = run(&build(red, blue));
    let (b, _) = run(&build(blue, red));
    let c = 12 * 32 + 16;
    assert!(a[c][0] > a[c][2], "index 0 (red) in front: {:?}", a[c]);
    assert!(b[c][2] > b[c][0], "index 0 (blue) in front: {:?}", b[c]);
    // The same scene renders and differentiates to the same bits on 1 and 3 threads.
    let g = build(red, blue);
    let bits = |threads| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let (rgb, gr) = pool.install(|| run(&g));
        let v: Vec<u32> = rgb
            .iter()
            .flatten()
            .chain(gr.means.as_flattened())
            .chain(&gr.sh)
            .map(|v| v.to_bits())
            .collect();
        v
    };
    assert_eq!(bits(1), bits(3));
    // Front and back get different gradients, each matching central differences.
    assert_ne!(ga.logit_opacities[0], ga.logit_opacities[1]);
    check(&build(red, blue), 0, &[P::Opacity, P::Sh(0), P::Mean(0)]);
    check(&build(red, blue), 1, &[P::Opacity, P::Sh(2), P::Mean(1)]);
}

#[test]
fn no_gaussians_render_the_background_with_empty_gradients() {
    let g = Gaussians::new(2);
    let (rgb, gr) = run(&g);
    assert!(rgb.iter().all(|&c| c == [0.3, 0.6, 0.9]));
    assert!(gr.means.is_empty() && gr.sh.is_empty());
}
