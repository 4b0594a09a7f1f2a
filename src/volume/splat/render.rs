//! The forward renderer of 3D Gaussian splatting on the CPU: EWA projection, 16 × 16
//! tiles, front-to-back alpha blending (Kerbl et al. 2023, as the reference CUDA code
//! and gsplat do it).
//!
//! [`render`] projects every Gaussian to the image ([`RenderSettings::near`] culls
//! those too close or behind the camera), bins the projected ellipses into
//! [`TILE`] × [`TILE`] pixel tiles, sorts each tile's list by depth (ties by Gaussian
//! index, so the result never depends on scheduling) and blends each pixel front to
//! back. Tiles run in parallel; each pixel is computed by exactly one job, so the image
//! is the same bits for any number of threads.
//!
//! Conventions are those of [`crate::volume`]: the camera looks down its −Z axis (depth
//! is `−z` in camera coordinates, world units), pixel `(x, y)` is centered at
//! `(x + 0.5, y + 0.5)` with y down, images are row-major. **Lens distortion is not
//! modeled**: the projection is a pinhole's, so [`render`] refuses a camera with
//! distortion; undistort such photos first.
//!
//! ```
//! use diffsvg::glam::{Affine3A, Vec3};
//! use diffsvg::volume::camera::Camera;
//! use diffsvg::volume::splat::{Gaussians, RenderSettings, render};
//! // One grey Gaussian 4 units in front of a 32 × 24 camera at the origin.
//! let mut g = Gaussians::new(0);
//! g.push([0.0, 0.0, -4.0], [-0.7; 3], [1.0, 0.0, 0.0, 0.0], 4.0, &[0.0; 3]);
//! let cam = Camera::from_fov_x(32, 24, 1.0, Affine3A::IDENTITY).unwrap();
//! let settings = RenderSettings { background: [0.0, 0.0, 1.0], ..Default::default() };
//! let out = render(&g, &cam, &settings).unwrap();
//! assert_eq!(out.rgb.len(), 32 * 24);
//! let center = out.rgb[12 * 32 + 16];
//! // Nearly opaque grey (SH 0 gives 0.5) over the blue background.
//! assert!(center[1] > 0.45 && center[2] < 0.55, "{center:?}");
//! assert_eq!(out.rgb[0], [0.0, 0.0, 1.0]); // the corner shows the background
//! assert_eq!(out.transmittance[0], 1.0);
//! ```

use glam::{Mat3, Vec2, Vec3};
use rayon::prelude::*;

use wide::f32x8;

use super::Gaussians;
use super::kernel::{BlendRow, blend_row, lane};
use crate::limits::MAX_SPLAT_TILE_PAIRS;
use crate::volume::camera::Camera;

/// Side of a screen tile, pixels.
pub const TILE: u32 = 16;

/// Largest opacity of one Gaussian at one pixel (the reference code's 0.99), so that
/// transmittance never reaches zero through a single splat.
pub(crate) const MAX_ALPHA: f32 = 0.99;

/// Contributions below this opacity (1/255) are skipped, as in the reference code.
pub(crate) const MIN_ALPHA: f32 = 1.0 / 255.0;

/// Projected x and y are clamped to this many times the half-frustum when computing the
/// perspective Jacobian (the reference code's 1.3), keeping it bounded near the border.
const FRUSTUM_CLAMP: f32 = 1.3;

/// Settings of [`render`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Linear RGB seen where the Gaussians leave the pixel transparent.
    pub background: [f32; 3],
    /// Gaussians whose center has depth (distance along the viewing axis, world units)
    /// at most this are culled. Default 0.01.
    pub near: f32,
    /// A pixel stops blending once its transmittance would fall below this; the Gaussian
    /// that would take it there is not blended (as in the reference code). Default 1e-4.
    pub early_stop: f32,
    /// Variance added to both diagonal entries of every projected 2D covariance,
    /// pixels² (a low-pass filter so a splat covers at least about a pixel). Default 0.3.
    pub dilation: f32,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            background: [0.0; 3],
            near: 0.01,
            early_stop: 1e-4,
            dilation: 0.3,
        }
    }
}

impl RenderSettings {
    fn validate(&self) -> Result<(), String> {
        if !self.background.iter().all(|v| v.is_finite()) {
            return Err("render settings: background is not finite".into());
        }
        if !(self.near.is_finite() && self.near > 0.0) {
            return Err(format!("render settings: near {} is not > 0", self.near));
        }
        if !(0.0..1.0).contains(&self.early_stop) {
            return Err(format!(
                "render settings: early_stop {} is not in [0, 1)",
                self.early_stop
            ));
        }
        if !(self.dilation.is_finite() && self.dilation >= 0.0) {
            return Err(format!(
                "render settings: dilation {} is not ≥ 0",
                self.dilation
            ));
        }
        Ok(())
    }
}

