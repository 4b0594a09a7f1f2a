//! Image paints: an [`ImagePaint`]'s pixels sampled at pixel centers as tiny-skia samples a
//! pattern shader, so that diffsvg draws an SVG `<image>` as resvg does.
//!
//! resvg fills the image's rectangle with a pattern of the decoded pixels (pad spread,
//! opacity 1) under the image's transform. tiny-skia maps each device pixel center by the
//! inverse transform, in `f32`, to image space and filters the premultiplied 8-bit pixels
//! there (its `highp` pipeline, `pipeline/highp.rs`):
//!
//! * **nearest** (`gather`): the pixel containing the point, its coordinates clamped to
//!   `[0, width − 1 ulp]` and truncated;
//! * **bilinear**: the pixels at `x ± 0.5`, `y ± 0.5`, weighted by `f = fract(x + 0.5)`
//!   as `1 − f` and `f`;
//! * **bicubic**: the pixels at `x − 1.5 … x + 1.5`, weighted by
//!   `[far(1 − f), near(1 − f), near(f), far(f)]` with `near(t) = (1 + 9t + 27t² − 21t³)/18`
//!   and `far(t) = (7t³ − 6t²)/18` (the Mitchell–Netravali cubic, B = C = 1/3), then each
//!   channel clamped to `[0, 1]` (its `Clamp0`, `ClampA` stages: alpha is not a bound).
//!
//! Every sample position is clamped into the image on its own (pad), so edges extend. A
//! transform that is a pure translation samples nearest whatever the quality asked, as
//! tiny-skia's `Pattern::push_stages` decides.

use crate::scene::{Affine, ImagePaint, ImageQuality, Point, invert};

/// An image paint ready for evaluation.
#[derive(Clone, Debug)]
pub(crate) struct ImageEval {
    /// Device → image space, in `f32` as tiny-skia applies it.
    inv: [f32; 6],
    width: usize,
    height: usize,
    /// Premultiplied RGBA, rounded to 8 bits as tiny-skia premultiplies a decoded image.
    premul: Vec<[u8; 4]>,
    /// The filter actually used.
    quality: ImageQuality,
    /// Item opacity clamped to `[0, 1]`.
    opacity: f32,
    /// Item opacity as given (its gradient is 0 outside `[0, 1]`).
    raw_opacity: f64,
}

/// tiny-skia's `premultiply_u8`: `c · a / 255` rounded to nearest.
#[inline]
pub(crate) fn premultiply_u8(c: u8, a: u8) -> u8 {
    let prod = u32::from(c) * u32::from(a) + 128;
    ((prod + (prod >> 8)) >> 8) as u8
}

/// Whether `t` moves without scaling, rotating or skewing (to a millionth).
fn is_translate(t: &Affine) -> bool {
    (t[0] - 1.0).abs() <= 1e-6
        && (t[3] - 1.0).abs() <= 1e-6
        && t[1].abs() <= 1e-6
        && t[2].abs() <= 1e-6
}

#[inline]
fn near(t: f32) -> f32 {
    t * (t * ((-21.0 / 18.0) * t + 27.0 / 18.0) + 9.0 / 18.0) + 1.0 / 18.0
}

#[inline]
fn far(t: f32) -> f32 {
    (t * t) * ((7.0 / 18.0) * t - 6.0 / 18.0)
}

/// One below `v` in the last place (tiny-skia's `ulp_sub`, for positive `v`).
#[inline]
fn ulp_sub(v: f32) -> f32 {
    f32::from_bits(v.to_bits() - 1)
}

impl ImageEval {
    /// Prepares `image` drawn with `opacity`; `None` when its transform is singular or it
    /// holds no pixels.
    pub(crate) fn new(image: &ImagePaint, opacity: f64) -> Option<ImageEval> {
        let (w, h) = (image.width as usize, image.height as usize);
        if w == 0 || h == 0 || image.pixels.len() != 4 * w * h {
            return None;
        }
        let inv = invert(&image.transform)?;
        let quality = if is_translate(&image.transform) {
            ImageQuality::Nearest
        } else {
            image.quality
        };
        let premul = image
            .pixels
            .chunks_exact(4)
            .map(|p| {
                let a = p[3];
                [
                    premultiply_u8(p[0], a),
                    premultiply_u8(p[1], a),
                    premultiply_u8(p[2], a),
                    a,
                ]
            })
            .collect();
        Some(ImageEval {
            inv: inv.map(|v| v as f32),
            width: w,
            height: h,
            premul,
            quality,
            opacity: opacity.clamp(0.0, 1.0) as f32,
            raw_opacity: opacity,
        })
    }

