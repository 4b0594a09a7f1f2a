//! Camera pose corrections, learned next to a model ("pose refinement"), and the
//! perturbation of poses used to test them.
//!
//! A **correction** is six numbers `[ωx, ωy, ωz, vx, vy, vz]` ([`PoseDelta`]), all in
//! world axes: the corrected camera turns about its own center by the rotation
//! `exp([ω]×)` (axis-angle, radians) and then moves by `v` (world units). With the loaded
//! camera-to-world rotation `R` and center `c`, the corrected camera has rotation
//! `exp([ω]×)·R` and center `c + v`; a ray `(o, d)` of the loaded camera becomes
//! `(o + v, exp([ω]×)·d)`. The zero correction changes nothing.
//!
//! The renderers' backward passes give the gradient with respect to a correction
//! `[ε, u]` applied on top of the camera they rendered (at `ε = u = 0`, the *local*
//! gradient). `delta_gradient` turns it into the gradient with respect to the stored
//! correction, through the left Jacobian of SO(3): `exp(ω + δ) = exp(J(ω)·δ)·exp(ω)` to
//! first order.

use glam::{Affine3A, Mat3, Mat3A, Vec3};

use super::camera::Camera;
use super::{Ray, dataset::View};
use crate::rng::Rng;

/// A pose correction `[ωx, ωy, ωz, vx, vy, vz]` (module documentation): rotation
/// vector in radians, then translation in world units, both in world axes.
pub type PoseDelta = [f32; 6];

/// `exp([ω]×)`: the rotation by `|ω|` radians about `ω / |ω|`.
pub(crate) fn rotation(omega: Vec3) -> Mat3 {
    let angle = omega.length();
    if angle < 1e-12 {
        // First order; exact to f32 precision at this size.
        return Mat3::IDENTITY + skew(omega);
    }
    Mat3::from_axis_angle(omega / angle, angle)
}

/// `[a]×`, the matrix with `[a]×·b = a × b`.
pub(crate) fn skew(a: Vec3) -> Mat3 {
    Mat3::from_cols(
        Vec3::new(0.0, a.z, -a.y),
        Vec3::new(-a.z, 0.0, a.x),
        Vec3::new(a.y, -a.x, 0.0),
    )
}

/// The left Jacobian of SO(3): `I + (1 − cos θ)/θ²·W + (θ − sin θ)/θ³·W²`, `W = [ω]×`,
/// `θ = |ω|` (in f64, series near 0).
fn left_jacobian(omega: Vec3) -> [[f64; 3]; 3] {
    let w = [omega.x as f64, omega.y as f64, omega.z as f64];
    let t2 = w[0] * w[0] + w[1] * w[1] + w[2] * w[2];
    let t = t2.sqrt();
    let (a, b) = if t < 1e-4 {
        (0.5 - t2 / 24.0, 1.0 / 6.0 - t2 / 120.0)
    } else {
        ((1.0 - t.cos()) / t2, (t - t.sin()) / (t2 * t))
    };
    let k = [[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]];
    let mut j = [[0.0; 3]; 3];
    for r in 0..3 {
        for c in 0..3 {
            let k2: f64 = (0..3).map(|m| k[r][m] * k[m][c]).sum();
            j[r][c] = if r == c { 1.0 } else { 0.0 } + a * k[r][c] + b * k2;
        }
    }
    j
}

/// The gradient with respect to the stored correction `delta` from the local gradient
/// `local = ∂L/∂[ε, u]` of a correction applied on top of the corrected camera (module
/// documentation): `∂L/∂ω = J(ω)ᵀ·∂L/∂ε`, `∂L/∂v = ∂L/∂u`.
pub(crate) fn delta_gradient(delta: &PoseDelta, local: &[f64; 6]) -> PoseDelta {
    let j = left_jacobian(Vec3::new(delta[0], delta[1], delta[2]));
    let mut out = [0.0f32; 6];
    for c in 0..3 {
        out[c] = (0..3).map(|r| j[r][c] * local[r]).sum::<f64>() as f32;
        out[3 + c] = local[3 + c] as f32;
    }
    out
}

/// `camera` with the correction `delta` applied (module documentation).
pub fn apply(camera: &Camera, delta: &PoseDelta) -> Camera {
    let r = rotation(Vec3::new(delta[0], delta[1], delta[2]));
    let v = Vec3::new(delta[3], delta[4], delta[5]);
    let c2w = Affine3A {
        matrix3: Mat3A::from(r) * camera.c2w.matrix3,
        translation: camera.c2w.translation + glam::Vec3A::from(v),
    };
    Camera { c2w, ..*camera }
}

/// The ray `ray` of a loaded camera as the camera corrected by `(rot, v)` sees it, where
/// `rot = rotation(ω)`: `(o + v, rot·d)`.
#[inline]
pub(crate) fn apply_to_ray(ray: &Ray, rot: &Mat3, v: Vec3) -> Ray {
    Ray {
        origin: ray.origin + v,
        dir: *rot * ray.dir,
    }
}

