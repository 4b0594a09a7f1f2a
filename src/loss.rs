//! Image losses over premultiplied RGBA in `[0, 1]`: the mean over pixels and channels.
//!
//! ```
//! use diffsvg::{Image, loss::Loss};
//! let a = Image::filled(2, 2, [1.0, 0.0, 0.0, 1.0]);
//! let b = Image::filled(2, 2, [0.5, 0.0, 0.0, 1.0]);
//! // (0.5)² in one channel of four: 0.0625.
//! assert_eq!(Loss::Mse.value(&a, &b), 0.0625);
//! let (_, d) = Loss::Mse.grad(&a, &b); // ∂L/∂a, the image's layout
//! assert_eq!(d.get(0, 0)[0], 2.0 * 0.5 / 16.0);
//! ```

use crate::image_io::Image;

/// Which loss.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Loss {
    /// Mean squared error.
    #[default]
    Mse,
    /// Mean absolute error.
    L1,
}

impl Loss {
    /// Loss of `img` against `target` (same size), over all four channels.
    pub fn value(self, img: &Image, target: &Image) -> f64 {
        self.eval(img, target, 4, false).0
    }

    /// Loss and `∂L/∂img`, over all four channels.
    pub fn grad(self, img: &Image, target: &Image) -> (f64, Image) {
        let (l, g) = self.eval(img, target, 4, true);
        (l, g.expect("gradient requested"))
    }

    /// Loss over the first `channels` channels (3: RGB only, for images composited over an
    /// opaque background; 4: premultiplied RGBA), the mean over pixels and those channels,
    /// and `∂L/∂img` when `want_grad` (zero in the other channels).
    ///
    /// The sum runs over bands of [`SUM_ROWS`] rows, each summed in pixel order, then over
    /// the bands in order: the order of the rasterizer's fused pass
    /// ([`raster::render_and_backward_fused`](crate::raster)), so both give the same bits.
    pub fn eval(
        self,
        img: &Image,
        target: &Image,
        channels: usize,
        want_grad: bool,
    ) -> (f64, Option<Image>) {
        assert_eq!(
            (img.width, img.height),
            (target.width, target.height),
            "image sizes differ"
        );
        let channels = channels.clamp(1, 4);
        let n = (img.data.len() * channels).max(1) as f64;
        let band = (img.width as usize * SUM_ROWS).max(1);
        let mut sum = 0.0f64;
        let mut g = want_grad.then(|| Image::new(img.width, img.height));
        for (k, (p, t)) in img
            .data
            .chunks(band)
            .zip(target.data.chunks(band))
            .enumerate()
        {
            let d = g
                .as_mut()
                .map(|g| &mut g.data[k * band..k * band + p.len()]);
            sum += self.band_sum(p, t, channels, n, d);
        }
        (sum / n, g)
    }

    /// One band's part of [`eval`](Self::eval): the sum of the per-channel terms over
    /// `img` against `target` (same length) in pixel order, not yet divided by `n`, the
    /// whole image's count of compared values. When `grad` is given, its first `channels`
    /// channels receive `∂L/∂img` (the others are left alone).
    pub(crate) fn band_sum(
        self,
        img: &[[f32; 4]],
        target: &[[f32; 4]],
        channels: usize,
        n: f64,
        mut grad: Option<&mut [[f32; 4]]>,
    ) -> f64 {
        let mut sum = 0.0f64;
        for (k, (p, t)) in img.iter().zip(target).enumerate() {
            for c in 0..channels {
                let d = p[c] as f64 - t[c] as f64;
                let (v, dv) = match self {
                    Loss::Mse => (d * d, 2.0 * d),
                    Loss::L1 => (d.abs(), d.signum() * (d != 0.0) as i32 as f64),
                };
                sum += v;
                if let Some(g) = grad.as_deref_mut() {
                    g[k][c] = (dv / n) as f32;
                }
            }
        }
        sum
    }
}

/// Rows per band of a loss sum (see [`Loss::eval`]); the rasterizer's bands have the same
/// height.
pub const SUM_ROWS: usize = 16;

impl crate::choice::Choice for Loss {
    const WHAT: &'static str = "loss";
    const ALL: &'static [Self] = &[Self::Mse, Self::L1];
    fn name(self) -> &'static str {
        match self {
            Self::Mse => "mse",
            Self::L1 => "l1",
        }
    }
    fn aliases(self) -> &'static [&'static str] {
        match self {
            Self::Mse => &["l2"],
            Self::L1 => &["mae"],
        }
    }
}

crate::choice::from_str_by_name!(Loss);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_and_gradients() {
        let a = Image::filled(2, 1, [0.5, 0.5, 0.5, 1.0]);
        let b = Image::filled(2, 1, [0.25, 0.5, 0.5, 1.0]);
        assert!((Loss::Mse.value(&a, &b) - 0.0625 / 4.0).abs() < 1e-12);
        assert!((Loss::L1.value(&a, &b) - 0.25 / 4.0).abs() < 1e-12);
        let (_, g) = Loss::Mse.grad(&a, &b);
        assert!((g.data[0][0] - 2.0 * 0.25 / 8.0).abs() < 1e-7);
        assert_eq!(g.data[0][1], 0.0);
    }

    #[test]
    fn loss_names_round_trip() {
        crate::choice::tests::round_trip::<Loss>();
    }
}