/// One Gaussian as projected to the image (what the blending and, later, the backward
/// pass need).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Projected {
    /// Index of the Gaussian in the model.
    pub index: u32,
    /// Center, continuous pixel coordinates (pixel `(x, y)` spans `[x, x + 1)`).
    pub mean2d: Vec2,
    /// Inverse of the dilated 2D covariance `[[a, b], [b, c]]`, stored `[a, b, c]`, 1/px².
    pub conic: [f32; 3],
    /// Depth of the center along the viewing axis, world units (> `near`).
    pub depth: f32,
    /// Screen radius, pixels: `ceil(√(2·ln(255·opacity)·λ))` with `λ` the larger
    /// eigenvalue of the 2D covariance, beyond which the splat's opacity is below 1/255.
    pub radius: f32,
    /// Half-width and half-height of the bounding box of that contour, pixels (rounded
    /// up): the screen box used for binning.
    pub extent: Vec2,
    /// `2·ln(255·opacity)`: the contour where the opacity falls to 1/255 is the conic's
    /// quadratic form `a·dx² + 2b·dx·dy + c·dy²` equal to this.
    pub reach: f32,
    /// Linear RGB seen along the direction from the camera center to the mean.
    pub color: Vec3,
    /// Peak opacity as blended: `sigmoid(logit)`, times [`compensation`](Self::compensation).
    pub opacity: f32,
    /// The anti-aliasing factor `√(det Σ / det(Σ + s·I))` of an
    /// [antialiased](Gaussians::antialiased) model (`Σ` the 2D covariance before the
    /// dilation `s`), 1 otherwise.
    pub compensation: f32,
}

/// The result of [`render`].
#[derive(Clone, Debug)]
pub struct Rendered {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Linear RGB per pixel, row-major with y down (`index = y · width + x`), composited
    /// over the background (the layout of `dataset::View::rgb`).
    pub rgb: Vec<[f32; 3]>,
    /// Final transmittance per pixel (same layout): the fraction of the background that
    /// shows through, in `[0, 1]`.
    pub transmittance: Vec<f32>,
    /// The Gaussians that survived culling, in model order (for the backward pass).
    pub(crate) projected: Vec<Projected>,
    /// Their tile lists.
    pub(crate) bins: Bins,
    /// Per pixel, how many entries of its tile's list blending visited.
    pub(crate) ends: Vec<u32>,
}

impl Rendered {
    /// Number of Gaussians that survived culling: in front of the camera (beyond
    /// [`RenderSettings::near`]), not degenerate, and overlapping the image.
    pub fn visible(&self) -> usize {
        self.projected.len()
    }

    /// The depth images of this rendering ([`Depth`]): the same splats, opacities and
    /// blending order as the colors, with each splat's depth (its center's distance along
    /// the viewing axis) in place of its color.
    pub fn depth(&self) -> Depth {
        let (w, h) = (self.width as usize, self.height as usize);
        let mut expected = vec![0.0f32; w * h];
        let mut median = vec![0.0f32; w * h];
        let n_tiles = self.bins.tiles_x as usize * self.bins.tiles_y as usize;
        let tiles: Vec<Vec<(usize, f32, f32)>> = (0..n_tiles)
            .into_par_iter()
            .map(|t| {
                let list = &self.bins.ids[self.bins.offsets[t]..self.bins.offsets[t + 1]];
                let (x0, x1, y0, y1) = tile_pixels(t, &self.bins, w, h);
                let mut out = Vec::with_capacity((x1 - x0) * (y1 - y0));
                for y in y0..y1 {
                    for x in x0..x1 {
                        let i = y * w + x;
                        let end = self.ends[i] as usize;
                        let (mut t, mut sum, mut med) = (1.0f32, 0.0f32, 0.0f32);
                        for &id in &list[..end] {
                            let p = &self.projected[id as usize];
                            let dx = x as f32 + 0.5 - p.mean2d.x;
                            let dy = y as f32 + 0.5 - p.mean2d.y;
                            let (alpha, counts) = super::kernel::alpha1(p, dx, dy);
                            if !counts {
                                continue;
                            }
                            sum += alpha * t * p.depth;
                            t *= 1.0 - alpha;
                            if med == 0.0 && t <= 0.5 {
                                med = p.depth;
                            }
                        }
                        let covered = 1.0 - t;
                        let ed = if covered > 0.0 { sum / covered } else { 0.0 };
                        out.push((i, ed, med));
                    }
                }
                out
            })
            .collect();
        for (i, ed, med) in tiles.into_iter().flatten() {
            expected[i] = ed;
            median[i] = med;
        }
        Depth {
            width: self.width,
            height: self.height,
            expected,
            median,
            opacity: self.transmittance.iter().map(|t| 1.0 - t).collect(),
        }
    }
}

/// Depth images of a splat rendering ([`Rendered::depth`]). Depths are distances along
/// the camera's viewing axis (`−z` in camera coordinates, not along the ray), world
/// units; 0 where a pixel has none. Row-major with y down, like [`Rendered::rgb`].
#[derive(Clone, Debug, PartialEq)]
pub struct Depth {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Expected depth: `Σ wᵢ·zᵢ / Σ wᵢ` over the splats blended at the pixel, with
    /// `wᵢ = αᵢ·Tᵢ` their blending weights and `zᵢ` their centers' depths (normalized by
    /// the accumulated opacity, gsplat's "ED"); 0 where nothing was blended.
    pub expected: Vec<f32>,
    /// Median depth: the depth of the splat with which the accumulated opacity
    /// `1 − T` reaches 0.5 (front to back); 0 where it never does.
    pub median: Vec<f32>,
    /// Accumulated opacity `1 − T`, in `[0, 1]`.
    pub opacity: Vec<f32>,
}

/// Renders `gaussians` seen by `camera` (see the module documentation).
///
/// # Errors
/// If the model or the settings are invalid ([`Gaussians::validate`]), the camera has
/// lens distortion, there are more than `u32::MAX` Gaussians, or the projected splats
/// would cover more than [`MAX_SPLAT_TILE_PAIRS`] (tile, Gaussian) pairs.
pub fn render(
    gaussians: &Gaussians,
    camera: &Camera,
    settings: &RenderSettings,
) -> Result<Rendered, String> {
    render_limited(gaussians, camera, settings, MAX_SPLAT_TILE_PAIRS)
}

