//! Fitting a mesh's vertex positions and vertex colors (or texels) to images of it from
//! known cameras, with Adam ([`crate::optim`]) and a uniform-Laplacian smoothness term.

use super::render::{RenderOptions, View};
use super::{Mesh, icosphere};
use crate::Image;
use crate::error::{Error, Result};
use crate::optim::{Moments, Rule};
use crate::volume::camera::{Camera, orbit};

/// How [`fit`] runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitOptions {
    /// Optimizer steps; each renders every training view once.
    pub iters: usize,
    /// Adam learning rate of vertex positions, world units per step.
    pub lr_positions: f64,
    /// Adam learning rate of vertex colors and texels, per step.
    pub lr_colors: f64,
    /// Weight of the smoothness energy `½ w Σ_edges |p_i − p_j|²`, per unit of the
    /// image loss (mean squared error over the pixels of all views).
    pub smoothness: f64,
    /// Rendering of every view.
    pub render: RenderOptions,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            iters: 200,
            lr_positions: 2e-3,
            lr_colors: 1e-2,
            smoothness: 1e-3,
            render: RenderOptions {
                background: Some([1.0; 3]),
                ..RenderOptions::default()
            },
        }
    }
}

/// Mean squared error over RGBA (premultiplied) of two images of the same size.
pub fn mse(a: &Image, b: &Image) -> f64 {
    let n = a.data.len().max(1) as f64;
    a.data
        .iter()
        .zip(&b.data)
        .map(|(p, q)| (0..4).map(|c| ((p[c] - q[c]) as f64).powi(2)).sum::<f64>())
        .sum::<f64>()
        / (4.0 * n)
}

/// `n` cameras on a circle around `mesh`'s bounding box, 20° above its equator (world
/// +Y up), at 2.6 times its bounding radius with a 40° field of view, `size × size`;
/// `phase` turns the circle by that fraction of a step (held-out views between the
/// training ones with 0.5).
pub fn orbit_cameras(mesh: &Mesh, n: usize, size: u32, phase: f64) -> Result<Vec<Camera>> {
    let (lo, hi) = mesh.bounds();
    let c = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
    let r = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt() * 0.5;
    let r = if r > 0.0 { r } else { 1.0 };
    let center = glam::Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32);
    let cams = orbit(
        n,
        center,
        (2.6 * r) as f32,
        20f32.to_radians(),
        glam::Vec3::Y,
        40f32.to_radians(),
        size,
        size,
    )
    .map_err(|e| Error::Setting {
        name: "orbit".into(),
        message: e.to_string(),
    })?;
    if phase == 0.0 {
        return Ok(cams);
    }
    // Turn each camera about the up axis through the center.
    let angle = (std::f64::consts::TAU * phase / n.max(1) as f64) as f32;
    let turn = glam::Affine3A::from_translation(center)
        * glam::Affine3A::from_rotation_y(angle)
        * glam::Affine3A::from_translation(-center);
    cams.into_iter()
        .map(|cam| {
            Camera::new(
                cam.width,
                cam.height,
                cam.fx,
                cam.fy,
                cam.cx,
                cam.cy,
                turn * cam.c2w,
            )
            .map_err(|e| Error::Setting {
                name: "orbit".into(),
                message: e.to_string(),
            })
        })
        .collect()
}

/// `n` cameras looking at `mesh`'s bounding-box center from all around: directions on a
/// Fibonacci sphere (evenly spread, poles included), at 2.6 times the bounding radius with
/// a 40° field of view (world +Y up; world +Z up for a view within 8° of a pole),
/// `size × size`; `phase` turns the spiral about +Y by that fraction of a turn (another
/// phase or count gives views between these: held-out views).
pub fn sphere_cameras(mesh: &Mesh, n: usize, size: u32, phase: f64) -> Result<Vec<Camera>> {
    let (lo, hi) = mesh.bounds();
    let c = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
    let r = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt() * 0.5;
    let r = if r > 0.0 { r } else { 1.0 };
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let ring = (1.0 - y * y).max(0.0).sqrt();
            let az = golden * i as f64 + std::f64::consts::TAU * phase;
            let dir = [ring * az.cos(), y, ring * az.sin()];
            let eye = [0, 1, 2].map(|k| (c[k] + 2.6 * r * dir[k]) as f32);
            let up = if y.abs() > 8f64.to_radians().cos() {
                glam::Vec3::Z
            } else {
                glam::Vec3::Y
            };
            Camera::look_at(
                glam::Vec3::from(eye),
                glam::Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32),
                up,
                40f32.to_radians(),
                size,
                size,
            )
            .map_err(|e| Error::Setting {
                name: "cameras".into(),
                message: e.to_string(),
            })
        })
        .collect()
}