/// Removes from the corrections `deltas` of cameras centered at `centers` (world units,
/// before correction) their common rigid motion: the turn `ω` about the world origin and
/// the move `t` that, applied to every camera at once (each then turns by `ω` and moves by
/// `ω × c + t`), best explain them in least squares, with moves measured in units of
/// `scale` (world units per radian). Photos alone cannot tell the scene and all its
/// cameras moved together from where they were (the gauge freedom of bundle
/// adjustment); without this, noisy steps let the training cameras drift together away
/// from the held-out ones, which keep their loaded poses. Linear in the corrections
/// (exact to first order in `ω`).
pub(crate) fn remove_common_motion(deltas: &mut [PoseDelta], centers: &[Vec3], scale: f32) {
    use glam::{DMat3, DVec3};
    let n = deltas.len().min(centers.len());
    if n == 0 {
        return;
    }
    let w2 = 1.0 / (scale as f64 * scale as f64);
    let omega = |d: &PoseDelta| DVec3::new(d[0] as f64, d[1] as f64, d[2] as f64);
    let v = |d: &PoseDelta| DVec3::new(d[3] as f64, d[4] as f64, d[5] as f64);
    let inv = 1.0 / n as f64;
    let c_mean = centers[..n].iter().map(|c| c.as_dvec3()).sum::<DVec3>() * inv;
    let v_mean = deltas[..n].iter().map(v).sum::<DVec3>() * inv;
    // With t = v̄ + c̄ × ω, minimise Σ |ωᵢ − ω|² + w² Σ |(vᵢ − v̄) + dᵢ × ω|², dᵢ = cᵢ − c̄.
    let mut m = DMat3::IDENTITY * n as f64;
    let mut rhs = DVec3::ZERO;
    for (d, c) in deltas[..n].iter().zip(centers) {
        let di = c.as_dvec3() - c_mean;
        let k = DMat3::from_cols(
            DVec3::new(0.0, di.z, -di.y),
            DVec3::new(-di.z, 0.0, di.x),
            DVec3::new(di.y, -di.x, 0.0),
        );
        m -= k * k * w2;
        rhs += omega(d) + di.cross(v(d) - v_mean) * w2;
    }
    let w = m.inverse() * rhs;
    if !w.is_finite() {
        return;
    }
    let t = v_mean + c_mean.cross(w);
    for (d, c) in deltas[..n].iter_mut().zip(centers) {
        let dv = w.cross(c.as_dvec3()) + t;
        for k in 0..3 {
            d[k] = (d[k] as f64 - w[k]) as f32;
            d[3 + k] = (d[3 + k] as f64 - dv[k]) as f32;
        }
    }
}

/// A rigid motion of the world, `x ↦ rotation·x + translation` (world units).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RigidMotion {
    /// The turn, about the world origin.
    pub rotation: Mat3,
    /// The move after the turn.
    pub translation: Vec3,
}

impl RigidMotion {
    /// No motion.
    pub const IDENTITY: RigidMotion = RigidMotion {
        rotation: Mat3::IDENTITY,
        translation: Vec3::ZERO,
    };

    /// `camera` carried along with the world: rotation `rotation·R`, center
    /// `rotation·c + translation`.
    pub fn move_camera(&self, camera: &Camera) -> Camera {
        let c2w = Affine3A {
            matrix3: Mat3A::from(self.rotation) * camera.c2w.matrix3,
            translation: (self.rotation * camera.position() + self.translation).into(),
        };
        Camera { c2w, ..*camera }
    }

    /// The motion that undoes this one.
    pub fn inverse(&self) -> RigidMotion {
        let rotation = self.rotation.transpose();
        RigidMotion {
            rotation,
            translation: -(rotation * self.translation),
        }
    }

    /// `self` after `first`.
    fn after(&self, first: &RigidMotion) -> RigidMotion {
        RigidMotion {
            rotation: self.rotation * first.rotation,
            translation: self.rotation * first.translation + self.translation,
        }
    }

    /// Its angle in degrees and how far it moves the point `at` (world units).
    pub fn size(&self, at: Vec3) -> (f64, f64) {
        let angle = rotation_vector(self.rotation.as_dmat3())
            .length()
            .to_degrees();
        let moved = (self.rotation * at + self.translation).distance(at);
        (angle, moved as f64)
    }
}

/// `R_b·R_aᵀ`, the turn from camera `a`'s orientation to `b`'s, in f64.
fn relative_rotation(a: &Camera, b: &Camera) -> glam::DMat3 {
    let ra = Mat3::from(a.c2w.matrix3).as_dmat3();
    let rb = Mat3::from(b.c2w.matrix3).as_dmat3();
    rb * ra.transpose()
}

/// The rotation vector `ω` of a rotation matrix (`rotation(ω) = r`), in f64.
fn rotation_vector(r: glam::DMat3) -> glam::DVec3 {
    let q = glam::DQuat::from_mat3(&r).normalize();
    let q = if q.w < 0.0 { -q } else { q };
    let s = q.xyz().length();
    if s < 1e-12 {
        return q.xyz() * 2.0;
    }
    q.xyz() * (2.0 * s.atan2(q.w) / s)
}