fn render_limited(
    gaussians: &Gaussians,
    camera: &Camera,
    settings: &RenderSettings,
    max_pairs: u64,
) -> Result<Rendered, String> {
    gaussians.validate()?;
    settings.validate()?;
    if camera.has_distortion() {
        return Err(
            "splat rendering models a pinhole camera: undistort the photos and use a camera \
             without distortion"
                .into(),
        );
    }
    if gaussians.len() > u32::MAX as usize {
        return Err(format!("{} Gaussians: more than 2³² − 1", gaussians.len()));
    }
    let projected = project(gaussians, camera, settings);
    let bins = bin(&projected, camera.width, camera.height, max_pairs)?;
    let blended = rasterize(&projected, &bins, camera, settings);
    Ok(Rendered {
        width: camera.width,
        height: camera.height,
        rgb: blended.rgb,
        transmittance: blended.transmittance,
        projected,
        bins,
        ends: blended.ends,
    })
}

/// The pinhole camera of one view in the form projection needs: world to OpenCV camera
/// axes (x right, y down, z forward) and intrinsics. Shared by the forward and backward
/// passes, so both see the same numbers.
pub(crate) struct Pinhole {
    /// World to OpenCV camera rotation.
    pub rot: Mat3,
    /// World to OpenCV camera translation.
    pub trans: Vec3,
    /// Camera center, world units.
    pub origin: Vec3,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
    /// Image size, pixels.
    pub w: f32,
    pub h: f32,
    /// Clamp bounds of x/z and y/z for the Jacobian.
    lx: (f32, f32),
    ly: (f32, f32),
    near: f32,
    /// [`RenderSettings::dilation`], pixels².
    pub dilation: f32,
}

/// What projecting one Gaussian computes (before culling by screen bounds), kept for the
/// backward pass.
pub(crate) struct Geometry {
    /// Mean in OpenCV camera axes.
    pub p: Vec3,
    /// Whether x/z and y/z were inside the clamp bounds (the Jacobian depends on x and y
    /// only then).
    pub inside: (bool, bool),
    /// `x/z` and `y/z`, clamped.
    pub u: Vec2,
    /// Rows of the perspective Jacobian.
    pub j0: Vec3,
    pub j1: Vec3,
    /// `R·S` (world axes): the covariance is `M·Mᵀ`.
    pub m: Mat3,
    /// The covariance in camera axes.
    pub cov: Mat3,
    /// The dilated 2D covariance `[[a, b], [b, c]]`.
    pub abc: [f32; 3],
}

impl Pinhole {
    pub(crate) fn new(camera: &Camera, settings: &RenderSettings) -> Pinhole {
        let w2c = camera.c2w.inverse();
        // World to OpenCV camera axes: flip y and z of OpenGL's.
        let flip = Mat3::from_diagonal(Vec3::new(1.0, -1.0, -1.0));
        let (w, h) = (camera.width as f32, camera.height as f32);
        let (fx, fy, cx, cy) = (camera.fx, camera.fy, camera.cx, camera.cy);
        // Frustum bounds on x/z and y/z, widened by 0.3 half-fields as in gsplat (the
        // reference's ±1.3·tan(fov/2) when the principal point is centered).
        let margin = FRUSTUM_CLAMP - 1.0;
        let (tan_x, tan_y) = (0.5 * w / fx, 0.5 * h / fy);
        Pinhole {
            rot: flip * Mat3::from(w2c.matrix3),
            trans: flip * Vec3::from(w2c.translation),
            origin: camera.position(),
            fx,
            fy,
            cx,
            cy,
            w,
            h,
            lx: (-cx / fx - margin * tan_x, (w - cx) / fx + margin * tan_x),
            ly: (-cy / fy - margin * tan_y, (h - cy) / fy + margin * tan_y),
            near: settings.near,
            dilation: settings.dilation,
        }
    }

    /// The projection of Gaussian `i`, or `None` when its center is not beyond the near
    /// plane.
    pub(crate) fn geometry(&self, gaussians: &Gaussians, i: usize) -> Option<Geometry> {
        let mean = Vec3::from_array(gaussians.means[i]);
        let p = self.rot * mean + self.trans;
        let z = p.z;
        if !(z > self.near && z.is_finite()) {
            return None;
        }
        let (ux, uy) = (p.x / z, p.y / z);
        let u = Vec2::new(
            ux.clamp(self.lx.0, self.lx.1),
            uy.clamp(self.ly.0, self.ly.1),
        );
        let inside = (u.x == ux, u.y == uy);
        let (fx, fy) = (self.fx, self.fy);
        // Rows of the perspective Jacobian at the (clamped) center.
        let j0 = Vec3::new(fx / z, 0.0, -fx * u.x / z);
        let j1 = Vec3::new(0.0, fy / z, -fy * u.y / z);
        // Σ = R S Sᵀ Rᵀ in world axes, then W Σ Wᵀ in camera axes.
        let m = Mat3::from_quat(gaussians.rotation(i)) * Mat3::from_diagonal(gaussians.scale(i));
        let cov = self.rot * (m * m.transpose()) * self.rot.transpose();
        let a = j0.dot(cov * j0) + self.dilation;
        let b = j0.dot(cov * j1);
        let c = j1.dot(cov * j1) + self.dilation;
        Some(Geometry {
            p,
            inside,
            u,
            j0,
            j1,
            m,
            cov,
            abc: [a, b, c],
        })
    }

    /// The projected center of a Gaussian at camera-axes point `p`, pixels.
    pub(crate) fn center(&self, p: Vec3) -> Vec2 {
        Vec2::new(self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy)
    }
}

