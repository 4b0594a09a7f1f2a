//! Fitting a mesh to images of it from known cameras, with Adam ([`crate::optim`]) and a
//! uniform-Laplacian smoothness term: vertex positions and vertex colors (or texels), and
//! on request the lights, the UVs and a pose correction of each training camera.

use super::render::{Lighting, MipPyramid, RenderOptions, View};
use super::{Mesh, icosphere};
use crate::Image;
use crate::error::{Error, Result};
use crate::optim::{Moments, Rule};
use crate::volume::camera::{Camera, orbit};
use crate::volume::pose::{self, PoseDelta};

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
    /// Adam learning rate of the lights of `render.lighting` (ambient and intensities,
    /// linear RGB; directions, as unit vectors, renormalized after each step); 0 keeps
    /// them fixed. Ambient and intensities are kept non-negative.
    pub lr_lights: f64,
    /// Adam learning rate of the UVs (texture coordinates per step; with a texture); 0
    /// keeps them fixed.
    pub lr_uvs: f64,
    /// Adam learning rates of each training view's pose correction
    /// ([`crate::volume::pose`]): rotation (radians per step) and translation (world
    /// units per step); `[0, 0]` keeps the cameras as given. When vertex positions move
    /// too, the corrections' common rigid motion is removed after every step
    /// (`pose::remove_common_motion`), since moving the mesh and every camera together
    /// changes no image.
    pub lr_poses: [f64; 2],
    /// Rendering of every view (its `lighting` is where [`fit`] starts from).
    pub render: RenderOptions,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            iters: 200,
            lr_positions: 2e-3,
            lr_colors: 1e-2,
            smoothness: 1e-3,
            lr_lights: 0.0,
            lr_uvs: 0.0,
            lr_poses: [0.0; 2],
            render: RenderOptions {
                background: Some([1.0; 3]),
                ..RenderOptions::default()
            },
        }
    }
}