/// The rigid motion of the world that best carries the cameras `cams` onto `truth`,
/// judged by how they see the scene: in least squares over every camera and every
/// point of `points` (world units, where the scene is), the angle by which the point
/// seen from the moved camera is off from where the true camera sees it. It is the
/// *frame* a model trained with `cams` lives in, against the truth's: photos fix
/// cameras only up to such a motion of the scene and every camera together (bundle
/// adjustment's gauge freedom), so a model trained on refined cameras is compared with
/// views from true cameras carried into its frame by the inverse of this. Judged by the
/// views of the scene and not by the poses' six numbers, since a refined camera's error
/// mostly lies where it costs the image least (a turn about the scene against a move).
/// Linear in the motion; three passes, each fitted to what the last left. Identity when
/// there is nothing to fit.
pub fn frame_motion(truth: &[Camera], cams: &[Camera], points: &[Vec3]) -> RigidMotion {
    use glam::{DMat3, DVec3};
    let n = truth.len().min(cams.len());
    let mut motion = RigidMotion::IDENTITY;
    for _ in 0..3 {
        // Normal equations of θ = (w, t): the point x moves by w × x + t = C θ with
        // C = [−[x]×, I]; a camera's own correction moves it by ω × (x − c) + v.
        let mut m = [[0.0f64; 6]; 6];
        let mut rhs = [0.0f64; 6];
        for (cam, t) in cams[..n].iter().zip(truth) {
            let cam = motion.move_camera(cam);
            let omega = rotation_vector(relative_rotation(&cam, t));
            let c = cam.position().as_dvec3();
            let v = t.position().as_dvec3() - c;
            for x in points {
                let x = x.as_dvec3();
                let ray = x - c;
                let d2 = ray.length_squared();
                if !(d2 > 1e-12) {
                    continue;
                }
                // The angle a move of x makes from the camera: (I − r̂ r̂ᵀ)/|x − c|.
                let rh = ray / d2.sqrt();
                let weight = (DMat3::IDENTITY - DMat3::from_cols(rh * rh.x, rh * rh.y, rh * rh.z))
                    * (1.0 / d2);
                let a = weight * (omega.cross(ray) + v);
                // Columns of C: −[x]× (w ↦ w × x) and I.
                let cols: [DVec3; 6] = [
                    DVec3::X.cross(x),
                    DVec3::Y.cross(x),
                    DVec3::Z.cross(x),
                    DVec3::X,
                    DVec3::Y,
                    DVec3::Z,
                ];
                let wc: Vec<DVec3> = cols.iter().map(|&k| weight * k).collect();
                for i in 0..6 {
                    rhs[i] += cols[i].dot(a);
                    for j in 0..6 {
                        m[i][j] += cols[i].dot(wc[j]);
                    }
                }
            }
        }
        let Some(theta) = solve6(m, rhs) else {
            break;
        };
        let step = RigidMotion {
            rotation: rotation(Vec3::new(theta[0] as f32, theta[1] as f32, theta[2] as f32)),
            translation: Vec3::new(theta[3] as f32, theta[4] as f32, theta[5] as f32),
        };
        motion = step.after(&motion);
    }
    motion
}

/// `k³` points evenly filling the box from `lo` to `hi` (corners included; its center
/// alone for `k = 1`): where the scene is, for [`frame_motion`].
pub fn lattice(lo: Vec3, hi: Vec3, k: usize) -> Vec<Vec3> {
    let at = |i: usize| {
        if k > 1 {
            i as f32 / (k - 1) as f32
        } else {
            0.5
        }
    };
    let mut out = Vec::with_capacity(k * k * k);
    for i in 0..k {
        for j in 0..k {
            for l in 0..k {
                out.push(lo + (hi - lo) * Vec3::new(at(i), at(j), at(l)));
            }
        }
    }
    out
}