    /// The premultiplied pixel at image-space `(x, y)`, each clamped into the image.
    #[inline]
    fn pixel(&self, x: f32, y: f32) -> [f32; 4] {
        let xm = ulp_sub(self.width as f32);
        let ym = ulp_sub(self.height as f32);
        // `max` then `min` as tiny-skia: a NaN becomes 0.
        let ix = x.max(0.0).min(xm) as usize;
        let iy = y.max(0.0).min(ym) as usize;
        let p = self.premul[iy * self.width + ix];
        const F: f32 = 1.0 / 255.0;
        [
            p[0] as f32 * F,
            p[1] as f32 * F,
            p[2] as f32 * F,
            p[3] as f32 * F,
        ]
    }

    /// The filtered premultiplied color at device point `p`, before the item opacity.
    pub(crate) fn sample(&self, p: Point) -> [f32; 4] {
        let (px, py) = (p[0] as f32, p[1] as f32);
        let t = &self.inv;
        let x = px * t[0] + (py * t[2] + t[4]);
        let y = px * t[1] + (py * t[3] + t[5]);
        match self.quality {
            ImageQuality::Nearest => self.pixel(x, y),
            ImageQuality::Bilinear => {
                let fx = fract(x + 0.5);
                let fy = fract(y + 0.5);
                self.filter(x, y, -0.5, &[1.0 - fx, fx], &[1.0 - fy, fy])
            }
            ImageQuality::Bicubic => {
                let fx = fract(x + 0.5);
                let fy = fract(y + 0.5);
                let wx = [far(1.0 - fx), near(1.0 - fx), near(fx), far(fx)];
                let wy = [far(1.0 - fy), near(1.0 - fy), near(fy), far(fy)];
                self.filter(x, y, -1.5, &wx, &wy).map(|v| v.clamp(0.0, 1.0))
            }
        }
    }

    /// The weighted sum of the pixels at `(x + start + i, y + start + j)`.
    #[inline]
    fn filter<const N: usize>(
        &self,
        x: f32,
        y: f32,
        start: f32,
        wx: &[f32; N],
        wy: &[f32; N],
    ) -> [f32; 4] {
        let mut out = [0.0f32; 4];
        let mut sy = y + start;
        for wj in wy {
            let mut sx = x + start;
            for wi in wx {
                let c = self.pixel(sx, sy);
                let w = wi * wj;
                for k in 0..4 {
                    out[k] += w * c[k];
                }
                sx += 1.0;
            }
            sy += 1.0;
        }
        out
    }

    /// Premultiplied color at device point `p`, the item opacity included.
    #[inline]
    pub(crate) fn at(&self, p: Point) -> [f32; 4] {
        self.sample(p).map(|v| v * self.opacity)
    }

    /// [`at`](Self::at) for the pixels `(x0 + i, y)`.
    pub(crate) fn row(&self, x0: usize, y: usize, out: &mut [[f32; 4]]) {
        let yc = y as f64 + 0.5;
        for (i, o) in out.iter_mut().enumerate() {
            *o = self.at([(x0 + i) as f64 + 0.5, yc]);
        }
    }

    /// Adds `∂L/∂opacity` at device point `p` to `out[0]`, given `gs = ∂L/∂(premultiplied
    /// color)`: the pixels have no parameters, the opacity scales the sample.
    pub(crate) fn backward(&self, p: Point, gs: [f64; 4], out: &mut [f64]) {
        if (0.0..=1.0).contains(&self.raw_opacity) {
            let s = self.sample(p);
            out[0] += (0..4).map(|k| gs[k] * s[k] as f64).sum::<f64>();
        }
    }
}

