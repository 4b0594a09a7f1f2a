//! The 2D jobs' settings, checked once for every front end: the command line, batch files
//! and the Python package build these structs and call `validate()`, whose errors
//! ([`Error::Setting`]) name the option as its field is named here (`max_segments`), so
//! that each front end can name it its own way (`--max-segments`, `max_segments=`).
//! The bounds live in [`crate::limits`].
//!
//! ```
//! use diffsvg::fit::vectorize::VectorizeOptions;
//! let opts = VectorizeOptions { segments: 1, ..VectorizeOptions::default() };
//! let e = opts.validate().unwrap_err();
//! assert_eq!(e.to_string(), "segments 1 must be between 2 and 64");
//! ```

use std::path::Path;

use super::FitOptions;
use super::Objective;
use super::digit::DigitOptions;
use super::glyph::GlyphOptions;
use super::vectorize::VectorizeOptions;
use crate::error::{Error, Result};
use crate::image_io::Image;
use crate::limits::{
    MAX_DIGIT_CURVES, MAX_DIGIT_SCALE, MAX_GLYPH_SEGMENTS, MAX_ITERS, MAX_PATHS,
    MAX_PYRAMID_LEVELS, PATH_SEGMENTS, check_count,
};
use crate::loss::Loss;
use crate::raster::{RenderOptions, render};
use crate::scene::{ParamGroup, Scene, Sizing};

fn setting(name: &str, message: String) -> Error {
    Error::Setting {
        name: name.into(),
        message,
    }
}

/// Refuses NaN and infinities.
fn check_finite(name: &str, v: f64) -> Result<()> {
    if !v.is_finite() {
        return Err(setting(name, format!("{v} must be a finite number")));
    }
    Ok(())
}

/// Refuses an IoU goal outside `(0, 1]` (0 would be reached by an empty drawing).
fn check_iou(name: &str, v: f64) -> Result<()> {
    if !(v > 0.0 && v <= 1.0) {
        return Err(setting(name, format!("{v} must be in (0, 1]")));
    }
    Ok(())
}

/// The learning-rate field of each group, as the front ends name it.
pub fn rate_name(g: ParamGroup) -> &'static str {
    match g {
        ParamGroup::Points => "lr_points",
        ParamGroup::Color => "lr_color",
        ParamGroup::Opacity => "lr_opacity",
        ParamGroup::StrokeWidth => "lr_width",
        ParamGroup::PaintGeometry => "lr_paint",
        ParamGroup::StopOffset => "lr_stops",
        ParamGroup::Transform => "lr_transform",
        ParamGroup::Filter => "lr_filter",
    }
}

impl FitOptions {
    /// Checks every setting: `iters` at most [`MAX_ITERS`], learning rates finite and
    /// ≥ 0 (named `lr_points`, `lr_color`, …), `until_psnr` finite, the rasterizer's
    /// tolerance positive.
    pub fn validate(&self) -> Result<()> {
        check_count("iters", self.iters, 0..=MAX_ITERS)?;
        for g in ParamGroup::ALL {
            let v = self.rates.get(g);
            if !(v.is_finite() && v >= 0.0) {
                return Err(setting(
                    rate_name(g),
                    format!(
                        "{v}: the learning rate of {} must be a finite number ≥ 0",
                        g.name()
                    ),
                ));
            }
        }
        if let Some(p) = self.until_psnr {
            check_finite("until_psnr", p)?;
        }
        let t = self.render.tolerance;
        if !(t > 0.0 && t.is_finite()) {
            return Err(setting(
                "tolerance",
                format!("{t} must be a positive number"),
            ));
        }
        Ok(())
    }
}

/// What a fit compares against its target: the loss, the pyramid and the color under
/// the drawing. With [`FitOptions`] it is a whole `fit` job.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObjectiveOptions {
    /// The loss over the target's channels.
    pub loss: Loss,
    /// Image pyramid levels in the loss (1: full resolution only), at most
    /// [`MAX_PYRAMID_LEVELS`].
    pub pyramid: usize,
    /// The color under the drawing (straight RGBA), or none (transparent).
    pub background: Option<[f32; 4]>,
}

impl Default for ObjectiveOptions {
    fn default() -> Self {
        ObjectiveOptions {
            loss: Loss::Mse,
            pyramid: 1,
            background: None,
        }
    }
}

impl ObjectiveOptions {
    /// Checks `pyramid` and `background` (each channel in `[0, 1]`).
    pub fn validate(&self) -> Result<()> {
        check_count("pyramid", self.pyramid, 1..=MAX_PYRAMID_LEVELS)?;
        if let Some(c) = self.background
            && !c.iter().all(|v| (0.0..=1.0).contains(v))
        {
            return Err(setting(
                "background",
                format!("{c:?}: every channel must be in [0, 1]"),
            ));
        }
        Ok(())
    }

    /// The objective against `target`, after [`validate`](Self::validate).
    pub fn objective(&self, target: &Image) -> Result<Objective> {
        self.validate()?;
        Ok(Objective::new(
            target,
            self.loss,
            self.background,
            self.pyramid,
        ))
    }
}

impl VectorizeOptions {
    /// Checks every setting: the path budget `paths` (1 to [`MAX_PATHS`]), `segments`
    /// ([`PATH_SEGMENTS`]), `target_psnr` finite, `iters`, and the fit's own settings.
    pub fn validate(&self) -> Result<()> {
        check_count("paths", self.paths, 1..=MAX_PATHS)?;
        check_count("segments", self.segments, PATH_SEGMENTS)?;
        check_count("iters", self.iters, 0..=MAX_ITERS)?;
        if let Some(p) = self.target_psnr {
            check_finite("target_psnr", p)?;
        }
        self.fit.validate()
    }
}