/// Projects every Gaussian, dropping those culled (behind `near`, degenerate, not
/// finite, or wholly off screen); the result is in model order.
pub(crate) fn project(
    gaussians: &Gaussians,
    camera: &Camera,
    settings: &RenderSettings,
) -> Vec<Projected> {
    let cam = Pinhole::new(camera, settings);
    (0..gaussians.len())
        .into_par_iter()
        .filter_map(|i| {
            let geo = cam.geometry(gaussians, i)?;
            let [a, b, c] = geo.abc;
            let det = a * c - b * b;
            if !(det > 0.0 && det.is_finite()) {
                return None;
            }
            let mid = 0.5 * (a + c);
            let lambda = mid + (mid * mid - det).max(0.1).sqrt();
            let compensation = if gaussians.antialiased {
                compensation(geo.abc, cam.dilation)
            } else {
                1.0
            };
            // Opacity-aware bound: beyond √(2·ln(255·o)·λ) pixels from the center the
            // opacity is below 1/255 in every direction, so nothing there is blended.
            let opacity = gaussians.opacity(i) * compensation;
            if !(opacity >= MIN_ALPHA) {
                return None;
            }
            let reach = 2.0 * (opacity / MIN_ALPHA).ln();
            let radius = (reach * lambda).sqrt().ceil();
            // The same contour's bounding box, per axis: √(reach·Σxx) and √(reach·Σyy)
            // (tighter than the radius for elongated splats).
            let extent = Vec2::new((reach * a).sqrt().ceil(), (reach * c).sqrt().ceil());
            let mean2d = cam.center(geo.p);
            if !(radius > 0.0 && radius.is_finite() && mean2d.is_finite()) {
                return None;
            }
            if mean2d.x + extent.x <= 0.0
                || mean2d.x - extent.x >= cam.w
                || mean2d.y + extent.y <= 0.0
                || mean2d.y - extent.y >= cam.h
            {
                return None;
            }
            let conic = [c / det, -b / det, a / det];
            if !conic.iter().all(|v| v.is_finite()) {
                return None;
            }
            let mean = Vec3::from_array(gaussians.means[i]);
            Some(Projected {
                index: i as u32,
                mean2d,
                conic,
                depth: geo.p.z,
                radius,
                extent,
                reach,
                color: gaussians.color(i, (mean - cam.origin).normalize()),
                opacity,
                compensation,
            })
        })
        .collect()
}

/// The anti-aliasing factor of Mip-Splatting's 2D filter (gsplat's `antialiased`
/// mode): `√(det Σ / det(Σ + s·I))`, with `[a, b, c]` the entries of the dilated
/// covariance `Σ + s·I` and `s` the dilation, pixels². A splat much larger than a pixel
/// keeps its opacity (the factor tends to 1); one much smaller than a pixel is spread
/// over about a pixel by the dilation and dimmed by this factor, so that its total
/// weight `opacity × area` stays what it was, at any resolution. 0 for a degenerate
/// (non-positive) `Σ`.
pub(crate) fn compensation([a, b, c]: [f32; 3], dilation: f32) -> f32 {
    let det = a * c - b * b;
    let det0 = (a - dilation) * (c - dilation) - b * b;
    (det0 / det).max(0.0).sqrt()
}

/// Per-tile lists of projected Gaussians (indices into the projected array), each
/// sorted front to back.
#[derive(Clone, Debug)]
pub(crate) struct Bins {
    /// Tiles across and down.
    pub tiles_x: u32,
    pub tiles_y: u32,
    /// Tile `t`'s list is `ids[offsets[t]..offsets[t + 1]]`, tiles row-major.
    pub offsets: Vec<usize>,
    pub ids: Vec<u32>,
}

/// The tiles `[x0, x1) × [y0, y1)` that a splat's screen box overlaps.
fn tile_box(p: &Projected, tiles_x: u32, tiles_y: u32) -> (u32, u32, u32, u32) {
    let t = TILE as f32;
    let span = |lo: f32, hi: f32, n: u32| {
        let a = (lo / t).floor().clamp(0.0, n as f32) as u32;
        let b = (hi / t).ceil().clamp(0.0, n as f32) as u32;
        (a, b.max(a))
    };
    let (x0, x1) = span(p.mean2d.x - p.extent.x, p.mean2d.x + p.extent.x, tiles_x);
    let (y0, y1) = span(p.mean2d.y - p.extent.y, p.mean2d.y + p.extent.y, tiles_y);
    (x0, x1, y0, y1)
}