/// `v − ⌊v⌋`, tiny-skia's `fract`.
#[inline]
fn fract(v: f32) -> f32 {
    v - v.floor()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    fn image(w: u32, h: u32, quality: ImageQuality, transform: Affine) -> ImagePaint {
        let pixels = (0..w * h)
            .flat_map(|k| {
                [
                    (k * 37 % 256) as u8,
                    (k * 91 % 256) as u8,
                    200,
                    (255 - k % 7 * 30) as u8,
                ]
            })
            .collect();
        ImagePaint {
            width: w,
            height: h,
            pixels: Arc::new(pixels),
            transform,
            quality,
        }
    }

    /// tiny-skia's cubic weights sum to 1 at every fraction, so a flat image stays flat.
    #[test]
    fn cubic_weights_are_a_partition_of_unity() {
        for k in 0..=100 {
            let f = k as f32 / 100.0;
            let s = far(1.0 - f) + near(1.0 - f) + near(f) + far(f);
            assert!((s - 1.0).abs() < 1e-6, "{f}: {s}");
        }
        // At a pixel center (f = 0.5) the two near pixels weigh 23/36 … the closed form.
        assert!((near(0.5) - (1.0 + 4.5 + 6.75 - 2.625) / 18.0).abs() < 1e-7);
    }

    /// Premultiplying rounds to nearest, as `c·a/255` rounded in `f64`.
    #[test]
    fn premultiply_rounds_to_nearest() {
        for c in 0..=255u8 {
            for a in [0u8, 1, 7, 128, 200, 254, 255] {
                let want = (c as f64 * a as f64 / 255.0).round() as u8;
                assert_eq!(premultiply_u8(c, a), want, "{c} {a}");
            }
        }
    }

    /// Nearest sampling under a scale reads the pixel under each center, edges extended;
    /// a pure translation samples nearest even when bicubic was asked for.
    #[test]
    fn nearest_reads_the_pixel_under_the_center() {
        let img = image(3, 2, ImageQuality::Nearest, [2.0, 0.0, 0.0, 2.0, 1.0, 1.0]);
        let e = ImageEval::new(&img, 1.0).unwrap();
        let px = |i: usize| e.premul[i].map(|v| v as f32 * (1.0 / 255.0));
        assert_eq!(e.at([1.5, 1.5]), px(0));
        assert_eq!(e.at([4.5, 2.5]), px(1));
        assert_eq!(e.at([6.5, 4.5]), px(5));
        assert_eq!(e.at([100.5, 100.5]), px(5));
        assert_eq!(e.at([-10.0, -10.0]), px(0));
        let moved = image(3, 2, ImageQuality::Bicubic, [1.0, 0.0, 0.0, 1.0, 0.25, 0.0]);
        assert_eq!(
            ImageEval::new(&moved, 1.0).unwrap().quality,
            ImageQuality::Nearest
        );
    }

    /// Bilinear and bicubic sampling of a flat image give its color everywhere; at a
    /// pixel center of a 2× scale bilinear blends the neighbours as 3/4 and 1/4.
    #[test]
    fn filters_keep_flat_images_flat_and_blend_neighbours() {
        for q in [ImageQuality::Bilinear, ImageQuality::Bicubic] {
            let mut img = image(4, 4, q, [2.5, 0.0, 0.3, 2.5, 0.0, 0.0]);
            img.pixels = Arc::new([10u8, 20, 30, 255].repeat(16));
            let e = ImageEval::new(&img, 0.5).unwrap();
            for p in [[0.5, 0.5], [3.7, 5.1], [9.5, 9.5], [30.0, 2.0]] {
                let c = e.at(p);
                let want = [10.0, 20.0, 30.0, 255.0].map(|v: f32| v / 255.0 * 0.5);
                for k in 0..4 {
                    assert!((c[k] - want[k]).abs() < 1e-5, "{q:?} {p:?}: {c:?}");
                }
            }
        }
        let mut img = image(2, 1, ImageQuality::Bilinear, [2.0, 0.0, 0.0, 2.0, 0.0, 0.0]);
        img.pixels = Arc::new(vec![0, 0, 0, 255, 255, 255, 255, 255]);
        let e = ImageEval::new(&img, 1.0).unwrap();
        // Device x = 1.5 is image x = 0.75: 3/4 of pixel 0, 1/4 of pixel 1.
        assert!((e.at([1.5, 0.5])[0] - 0.25).abs() < 1e-6);
        assert!((e.at([2.5, 0.5])[0] - 0.75).abs() < 1e-6);
    }

    /// The opacity gradient is the sample: checked against central differences.
    #[test]
    fn opacity_gradient_matches_differences() {
        let img = image(3, 3, ImageQuality::Bicubic, [1.7, 0.2, -0.1, 1.3, 0.4, 0.6]);
        let gs = [0.3, -0.7, 0.2, 0.9];
        let loss = |o: f64| {
            let c = ImageEval::new(&img, o).unwrap().at([2.5, 1.5]);
            (0..4).map(|k| gs[k] * c[k] as f64).sum::<f64>()
        };
        let mut g = [0.0];
        ImageEval::new(&img, 0.6)
            .unwrap()
            .backward([2.5, 1.5], gs, &mut g);
        let h = 1e-3;
        let fd = (loss(0.6 + h) - loss(0.6 - h)) / (2.0 * h);
        assert!((g[0] - fd).abs() < 1e-4, "{} vs {fd}", g[0]);
    }
}