/// Solves `m·x = b` by Gaussian elimination with partial pivoting; `None` when `m` is
/// singular (a pivot below 1e-12 of the largest entry) or the result is not finite.
fn solve6(mut m: [[f64; 6]; 6], mut b: [f64; 6]) -> Option<[f64; 6]> {
    let scale = m.iter().flatten().fold(0.0f64, |a, v| a.max(v.abs()));
    if !(scale > 0.0) {
        return None;
    }
    for col in 0..6 {
        let p = (col..6).max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))?;
        if !(m[p][col].abs() > 1e-12 * scale) {
            return None;
        }
        m.swap(col, p);
        b.swap(col, p);
        for r in col + 1..6 {
            let f = m[r][col] / m[col][col];
            for k in col..6 {
                m[r][k] -= f * m[col][k];
            }
            b[r] -= f * b[col];
        }
    }
    let mut x = [0.0; 6];
    for r in (0..6).rev() {
        let s: f64 = (r + 1..6).map(|k| m[r][k] * x[k]).sum();
        x[r] = (b[r] - s) / m[r][r];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// The point nearest, in least squares, to every view's optical axis (the line through
/// its camera's `center` along its unit `axis`): where an inward-facing capture looks.
/// `None` when the axes are nearly parallel (a forward-facing capture), where no such
/// point is well defined.
pub(crate) fn focus_point(centers: &[Vec3], axes: &[Vec3]) -> Option<Vec3> {
    use glam::{DMat3, DVec3};
    let mut m = DMat3::ZERO;
    let mut rhs = DVec3::ZERO;
    for (c, f) in centers.iter().zip(axes) {
        let f = f.as_dvec3().normalize_or_zero();
        // I − f fᵀ: the part of a vector across the axis.
        let p = DMat3::IDENTITY - DMat3::from_cols(f * f.x, f * f.y, f * f.z);
        m += p;
        rhs += p * c.as_dvec3();
    }
    // Parallel axes leave m with a null direction: its determinant, relative to the
    // scale n³ of a well-spread capture, tells how far from parallel they are.
    let n = centers.len().min(axes.len()) as f64;
    if n < 2.0 || m.determinant() < 1e-6 * n * n * n {
        return None;
    }
    let g = m.inverse() * rhs;
    g.is_finite().then(|| g.as_vec3())
}

/// The pose corrections of the training views while a model trains, with their Adam
/// state, stepped one view at a time from each view's local gradient (the renderers'
/// `∂L/∂[ε, u]`, module documentation).
///
/// **Pivoted coordinates.** Adam steps each view's correction as `[ω, u]`: a turn `ω`
/// about a *pivot* `p` on the view's axis and a move `u`; the stored correction (turn
/// about the camera's center `c`, then move `v`) is `[ω, u + (exp([ω]×) − I)·(c − p)]`.
/// The pivot is the point of the axis nearest the capture's [`focus_point`]. A turn about
/// the camera's center and a move across the axis shift the image alike, so in the
/// stored coordinates the photos fix their sum well and their difference (the camera
/// orbiting the object it looks at, which only changes the parallax) barely: a badly
/// conditioned pair that Adam, scaling each coordinate alone, cannot separate. About the
/// pivot the two are separate coordinates: the move shifts the image and the turn
/// orbits. With the model held fixed, 8 cameras perturbed by 1.5° come back to 0.012°
/// (voxels) and 0.0049° (splats) where the stored coordinates left 0.14° and 0.034°
/// (the trainers' tests). Trained together with a model, though, the orbit wanders
/// while the model is rough: on lego the pivoted coordinates from the start lost on
/// average over three seeds, and the voxels switch to them half-way instead (the splats
/// never; `TrainOptions::pivot_poses_from`, docs/3d.md). Without a focus point
/// (or with the pivot behind a camera) the pivot is the camera's center, the stored
/// coordinates themselves.
pub(crate) struct Refiner {
    /// The stored corrections, as applied to the cameras.
    deltas: Vec<PoseDelta>,
    /// The optimized coordinates `[ω, u]`.
    params: Vec<PoseDelta>,
    /// `c − p` of each view.
    offsets: Vec<Vec3>,
    /// `p` of each view.
    pivots: Vec<Vec3>,
    moments: Vec<crate::optim::Moments<f32>>,
}

impl Refiner {
    /// Zero corrections, stepped in the stored coordinates, for views whose cameras are
    /// centered at `centers`.
    pub(crate) fn new(centers: &[Vec3]) -> Refiner {
        let n = centers.len();
        Refiner {
            deltas: vec![[0.0; 6]; n],
            params: vec![[0.0; 6]; n],
            offsets: vec![Vec3::ZERO; n],
            pivots: centers.to_vec(),
            moments: Self::fresh_moments(n),
        }
    }

    fn fresh_moments(n: usize) -> Vec<crate::optim::Moments<f32>> {
        let adam = crate::optim::Rule::Adam {
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-15,
        };
        (0..n)
            .map(|_| crate::optim::Moments::new(adam, 6))
            .collect()
    }

    /// Switches to pivoted coordinates, the views' cameras looking along the unit
    /// `axes` (one each), keeping the stored corrections; Adam's moments start afresh.
    /// Without a focus point (or for a view whose pivot would lie behind its camera) the
    /// pivot is the camera's center and the coordinates stay the stored ones.
    pub(crate) fn pivot(&mut self, axes: &[Vec3]) {
        let centers: Vec<Vec3> = self
            .pivots
            .iter()
            .zip(&self.offsets)
            .map(|(&p, &a)| p + a)
            .collect();
        let focus = focus_point(&centers, axes);
        for (v, &c) in centers.iter().enumerate() {
            let a = match (focus, axes.get(v)) {
                (Some(g), Some(f)) => {
                    let f = f.normalize_or_zero();
                    let depth = (g - c).dot(f);
                    if depth > 0.0 { -f * depth } else { Vec3::ZERO }
                }
                _ => Vec3::ZERO,
            };
            self.offsets[v] = a;
            self.pivots[v] = c - a;
            let d = self.deltas[v];
            let u = Vec3::new(d[3], d[4], d[5]) - (rotation(Vec3::new(d[0], d[1], d[2])) * a - a);
            self.params[v] = [d[0], d[1], d[2], u.x, u.y, u.z];
        }
        self.moments = Self::fresh_moments(centers.len());
    }

    /// The iteration of a run of `iterations` at which a trainer switches to pivoted
    /// coordinates when asked to from the fraction `from` of its run (0: from the start;
    /// 1 or more, or not a number: never).
    pub(crate) fn pivot_iteration(from: f32, iterations: usize) -> Option<usize> {
        (from < 1.0).then(|| (from.max(0.0) * iterations as f32) as usize)
    }

    /// The stored corrections, one per view.
    pub(crate) fn deltas(&self) -> &[PoseDelta] {
        &self.deltas
    }

    /// The stored corrections, one per view.
    pub(crate) fn into_deltas(self) -> Vec<PoseDelta> {
        self.deltas
    }

    /// One Adam step of view `view` from its local gradient `local` (`∂L/∂[ε, u]` at its
    /// corrected camera), with rates `[turn (radians), move (world units)]`.
    pub(crate) fn step(&mut self, view: usize, local: &[f64; 6], rates: [f32; 2]) {
        let g = self.gradient(view, local);
        let mut step = self.moments[view].lazy_step();
        for (k, &gk) in g.iter().enumerate() {
            if gk.is_finite() {
                step.apply(k, &mut self.params[view][k], gk, rates[k / 3]);
            }
        }
        self.deltas[view] = self.delta_of(view, &self.params[view]);
    }

    /// The gradient with respect to view `view`'s coordinates `[ω, u]` from the local
    /// gradient `local` at its stored correction. With `v = u + (R(ω) − I)·a`, turning
    /// `ω` by `δ` moves `v` by `(J δ) × (R a)`, so the turn's gradient gains
    /// `Jᵀ·((R a) × ∂L/∂v)`.
    fn gradient(&self, view: usize, local: &[f64; 6]) -> PoseDelta {
        let d = &self.deltas[view];
        let ra = rotation(Vec3::new(d[0], d[1], d[2])) * self.offsets[view];
        let extra = ra
            .as_dvec3()
            .cross(glam::DVec3::new(local[3], local[4], local[5]));
        let mut g = *local;
        for k in 0..3 {
            g[k] += extra[k];
        }
        delta_gradient(d, &g)
    }

    /// The stored correction of view `view` at coordinates `p = [ω, u]`.
    fn delta_of(&self, view: usize, p: &PoseDelta) -> PoseDelta {
        let r = rotation(Vec3::new(p[0], p[1], p[2]));
        let a = self.offsets[view];
        let v = Vec3::new(p[3], p[4], p[5]) + (r * a - a);
        [p[0], p[1], p[2], v.x, v.y, v.z]
    }

    /// Removes the corrections' common rigid motion ([`remove_common_motion`], moves in
    /// units of `scale`), fitted in the optimized coordinates: there a rigid motion of
    /// every camera is a turn `w` and moves `w × pᵢ + t` about the pivots `pᵢ`. Fitting
    /// it in the coordinates Adam steps matters: a push that every view feels alike (the
    /// perturbation's own common part, which the photos ask for and the anchor forbids)
    /// gives every view the same step there, which this removes exactly; fitted in the
    /// stored coordinates instead, part of it stayed after each step and the corrections
    /// drifted away (8 cameras perturbed by 1.5°: 19.8° after 300 steps).
    pub(crate) fn anchor(&mut self, scale: f32) {
        remove_common_motion(&mut self.params, &self.pivots, scale);
        for v in 0..self.params.len() {
            self.deltas[v] = self.delta_of(v, &self.params[v]);
        }
    }
}

/// How far pose `b` is from pose `a`: the angle of `R_b·R_aᵀ` in degrees and the
/// distance between the centers in world units.
/// The angle is that of the rotation vector, in f64 (the arc cosine of the trace, in f32,
/// could not tell angles below about 0.03° from zero).
pub fn pose_error(a: &Camera, b: &Camera) -> (f64, f64) {
    let angle = rotation_vector(relative_rotation(a, b)).length();
    (
        angle.to_degrees(),
        a.position().as_dvec3().distance(b.position().as_dvec3()),
    )
}

/// Moves each view's camera by a random correction of exactly `degrees` of rotation
/// (about a uniformly random axis through the camera's center) and `distance` world
/// units of translation (in a uniformly random direction), drawn from `seed`; returns
/// the corrections applied, in the order of `views`. Used to test pose refinement.
pub fn perturb(views: &mut [View], degrees: f32, distance: f32, seed: u64) -> Vec<PoseDelta> {
    let mut cams: Vec<Camera> = views.iter().map(|v| v.camera).collect();
    let deltas = perturb_cameras(&mut cams, degrees, distance, seed);
    for (v, c) in views.iter_mut().zip(cams) {
        v.camera = c;
    }
    deltas
}

/// [`perturb`] on cameras alone (the same corrections for the same seed).
pub fn perturb_cameras(
    cams: &mut [Camera],
    degrees: f32,
    distance: f32,
    seed: u64,
) -> Vec<PoseDelta> {
    let mut rng = Rng::new(seed ^ 0x5eed_905e);
    let unit = |rng: &mut Rng| loop {
        let p = Vec3::new(rng.uniform(), rng.uniform(), rng.uniform()) * 2.0 - 1.0;
        let l = p.length();
        if l > 1e-3 && l <= 1.0 {
            return p / l;
        }
    };
    cams.iter_mut()
        .map(|c| {
            let w = unit(&mut rng) * degrees.to_radians();
            let t = unit(&mut rng) * distance;
            let delta = [w.x, w.y, w.z, t.x, t.y, t.z];
            *c = apply(c, &delta);
            delta
        })
        .collect()
}

/// The mean pose error ([`pose_error`]) of the cameras `loaded` corrected by `poses`
/// (none past its end) against `truth`.
#[cfg(test)]
pub(crate) fn mean_error(truth: &[Camera], loaded: &[Camera], poses: &[PoseDelta]) -> (f64, f64) {
    let n = truth.len().min(loaded.len()).max(1) as f64;
    let mut sum = (0.0, 0.0);
    for (i, (t, l)) in truth.iter().zip(loaded).enumerate() {
        let cam = poses.get(i).map_or(*l, |d| apply(l, d));
        let (a, d) = pose_error(t, &cam);
        sum = (sum.0 + a / n, sum.1 + d / n);
    }
    sum
}

/// Asserts that a perturbation of `degrees` and `units` gave the mean pose error
/// `before`, and that refinement brought both its parts below `fraction` of that
/// (`after`).
#[cfg(test)]
pub(crate) fn assert_fraction_is_left(
    before: (f64, f64),
    after: (f64, f64),
    degrees: f64,
    units: f64,
    fraction: f64,
) {
    assert!(
        (before.0 - degrees).abs() < 1e-3 && (before.1 - units).abs() < 1e-4,
        "{before:?}"
    );
    assert!(
        after.0 < before.0 * fraction && after.1 < before.1 * fraction,
        "pose error {before:?} → {after:?}"
    );
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> Camera {
        Camera::look_at(Vec3::new(1.0, -2.0, 3.0), Vec3::ZERO, Vec3::Z, 0.8, 8, 6).unwrap()
    }

    #[test]
    fn rotation_is_rodrigues_and_rays_follow_the_camera() {
        let w = Vec3::new(0.1, -0.2, 0.3);
        let r = rotation(w);
        // A rotation fixes its axis and turns by |ω|.
        assert!((r * w - w).length() < 1e-6);
        let x = w.normalize().any_orthonormal_vector();
        assert!((x.dot(r * x) - w.length().cos()).abs() < 1e-5);
        // The corrected camera's rays are the corrected rays of the loaded camera.
        let delta = [0.1, -0.2, 0.3, 0.5, 0.25, -1.0];
        let (c0, c1) = (cam(), apply(&cam(), &delta));
        c1.validate().unwrap();
        let v = Vec3::new(delta[3], delta[4], delta[5]);
        for (a, b) in c0.rays().iter().zip(c1.rays()) {
            let moved = apply_to_ray(a, &r, v);
            assert!((moved.origin - b.origin).length() < 1e-5);
            assert!((moved.dir - b.dir).length() < 1e-5);
        }
        let (angle, dist) = pose_error(&c0, &c1);
        assert!(
            (angle - (w.length() as f64).to_degrees()).abs() < 1e-3,
            "{angle}"
        );
        assert!((dist - v.length() as f64).abs() < 1e-5);
    }

    /// `delta_gradient` against central differences: for `L(ω) = a·(exp(ω)·b)`, the local
    /// gradient at `ω` is `(exp(ω)·b) × a` (rotating by `ε` on top moves `x` by `ε × x`).
    #[test]
    fn delta_gradient_matches_central_differences() {
        let (a, b) = (Vec3::new(0.3, -1.1, 0.7), Vec3::new(0.9, 0.4, -0.5));
        for omega in [Vec3::new(0.4, -0.7, 1.2), Vec3::new(1e-6, 0.0, 2e-6)] {
            let f = |w: Vec3| -> f64 {
                let x = rotation(w) * b;
                (a.x as f64) * x.x as f64 + (a.y as f64) * x.y as f64 + (a.z as f64) * x.z as f64
            };
            let x = rotation(omega) * b;
            let local = x.cross(a);
            let delta = [omega.x, omega.y, omega.z, 0.0, 0.0, 0.0];
            let g = delta_gradient(
                &delta,
                &[
                    local.x as f64,
                    local.y as f64,
                    local.z as f64,
                    1.0,
                    2.0,
                    3.0,
                ],
            );
            assert_eq!(&g[3..], &[1.0, 2.0, 3.0]);
            let h = 1e-3f32;
            for k in 0..3 {
                let mut e = Vec3::ZERO;
                e[k] = h;
                let fd = (f(omega + e) - f(omega - e)) / (2.0 * h as f64);
                assert!(
                    (fd - g[k] as f64).abs() < 1e-3,
                    "ω {omega}, {k}: {} vs {fd}",
                    g[k]
                );
            }
        }
    }

    /// A common motion of every camera is removed entirely; what is left has none (a
    /// second pass changes nothing), and a motion that differs between the cameras is
    /// kept but for its common part.
    #[test]
    fn common_motion_is_removed() {
        let centers: Vec<Vec3> = (0..12)
            .map(|i| {
                let a = i as f32 * 0.7;
                Vec3::new(4.0 * a.cos(), 4.0 * a.sin(), 1.0 + 0.3 * i as f32)
            })
            .collect();
        let (w, t) = (Vec3::new(0.01, -0.02, 0.005), Vec3::new(0.03, 0.01, -0.02));
        let common = |c: Vec3| {
            let v = w.cross(c) + t;
            [w.x, w.y, w.z, v.x, v.y, v.z]
        };
        let mut deltas: Vec<PoseDelta> = centers.iter().map(|&c| common(c)).collect();
        remove_common_motion(&mut deltas, &centers, 4.0);
        for d in &deltas {
            assert!(d.iter().all(|x| x.abs() < 1e-6), "{d:?}");
        }
        // Own motions plus the common one: the common part goes, a second pass is a no-op.
        let mut rng = Rng::new(7);
        let own: Vec<PoseDelta> = centers
            .iter()
            .map(|_| std::array::from_fn(|_| (rng.uniform() - 0.5) * 0.02))
            .collect();
        let mut mixed: Vec<PoseDelta> = own
            .iter()
            .zip(&centers)
            .map(|(o, &c)| std::array::from_fn(|k| o[k] + common(c)[k]))
            .collect();
        let mut alone = own.clone();
        remove_common_motion(&mut mixed, &centers, 4.0);
        remove_common_motion(&mut alone, &centers, 4.0);
        let once = mixed.clone();
        remove_common_motion(&mut mixed, &centers, 4.0);
        for ((a, b), c) in mixed.iter().zip(&once).zip(&alone) {
            for k in 0..6 {
                assert!((a[k] - b[k]).abs() < 1e-6 && (b[k] - c[k]).abs() < 1e-6);
            }
        }
        assert!(alone.iter().flatten().any(|x| x.abs() > 1e-3));
    }

    /// Cameras around a point looking at it: the focus point is that point; parallel
    /// axes have none.
    #[test]
    fn focus_point_is_where_the_cameras_look() {
        let target = Vec3::new(0.3, -0.2, 0.5);
        let cams: Vec<Camera> = (0..7)
            .map(|i| {
                let a = i as f32 * 0.9;
                let eye = target + Vec3::new(4.0 * a.cos(), 4.0 * a.sin(), 1.0 + 0.2 * i as f32);
                Camera::look_at(eye, target, Vec3::Z, 0.8, 8, 6).unwrap()
            })
            .collect();
        let centers: Vec<Vec3> = cams.iter().map(|c| c.position()).collect();
        let axes: Vec<Vec3> = cams.iter().map(|c| c.forward()).collect();
        let g = focus_point(&centers, &axes).unwrap();
        assert!((g - target).length() < 1e-4, "{g}");
        let parallel = vec![Vec3::Y; centers.len()];
        assert!(focus_point(&centers, &parallel).is_none());
        assert!(focus_point(&centers[..1], &axes[..1]).is_none());
    }

    /// The pivoted coordinates' gradient against central differences of a loss of the
    /// corrected camera, `L = Σ q_k · (camera-to-world of p_k)`, whose local gradient is
    /// `(Σ (R p_k) × q_k, Σ q_k)`; and a pivot at the camera's center (no focus point)
    /// leaves the coordinates the stored ones.
    #[test]
    fn pivoted_gradient_matches_central_differences() {
        let cams: Vec<Camera> = (0..5)
            .map(|i| {
                let a = i as f32 * 1.3;
                let eye = Vec3::new(4.0 * a.cos(), 4.0 * a.sin(), 1.0);
                Camera::look_at(eye, Vec3::ZERO, Vec3::Z, 0.8, 8, 6).unwrap()
            })
            .collect();
        let centers: Vec<Vec3> = cams.iter().map(|c| c.position()).collect();
        let axes: Vec<Vec3> = cams.iter().map(|c| c.forward()).collect();
        let pts = [Vec3::new(0.2, -0.1, -3.0), Vec3::new(-0.4, 0.3, -4.5)];
        let qs = [Vec3::new(0.7, -0.2, 0.4), Vec3::new(-0.3, 0.9, 0.1)];
        let loss = |cam: &Camera| -> f64 {
            pts.iter()
                .zip(&qs)
                .map(|(p, q)| cam.c2w.transform_point3(*p).dot(*q) as f64)
                .sum()
        };
        let mut r = Refiner::new(&centers);
        r.pivot(&axes);
        assert!(r.pivots.iter().all(|p| p.length() < 1e-4), "{:?}", r.pivots);
        let view = 2;
        let p: PoseDelta = [0.02, -0.03, 0.015, 0.05, -0.02, 0.03];
        r.params[view] = p;
        r.deltas[view] = r.delta_of(view, &p);
        let cam = apply(&cams[view], &r.deltas[view]);
        let rm = Mat3::from(cam.c2w.matrix3);
        let mut local = [0.0f64; 6];
        for (pk, qk) in pts.iter().zip(&qs) {
            let ge = (rm * *pk).cross(*qk);
            for k in 0..3 {
                local[k] += ge[k] as f64;
                local[3 + k] += qk[k] as f64;
            }
        }
        let g = r.gradient(view, &local);
        let h = 1e-3f32;
        for k in 0..6 {
            let (mut a, mut b) = (p, p);
            a[k] += h;
            b[k] -= h;
            let la = loss(&apply(&cams[view], &r.delta_of(view, &a)));
            let lb = loss(&apply(&cams[view], &r.delta_of(view, &b)));
            let fd = (la - lb) / (2.0 * h as f64);
            assert!(
                (fd - g[k] as f64).abs() < 2e-3 * (1.0 + fd.abs()),
                "{k}: {} vs {fd}",
                g[k]
            );
        }
        // Unpivoted: the coordinates are the stored correction.
        let mut plain = Refiner::new(&centers);
        plain.step(view, &local, [1e-3, 1e-3]);
        assert_eq!(plain.params[view], plain.deltas[view]);
        assert_ne!(plain.deltas[view], [0.0; 6]);
        // Switching to pivoted coordinates keeps the stored corrections.
        let before = plain.deltas.clone();
        plain.pivot(&axes);
        assert_eq!(plain.deltas, before);
        for (v, d) in before.iter().enumerate() {
            let back = plain.delta_of(v, &plain.params[v]);
            assert!(
                (0..6).all(|k| (back[k] - d[k]).abs() < 1e-6),
                "{back:?} vs {d:?}"
            );
        }
        assert_ne!(plain.params[view], plain.deltas[view]);
        assert_eq!(Refiner::pivot_iteration(0.5, 3000), Some(1500));
        assert_eq!(Refiner::pivot_iteration(-1.0, 3000), Some(0));
        assert_eq!(Refiner::pivot_iteration(1.0, 3000), None);
        assert_eq!(Refiner::pivot_iteration(f32::NAN, 3000), None);
    }

    /// Cameras on a ring around the origin, looking at it.
    fn ring(n: usize) -> Vec<Camera> {
        (0..n)
            .map(|i| {
                let a = i as f32 * std::f32::consts::TAU / n as f32;
                let eye = Vec3::new(4.0 * a.cos(), 4.0 * a.sin(), 1.0 + 0.3 * (3.0 * a).sin());
                Camera::look_at(eye, Vec3::ZERO, Vec3::Z, 0.8, 32, 24).unwrap()
            })
            .collect()
    }

    /// A 3×3×3 lattice of points filling the cube of side 2 about the origin.
    fn box_points() -> Vec<Vec3> {
        lattice(Vec3::splat(-1.0), Vec3::ONE, 3)
    }

    #[test]
    fn frame_motion_finds_the_scene_s_motion() {
        let truth = ring(12);
        let g = RigidMotion {
            rotation: rotation(Vec3::new(0.02, -0.03, 0.05)),
            translation: Vec3::new(0.1, -0.05, 0.2),
        };
        // Cameras carried by `g` alone: the frame is `g`'s inverse, to f32 round-off, and
        // nothing is left in it.
        let moved: Vec<Camera> = truth.iter().map(|c| g.move_camera(c)).collect();
        let f = frame_motion(&truth, &moved, &box_points());
        let back = f.after(&g);
        let (angle, dist) = back.size(Vec3::new(0.0, 0.0, 1.0));
        assert!(angle < 1e-4 && dist < 1e-5, "{angle} {dist}");
        let (ga, gd) = g.size(Vec3::ZERO);
        let (fa, fd) = f.size(Vec3::ZERO);
        assert!(
            (ga - fa).abs() < 1e-4 && (gd - fd).abs() < 1e-5,
            "{ga} {fa} {gd} {fd}"
        );
        for (t, c) in truth.iter().zip(&moved) {
            let (a, d) = pose_error(t, &f.move_camera(c));
            assert!(a < 1e-3 && d < 1e-5, "{a} {d}");
        }
        // With each camera also perturbed on its own, the frame removes the common part
        // only: the per-view errors left are about the perturbation's size, less than
        // with the motion.
        let mut noisy = moved.clone();
        perturb_cameras(&mut noisy, 0.2, 0.01, 5);
        let f = frame_motion(&truth, &noisy, &box_points());
        let mean = |cams: &[Camera]| {
            truth
                .iter()
                .zip(cams)
                .map(|(t, c)| pose_error(t, c).0)
                .sum::<f64>()
                / 12.0
        };
        let before = mean(&noisy);
        let in_frame: Vec<Camera> = noisy.iter().map(|c| f.move_camera(c)).collect();
        let after = mean(&in_frame);
        assert!(before > 1.5 && after < 0.25, "{before} {after}");
        let (angle, _) = f.after(&g).size(Vec3::ZERO);
        assert!(angle < 0.2, "{angle}");
    }

    #[test]
    fn perturbation_has_the_asked_size() {
        let c = cam();
        let mut views: Vec<View> = (0..5)
            .map(|i| View {
                name: format!("v{i}"),
                camera: c,
                width: c.width,
                height: c.height,
                rgb: vec![[0.0; 3]; (c.width * c.height) as usize],
            })
            .collect();
        let deltas = perturb(&mut views, 0.5, 0.02, 3);
        assert_eq!(deltas.len(), 5);
        assert_ne!(deltas[0], deltas[1]);
        for v in &views {
            let (angle, dist) = pose_error(&c, &v.camera);
            assert!((angle - 0.5).abs() < 1e-2, "{angle}");
            assert!((dist - 0.02).abs() < 1e-5, "{dist}");
        }
    }
}