/// An icosphere (`subdivisions`) around `reference`'s bounds, with gray vertex colors:
/// the usual start of a fit.
pub fn sphere_around(reference: &Mesh, subdivisions: u32) -> Mesh {
    let (lo, hi) = reference.bounds();
    let c = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
    let r = (0..3).map(|k| hi[k] - lo[k]).fold(0.0, f64::max) * 0.5;
    let mut m = icosphere(subdivisions, if r > 0.0 { r } else { 1.0 });
    for p in &mut m.positions {
        for k in 0..3 {
            p[k] += c[k];
        }
    }
    m.colors = Some(vec![[0.5; 3]; m.positions.len()]);
    m
}

/// One step's report.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Step {
    /// Step index, from 0.
    pub iter: usize,
    /// Mean squared error over the training views before the step.
    pub mse: f64,
}

/// Fits `mesh`'s positions and colors (vertex colors, or texels when it has a texture)
/// to `views` (camera, target image) in place. Vertices at bit-identical positions
/// (UV-seam copies) share their summed position gradient and so move together.
/// `progress` sees every step and stops the fit by returning `false`. Returns the final
/// training MSE. Deterministic: views are rendered one after another and their gradients
/// added in order.
pub fn fit(
    mesh: &mut Mesh,
    views: &[(Camera, Image)],
    opts: &FitOptions,
    mut progress: impl FnMut(Step) -> bool,
) -> Result<f64> {
    if views.is_empty() {
        return Err(Error::Setting {
            name: "views".into(),
            message: "no training views".into(),
        });
    }
    crate::limits::check_count("iters", opts.iters, 0..=crate::limits::MAX_ITERS)?;
    for (name, v) in [
        ("lr_positions", opts.lr_positions),
        ("lr_colors", opts.lr_colors),
        ("smoothness", opts.smoothness),
    ] {
        if !(v >= 0.0 && v.is_finite()) {
            return Err(Error::Setting {
                name: name.into(),
                message: format!("{v} must be finite and not negative"),
            });
        }
    }
    mesh.validate(std::path::Path::new("<mesh>"))?;
    let adam = Rule::Adam {
        beta1: 0.9,
        beta2: 0.99,
        eps: 1e-12,
    };
    let np = mesh.positions.len() * 3;
    let mut pos_m = Moments::new(adam, np);
    let ncol = mesh
        .texture
        .as_ref()
        .map(|t| t.data.len())
        .or(mesh.colors.as_ref().map(|c| c.len()))
        .unwrap_or(0)
        * 3;
    let mut col_m = Moments::new(adam, ncol);
    let edges = edges(mesh);
    // Vertices at one position (UV-seam copies) share their summed gradient, so they
    // move together and the surface does not crack.
    let (group, n_groups) = super::refine::position_groups(&mesh.positions);
    let welded = n_groups < mesh.positions.len();
    let pixels: f64 = views
        .iter()
        .map(|(c, _)| c.width as f64 * c.height as f64)
        .sum();
    let mut last = f64::NAN;
    for iter in 0..opts.iters {
        let mut gpos = vec![0.0f64; np];
        let mut gcol = vec![0.0f64; ncol];
        let mut err = 0.0;
        for (cam, target) in views {
            let view = View::new(mesh, cam, opts.render)?;
            let img = view.render();
            if (img.width, img.height) != (target.width, target.height) {
                return Err(Error::Setting {
                    name: "views".into(),
                    message: format!(
                        "a target is {}×{}, its camera {}×{}",
                        target.width, target.height, img.width, img.height
                    ),
                });
            }
            // Loss: Σ over views and pixels of the RGBA squared error / (4 · pixels).
            let mut d = img.clone();
            for (p, t) in d.data.iter_mut().zip(&target.data) {
                for c in 0..4 {
                    let e = p[c] as f64 - t[c] as f64;
                    err += e * e;
                    p[c] = (2.0 * e / (4.0 * pixels)) as f32;
                }
            }
            let g = view.backward(&d, mesh.texture.is_some())?;
            for (i, v) in g.positions.iter().enumerate() {
                for k in 0..3 {
                    gpos[3 * i + k] += v[k];
                }
            }
            if let Some(gt) = g.texture.as_ref().or(g.colors.as_ref()) {
                for (i, v) in gt.iter().enumerate() {
                    for k in 0..3 {
                        gcol[3 * i + k] += v[k];
                    }
                }
            }
        }
        last = err / (4.0 * pixels);
        if !progress(Step { iter, mse: last }) {
            break;
        }
        for &(a, b) in &edges {
            let (pa, pb) = (mesh.positions[a as usize], mesh.positions[b as usize]);
            for k in 0..3 {
                let d = opts.smoothness * (pa[k] - pb[k]);
                gpos[3 * a as usize + k] += d;
                gpos[3 * b as usize + k] -= d;
            }
        }
        if welded {
            let mut sum = vec![[0.0f64; 3]; n_groups];
            for (i, &g) in group.iter().enumerate() {
                for k in 0..3 {
                    sum[g as usize][k] += gpos[3 * i + k];
                }
            }
            for (i, &g) in group.iter().enumerate() {
                gpos[3 * i..3 * i + 3].copy_from_slice(&sum[g as usize]);
            }
        }
        let mut flat: Vec<f64> = mesh.positions.iter().flatten().copied().collect();
        pos_m.step(&mut flat, &gpos, &vec![opts.lr_positions; np], 1.0);
        for (p, c) in mesh.positions.iter_mut().zip(flat.chunks_exact(3)) {
            p.copy_from_slice(c);
        }
        let cols: Option<&mut Vec<[f64; 3]>> = match (&mut mesh.texture, &mut mesh.colors) {
            (Some(t), _) => Some(&mut t.data),
            (None, Some(c)) => Some(c),
            _ => None,
        };
        if let Some(cols) = cols {
            let mut flat: Vec<f64> = cols.iter().flatten().copied().collect();
            col_m.step(&mut flat, &gcol, &vec![opts.lr_colors; ncol], 1.0);
            for (p, c) in cols.iter_mut().zip(flat.chunks_exact(3)) {
                *p = [
                    c[0].clamp(0.0, 1.0),
                    c[1].clamp(0.0, 1.0),
                    c[2].clamp(0.0, 1.0),
                ];
            }
        }
    }
    Ok(last)
}

