//! Resampling distorted photos into pinhole photos, so that renderers which project
//! through a plain pinhole (Gaussian splatting) can be fitted to them.
//!
//! Conventions (those of [`crate::volume`] and [`camera`](super::camera)):
//!
//! * images are row-major with y down; pixel `(x, y)` covers `[x, x+1] × [y, y+1]` and
//!   its center is `(x + 0.5, y + 0.5)`, in pixels of the image;
//! * distortion is the OpenCV radial-tangential model of [`Camera::distort`], acting on
//!   OpenCV normalized coordinates `((u − cx)/fx, (v − cy)/fy)` (y down);
//! * colors are resampled as loaded (linear-in-file RGB in `[0, 1]`), by bilinear
//!   interpolation between pixel centers; no gamma handling.
//!
//! The output keeps the size, focal lengths, principal point and pose of the input and
//! sets the distortion to zero: each output pixel shows the ray that a pinhole camera
//! with those intrinsics sees through it, taken from the photo where the distorted lens
//! put that ray. Where the lens put it outside the photo (pincushion distortion near the
//! corners) the nearest edge pixel is repeated, and the pixel is counted as outside.

use glam::Vec2;
use rayon::prelude::*;

use super::camera::Camera;
use super::dataset::{Dataset, View};

/// A copy of `view` as a pinhole camera would have taken it: same size, same
/// `fx, fy, cx, cy` and pose, distortion zero.
///
/// Each output pixel center `(x + 0.5, y + 0.5)` is taken to OpenCV normalized pinhole
/// coordinates, distorted with [`Camera::distort`], taken back to pixel coordinates of
/// the photo and sampled there bilinearly (pixel centers at `+0.5`), clamped to the edge
/// outside the photo. Colors are interpolated as loaded (linear RGB in `[0, 1]`).
///
/// Returns the new view and how many of its pixels sampled a point outside the photo
/// (outside `[0, width] × [0, height]` in pixels), so that callers can report how much
/// of the image is edge-repeated. A view without distortion is returned unchanged
/// (identical pixels) with count 0.
///
/// # Panics
/// If `view.rgb` does not hold `width × height` pixels.
pub fn undistort_view(view: &View) -> (View, usize) {
    let (w, h) = (view.width as usize, view.height as usize);
    assert_eq!(view.rgb.len(), w * h, "{}: pixel count", view.name);
    if !view.camera.has_distortion() {
        return (view.clone(), 0);
    }
    let (rgb, outside) = resample(&view.camera, w, h, &view.rgb);
    let out = View {
        name: view.name.clone(),
        camera: view.camera.with_distortion(0.0, 0.0, 0.0, 0.0),
        width: view.width,
        height: view.height,
        rgb,
    };
    (out, outside)
}

/// Every view of `data` undistorted with [`undistort_view`], train and test, in order;
/// views without distortion are returned unchanged. Runs in parallel over views and rows
/// (rayon); the result does not depend on the thread count.
///
/// Returns the new dataset and the total number of output pixels, over all views, that
/// sampled outside their photo.
pub fn undistort_dataset(data: &Dataset) -> (Dataset, usize) {
    let split = |views: &[View]| -> (Vec<View>, usize) {
        let done: Vec<(View, usize)> = views.par_iter().map(undistort_view).collect();
        let outside = done.iter().map(|(_, n)| n).sum();
        (done.into_iter().map(|(v, _)| v).collect(), outside)
    };
    let ((train, a), (test, b)) = rayon::join(|| split(&data.train), || split(&data.test));
    (
        Dataset {
            train,
            test,
            name: data.name.clone(),
            white_background: data.white_background,
            warnings: data.warnings.clone(),
            points: data.points.clone(),
        },
        a + b,
    )
}

/// The pinhole resampling of a `w × h` photo `rgb` taken by `camera` (see
/// [`undistort_view`]), without the shortcut for cameras without distortion; and the
/// number of output pixels that sampled outside the photo.
fn resample(camera: &Camera, w: usize, h: usize, rgb: &[[f32; 3]]) -> (Vec<[f32; 3]>, usize) {
    let mut out = vec![[0.0f32; 3]; w * h];
    if w == 0 || h == 0 {
        return (out, 0);
    }
    let (fx, fy) = (camera.fx as f64, camera.fy as f64);
    let (cx, cy) = (camera.cx as f64, camera.cy as f64);
    let outside = out
        .par_chunks_mut(w)
        .enumerate()
        .map(|(y, row)| {
            let yn = ((y as f64 + 0.5) - cy) / fy;
            let mut outside = 0;
            for (x, px) in row.iter_mut().enumerate() {
                let xn = ((x as f64 + 0.5) - cx) / fx;
                let d = camera.distort(Vec2::new(xn as f32, yn as f32));
                let u = d.x as f64 * fx + cx;
                let v = d.y as f64 * fy + cy;
                let inside = (0.0..=w as f64).contains(&u) && (0.0..=h as f64).contains(&v);
                outside += usize::from(!inside);
                *px = bilinear(rgb, w, h, u, v);
            }
            outside
        })
        .sum();
    (out, outside)
}

