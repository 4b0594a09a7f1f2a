//! The image objective: background compositing, the loss, and an optional multi-scale
//! (image pyramid) term.

use crate::image_io::{Image, over_background_backward_px, over_background_px, premultiplied};
use crate::loss::Loss;
use crate::metrics::psnr_from_mse;
use crate::raster::{BandLoss, Prepared, render_and_backward_fused};
use crate::scene::Scene;

/// What a fit minimizes: `Σ_k L(down^k(render over background), down^k(target))` for
/// pyramid levels `k = 0 … levels − 1`, each level a 2×2 box average of the one above
/// (odd last rows and columns dropped). Level 0 alone is the plain loss.
///
/// Images are premultiplied RGBA in `[0, 1]`. With an opaque background the comparison is
/// over RGB only (alpha is 1 on both sides); otherwise over all four premultiplied
/// channels.
#[derive(Clone, Debug)]
pub struct Objective {
    loss: Loss,
    background: Option<[f32; 4]>,
    channels: usize,
    /// Target pyramid, level 0 first, composited over the background.
    targets: Vec<Image>,
    /// The target as given (before compositing), for [`with_background`](Self::with_background).
    source: Image,
}

/// Smallest side a pyramid level may have.
const MIN_LEVEL_SIDE: u32 = 8;

impl Objective {
    /// An objective against `target` (premultiplied), composited with it over
    /// `background` (straight RGBA) when given, with up to `levels` pyramid levels (at
    /// least 1; fewer when the image gets smaller than 8 pixels).
    pub fn new(target: &Image, loss: Loss, background: Option<[f32; 4]>, levels: usize) -> Self {
        let mut t = target.clone();
        if let Some(bg) = background {
            t.over_background(bg);
        }
        let channels = if background.is_some_and(|b| b[3] >= 1.0) {
            3
        } else {
            4
        };
        let mut targets = vec![t];
        while targets.len() < levels.max(1) {
            let last = targets.last().expect("level 0 exists");
            if last.width / 2 < MIN_LEVEL_SIDE || last.height / 2 < MIN_LEVEL_SIDE {
                break;
            }
            targets.push(downsample(last));
        }
        Objective {
            loss,
            background,
            channels,
            targets,
            source: target.clone(),
        }
    }

    /// The same objective (target, loss, levels) over another background.
    pub fn with_background(&self, background: [f32; 4]) -> Objective {
        Objective::new(
            &self.source,
            self.loss,
            Some(background),
            self.targets.len(),
        )
    }

    /// The gradient of the objective with respect to an opaque background's straight
    /// red, green and blue (`[0, 1]` each), at `render` (premultiplied, not composited).
    /// Both sides are composited over it (`image + background · (1 − image.a)`), and
    /// every loss is a function of their difference, so a pixel weighs in by
    /// `target.a − render.a`: an opaque target's backdrop is matched where the drawing
    /// leaves the canvas uncovered. `None` without a background or with a translucent one.
    pub fn background_gradient(&self, render: &Image) -> Option<[f64; 3]> {
        self.background.filter(|b| b[3] >= 1.0)?;
        let (_, _, g) = self.composite_gradient(render);
        let mut sum = [0.0f64; 3];
        for ((gp, p), t) in g.data.iter().zip(&render.data).zip(&self.source.data) {
            let k = (t[3].clamp(0.0, 1.0) - p[3].clamp(0.0, 1.0)) as f64;
            for c in 0..3 {
                sum[c] += gp[c] as f64 * k;
            }
        }
        Some(sum)
    }

    /// The target as compared (composited over the background).
    pub fn target(&self) -> &Image {
        &self.targets[0]
    }

    /// The background, straight RGBA.
    pub fn background(&self) -> Option<[f32; 4]> {
        self.background
    }

    /// Pyramid levels in use.
    pub fn levels(&self) -> usize {
        self.targets.len()
    }

    /// `render` composited over the background as compared with the target.
    pub fn composite(&self, render: &Image) -> Image {
        let mut img = render.clone();
        if let Some(bg) = self.background {
            img.over_background(bg);
        }
        img
    }

    /// The loss of a rendering (premultiplied, not yet composited) and `∂L/∂render`.
    pub fn eval(&self, render: &Image) -> (f64, Image) {
        let (l, _, g) = self.eval_with_mse(render);
        (l, g)
    }

    /// [`eval`](Self::eval) plus the full-resolution MSE of [`mse`](Self::mse), from the
    /// same compositing (no second pass when the loss is a one-level MSE).
    pub fn eval_with_mse(&self, render: &Image) -> (f64, f64, Image) {
        let (total, mse, mut grad) = self.composite_gradient(render);
        if let Some(bg) = self.background {
            grad.over_background_backward(bg);
        }
        (total, mse, grad)
    }