/// Bins the splats into tiles and sorts each tile by depth, ties by Gaussian index;
/// refuses more than `max_pairs` (tile, Gaussian) pairs before allocating them.
pub(crate) fn bin(
    projected: &[Projected],
    width: u32,
    height: u32,
    max_pairs: u64,
) -> Result<Bins, String> {
    let tiles_x = width.div_ceil(TILE);
    let tiles_y = height.div_ceil(TILE);
    let n_tiles = tiles_x as usize * tiles_y as usize;
    let mut counts = vec![0usize; n_tiles + 1];
    let mut pairs = 0u64;
    for p in projected {
        let (x0, x1, y0, y1) = tile_box(p, tiles_x, tiles_y);
        pairs += (x1 - x0) as u64 * (y1 - y0) as u64;
    }
    if pairs > max_pairs {
        return Err(format!(
            "the splats cover {pairs} (tile, Gaussian) pairs, above the limit of {max_pairs} \
             (limits::MAX_SPLAT_TILE_PAIRS): render smaller or with fewer or smaller Gaussians"
        ));
    }
    for p in projected {
        let (x0, x1, y0, y1) = tile_box(p, tiles_x, tiles_y);
        for ty in y0..y1 {
            for tx in x0..x1 {
                counts[ty as usize * tiles_x as usize + tx as usize + 1] += 1;
            }
        }
    }
    for t in 0..n_tiles {
        counts[t + 1] += counts[t];
    }
    let offsets = counts;
    let mut cursor = offsets.clone();
    let mut ids = vec![0u32; pairs as usize];
    for (k, p) in projected.iter().enumerate() {
        let (x0, x1, y0, y1) = tile_box(p, tiles_x, tiles_y);
        for ty in y0..y1 {
            for tx in x0..x1 {
                let t = ty as usize * tiles_x as usize + tx as usize;
                ids[cursor[t]] = k as u32;
                cursor[t] += 1;
            }
        }
    }
    // Split into the tiles' slices, then sort each in parallel. Ids are unique within a
    // tile and in model order, so (depth, id) is a total order: deterministic.
    let mut slices = Vec::with_capacity(n_tiles);
    let mut rest = ids.as_mut_slice();
    for t in 0..n_tiles {
        let (head, tail) = rest.split_at_mut(offsets[t + 1] - offsets[t]);
        slices.push(head);
        rest = tail;
    }
    slices.par_iter_mut().for_each(|s| {
        s.sort_unstable_by(|&a, &b| {
            let (pa, pb) = (&projected[a as usize], &projected[b as usize]);
            pa.depth.total_cmp(&pb.depth).then(a.cmp(&b))
        })
    });
    Ok(Bins {
        tiles_x,
        tiles_y,
        offsets,
        ids,
    })
}

/// What blending leaves for the backward pass: the image, the final transmittance and,
/// per pixel, how many entries of its tile's list were visited.
pub(crate) struct Blended {
    pub rgb: Vec<[f32; 3]>,
    pub transmittance: Vec<f32>,
    pub ends: Vec<u32>,
}

/// The pixels `[x0, x1) × [y0, y1)` of tile `t`.
pub(crate) fn tile_pixels(
    t: usize,
    bins: &Bins,
    w: usize,
    h: usize,
) -> (usize, usize, usize, usize) {
    let tx = (t % bins.tiles_x as usize) * TILE as usize;
    let ty = (t / bins.tiles_x as usize) * TILE as usize;
    (
        tx,
        (tx + TILE as usize).min(w),
        ty,
        (ty + TILE as usize).min(h),
    )
}

/// Blends every pixel front to back, tile by tile ([`blend_tile`]).
fn rasterize(
    projected: &[Projected],
    bins: &Bins,
    camera: &Camera,
    settings: &RenderSettings,
) -> Blended {
    let (w, h) = (camera.width as usize, camera.height as usize);
    let n_tiles = bins.tiles_x as usize * bins.tiles_y as usize;
    // One job per tile, each writing only its own buffer; scattered afterwards.
    let tiles: Vec<TileOut> = (0..n_tiles)
        .into_par_iter()
        .map(|t| {
            let list = &bins.ids[bins.offsets[t]..bins.offsets[t + 1]];
            blend_tile(projected, list, tile_pixels(t, bins, w, h), settings)
        })
        .collect();
    let mut out = Blended {
        rgb: vec![[0.0; 3]; w * h],
        transmittance: vec![0.0; w * h],
        ends: vec![0; w * h],
    };
    for (t, tile) in tiles.iter().enumerate() {
        let (x0, x1, y0, y1) = tile_pixels(t, bins, w, h);
        for y in y0..y1 {
            let r = y - y0;
            for x in x0..x1 {
                let (c, i) = (x - x0, y * w + x);
                let row = &tile.rows[r];
                out.rgb[i] = row.rgb.map(|ch| lane(&ch, c));
                out.transmittance[i] = lane(&row.t, c);
                out.ends[i] = row.end[c / 8].as_array()[c % 8] as u32;
            }
        }
    }
    out
}

/// One tile's pixels over the full [`TILE`] × [`TILE`] square, by row (pixels past the
/// image's edge are computed as done from the start and dropped).
struct TileOut {
    rows: [BlendRow; TILE as usize],
}

/// The rows of a tile starting at pixel row `y0` (at most `rows`) that splat `p` can
/// reach: its screen box `center.y ± extent.y`, as `[r0, r1)` tile rows.
#[inline]
pub(crate) fn splat_rows(p: &Projected, y0: usize, rows: usize) -> (usize, usize) {
    let lo = floor_within(p.mean2d.y - p.extent.y - 0.5 - y0 as f32, rows);
    let hi = ceil_within(p.mean2d.y + p.extent.y - 0.5 - y0 as f32 + 1.0, rows);
    (lo, hi)
}

/// `⌊x⌋` clamped to `[0, max]` (NaN gives 0), without a library call: `floor` is one
/// on plain x86-64, and these run once per splat and tile row.
#[inline]
pub(crate) fn floor_within(x: f32, max: usize) -> usize {
    // Truncation is the floor for x ≥ 0; below 0 the clamp gives 0 either way.
    (x.max(0.0) as usize).min(max)
}

/// `⌈x⌉` clamped to `[0, max]` (NaN gives 0), without a library call.
#[inline]
pub(crate) fn ceil_within(x: f32, max: usize) -> usize {
    let x = x.max(0.0);
    let t = x as usize;
    (t + ((t as f32) < x) as usize).min(max)
}

