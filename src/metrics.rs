//! Image comparison metrics on premultiplied RGBA.
//!
//! ```
//! use diffsvg::{Image, metrics};
//! let a = Image::filled(8, 8, [1.0, 1.0, 1.0, 1.0]);
//! let mut b = a.clone();
//! b.data[0] = [0.0, 1.0, 1.0, 1.0];
//! let c = metrics::compare(&a, &b);
//! assert_eq!(c.max, 255.0);
//! assert!((c.psnr - 10.0 * 256f64.log10()).abs() < 1e-9); // one channel of 256 off by 1
//! assert!((metrics::psnr_from_mse(0.01) - 20.0).abs() < 1e-12);
//! ```

use crate::image_io::Image;

/// Differences between two images of the same size, over all four premultiplied channels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Comparison {
    /// Mean absolute difference, in 0–255 levels.
    pub mae: f64,
    /// Largest absolute difference of any channel, in 0–255 levels.
    pub max: f64,
    /// Peak signal-to-noise ratio in dB (peak 1.0); infinite for identical images.
    pub psnr: f64,
    /// Mean squared error with values in `[0, 1]`.
    pub mse: f64,
}

/// Compares `a` with `b`. Panics if the sizes differ (callers check sizes first).
pub fn compare(a: &Image, b: &Image) -> Comparison {
    assert_eq!(
        (a.width, a.height),
        (b.width, b.height),
        "image sizes differ"
    );
    let mut abs = 0.0f64;
    let mut sq = 0.0f64;
    let mut max = 0.0f64;
    for (p, q) in a.data.iter().zip(&b.data) {
        for c in 0..4 {
            let d = (p[c] as f64 - q[c] as f64).abs();
            abs += d;
            sq += d * d;
            max = max.max(d);
        }
    }
    let n = (a.data.len() * 4).max(1) as f64;
    let mse = sq / n;
    Comparison {
        mae: abs / n * 255.0,
        max: max * 255.0,
        psnr: psnr_from_mse(mse),
        mse,
    }
}

/// PSNR in dB (peak 1) of a mean squared error for signals in `[0, 1]`:
/// `10 · log10(1 / MSE)`; infinite for an MSE of 0.
pub fn psnr_from_mse(mse: f64) -> f64 {
    if mse <= 0.0 {
        f64::INFINITY
    } else {
        -10.0 * mse.log10()
    }
}

/// Intersection over union of the pixels at or above `threshold` in `a` and in `b`
/// (intensities or coverages, same length, e.g. ink masks at `threshold = 0.5`); 1 when
/// neither has any.
pub fn iou(a: &[f32], b: &[f32], threshold: f32) -> f64 {
    let (mut inter, mut union) = (0usize, 0usize);
    for (&x, &y) in a.iter().zip(b) {
        let (p, q) = (x >= threshold, y >= threshold);
        inter += (p && q) as usize;
        union += (p || q) as usize;
    }
    if union == 0 {
        1.0
    } else {
        inter as f64 / union as f64
    }
}

/// A visual difference image: black where equal, brighter where different (amplified ×4),
/// opaque.
pub fn difference_image(a: &Image, b: &Image) -> Image {
    let data = a
        .data
        .iter()
        .zip(&b.data)
        .map(|(p, q)| {
            let d = |c: usize| ((p[c] - q[c]).abs() * 4.0).min(1.0);
            let da = d(3);
            [d(0).max(da), d(1).max(da), d(2).max(da), 1.0]
        })
        .collect();
    Image {
        width: a.width,
        height: a.height,
        data,
    }
}

/// The median of `v` (sorted in place; the upper one of the two middle values for an
/// even count); 0 when `v` is empty. Used for timings, where one slow run must not count.
pub fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(|a, b| a.total_cmp(b));
    v[v.len() / 2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_images_have_infinite_psnr() {
        let a = Image::filled(3, 3, [0.2, 0.3, 0.4, 1.0]);
        let c = compare(&a, &a);
        assert_eq!(c.mae, 0.0);
        assert!(c.psnr.is_infinite());
    }

    #[test]
    fn known_difference() {
        let a = Image::filled(2, 1, [0.0; 4]);
        let mut b = a.clone();
        b.data[0] = [1.0, 0.0, 0.0, 0.0];
        let c = compare(&a, &b);
        assert!((c.mae - 255.0 / 8.0).abs() < 1e-9);
        assert_eq!(c.max, 255.0);
        assert!((c.psnr - 10.0 * 8f64.log10()).abs() < 1e-9);
    }

    #[test]
    fn iou_of_masks() {
        let a = [0.0, 0.5, 0.9, 0.2];
        let b = [0.6, 0.49, 1.0, 0.0];
        // Inked: a at 1 and 2, b at 0 and 2: one shared of three.
        assert_eq!(iou(&a, &b, 0.5), 1.0 / 3.0);
        assert_eq!(iou(&a, &b, 0.3), 2.0 / 3.0);
        assert_eq!(iou(&[0.1; 4], &[0.2; 4], 0.5), 1.0);
    }
}