/// The mesh's undirected edges, each once, sorted.
fn edges(mesh: &Mesh) -> Vec<(u32, u32)> {
    let mut e: Vec<(u32, u32)> = mesh
        .triangles
        .iter()
        .flat_map(|t| (0..3).map(move |k| (t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3]))))
        .collect();
    e.sort_unstable();
    e.dedup();
    e
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fitting_a_sphere_to_a_smaller_colored_sphere_lowers_the_error() {
        let mut reference = icosphere(2, 0.6);
        reference.colors = Some(
            reference
                .positions
                .iter()
                .map(|p| [0.5 + 0.5 * p[0] / 0.6, 0.3, 0.8])
                .collect(),
        );
        let cams = orbit_cameras(&reference, 4, 24, 0.0).unwrap();
        let views: Vec<(Camera, Image)> = cams
            .iter()
            .map(|c| {
                (
                    *c,
                    super::super::render(&reference, c, &FitOptions::default().render).unwrap(),
                )
            })
            .collect();
        let mut model = sphere_around(&reference, 2);
        for p in &mut model.positions {
            for v in p.iter_mut() {
                *v *= 1.3;
            }
        }
        let mut first = None;
        let opts = FitOptions {
            iters: 40,
            lr_positions: 5e-3,
            lr_colors: 2e-2,
            ..FitOptions::default()
        };
        let last = fit(&mut model, &views, &opts, |s| {
            first.get_or_insert(s.mse);
            true
        })
        .unwrap();
        let first = first.unwrap();
        assert!(last < 0.5 * first, "mse {first} → {last}");
    }

    #[test]
    fn seam_copies_move_together() {
        // An octahedron whose vertex 0 is split in two copies (a UV seam) used by
        // different triangles, fitted to a smaller octahedron: the copies stay together.
        let reference = crate::mesh::octahedron();
        let cams = orbit_cameras(&reference, 3, 16, 0.0).unwrap();
        let opts = FitOptions {
            iters: 10,
            lr_positions: 1e-2,
            ..FitOptions::default()
        };
        let views: Vec<(Camera, Image)> = cams
            .iter()
            .map(|c| {
                (
                    *c,
                    super::super::render(&reference, c, &opts.render).unwrap(),
                )
            })
            .collect();
        let mut model = crate::mesh::octahedron();
        for p in &mut model.positions {
            *p = p.map(|v| 1.2 * v);
        }
        model.positions.push(model.positions[0]);
        for t in &mut model.triangles[..2] {
            for v in t.iter_mut() {
                if *v == 0 {
                    *v = 6;
                }
            }
        }
        let start = model.positions[0];
        fit(&mut model, &views, &opts, |_| true).unwrap();
        assert_ne!(model.positions[0], start, "the vertex moved");
        assert_eq!(model.positions[0], model.positions[6]);
    }
}