    /// [`eval_with_mse`](Self::eval_with_mse) with the gradient taken with respect to the
    /// composited image (before the compositing is undone).
    fn composite_gradient(&self, render: &Image) -> (f64, f64, Image) {
        let img = self.composite(render);
        let (mut total, g) = self.loss.eval(&img, &self.targets[0], self.channels, true);
        let mse = if self.loss == Loss::Mse {
            total
        } else {
            Loss::Mse
                .eval(&img, &self.targets[0], self.channels, false)
                .0
        };
        let mut grad = g.expect("gradient requested");
        if self.targets.len() > 1 {
            // Down the pyramid keeping each level's gradient, then back up.
            let mut levels = vec![img];
            let mut grads = Vec::new();
            for t in &self.targets[1..] {
                let down = downsample(levels.last().expect("level 0 exists"));
                let (l, g) = self.loss.eval(&down, t, self.channels, true);
                total += l;
                grads.push(g.expect("gradient requested"));
                levels.push(down);
            }
            let mut carry: Option<Image> = None;
            for k in (0..grads.len()).rev() {
                let mut g = grads[k].clone();
                if let Some(c) = carry.take() {
                    let up = upsample_backward(&c, g.width, g.height);
                    add(&mut g, &up);
                }
                carry = Some(g);
            }
            if let Some(c) = carry {
                let up = upsample_backward(&c, grad.width, grad.height);
                add(&mut grad, &up);
            }
        }
        (total, mse, grad)
    }

    /// Whether the objective is a sum of per-pixel terms (one pyramid level), which
    /// [`render_and_backward`](Self::render_and_backward) evaluates inside the backward
    /// pass.
    pub fn is_per_pixel(&self) -> bool {
        self.targets.len() == 1
    }

    /// Renders `p` (prepared from `scene` for the backward pass) and returns the
    /// rendering (not composited), the objective, the full-resolution MSE and the gradient
    /// in [`Scene::params`] order: the bits of [`render_prepared`](crate::raster::render_prepared),
    /// [`eval_with_mse`](Self::eval_with_mse) and
    /// [`backward_with_stats`](crate::raster::backward_with_stats) in a row. Per-pixel
    /// objectives take the fused pass (each row band rendered, scored and differentiated
    /// at once); the pyramid renders first and differentiates after.
    pub fn render_and_backward(&self, scene: &Scene, p: &Prepared) -> (Image, f64, f64, Vec<f64>) {
        if self.is_per_pixel() {
            let f = render_and_backward_fused(scene, p, self);
            let n = self.value_count();
            let (loss, mse) = (f.sums[0] / n, f.sums[1] / n);
            (f.image, loss, mse, f.grad)
        } else {
            let img = crate::raster::render_prepared(p);
            let (loss, mse, d) = self.eval_with_mse(&img);
            let g = crate::raster::backward_with_stats(scene, p, &d).0;
            (img, loss, mse, g)
        }
    }

    /// Count of compared values at full resolution (pixels × channels), the divisor of
    /// the mean.
    fn value_count(&self) -> f64 {
        (self.targets[0].data.len() * self.channels).max(1) as f64
    }

    /// Mean squared error of a rendering against the target at full resolution, over the
    /// compared channels.
    pub fn mse(&self, render: &Image) -> f64 {
        let img = self.composite(render);
        Loss::Mse
            .eval(&img, &self.targets[0], self.channels, false)
            .0
    }

    /// PSNR in dB (peak 1) of a rendering against the target, from [`mse`](Self::mse).
    pub fn psnr(&self, render: &Image) -> f64 {
        psnr_from_mse(self.mse(render))
    }
}

impl BandLoss for Objective {
    /// Level 0 of [`eval_with_mse`](Objective::eval_with_mse) over one band: composited
    /// over the background, compared, differentiated and the compositing undone, with the
    /// same per-pixel operations and sums; returns (loss sum, MSE sum) before the mean.
    fn band(&self, y0: usize, rendered: &[[f32; 4]], d_out: &mut [[f32; 4]]) -> [f64; 2] {
        let t = &self.targets[0];
        let start = y0 * t.width as usize;
        let target = &t.data[start..start + rendered.len()];
        let n = self.value_count();
        let bg = self.background.map(premultiplied);
        let composited: std::borrow::Cow<'_, [[f32; 4]]> = match bg {
            Some(b) => {
                let mut c = rendered.to_vec();
                for p in &mut c {
                    over_background_px(p, b);
                }
                c.into()
            }
            None => rendered.into(),
        };
        let loss = self
            .loss
            .band_sum(&composited, target, self.channels, n, Some(d_out));
        let mse = if self.loss == Loss::Mse {
            loss
        } else {
            Loss::Mse.band_sum(&composited, target, self.channels, n, None)
        };
        if let Some(b) = bg {
            for g in d_out.iter_mut() {
                over_background_backward_px(g, b);
            }
        }
        [loss, mse]
    }
}