/// Front-to-back blending of one tile, splat by splat over the tile's pixels (the inner
/// loop over a row of [`TILE`] pixels is branch-free, so the compiler vectorizes it).
/// Per pixel: the accumulated color over the background, the final transmittance, and
/// one past the last splat of `list` that was blended (0 if none).
fn blend_tile(
    projected: &[Projected],
    list: &[u32],
    (x0, x1, y0, y1): (usize, usize, usize, usize),
    settings: &RenderSettings,
) -> TileOut {
    let mut out = TileOut {
        rows: [BlendRow::new(x1 - x0); TILE as usize],
    };
    for row in out.rows.iter_mut().skip(y1 - y0) {
        *row = BlendRow::new(0);
    }
    let mut n_live = ((x1 - x0) * (y1 - y0)) as u32;
    let rows = y1 - y0;
    for (k, &id) in list.iter().enumerate() {
        if n_live == 0 {
            break;
        }
        let p = &projected[id as usize];
        let (r0, r1) = splat_rows(p, y0, rows);
        let left = p.mean2d.x - x0 as f32;
        for r in r0..r1 {
            let dy = (y0 + r) as f32 + 0.5 - p.mean2d.y;
            n_live -= blend_row(
                &mut out.rows[r],
                p,
                left,
                dy,
                k as i32 + 1,
                settings.early_stop,
            );
        }
    }
    let bg = settings.background;
    for row in &mut out.rows {
        for (c, channel) in row.rgb.iter_mut().enumerate() {
            for (v, t) in channel.iter_mut().zip(&row.t) {
                *v += *t * f32x8::splat(bg[c]);
            }
        }
    }
    out
}