impl DigitOptions {
    /// Checks every setting: `scale` (1 to [`MAX_DIGIT_SCALE`]), `target_iou` in
    /// `(0, 1]`, `max_strokes` and `max_segments` (1 to [`MAX_DIGIT_CURVES`]), the step
    /// counts (at most [`MAX_ITERS`]).
    pub fn validate(&self) -> Result<()> {
        check_count("scale", self.scale as usize, 1..=MAX_DIGIT_SCALE as usize)?;
        check_iou("target_iou", self.target_iou)?;
        check_count("max_strokes", self.max_strokes, 1..=MAX_DIGIT_CURVES)?;
        check_count("max_segments", self.max_segments, 1..=MAX_DIGIT_CURVES)?;
        check_count("steps", self.steps, 1..=MAX_ITERS)?;
        check_count("stage_steps", self.stage_steps, 1..=MAX_ITERS)
    }
}

impl GlyphOptions {
    /// Checks every setting: the IoU goal (named `iou`) in `(0, 1]`, `max_segments`
    /// (1 to [`MAX_GLYPH_SEGMENTS`]), `iters` (1 to [`MAX_ITERS`]).
    pub fn validate(&self) -> Result<()> {
        check_iou("iou", self.iou_goal)?;
        check_count("max_segments", self.max_segments, 1..=MAX_GLYPH_SEGMENTS)?;
        check_count("iters", self.iters, 1..=MAX_ITERS)
    }
}

/// Loads a target picture for fitting: PNG or JPEG (sizes read from the header before
/// decoding), or an SVG or SVGZ rendered by diffsvg at its own size; then resampled to
/// `size` (width, height) when given. Refuses an empty picture. Errors name the file.
/// An SVG's `<text>` is set in the bundled fonts; [`load_target_with`] takes others.
pub fn load_target(path: &Path, size: Option<(u32, u32)>) -> Result<Image> {
    load_target_with(path, size, crate::scene::fonts::bundled())
}

/// [`load_target`] with these fonts for an SVG target's `<text>`.
pub fn load_target_with(
    path: &Path,
    size: Option<(u32, u32)>,
    fonts: &crate::scene::Fonts,
) -> Result<Image> {
    let is_svg = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("svg") || e.eq_ignore_ascii_case("svgz"));
    let t = if is_svg {
        render(
            &Scene::load_with(path, Sizing::Natural, fonts)?,
            &RenderOptions::default(),
        )
    } else {
        Image::load(path)?
    };
    if t.width == 0 || t.height == 0 {
        return Err(Error::Image {
            path: path.to_path_buf(),
            message: "image is empty".into(),
        });
    }
    match size {
        Some((w, h)) => t.resized_checked(w, h, path),
        None => Ok(t),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `validate` of the defaults changed by `f`, its error as text.
    fn changed<T>(
        mut o: T,
        f: &dyn Fn(&mut T),
        validate: fn(&T) -> Result<()>,
    ) -> Result<(), String> {
        f(&mut o);
        validate(&o).map_err(|e| e.to_string())
    }

    /// Each bound is refused just past it and accepted at it, with the option's name.
    #[test]
    fn bounds_name_their_option() {
        let v = |f: &dyn Fn(&mut VectorizeOptions)| {
            changed(VectorizeOptions::default(), f, VectorizeOptions::validate)
        };
        assert_eq!(
            v(&|o| o.segments = 1),
            Err("segments 1 must be between 2 and 64".into())
        );
        assert!(v(&|o| o.segments = 2).is_ok());
        assert_eq!(
            v(&|o| o.paths = MAX_PATHS + 1),
            Err(format!(
                "paths {} must be between 1 and {MAX_PATHS}",
                MAX_PATHS + 1
            ))
        );
        assert!(v(&|o| o.paths = MAX_PATHS).is_ok());
        assert!(v(&|o| o.iters = 0).is_ok());
        assert!(
            v(&|o| o.iters = MAX_ITERS + 1)
                .unwrap_err()
                .starts_with("iters ")
        );
        assert!(
            v(&|o| o.fit.rates.color = f64::INFINITY)
                .unwrap_err()
                .starts_with("lr_color inf: the learning rate of colors")
        );
        assert!(v(&|o| o.target_psnr = Some(f64::NAN)).is_err());
        let p = |n| {
            ObjectiveOptions {
                pyramid: n,
                ..Default::default()
            }
            .validate()
        };
        assert!(p(0).is_err() && p(MAX_PYRAMID_LEVELS + 1).is_err());
        assert!(p(1).is_ok() && p(MAX_PYRAMID_LEVELS).is_ok());
        let d = |f: &dyn Fn(&mut DigitOptions)| {
            changed(DigitOptions::default(), f, DigitOptions::validate)
        };
        assert!(d(&|_| ()).is_ok());
        assert_eq!(
            d(&|o| o.scale = 17),
            Err("scale 17 must be between 1 and 16".into())
        );
        assert!(d(&|o| o.target_iou = 0.0).is_err());
        assert!(
            d(&|o| o.max_segments = 0)
                .unwrap_err()
                .starts_with("max_segments 0")
        );
        let g = |f: &dyn Fn(&mut GlyphOptions)| {
            changed(GlyphOptions::default(), f, GlyphOptions::validate)
        };
        assert!(g(&|_| ()).is_ok());
        assert_eq!(
            g(&|o| o.iou_goal = 0.0),
            Err("iou 0 must be in (0, 1]".into())
        );
        assert!(g(&|o| o.iou_goal = 1.0).is_ok());
        assert!(g(&|o| o.max_segments = 1025).is_err());
    }
}