/// 2×2 box average; odd last rows and columns are dropped.
fn downsample(img: &Image) -> Image {
    let (w, h) = (img.width / 2, img.height / 2);
    let mut out = Image::new(w, h);
    let src_w = img.width as usize;
    for y in 0..h as usize {
        for x in 0..w as usize {
            let mut acc = [0.0f32; 4];
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let p = img.data[(2 * y + dy) * src_w + 2 * x + dx];
                for c in 0..4 {
                    acc[c] += 0.25 * p[c];
                }
            }
            out.data[y * w as usize + x] = acc;
        }
    }
    out
}

/// Backward of [`downsample`]: spreads each coarse gradient over its four fine pixels.
fn upsample_backward(coarse: &Image, width: u32, height: u32) -> Image {
    let mut out = Image::new(width, height);
    for y in 0..coarse.height as usize {
        for x in 0..coarse.width as usize {
            let g = coarse.data[y * coarse.width as usize + x];
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let o = &mut out.data[(2 * y + dy) * width as usize + 2 * x + dx];
                for c in 0..4 {
                    o[c] += 0.25 * g[c];
                }
            }
        }
    }
    out
}

fn add(a: &mut Image, b: &Image) {
    for (p, q) in a.data.iter_mut().zip(&b.data) {
        for c in 0..4 {
            p[c] += q[c];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::random::Rng;

    fn noise(w: u32, h: u32, seed: u64) -> Image {
        let mut rng = Rng::new(seed);
        let mut img = Image::new(w, h);
        for p in &mut img.data {
            let a = rng.range(0.0, 1.0) as f32;
            *p = [
                a * rng.range(0.0, 1.0) as f32,
                a * rng.range(0.0, 1.0) as f32,
                a * rng.range(0.0, 1.0) as f32,
                a,
            ];
        }
        img
    }

    /// The image gradient of every configuration matches central differences.
    #[test]
    fn gradient_matches_finite_differences() {
        let target = noise(19, 17, 1);
        let render = noise(19, 17, 2);
        for (bg, levels) in [
            (None, 1),
            (Some([1.0, 1.0, 1.0, 1.0]), 1),
            (Some([0.2, 0.4, 0.9, 0.5]), 2),
            (None, 3),
        ] {
            let o = Objective::new(&target, Loss::Mse, bg, levels);
            let (_, g) = o.eval(&render);
            for &(k, c) in &[(0usize, 0usize), (40, 3), (150, 1), (322, 2), (200, 3)] {
                let h = 1e-2f32;
                let mut a = render.clone();
                a.data[k][c] += h;
                let mut b = render.clone();
                b.data[k][c] -= h;
                let fd = (o.eval(&a).0 - o.eval(&b).0) / (2.0 * h as f64);
                let an = g.data[k][c] as f64;
                assert!(
                    (fd - an).abs() <= 1e-4 * an.abs().max(1e-3),
                    "bg {bg:?} levels {levels} px {k} ch {c}: fd {fd} analytic {an}"
                );
            }
        }
    }

    #[test]
    fn pyramid_and_channels() {
        let t = noise(40, 20, 3);
        let o = Objective::new(&t, Loss::Mse, None, 9);
        // 40×20 → 20×10 → stop (next would be 10×5 < 8).
        assert_eq!(o.levels(), 2);
        assert_eq!(o.psnr(&t), f64::INFINITY);
        // Over an opaque background only RGB counts: an alpha-only difference under a
        // white background still shows as a color change, while the alpha channel itself
        // is not averaged in.
        let white = Objective::new(&t, Loss::Mse, Some([1.0; 4]), 1);
        assert_eq!(white.channels, 3);
        assert!(white.target().data.iter().all(|p| p[3] == 1.0));
    }

    /// The background's gradient against central differences of the objective over
    /// moved backgrounds, with one and with three pyramid levels.
    #[test]
    fn background_gradient_matches_finite_differences() {
        let (render, target) = (noise(20, 18, 3), noise(20, 18, 4));
        let bg = [0.3f32, 0.6, 0.2, 1.0];
        for levels in [1, 3] {
            let obj = Objective::new(&target, Loss::Mse, Some(bg), levels);
            let g = obj.background_gradient(&render).unwrap();
            for c in 0..3 {
                let h = 1e-3f32;
                let at = |d: f32| {
                    let mut b = bg;
                    b[c] += d;
                    obj.with_background(b).eval(&render).0
                };
                let fd = (at(h) - at(-h)) / (2.0 * h as f64);
                // The objective is a mean: the gradient is per compared value.
                let analytic = g[c];
                assert!(
                    (analytic - fd).abs() <= 1e-3 * fd.abs().max(1e-3),
                    "levels {levels}, channel {c}: {analytic} against {fd}"
                );
            }
        }
        let translucent = Objective::new(&target, Loss::Mse, Some([1.0, 1.0, 1.0, 0.5]), 1);
        assert!(translucent.background_gradient(&render).is_none());
    }
}