/// [`rasterize`]'s image, for the backward pass's tests.
#[cfg(test)]
pub(crate) fn rasterize_for_tests(
    projected: &[Projected],
    bins: &Bins,
    camera: &Camera,
    settings: &RenderSettings,
) -> Vec<[f32; 3]> {
    rasterize(projected, bins, camera, settings).rgb
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Affine3A;

    /// A 64 × 48 camera at the origin looking down −Z, 60° across.
    fn camera() -> Camera {
        Camera::from_fov_x(64, 48, 60f32.to_radians(), Affine3A::IDENTITY).unwrap()
    }

    /// SH DC giving linear color `c` (degree 0).
    fn dc(c: [f32; 3]) -> [f32; 3] {
        c.map(|v| (v - 0.5) / 0.282_094_8)
    }

    fn settings(bg: [f32; 3]) -> RenderSettings {
        RenderSettings {
            background: bg,
            ..Default::default()
        }
    }

    #[test]
    fn one_gaussian_matches_direct_evaluation() {
        let cam = camera();
        let (mean, s, logit) = ([0.3f32, -0.2, -4.0], 0.15f32, -1.0f32);
        let mut g = Gaussians::new(0);
        // Opacity 0.27: below 1/255 at 3σ, so the 3σ cutoff changes nothing.
        g.push(mean, [s.ln(); 3], [0.3, 0.1, -0.7, 0.2], logit, &[0.0; 3]);
        let bg = [0.1f32, 0.2, 0.3];
        let out = render(&g, &cam, &settings(bg)).unwrap();
        // Independent evaluation in f64: camera axes = world axes; OpenCV y and z flip.
        let (x, y, z) = (mean[0] as f64, -mean[1] as f64, -mean[2] as f64);
        let (fx, fy) = (cam.fx as f64, cam.fy as f64);
        let u = fx * x / z + cam.cx as f64;
        let v = fy * y / z + cam.cy as f64;
        let j = [
            [fx / z, 0.0, -fx * x / (z * z)],
            [0.0, fy / z, -fy * y / (z * z)],
        ];
        let s2 = (s as f64).powi(2);
        let dot = |r: [f64; 3], q: [f64; 3]| r[0] * q[0] + r[1] * q[1] + r[2] * q[2];
        let a = s2 * dot(j[0], j[0]) + 0.3;
        let b = s2 * dot(j[0], j[1]);
        let c = s2 * dot(j[1], j[1]) + 0.3;
        let det = a * c - b * b;
        let o = 1.0 / (1.0 + (-logit as f64).exp());
        let mut worst = 0.0f64;
        let mut brightest = (0, 0.0f32);
        for py in 0..48 {
            for px in 0..64 {
                let (dx, dy) = (px as f64 + 0.5 - u, py as f64 + 0.5 - v);
                let q = (c * dx * dx - 2.0 * b * dx * dy + a * dy * dy) / det;
                let alpha = (o * (-0.5 * q).exp()).min(0.99);
                let alpha = if alpha < 1.0 / 255.0 { 0.0 } else { alpha };
                let i = py * 64 + px;
                for ch in 0..3 {
                    let want = 0.5 * alpha + (1.0 - alpha) * bg[ch] as f64;
                    worst = worst.max((out.rgb[i][ch] as f64 - want).abs());
                }
                worst = worst.max((out.transmittance[i] as f64 - (1.0 - alpha)).abs());
                if out.rgb[i][0] > brightest.1 {
                    brightest = (i, out.rgb[i][0]);
                }
            }
        }
        assert!(worst < 1e-5, "largest difference {worst}");
        // Its center is where the camera projects the mean.
        let at = cam.project(Vec3::from_array(mean)).unwrap();
        assert!((out.projected[0].mean2d - at).length() < 1e-3);
        let want = at.y.floor() as usize * 64 + at.x.floor() as usize;
        assert_eq!(brightest.0, want, "brightest pixel vs. projection {at}");
        assert!(brightest.1 > bg[0] + 0.05);
    }

    #[test]
    fn behind_near_and_off_screen_are_culled() {
        let cam = camera();
        let bg = [0.2, 0.4, 0.6];
        let mut g = Gaussians::new(0);
        g.push(
            [0.0, 0.0, 2.0],
            [0.0; 3],
            [1.0, 0.0, 0.0, 0.0],
            5.0,
            &[0.0; 3],
        ); // behind
        g.push(
            [0.0, 0.0, -0.005],
            [0.0; 3],
            [1.0, 0.0, 0.0, 0.0],
            5.0,
            &[0.0; 3],
        ); // straddles near
        g.push(
            [100.0, 0.0, -5.0],
            [-2.0; 3],
            [1.0, 0.0, 0.0, 0.0],
            5.0,
            &[0.0; 3],
        ); // off screen
        g.push(
            [0.0, 0.0, 0.0],
            [0.0; 3],
            [1.0, 0.0, 0.0, 0.0],
            5.0,
            &[0.0; 3],
        ); // at the eye
        let s = settings(bg);
        assert!(project(&g, &cam, &s).is_empty());
        let out = render(&g, &cam, &s).unwrap();
        assert!(out.rgb.iter().all(|&c| c == bg));
        assert!(out.transmittance.iter().all(|&t| t == 1.0));
        // The same off-screen Gaussian moved into view is kept: the cull is real.
        g.means[2] = [0.0, 0.0, -5.0];
        assert_eq!(project(&g, &cam, &s).len(), 1);
    }

    #[test]
    fn nearer_wins_and_ties_go_to_the_lower_index() {
        let cam = camera();
        let red = dc([1.0, 0.0, 0.0]);
        let blue = dc([0.0, 0.0, 1.0]);
        let center = 24 * 64 + 32;
        let build = |first: (f32, [f32; 3]), second: (f32, [f32; 3])| {
            let mut g = Gaussians::new(0);
            for (z, col) in [first, second] {
                g.push([0.0, 0.0, z], [-1.0; 3], [1.0, 0.0, 0.0, 0.0], 8.0, &col);
            }
            render(&g, &cam, &settings([0.0; 3])).unwrap()
        };
        let a = build((-3.0, red), (-5.0, blue));
        let b = build((-5.0, blue), (-3.0, red));
        let c = a.rgb[center];
        assert!(c[0] > 0.98 && c[2] < 0.02, "{c:?}");
        assert_eq!(a.rgb, b.rgb);
        assert_eq!(a.transmittance, b.transmittance);
        // Same depth: index 0 is in front.
        let c = build((-4.0, red), (-4.0, blue)).rgb[center];
        assert!(c[0] > 0.98 && c[2] < 0.02, "{c:?}");
        let c = build((-4.0, blue), (-4.0, red)).rgb[center];
        assert!(c[2] > 0.98 && c[0] < 0.02, "{c:?}");
    }

    #[test]
    fn huge_and_degenerate_gaussians_stay_finite() {
        let cam = camera();
        let bg = [0.5; 3];
        let mut g = Gaussians::new(0);
        g.push(
            [0.0, 0.0, -5.0],
            [5.0; 3],
            [1.0, 0.0, 0.0, 0.0],
            0.0,
            &dc([1.0, 0.0, 0.0]),
        );
        let out = render(&g, &cam, &settings(bg)).unwrap();
        assert!(out.rgb.iter().flatten().all(|v| v.is_finite()));
        // Covers every pixel, corners included.
        assert!(
            out.rgb.iter().all(|c| c[0] > 0.6 && c[1] < 0.4),
            "{:?}",
            out.rgb[0]
        );
        let mut g = Gaussians::new(0);
        for (k, rot) in [
            [1.0, 0.0, 0.0, 0.0],
            [0.6, 0.0, 0.8, 0.0],
            [0.5, 0.5, 0.5, 0.5],
        ]
        .into_iter()
        .enumerate()
        {
            let mean = [k as f32 * 0.3 - 0.3, 0.1, -3.0];
            g.push(
                mean,
                [1e-6f32.ln(), -1.0, -1.5],
                rot,
                3.0,
                &dc([0.0, 1.0, 0.0]),
            );
        }
        let out = render(&g, &cam, &settings(bg)).unwrap();
        assert!(out.rgb.iter().flatten().all(|v| v.is_finite()));
        assert!(out.transmittance.iter().all(|t| t.is_finite()));
        assert!(
            out.rgb.iter().any(|c| c[1] > 0.6),
            "the flat splats are drawn"
        );
    }

    /// A reproducible scene of `n` Gaussians in front of [`camera`].
    fn random_scene(n: usize) -> Gaussians {
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 40) as f32 / (1u64 << 24) as f32
        };
        let mut g = Gaussians::new(1);
        for _ in 0..n {
            let mean = [next() * 4.0 - 2.0, next() * 3.0 - 1.5, -2.0 - next() * 4.0];
            let ls = [0.0; 3].map(|_: f32| -3.5 + 2.0 * next());
            let rot = [next() - 0.5, next() - 0.5, next() - 0.5, next() + 0.1];
            let sh: Vec<f32> = (0..12).map(|_| next() - 0.5).collect();
            g.push(mean, ls, rot, next() * 6.0 - 2.0, &sh);
        }
        g
    }

    #[test]
    fn same_bits_for_any_thread_count() {
        let g = random_scene(500);
        let cam = camera();
        let s = settings([0.1, 0.2, 0.3]);
        let run = |threads| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| render(&g, &cam, &s).unwrap())
        };
        let (one, three) = (run(1), run(3));
        let bits = |r: &Rendered| -> Vec<u32> {
            r.rgb
                .iter()
                .flatten()
                .chain(&r.transmittance)
                .map(|v| v.to_bits())
                .collect()
        };
        assert_eq!(bits(&one), bits(&three));
        assert!(
            one.projected.len() > 400,
            "{} projected",
            one.projected.len()
        );
        assert!(
            one.transmittance.iter().any(|&t| t < 0.5),
            "the scene covers pixels"
        );
    }

    /// With anti-aliasing, a splat smaller than a pixel keeps its total weight (the sum of
    /// its opacity over the image, in units of the coarse image's pixels) when the image
    /// is rendered at twice the resolution; without it, the dilation makes the small
    /// splat heavier at the coarse resolution.
    #[test]
    fn antialiased_weight_is_the_same_at_two_resolutions() {
        let weight = |antialiased: bool, w: u32| {
            let cam = Camera::from_fov_x(w, w, 1.0, Affine3A::IDENTITY).unwrap();
            let fx32 = 16.0 / 0.5f32.tan();
            let mut g = Gaussians::new(0);
            g.antialiased = antialiased;
            // A standard deviation of 0.5 px at 32 px across, 4 units away.
            let sigma = 0.5 * 4.0 / fx32;
            g.push(
                [0.0, 0.0, -4.0],
                [sigma.ln(); 3],
                [1.0, 0.0, 0.0, 0.0],
                logit(0.3),
                &[0.0; 3],
            );
            let out = render(&g, &cam, &settings([0.0; 3])).unwrap();
            let covered: f64 = out.transmittance.iter().map(|&t| 1.0 - t as f64).sum();
            let k = out.projected[0].compensation;
            (covered * (32.0 / w as f64).powi(2), k)
        };
        let (aa32, k32) = weight(true, 32);
        let (aa64, k64) = weight(true, 64);
        // Isotropic: k = √(det Σ / det(Σ + 0.3·I)) = σ²/(σ² + 0.3), σ² = 0.25 and 1 px².
        assert!((k32 - 0.25 / 0.55).abs() < 1e-3, "{k32}");
        assert!((k64 - 1.0 / 1.3).abs() < 1e-3, "{k64}");
        assert!((aa64 / aa32 - 1.0).abs() < 0.06, "{aa32} vs {aa64}");
        let (plain32, _) = weight(false, 32);
        let (plain64, _) = weight(false, 64);
        assert!(plain64 / plain32 < 0.7, "{plain32} vs {plain64}");
        assert_eq!(weight(false, 32).1, 1.0);
    }

    /// Two walls facing the camera, each one Gaussian flattened along the view: a
    /// third-transparent one at depth 2 before an opaque one at depth 4. At the center
    /// the weights are 0.3 and 0.7·0.99, so the expected depth is their mean of 2 and 4,
    /// and the accumulated opacity crosses 0.5 at the second wall (the median depth).
    #[test]
    fn depth_of_two_walls() {
        let cam = camera();
        let mut g = Gaussians::new(0);
        let wall = |g: &mut Gaussians, z: f32, o: f32| {
            g.push(
                [0.0, 0.0, -z],
                [2f32.ln(), 2f32.ln(), 1e-3f32.ln()],
                [1.0, 0.0, 0.0, 0.0],
                logit(o),
                &[0.0; 3],
            )
        };
        wall(&mut g, 4.0, 0.999);
        wall(&mut g, 2.0, 0.3);
        let out = render(&g, &cam, &settings([0.0; 3])).unwrap();
        let d = out.depth();
        let c = 24 * 64 + 32;
        let (w1, w2) = (0.3f32, 0.7 * 0.99);
        let want = (w1 * 2.0 + w2 * 4.0) / (w1 + w2);
        assert!(
            (d.expected[c] - want).abs() < 2e-3,
            "{} vs {want}",
            d.expected[c]
        );
        assert_eq!(d.median[c], 4.0);
        assert!((d.opacity[c] - (w1 + w2)).abs() < 1e-3);
        // Only the near wall: its depth, and no median (opacity 0.3 < 0.5).
        let mut near = Gaussians::new(0);
        wall(&mut near, 2.0, 0.3);
        let d = render(&near, &cam, &settings([0.0; 3])).unwrap().depth();
        assert!((d.expected[c] - 2.0).abs() < 1e-5);
        assert_eq!(d.median[c], 0.0);
        // Nothing: zeros.
        let d = render(&Gaussians::new(0), &cam, &settings([0.0; 3]))
            .unwrap()
            .depth();
        assert!(d.expected.iter().chain(&d.median).all(|&v| v == 0.0));
        assert_eq!((d.width, d.height, d.expected.len()), (64, 48, 64 * 48));
    }

    fn logit(p: f32) -> f32 {
        (p / (1.0 - p)).ln()
    }

    #[test]
    fn no_gaussians_give_the_background() {
        let bg = [0.25, 0.5, 0.75];
        let out = render(&Gaussians::new(2), &camera(), &settings(bg)).unwrap();
        assert_eq!((out.width, out.height), (64, 48));
        assert_eq!(out.rgb, vec![bg; 64 * 48]);
        assert_eq!(out.transmittance, vec![1.0; 64 * 48]);
    }

    #[test]
    fn tile_pairs_are_limited_and_bad_input_refused() {
        let g = random_scene(50);
        let cam = camera();
        let s = settings([0.0; 3]);
        let err = render_limited(&g, &cam, &s, 10).unwrap_err();
        assert!(err.contains("MAX_SPLAT_TILE_PAIRS"), "{err}");
        assert!(render_limited(&g, &cam, &s, u64::MAX).is_ok());
        let distorted = cam.with_distortion(0.1, 0.0, 0.0, 0.0);
        assert!(
            render(&g, &distorted, &s)
                .unwrap_err()
                .contains("undistort")
        );
        let bad = RenderSettings { near: 0.0, ..s };
        assert!(render(&g, &cam, &bad).unwrap_err().contains("near"));
    }
}