impl FitOptions {
    /// Whether the training cameras get pose corrections.
    pub fn fits_poses(&self) -> bool {
        self.lr_poses != [0.0; 2]
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

/// The fit's state as [`fit`]'s `progress` sees it, before step [`Step::iter`]: after
/// `iter` steps.
#[derive(Clone, Copy, Debug)]
pub struct Snapshot<'a> {
    /// The mesh.
    pub mesh: &'a Mesh,
    /// The rendering options with the current lights: render held-out views with these.
    pub render: RenderOptions,
    /// Each training view's pose correction.
    pub poses: &'a [PoseDelta],
}

/// What [`fit`] returns besides the mesh it fits in place.
#[derive(Clone, Debug, PartialEq)]
pub struct Fitted {
    /// The final training MSE (before the last step).
    pub mse: f64,
    /// The fitted lights (`render.lighting` as given when `lr_lights` is 0).
    pub lighting: Option<Lighting>,
    /// Each training view's pose correction, in the order of the views (zeros when
    /// poses are not fitted): the view was rendered from `pose::apply(camera, δ)`.
    pub poses: Vec<PoseDelta>,
}

/// Checks that a learning rate or weight is finite and not negative.
fn check_rate(name: &str, v: f64) -> Result<()> {
    if v >= 0.0 && v.is_finite() {
        Ok(())
    } else {
        Err(Error::Setting {
            name: name.into(),
            message: format!("{v} must be finite and not negative"),
        })
    }
}

/// One Adam step of the flat parameters `flat`, every one at rate `lr`.
fn adam_step(m: &mut Moments<f64>, flat: &mut [f64], grad: &[f64], lr: f64) {
    m.step(flat, grad, &vec![lr; flat.len()], 1.0);
}

/// The lights as a flat vector: ambient, then each light's direction and intensity.
fn lights_flat(l: &Lighting) -> Vec<f64> {
    let mut v = l.ambient.to_vec();
    for d in l.lights() {
        v.extend_from_slice(&d.direction);
        v.extend_from_slice(&d.intensity);
    }
    v
}

/// Fits `mesh` to `views` (camera, target image) in place: vertex positions, colors
/// (vertex colors, or texels when it has a texture), and, when their rates are not zero,
/// the lights of `opts.render.lighting`, the UVs and a pose correction per training view
/// (held-out views are not given to `fit`: they keep their cameras). Vertices at
/// bit-identical positions (UV-seam copies) share their summed position gradient and so
/// move together. `progress` sees every step with the state before it, and stops the fit
/// by returning `false`. Deterministic: views are rendered one after another and their
/// gradients added in order.
pub fn fit(
    mesh: &mut Mesh,
    views: &[(Camera, Image)],
    opts: &FitOptions,
    mut progress: impl FnMut(Step, &Snapshot) -> bool,
) -> Result<Fitted> {
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
        ("lr_lights", opts.lr_lights),
        ("lr_uvs", opts.lr_uvs),
        ("lr_poses", opts.lr_poses[0]),
        ("lr_poses", opts.lr_poses[1]),
    ] {
        check_rate(name, v)?;
    }
    mesh.validate(std::path::Path::new("<mesh>"))?;
    let setting = |name: &str, message: &str| Error::Setting {
        name: name.into(),
        message: message.into(),
    };
    let fit_lights = opts.lr_lights > 0.0;
    if fit_lights && opts.render.lighting.is_none() {
        return Err(setting("lr_lights", "there are no lights to fit"));
    }
    let fit_uvs = opts.lr_uvs > 0.0;
    if fit_uvs && (mesh.texture.is_none() || mesh.uvs.is_none()) {
        return Err(setting("lr_uvs", "the mesh has no texture and UVs to fit"));
    }
    let fit_poses = opts.fits_poses();
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
    let mut render = opts.render;
    let nlight = render.lighting.as_ref().map_or(0, |l| lights_flat(l).len());
    let mut light_m = Moments::new(adam, if fit_lights { nlight } else { 0 });
    let nuv = if fit_uvs { mesh.positions.len() * 2 } else { 0 };
    let mut uv_m = Moments::new(adam, nuv);
    let mut poses: Vec<PoseDelta> = vec![[0.0; 6]; views.len()];
    let mut pose_m = Moments::new(adam, if fit_poses { 6 * views.len() } else { 0 });
    let centers: Vec<glam::Vec3> = views.iter().map(|(c, _)| c.position()).collect();
    let radius = {
        let (lo, hi) = mesh.bounds();
        ((0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt() * 0.5).max(1e-9)
    };
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
        let mut glight = vec![0.0f64; if fit_lights { nlight } else { 0 }];
        let mut guv = vec![0.0f64; nuv];
        let mut gpose = vec![0.0f64; pose_m.len()];
        let mut err = 0.0;
        // Mip levels (with `render.mipmaps`): once per texture version, for every view.
        let pyramid = MipPyramid::for_mesh(mesh, &render);
        for (v, (cam, target)) in views.iter().enumerate() {
            let cam = if fit_poses {
                pose::apply(cam, &poses[v])
            } else {
                *cam
            };
            let view = View::with_pyramid(mesh, &cam, render, pyramid.as_ref())?;
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
            if let (true, Some(lg)) = (fit_lights, &g.lighting) {
                let mut j = 0;
                for k in 0..3 {
                    glight[k] += lg.ambient[k];
                }
                for (d, i) in lg.directions.iter().zip(&lg.intensities) {
                    for k in 0..3 {
                        glight[3 + j + k] += d[k];
                        glight[6 + j + k] += i[k];
                    }
                    j += 6;
                }
            }
            if let (true, Some(gu)) = (fit_uvs, &g.uvs) {
                for (i, u) in gu.iter().enumerate() {
                    guv[2 * i] += u[0];
                    guv[2 * i + 1] += u[1];
                }
            }
            if fit_poses {
                let gd = pose::delta_gradient(&poses[v], &g.pose);
                for k in 0..6 {
                    gpose[6 * v + k] = gd[k] as f64;
                }
            }
        }
        last = err / (4.0 * pixels);
        let snap = Snapshot {
            mesh,
            render,
            poses: &poses,
        };
        if !progress(Step { iter, mse: last }, &snap) {
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
        adam_step(&mut pos_m, &mut flat, &gpos, opts.lr_positions);
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
            adam_step(&mut col_m, &mut flat, &gcol, opts.lr_colors);
            for (p, c) in cols.iter_mut().zip(flat.chunks_exact(3)) {
                *p = [
                    c[0].clamp(0.0, 1.0),
                    c[1].clamp(0.0, 1.0),
                    c[2].clamp(0.0, 1.0),
                ];
            }
        }
        if let (true, Some(l)) = (fit_lights, render.lighting.as_mut()) {
            let mut flat = lights_flat(l);
            adam_step(&mut light_m, &mut flat, &glight, opts.lr_lights);
            for k in 0..3 {
                l.ambient[k] = flat[k].max(0.0);
            }
            let count = l.lights().len();
            for (j, d) in l.lights[..count].iter_mut().enumerate() {
                let o = 3 + 6 * j;
                let n = (flat[o..o + 3].iter().map(|v| v * v).sum::<f64>()).sqrt();
                // A direction that collapsed to zero keeps its last value.
                if n > 0.0 && n.is_finite() {
                    d.direction = [flat[o] / n, flat[o + 1] / n, flat[o + 2] / n];
                }
                for k in 0..3 {
                    d.intensity[k] = flat[o + 3 + k].max(0.0);
                }
            }
        }
        if let (true, Some(uvs)) = (fit_uvs, mesh.uvs.as_mut()) {
            let mut flat: Vec<f64> = uvs.iter().flatten().copied().collect();
            adam_step(&mut uv_m, &mut flat, &guv, opts.lr_uvs);
            for (p, c) in uvs.iter_mut().zip(flat.chunks_exact(2)) {
                p.copy_from_slice(c);
            }
        }
        if fit_poses {
            let mut flat: Vec<f64> = poses.iter().flatten().map(|&v| v as f64).collect();
            let rates: Vec<f64> = (0..flat.len())
                .map(|i| opts.lr_poses[(i % 6) / 3])
                .collect();
            pose_m.step(&mut flat, &gpose, &rates, 1.0);
            for (p, c) in poses.iter_mut().zip(flat.chunks_exact(6)) {
                *p = std::array::from_fn(|k| c[k] as f32);
            }
            if opts.lr_positions > 0.0 && poses.len() > 1 {
                pose::remove_common_motion(&mut poses, &centers, radius as f32);
            }
        }
    }
    Ok(Fitted {
        mse: last,
        lighting: render.lighting,
        poses,
    })
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
        let last = fit(&mut model, &views, &opts, |s, _| {
            first.get_or_insert(s.mse);
            true
        })
        .unwrap()
        .mse;
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
        fit(&mut model, &views, &opts, |_, _| true).unwrap();
        assert_ne!(model.positions[0], start, "the vertex moved");
        assert_eq!(model.positions[0], model.positions[6]);
    }

    /// `mesh`'s renders from `cams` with `opts`.
    fn renders(mesh: &Mesh, cams: &[Camera], opts: &RenderOptions) -> Vec<(Camera, Image)> {
        cams.iter()
            .map(|c| (*c, super::super::render(mesh, c, opts).unwrap()))
            .collect()
    }

    /// A fit that moves nothing but what `opts` turns on.
    fn only(opts: FitOptions) -> FitOptions {
        FitOptions {
            lr_positions: 0.0,
            lr_colors: 0.0,
            smoothness: 0.0,
            ..opts
        }
    }

    fn angle_deg(a: [f64; 3], b: [f64; 3]) -> f64 {
        let n = |v: [f64; 3]| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        let c = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]) / (n(a) * n(b));
        c.clamp(-1.0, 1.0).acos().to_degrees()
    }

    #[test]
    fn fitting_lights_recovers_a_turned_light() {
        // A gray sphere lit by one light; the model is the same sphere with the light
        // turned by about 25° and its intensity and ambient off: fitting the lights alone
        // brings the direction back within a few degrees.
        use crate::mesh::DirLight;
        let mut sphere = icosphere(3, 0.6);
        sphere.colors = Some(vec![[0.8; 3]; sphere.positions.len()]);
        let truth = [0.3, 0.8, 0.5];
        let lit = |direction: [f64; 3], intensity: f64, ambient: f64| RenderOptions {
            lighting: Some(
                Lighting::new(
                    [ambient; 3],
                    &[DirLight {
                        direction,
                        intensity: [intensity; 3],
                    }],
                )
                .unwrap(),
            ),
            ..FitOptions::default().render
        };
        let cams = orbit_cameras(&sphere, 6, 32, 0.0).unwrap();
        let views = renders(&sphere, &cams, &lit(truth, 0.9, 0.2));
        let start = [0.7, 0.65, 0.1];
        let before = angle_deg(start, truth);
        let opts = only(FitOptions {
            iters: 120,
            lr_lights: 1e-2,
            render: lit(start, 0.7, 0.3),
            ..FitOptions::default()
        });
        let mut model = sphere.clone();
        let mut first = None;
        let out = fit(&mut model, &views, &opts, |s, _| {
            first.get_or_insert(s.mse);
            true
        })
        .unwrap();
        let l = out.lighting.unwrap();
        let after = angle_deg(l.lights()[0].direction, truth);
        eprintln!(
            "light: {before:.1}° → {after:.2}° off, intensity {:.3}, ambient {:.3}, mse {:.2e} → {:.2e}",
            l.lights()[0].intensity[0],
            l.ambient[0],
            first.unwrap(),
            out.mse
        );
        assert!(before > 20.0, "{before}");
        assert!(after < 3.0, "the light is {after}° off");
        assert_eq!(model, sphere, "nothing else moved");
    }

    #[test]
    fn fitting_poses_turns_a_turned_camera_back() {
        // Four views of a colored torus knot (a silhouette that shows every turn); the
        // second camera is given turned by 1° about an axis across its view (the image
        // moves by about a pixel): its pose correction turns it back. (A turn across the
        // view looks much like a move sideways; with the move held fixed the angle is
        // what the images decide, with both the images still match.)
        let mut sphere = crate::mesh::torus_knot(96, 8);
        sphere.colors = Some(
            sphere
                .positions
                .iter()
                .map(|p| p.map(|v| 0.5 + 0.4 * v.clamp(-1.0, 1.0)))
                .collect(),
        );
        let opts = FitOptions::default();
        let cams = orbit_cameras(&sphere, 4, 64, 0.0).unwrap();
        let mut views = renders(&sphere, &cams, &opts.render);
        let m = cams[1].c2w.matrix3;
        let w = (glam::Vec3::from(m.x_axis) * 0.6 + glam::Vec3::from(m.y_axis) * 0.8).normalize()
            * 1f32.to_radians();
        views[1].0 = pose::apply(&cams[1], &[w.x, w.y, w.z, 0.0, 0.0, 0.0]);
        let (deg0, _) = pose::pose_error(&views[1].0, &cams[1]);
        for (lr, most) in [([5e-4, 0.0], 0.5), ([5e-4, 5e-4], 1.0)] {
            let o = only(FitOptions {
                iters: 80,
                lr_poses: lr,
                ..opts
            });
            let mut model = sphere.clone();
            let mut mses = Vec::new();
            let out = fit(&mut model, &views, &o, |s, _| {
                mses.push(s.mse);
                true
            })
            .unwrap();
            assert_eq!(
                out.poses.len(),
                views.len(),
                "one correction per training view"
            );
            let (deg1, dist1) =
                pose::pose_error(&pose::apply(&views[1].0, &out.poses[1]), &cams[1]);
            let (first, last) = (mses[0], *mses.last().unwrap());
            eprintln!(
                "pose (rates {lr:?}): {deg0:.3}° → {deg1:.3}°, moved {dist1:.4}; mse {first:.2e} → {last:.2e}"
            );
            assert!(last < 0.1 * first, "mse {first} → {last}");
            assert!(deg1 < most * deg0, "{deg0}° → {deg1}°");
            assert_eq!(model, sphere, "the mesh is not moved");
            for v in [0, 2, 3] {
                let (deg, _) = pose::pose_error(&pose::apply(&cams[v], &out.poses[v]), &cams[v]);
                assert!(
                    deg < 0.25,
                    "view {v}, rendered from its own pose, turned by {deg}°"
                );
            }
        }
    }

    #[test]
    fn fitting_uvs_lowers_the_error_of_shifted_uvs() {
        let mut sphere = icosphere(2, 0.6);
        sphere.uvs = Some(
            sphere
                .positions
                .iter()
                .map(|p| [0.5 + 0.35 * p[0], 0.5 + 0.35 * p[1]])
                .collect(),
        );
        sphere.texture = Some(crate::mesh::Texture {
            width: 8,
            height: 8,
            data: (0..64)
                .map(|i| [(i % 8) as f64 / 7.0, (i / 8) as f64 / 7.0, 0.5])
                .collect(),
        });
        let opts = FitOptions::default();
        let cams = orbit_cameras(&sphere, 4, 32, 0.0).unwrap();
        let views = renders(&sphere, &cams, &opts.render);
        let mut model = sphere.clone();
        for uv in model.uvs.as_mut().unwrap() {
            uv[0] += 0.04;
            uv[1] -= 0.03;
        }
        let opts = only(FitOptions {
            iters: 60,
            lr_uvs: 2e-3,
            ..opts
        });
        let mut first = None;
        let out = fit(&mut model, &views, &opts, |s, _| {
            first.get_or_insert(s.mse);
            true
        })
        .unwrap();
        let first = first.unwrap();
        eprintln!("uvs: mse {first:.2e} → {:.2e}", out.mse);
        assert!(out.mse < 0.25 * first, "mse {first} → {}", out.mse);
        // Without a texture there are no UVs to fit.
        let mut plain = icosphere(1, 1.0);
        assert!(fit(&mut plain, &views, &opts, |_, _| true).is_err());
    }
}