/// Bilinear sample of the `w × h` image `rgb` (both non-zero) at continuous pixel
/// coordinates `(u, v)` (pixel `(x, y)` centered at `(x + 0.5, y + 0.5)`), clamped to
/// the edge pixels outside; a non-finite coordinate samples the image's center line.
fn bilinear(rgb: &[[f32; 3]], w: usize, h: usize, u: f64, v: f64) -> [f32; 3] {
    // Index-space coordinates, clamped so that the edge pixels repeat outward.
    let axis = |c: f64, n: usize| -> (usize, usize, f32) {
        let max = (n - 1) as f64;
        let p = if c.is_finite() {
            (c - 0.5).clamp(0.0, max)
        } else {
            max / 2.0
        };
        let i0 = p.floor() as usize;
        let i1 = (i0 + 1).min(n - 1);
        (i0, i1, (p - i0 as f64) as f32)
    };
    let (x0, x1, tx) = axis(u, w);
    let (y0, y1, ty) = axis(v, h);
    let at = |x: usize, y: usize| rgb[y * w + x];
    let (a, b, c, d) = (at(x0, y0), at(x1, y0), at(x0, y1), at(x1, y1));
    std::array::from_fn(|k| {
        let top = a[k] + (b[k] - a[k]) * tx;
        let bottom = c[k] + (d[k] - c[k]) * tx;
        top + (bottom - top) * ty
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Affine3A, Vec3};

    fn pose() -> Affine3A {
        Affine3A::from_translation(Vec3::new(0.5, -1.0, 3.0))
    }

    fn view(camera: Camera, rgb: Vec<[f32; 3]>) -> View {
        View {
            name: "test/v".into(),
            camera,
            width: camera.width,
            height: camera.height,
            rgb,
        }
    }

    /// A smooth scene as a function of undistorted (pinhole) OpenCV normalized
    /// coordinates: what an ideal lens would see along that ray.
    fn scene(p: Vec2) -> [f32; 3] {
        let (x, y) = (p.x as f64, p.y as f64);
        [
            0.5 + 0.4 * (2.0 * x + 1.0).sin(),
            0.5 + 0.4 * (3.0 * y - 0.5).cos(),
            0.5 + 0.3 * (4.0 * x * y + x).sin(),
        ]
        .map(|c| c as f32)
    }

    /// The photo a camera with distortion takes of [`scene`]: each pixel center's
    /// normalized coordinates undistorted, and the scene evaluated there.
    fn photo_of_scene(cam: &Camera) -> Vec<[f32; 3]> {
        let mut rgb = Vec::new();
        for y in 0..cam.height {
            for x in 0..cam.width {
                let xd = (x as f32 + 0.5 - cam.cx) / cam.fx;
                let yd = (y as f32 + 0.5 - cam.cy) / cam.fy;
                rgb.push(scene(cam.undistort(Vec2::new(xd, yd))));
            }
        }
        rgb
    }

    #[test]
    fn camera_without_distortion_gives_back_the_image() {
        let cam = Camera::new(7, 5, 6.0, 6.5, 3.2, 2.4, pose()).unwrap();
        let rgb: Vec<[f32; 3]> = (0..35)
            .map(|i| [i as f32 / 35.0, (i * 7 % 11) as f32 / 11.0, 0.25])
            .collect();
        let v = view(cam, rgb.clone());
        let (u, outside) = undistort_view(&v);
        assert_eq!(u, v);
        assert_eq!(outside, 0);
        // The resampling itself is the identity up to round-off for such a camera.
        let (r, outside) = resample(&cam, 7, 5, &rgb);
        assert_eq!(outside, 0);
        for (a, b) in r.iter().zip(&rgb) {
            for k in 0..3 {
                assert!((a[k] - b[k]).abs() < 1e-5, "{a:?} vs {b:?}");
            }
        }
    }

    #[test]
    fn undistorted_photo_matches_the_pinhole_view() {
        // Pincushion (k1 > 0: corners sample outside the photo) and barrel distortion,
        // stronger than fox's, with an off-center principal point.
        for (k1, k2, p1, p2) in [(0.15, -0.05, 0.002, -0.003), (-0.2, 0.05, -0.001, 0.002)] {
            let cam = Camera::new(96, 72, 80.0, 82.0, 47.3, 36.8, pose())
                .unwrap()
                .with_distortion(k1, k2, p1, p2);
            cam.validate().unwrap();
            let photo = view(cam, photo_of_scene(&cam));
            let (u, outside) = undistort_view(&photo);
            assert!(!u.camera.has_distortion());
            assert_eq!(u.camera, cam.with_distortion(0.0, 0.0, 0.0, 0.0));
            assert_eq!((u.width, u.height, u.rgb.len()), (96, 72, 96 * 72));
            assert_eq!(u.name, photo.name);
            // Count how many pixels map outside independently, and compare in the
            // interior (source more than one pixel inside the photo's edge).
            let (mut max_err, mut max_raw, mut out_count, mut compared) = (0.0f32, 0.0f32, 0, 0);
            for y in 0..72 {
                for x in 0..96 {
                    let p = Vec2::new(
                        (x as f32 + 0.5 - cam.cx) / cam.fx,
                        (y as f32 + 0.5 - cam.cy) / cam.fy,
                    );
                    let d = cam.distort(p);
                    let (su, sv) = (d.x * cam.fx + cam.cx, d.y * cam.fy + cam.cy);
                    if !((0.0..=96.0).contains(&su) && (0.0..=72.0).contains(&sv)) {
                        out_count += 1;
                    }
                    if !(1.5..=94.5).contains(&su) || !(1.5..=70.5).contains(&sv) {
                        continue;
                    }
                    compared += 1;
                    let want = scene(p);
                    let got = u.rgb[y * 96 + x];
                    let raw = photo.rgb[y * 96 + x];
                    for k in 0..3 {
                        max_err = max_err.max((got[k] - want[k]).abs());
                        max_raw = max_raw.max((raw[k] - want[k]).abs());
                    }
                }
            }
            assert_eq!(outside, out_count);
            if k1 > 0.0 {
                assert!(outside > 0, "pincushion corners sample outside");
            } else {
                assert_eq!(outside, 0, "barrel distortion stays inside");
            }
            assert!(compared > 96 * 72 * 3 / 4, "{compared}");
            // Bilinear error of a smooth image at this sampling: well under 1e-3; the
            // distorted photo itself is off by far more.
            assert!(max_err < 1e-3, "k1 {k1}: max error {max_err}");
            assert!(
                max_raw > 20.0 * max_err,
                "k1 {k1}: raw {max_raw} vs {max_err}"
            );
        }
    }

    #[test]
    fn dataset_undistortion_keeps_splits_and_order() {
        let plain = Camera::new(8, 6, 4.0, 4.0, 4.0, 3.0, pose()).unwrap();
        let bent = plain.with_distortion(0.3, 0.0, 0.0, 0.0);
        bent.validate().unwrap();
        let img = |s: f32| (0..48).map(|i| [s, i as f32 / 48.0, 0.5]).collect();
        let data = Dataset {
            train: vec![view(bent, img(0.1)), view(plain, img(0.2))],
            test: vec![view(bent, img(0.3))],
            name: "d".into(),
            white_background: false,
            warnings: Vec::new(),
            points: None,
        };
        let (u, outside) = undistort_dataset(&data);
        assert_eq!((u.train.len(), u.test.len()), (2, 1));
        assert_eq!(u.train[1], data.train[1]);
        let (a, na) = undistort_view(&data.train[0]);
        let (c, nc) = undistort_view(&data.test[0]);
        assert_eq!((&u.train[0], &u.test[0]), (&a, &c));
        assert_eq!(outside, na + nc);
        assert!(outside > 0);
        assert!(
            u.train
                .iter()
                .chain(&u.test)
                .all(|v| !v.camera.has_distortion())
        );
        assert_eq!((u.name.as_str(), u.white_background), ("d", false));
    }

    #[test]
    fn fox_undistorts_when_present() {
        let Some(scenes) = crate::volume::dataset::tests::scenes("fox_undistorts_when_present")
        else {
            return;
        };
        let fox = scenes.join("fox");
        let data = super::super::dataset::load(&fox, 8).unwrap();
        assert!(data.train.iter().all(|v| v.camera.has_distortion()));
        let t = std::time::Instant::now();
        let (u, outside) = undistort_dataset(&data);
        let pixels: usize = u.train.iter().chain(&u.test).map(|v| v.rgb.len()).sum();
        eprintln!(
            "fox at downscale 8: undistorted {} views in {:.3} s, {outside} of {pixels} pixels \
             ({:.4} %) sampled outside",
            u.train.len() + u.test.len(),
            t.elapsed().as_secs_f64(),
            100.0 * outside as f64 / pixels as f64
        );
        assert_eq!(
            (u.train.len(), u.test.len()),
            (data.train.len(), data.test.len())
        );
        for (a, b) in u
            .train
            .iter()
            .chain(&u.test)
            .zip(data.train.iter().chain(&data.test))
        {
            assert!(!a.camera.has_distortion(), "{}", a.name);
            assert_eq!(
                (a.name.as_str(), a.width, a.height),
                (b.name.as_str(), b.width, b.height)
            );
            assert_eq!(a.camera.c2w, b.camera.c2w);
            assert!(a.rgb.iter().flatten().all(|c| c.is_finite()), "{}", a.name);
        }
        // Fox's mild pincushion pushes the outermost ring of pixels (about a pixel wide
        // at this scale) just outside the photo: about 2 % of the pixels.
        assert!(outside * 20 < pixels, "{outside} of {pixels} outside");
        let ring: usize = (u.train.iter().chain(&u.test))
            .map(|v| 4 * (v.width + v.height) as usize - 16)
            .sum();
        assert!(
            outside <= ring,
            "{outside} outside, more than the outer 2-pixel ring"
        );
    }
}
