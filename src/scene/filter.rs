//! SVG filters on a [`Group`](super::Group): a chain of image operators applied to the
//! group's layer before it is clipped, masked and composited (resvg's order).
//!
//! Everything is in device pixels, as in the rest of the scene: the filter region and the
//! primitives' subregions are whole-pixel rectangles `[x0, y0, x1, y1]` (end exclusive),
//! found as resvg finds them (the user-space rectangle's bounding box under the group's
//! transform, its corner floored and its size rounded up); blur deviations and offsets are
//! scaled by the transform's axis scales. Colors are straight sRGB in `[0, 1]`.
//!
//! The gradient reaches the content beneath (its points, colors and opacities) through
//! each operator's adjoint (`raster/filter/`), and these primitives' own numbers are
//! parameters ([`FilterPrimitive::slots_mut`]): feFlood's color and opacity, feOffset's
//! `dx, dy`, feGaussianBlur's deviations, feDropShadow's `dx, dy`, deviations, color and
//! opacity, feColorMatrix's twenty values, feComponentTransfer's functions' numbers,
//! feComposite's `k1 … k4` and the lightings' constants, color and light
//! ([`Lighting::values_mut`]). Deviations and
//! offsets have a gradient only when filters are evaluated exactly
//! ([`RenderOptions::exact_filters`](crate::raster::RenderOptions::exact_filters)):
//! resvg's box blurs and whole-pixel offsets are piecewise constant in them.

use super::BlendMode;
use super::params::ParamGroup;

/// One `<filter>` (or CSS filter function) applied to a group.
#[derive(Clone, Debug, PartialEq)]
pub struct Filter {
    /// The SVG id of the `<filter>` element (empty for a CSS filter function).
    pub id: String,
    /// The filter region in device pixels, `[x0, y0, x1, y1]`, end exclusive.
    pub region: [i64; 4],
    /// The primitives, applied in order; the last one's result is the filter's output.
    pub primitives: Vec<FilterPrimitive>,
}

/// One filter primitive with its subregion and working color space.
#[derive(Clone, Debug, PartialEq)]
pub struct FilterPrimitive {
    /// The primitive subregion in device pixels, `[x0, y0, x1, y1]`: the result is
    /// transparent outside it (except feOffset's, as in resvg).
    pub subregion: [i64; 4],
    /// `color-interpolation-filters: linearRGB` (the default) rather than `sRGB`.
    pub linear_rgb: bool,
    /// The `result` name (written back by the SVG writer; inputs refer to results by
    /// index).
    pub result: String,
    /// What the primitive does.
    pub kind: FilterKind,
}

/// Where a primitive's input comes from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FilterInput {
    /// The group's layer.
    SourceGraphic,
    /// The group's layer with its color channels set to zero.
    SourceAlpha,
    /// The result of an earlier primitive, by index.
    Result(usize),
}

/// A feComposite operator.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CompositeOp {
    /// `in` over `in2`.
    Over,
    /// `in` where `in2` is.
    In,
    /// `in` where `in2` is not.
    Out,
    /// `in` over `in2` where `in2` is.
    Atop,
    /// Each where the other is not.
    Xor,
    /// The sum, clamped.
    Lighter,
    /// `k1·i1·i2 + k2·i1 + k3·i2 + k4` per premultiplied channel, clamped.
    Arithmetic([f64; 4]),
}

/// A feComponentTransfer function of one channel (straight values in `[0, 1]`).
#[derive(Clone, Debug, PartialEq)]
pub enum TransferFunction {
    /// Unchanged.
    Identity,
    /// Piecewise linear through the values.
    Table(Vec<f64>),
    /// Piecewise constant.
    Discrete(Vec<f64>),
    /// `slope · c + intercept`.
    Linear {
        /// Slope.
        slope: f64,
        /// Intercept.
        intercept: f64,
    },
    /// `amplitude · c^exponent + offset`.
    Gamma {
        /// Amplitude.
        amplitude: f64,
        /// Exponent.
        exponent: f64,
        /// Offset.
        offset: f64,
    },
}

/// What a primitive does.
#[derive(Clone, Debug, PartialEq)]
pub enum FilterKind {
    /// feFlood: the subregion filled with one color.
    Flood {
        /// Straight sRGB color.
        color: [f64; 3],
        /// Opacity.
        opacity: f64,
    },
    /// feOffset: the input moved by whole pixels (`dx`, `dy` truncated, as resvg does).
    Offset {
        /// Input.
        input: FilterInput,
        /// Device pixels.
        dx: f64,
        /// Device pixels.
        dy: f64,
    },
    /// feGaussianBlur.
    Blur {
        /// Input.
        input: FilterInput,
        /// Standard deviations along x and y, device pixels.
        std_dev: [f64; 2],
    },
    /// feDropShadow: the input over its blurred, flooded and offset alpha.
    DropShadow {
        /// Input.
        input: FilterInput,
        /// Device pixels.
        dx: f64,
        /// Device pixels.
        dy: f64,
        /// Standard deviations along x and y, device pixels.
        std_dev: [f64; 2],
        /// Straight sRGB color.
        color: [f64; 3],
        /// Opacity.
        opacity: f64,
    },
    /// feMerge: the inputs composited source-over, first at the bottom.
    Merge {
        /// Inputs.
        inputs: Vec<FilterInput>,
    },
    /// feBlend: `input1` blended onto `input2`.
    Blend {
        /// `in`.
        input1: FilterInput,
        /// `in2`.
        input2: FilterInput,
        /// Blend mode.
        mode: BlendMode,
    },
    /// feComposite: `input1` composited with `input2`.
    Composite {
        /// `in`.
        input1: FilterInput,
        /// `in2`.
        input2: FilterInput,
        /// Operator.
        op: CompositeOp,
    },
    /// feColorMatrix as a 4 × 5 matrix on straight colors (`saturate`, `hueRotate` and
    /// `luminanceToAlpha` are turned into theirs).
    ColorMatrix {
        /// Input.
        input: FilterInput,
        /// Row-major, as SVG's `values`.
        matrix: [f64; 20],
    },
    /// feComponentTransfer: one function per channel, R, G, B, A.
    ComponentTransfer {
        /// Input.
        input: FilterInput,
        /// Functions of R, G, B and A.
        funcs: Box<[TransferFunction; 4]>,
    },
    /// feMorphology: each channel's minimum (erode) or maximum (dilate) over a window of
    /// `2·⌈radius⌉` pixels per axis (resvg's window), premultiplied.
    Morphology {
        /// Input.
        input: FilterInput,
        /// Dilate (maximum) rather than erode (minimum).
        dilate: bool,
        /// Radii along x and y, device pixels (a radius that is not positive makes the
        /// result transparent, as in resvg).
        radius: [f64; 2],
    },
    /// feConvolveMatrix over the filter region's pixels.
    ConvolveMatrix(Box<Convolve>),
    /// feTile: the input's subregion repeated over the region.
    Tile {
        /// Input.
        input: FilterInput,
    },
    /// feDisplacementMap: `input1` resampled (nearest pixel, as resvg) at offsets read from
    /// `input2`'s premultiplied channels.
    DisplacementMap {
        /// `in`: the image moved.
        input1: FilterInput,
        /// `in2`: the map.
        input2: FilterInput,
        /// Pixels moved per unit of channel value along x and y (resvg's: the `scale`
        /// attribute squared times the axis scale).
        scale: [f64; 2],
        /// The channels (0 R, 1 G, 2 B, 3 A) read for x and y.
        channels: [usize; 2],
    },
    /// feTurbulence: Perlin noise of the reference implementation in the SVG spec.
    Turbulence(Box<Turbulence>),
    /// feDiffuseLighting or feSpecularLighting on the input's alpha as a height map.
    Lighting(Box<Lighting>),
    /// feImage: an element or picture rendered into the subregion, in device pixels of
    /// the canvas (placed as resvg places it). Its nodes are not part of the scene's
    /// parameters: nothing in them gets a gradient.
    Image {
        /// What is drawn, already in device pixels.
        nodes: Vec<super::Node>,
    },
}

/// feConvolveMatrix's parameters (kernel in SVG's order, row-major, not flipped).
#[derive(Clone, Debug, PartialEq)]
pub struct Convolve {
    /// Input.
    pub input: FilterInput,
    /// Columns and rows (`order`).
    pub order: [usize; 2],
    /// `kernelMatrix`, row-major, `order[0] · order[1]` values.
    pub kernel: Vec<f64>,
    /// `targetX`, `targetY`.
    pub target: [usize; 2],
    /// Divisor (never zero).
    pub divisor: f64,
    /// Bias.
    pub bias: f64,
    /// `edgeMode`: 0 none, 1 duplicate, 2 wrap.
    pub edge: u8,
    /// `preserveAlpha`: convolve the straight colors and keep alpha.
    pub preserve_alpha: bool,
}

/// feTurbulence's parameters and where its lattice lies on the canvas.
#[derive(Clone, Debug, PartialEq)]
pub struct Turbulence {
    /// `baseFrequency` along x and y, per user unit.
    pub base_frequency: [f64; 2],
    /// `numOctaves`, bounded by [`MAX_TURBULENCE_OCTAVES`](crate::limits::MAX_TURBULENCE_OCTAVES).
    pub octaves: u32,
    /// `seed`, truncated as usvg reads it.
    pub seed: i32,
    /// `stitchTiles="stitch"`.
    pub stitch: bool,
    /// `type="fractalNoise"` rather than `turbulence`.
    pub fractal: bool,
    /// The group transform's translation, device pixels: noise is sampled at
    /// `(device − origin) / scale` (resvg's mapping).
    pub origin: [f64; 2],
    /// The transform's axis scales.
    pub scale: [f64; 2],
}

/// A light source, in device pixels (z scaled as resvg scales it).
#[derive(Clone, Debug, PartialEq)]
pub enum LightSource {
    /// feDistantLight: degrees.
    Distant {
        /// Azimuth.
        azimuth: f64,
        /// Elevation.
        elevation: f64,
    },
    /// fePointLight at a position.
    Point {
        /// Position.
        pos: [f64; 3],
    },
    /// feSpotLight.
    Spot {
        /// Position.
        pos: [f64; 3],
        /// Where it points.
        points_at: [f64; 3],
        /// `specularExponent` of the cone's falloff.
        exponent: f64,
        /// `limitingConeAngle` in degrees.
        cone: Option<f64>,
    },
}

/// feDiffuseLighting or feSpecularLighting.
#[derive(Clone, Debug, PartialEq)]
pub struct Lighting {
    /// Input (only its alpha is read).
    pub input: FilterInput,
    /// `Some(specularExponent)` for feSpecularLighting.
    pub specular: Option<f64>,
    /// `surfaceScale`.
    pub surface_scale: f64,
    /// `diffuseConstant` or `specularConstant`.
    pub constant: f64,
    /// `lighting-color`, sRGB in `[0, 1]` (used as it is in either color space, as resvg).
    pub color: [f64; 3],
    /// The light.
    pub light: LightSource,
}

impl TransferFunction {
    /// The function's numbers, as parameters: a table's or discrete function's values,
    /// `slope, intercept`, or `amplitude, exponent, offset`.
    pub fn values_mut(&mut self) -> Vec<&mut f64> {
        match self {
            TransferFunction::Identity => Vec::new(),
            TransferFunction::Table(v) | TransferFunction::Discrete(v) => v.iter_mut().collect(),
            TransferFunction::Linear { slope, intercept } => vec![slope, intercept],
            TransferFunction::Gamma {
                amplitude,
                exponent,
                offset,
            } => vec![amplitude, exponent, offset],
        }
    }

    /// The number of [`values_mut`](Self::values_mut).
    pub fn value_count(&self) -> usize {
        match self {
            TransferFunction::Identity => 0,
            TransferFunction::Table(v) | TransferFunction::Discrete(v) => v.len(),
            TransferFunction::Linear { .. } => 2,
            TransferFunction::Gamma { .. } => 3,
        }
    }
}

impl Lighting {
    /// The primitive's numbers as parameters, in slot order, each with its group:
    /// `surfaceScale` and the diffuse or specular constant ([`ParamGroup::Filter`]),
    /// `lighting-color` ([`ParamGroup::Color`]), feSpecularLighting's exponent, then the
    /// light's: a distant light's azimuth and elevation (degrees), a point light's
    /// position, a spot light's position, where it points and its exponent (device pixels;
    /// the cone's angle is not a parameter: its edge is a jump).
    pub fn values_mut(&mut self) -> Vec<(ParamGroup, &mut f64)> {
        use ParamGroup::{Color, Filter};
        let mut v = vec![
            (Filter, &mut self.surface_scale),
            (Filter, &mut self.constant),
        ];
        v.extend(self.color.iter_mut().map(|c| (Color, c)));
        if let Some(e) = &mut self.specular {
            v.push((Filter, e));
        }
        match &mut self.light {
            LightSource::Distant { azimuth, elevation } => {
                v.push((Filter, azimuth));
                v.push((Filter, elevation));
            }
            LightSource::Point { pos } => v.extend(pos.iter_mut().map(|c| (Filter, c))),
            LightSource::Spot {
                pos,
                points_at,
                exponent,
                ..
            } => {
                v.extend(pos.iter_mut().map(|c| (Filter, c)));
                v.extend(points_at.iter_mut().map(|c| (Filter, c)));
                v.push((Filter, exponent));
            }
        }
        v
    }

    /// The values of [`values_mut`](Self::values_mut).
    pub(crate) fn values(&self) -> Vec<f64> {
        self.clone()
            .values_mut()
            .into_iter()
            .map(|(_, v)| *v)
            .collect()
    }

    /// The number of [`values_mut`](Self::values_mut).
    pub fn value_count(&self) -> usize {
        let light = match self.light {
            LightSource::Distant { .. } => 2,
            LightSource::Point { .. } => 3,
            LightSource::Spot { .. } => 7,
        };
        5 + self.specular.is_some() as usize + light
    }
}

impl Filter {
    /// Number of parameter slots of the filter's primitives.
    pub fn slot_count(&self) -> usize {
        self.primitives.iter().map(|p| p.kind.slot_count()).sum()
    }
}

impl FilterPrimitive {
    /// The primitive's parameters in slot order, each with its group (see the module
    /// docs): pixel quantities (offsets, deviations) and unitless ones (matrix values,
    /// `k1 … k4`) are [`ParamGroup::Filter`], a flood's or shadow's color
    /// [`ParamGroup::Color`] and its opacity [`ParamGroup::Opacity`].
    pub fn slots_mut(&mut self) -> Vec<(ParamGroup, &mut f64)> {
        use ParamGroup::{Color, Filter, Opacity};
        match &mut self.kind {
            FilterKind::Flood { color, opacity } => {
                let mut v: Vec<_> = color.iter_mut().map(|c| (Color, c)).collect();
                v.push((Opacity, opacity));
                v
            }
            FilterKind::Offset { dx, dy, .. } => vec![(Filter, dx), (Filter, dy)],
            FilterKind::Blur { std_dev, .. } => std_dev.iter_mut().map(|s| (Filter, s)).collect(),
            FilterKind::DropShadow {
                dx,
                dy,
                std_dev,
                color,
                opacity,
                ..
            } => {
                let mut v = vec![(Filter, dx), (Filter, dy)];
                v.extend(std_dev.iter_mut().map(|s| (Filter, s)));
                v.extend(color.iter_mut().map(|c| (Color, c)));
                v.push((Opacity, opacity));
                v
            }
            FilterKind::ColorMatrix { matrix, .. } => {
                matrix.iter_mut().map(|m| (Filter, m)).collect()
            }
            FilterKind::Lighting(l) => l.values_mut(),
            FilterKind::ComponentTransfer { funcs, .. } => funcs
                .iter_mut()
                .flat_map(TransferFunction::values_mut)
                .map(|v| (Filter, v))
                .collect(),
            FilterKind::Composite {
                op: CompositeOp::Arithmetic(k),
                ..
            } => k.iter_mut().map(|k| (Filter, k)).collect(),
            _ => Vec::new(),
        }
    }
}

impl FilterKind {
    /// Number of parameter slots ([`FilterPrimitive::slots_mut`]).
    pub fn slot_count(&self) -> usize {
        match self {
            FilterKind::Flood { .. } => 4,
            FilterKind::Offset { .. } | FilterKind::Blur { .. } => 2,
            FilterKind::DropShadow { .. } => 8,
            FilterKind::ColorMatrix { .. } => 20,
            FilterKind::ComponentTransfer { funcs, .. } => {
                funcs.iter().map(TransferFunction::value_count).sum()
            }
            FilterKind::Lighting(l) => l.value_count(),
            FilterKind::Composite {
                op: CompositeOp::Arithmetic(_),
                ..
            } => 4,
            _ => 0,
        }
    }

    /// Whether the primitive's [`ParamGroup::Filter`] slots are unitless (color-matrix
    /// values, feComposite's `k`) rather than device pixels.
    pub(crate) fn unitless(&self) -> bool {
        matches!(
            self,
            FilterKind::ColorMatrix { .. }
                | FilterKind::Composite { .. }
                | FilterKind::ComponentTransfer { .. }
        )
    }

    /// The inputs the primitive reads.
    pub fn inputs(&self) -> Vec<&FilterInput> {
        match self {
            FilterKind::Flood { .. } => Vec::new(),
            FilterKind::Offset { input, .. }
            | FilterKind::Blur { input, .. }
            | FilterKind::DropShadow { input, .. }
            | FilterKind::ColorMatrix { input, .. }
            | FilterKind::ComponentTransfer { input, .. }
            | FilterKind::Morphology { input, .. }
            | FilterKind::Tile { input } => vec![input],
            FilterKind::ConvolveMatrix(c) => vec![&c.input],
            FilterKind::Lighting(l) => vec![&l.input],
            FilterKind::Turbulence(_) | FilterKind::Image { .. } => Vec::new(),
            FilterKind::Merge { inputs } => inputs.iter().collect(),
            FilterKind::Blend { input1, input2, .. }
            | FilterKind::Composite { input1, input2, .. }
            | FilterKind::DisplacementMap { input1, input2, .. } => vec![input1, input2],
        }
    }
}

/// The saturate matrix of feColorMatrix (`values` clamped at 0, as resvg does).
pub(crate) fn saturate_matrix(v: f64) -> [f64; 20] {
    let v = v.max(0.0);
    rgb_matrix([
        0.213 + 0.787 * v,
        0.715 - 0.715 * v,
        0.072 - 0.072 * v,
        0.213 - 0.213 * v,
        0.715 + 0.285 * v,
        0.072 - 0.072 * v,
        0.213 - 0.213 * v,
        0.715 - 0.715 * v,
        0.072 + 0.928 * v,
    ])
}

/// The hueRotate matrix of feColorMatrix, for an angle in degrees.
pub(crate) fn hue_rotate_matrix(degrees: f64) -> [f64; 20] {
    let (a2, a1) = degrees.to_radians().sin_cos();
    rgb_matrix([
        0.213 + 0.787 * a1 - 0.213 * a2,
        0.715 - 0.715 * a1 - 0.715 * a2,
        0.072 - 0.072 * a1 + 0.928 * a2,
        0.213 - 0.213 * a1 + 0.143 * a2,
        0.715 + 0.285 * a1 + 0.140 * a2,
        0.072 - 0.072 * a1 - 0.283 * a2,
        0.213 - 0.213 * a1 - 0.787 * a2,
        0.715 - 0.715 * a1 + 0.715 * a2,
        0.072 + 0.928 * a1 + 0.072 * a2,
    ])
}

/// The luminanceToAlpha matrix of feColorMatrix.
pub(crate) fn luminance_to_alpha_matrix() -> [f64; 20] {
    let mut m = [0.0; 20];
    m[15..18].copy_from_slice(&[0.2125, 0.7154, 0.0721]);
    m
}

/// A 4 × 5 matrix that maps the color channels by `m` and keeps alpha.
fn rgb_matrix(m: [f64; 9]) -> [f64; 20] {
    let mut out = [0.0; 20];
    for r in 0..3 {
        out[r * 5..r * 5 + 3].copy_from_slice(&m[r * 3..r * 3 + 3]);
    }
    out[18] = 1.0;
    out
}

/// The axis scales resvg applies to blur deviations and offsets (tiny-skia's
/// `Transform::get_scale`): the norms of the matrix rows.
fn axis_scales(t: &super::Affine) -> (f64, f64) {
    (t[0].hypot(t[2]), t[1].hypot(t[3]))
}

/// A user-space rectangle's device box under `t`, whole pixels as resvg rounds it
/// (`Rect::to_int_rect`: the corner floored, the size rounded up, at least 1).
fn device_rect(r: usvg::NonZeroRect, t: &super::Affine) -> [i64; 4] {
    let corners = [
        [r.left() as f64, r.top() as f64],
        [r.right() as f64, r.top() as f64],
        [r.left() as f64, r.bottom() as f64],
        [r.right() as f64, r.bottom() as f64],
    ]
    .map(|p| super::apply(t, p));
    let (mut x0, mut y0, mut x1, mut y1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for [x, y] in corners {
        (x0, y0, x1, y1) = (x0.min(x), y0.min(y), x1.max(x), y1.max(y));
    }
    // In f32 as resvg computes it; bounded so that no later sum overflows (a region is
    // cut to the canvas before anything is allocated).
    let lim = 1e12;
    let (x, y) = ((x0 as f32).floor() as f64, (y0 as f32).floor() as f64);
    let w = (((x1 - x0) as f32).ceil() as f64).max(1.0);
    let h = (((y1 - y0) as f32).ceil() as f64).max(1.0);
    let c = |v: f64| v.clamp(-lim, lim) as i64;
    [c(x), c(y), c(x + w), c(y + h)]
}

/// A light source in device pixels: positions mapped by `t`, heights scaled by
/// `√(a² + d²) / √2` of its diagonal (resvg's scaling).
fn light(l: usvg::filter::LightSource, t: &super::Affine) -> LightSource {
    use usvg::filter::LightSource as L;
    let sz = t[0].hypot(t[3]) / std::f64::consts::SQRT_2;
    let at = |x: f32, y: f32, z: f32| {
        let [px, py] = super::apply(t, [x as f64, y as f64]);
        [px, py, z as f64 * sz]
    };
    match l {
        L::DistantLight(d) => LightSource::Distant {
            azimuth: d.azimuth as f64,
            elevation: d.elevation as f64,
        },
        L::PointLight(p) => LightSource::Point {
            pos: at(p.x, p.y, p.z),
        },
        L::SpotLight(s) => LightSource::Spot {
            pos: at(s.x, s.y, s.z),
            points_at: at(s.points_at_x, s.points_at_y, s.points_at_z),
            exponent: s.specular_exponent.get() as f64,
            cone: s.limiting_cone_angle.map(|a| a as f64),
        },
    }
}

fn color(c: usvg::Color) -> [f64; 3] {
    [c.red, c.green, c.blue].map(|v| v as f64 / 255.0)
}

fn transfer(f: &usvg::filter::TransferFunction) -> TransferFunction {
    use usvg::filter::TransferFunction as U;
    let vals = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<f64>>();
    match f {
        U::Identity => TransferFunction::Identity,
        // An empty table changes nothing (resvg skips it).
        U::Table(v) if v.is_empty() => TransferFunction::Identity,
        U::Discrete(v) if v.is_empty() => TransferFunction::Identity,
        U::Table(v) => TransferFunction::Table(vals(v)),
        U::Discrete(v) => TransferFunction::Discrete(vals(v)),
        U::Linear { slope, intercept } => TransferFunction::Linear {
            slope: *slope as f64,
            intercept: *intercept as f64,
        },
        U::Gamma {
            amplitude,
            exponent,
            offset,
        } => TransferFunction::Gamma {
            amplitude: *amplitude as f64,
            exponent: *exponent as f64,
            offset: *offset as f64,
        },
    }
}

/// Converts feImage's content (a usvg group) to scene nodes drawn under a transform to
/// device pixels; `Err` says why it is refused.
pub(crate) type ImageContent<'a> =
    dyn Fn(&usvg::Group, &super::Affine) -> Result<Vec<super::Node>, String> + 'a;

/// Converts usvg's filters of a group whose user space `t` maps to device pixels; `Err`
/// names a primitive diffsvg does not render.
pub(crate) fn from_usvg(
    filters: &[std::sync::Arc<usvg::filter::Filter>],
    t: &super::Affine,
    blend: impl Fn(usvg::BlendMode) -> BlendMode,
    image: &ImageContent<'_>,
) -> Result<Vec<Filter>, String> {
    use usvg::filter::Kind as K;
    let (sx, sy) = axis_scales(t);
    let count: usize = filters.iter().map(|f| f.primitives().len()).sum();
    if count > crate::limits::MAX_FILTER_PRIMITIVES {
        return Err(format!(
            "filters of {count} primitives on one element (limit {})",
            crate::limits::MAX_FILTER_PRIMITIVES
        ));
    }
    let mut out = Vec::with_capacity(filters.len());
    for f in filters {
        let mut prims: Vec<FilterPrimitive> = Vec::new();
        for p in f.primitives() {
            // A reference to an unknown name is the source graphic (resvg's fallback);
            // the latest result of that name wins.
            let input = |i: &usvg::filter::Input| match i {
                usvg::filter::Input::SourceGraphic => FilterInput::SourceGraphic,
                usvg::filter::Input::SourceAlpha => FilterInput::SourceAlpha,
                usvg::filter::Input::Reference(name) => prims
                    .iter()
                    .rposition(|q| q.result == *name)
                    .map_or(FilterInput::SourceGraphic, FilterInput::Result),
            };
            let std_dev = |x: usvg::PositiveF32, y: usvg::PositiveF32| {
                [x.get() as f64 * sx, y.get() as f64 * sy]
            };
            let kind = match p.kind() {
                K::Flood(fe) => FilterKind::Flood {
                    color: color(fe.color()),
                    opacity: fe.opacity().get() as f64,
                },
                K::Offset(fe) => FilterKind::Offset {
                    input: input(fe.input()),
                    dx: fe.dx() as f64 * sx,
                    dy: fe.dy() as f64 * sy,
                },
                K::GaussianBlur(fe) => FilterKind::Blur {
                    input: input(fe.input()),
                    std_dev: std_dev(fe.std_dev_x(), fe.std_dev_y()),
                },
                K::DropShadow(fe) => FilterKind::DropShadow {
                    input: input(fe.input()),
                    dx: fe.dx() as f64 * sx,
                    dy: fe.dy() as f64 * sy,
                    std_dev: std_dev(fe.std_dev_x(), fe.std_dev_y()),
                    color: color(fe.color()),
                    opacity: fe.opacity().get() as f64,
                },
                K::Merge(fe) => FilterKind::Merge {
                    inputs: fe.inputs().iter().map(input).collect(),
                },
                K::Blend(fe) => FilterKind::Blend {
                    input1: input(fe.input1()),
                    input2: input(fe.input2()),
                    mode: blend(fe.mode()),
                },
                K::Composite(fe) => {
                    use usvg::filter::CompositeOperator as O;
                    FilterKind::Composite {
                        input1: input(fe.input1()),
                        input2: input(fe.input2()),
                        op: match fe.operator() {
                            O::Over => CompositeOp::Over,
                            O::In => CompositeOp::In,
                            O::Out => CompositeOp::Out,
                            O::Atop => CompositeOp::Atop,
                            O::Xor => CompositeOp::Xor,
                            O::Lighter => CompositeOp::Lighter,
                            O::Arithmetic { k1, k2, k3, k4 } => {
                                CompositeOp::Arithmetic([k1, k2, k3, k4].map(|k| k as f64))
                            }
                        },
                    }
                }
                K::ColorMatrix(fe) => {
                    use usvg::filter::ColorMatrixKind as M;
                    FilterKind::ColorMatrix {
                        input: input(fe.input()),
                        matrix: match fe.kind() {
                            M::Matrix(v) => {
                                std::array::from_fn(|i| v.get(i).copied().unwrap_or(0.0) as f64)
                            }
                            M::Saturate(v) => saturate_matrix(v.get() as f64),
                            M::HueRotate(a) => hue_rotate_matrix(*a as f64),
                            M::LuminanceToAlpha => luminance_to_alpha_matrix(),
                        },
                    }
                }
                K::ComponentTransfer(fe) => FilterKind::ComponentTransfer {
                    input: input(fe.input()),
                    funcs: Box::new([
                        transfer(fe.func_r()),
                        transfer(fe.func_g()),
                        transfer(fe.func_b()),
                        transfer(fe.func_a()),
                    ]),
                },
                K::Morphology(fe) => FilterKind::Morphology {
                    input: input(fe.input()),
                    dilate: fe.operator() == usvg::filter::MorphologyOperator::Dilate,
                    radius: [
                        fe.radius_x().get() as f64 * sx,
                        fe.radius_y().get() as f64 * sy,
                    ],
                },
                K::ConvolveMatrix(fe) => {
                    let m = fe.matrix();
                    let taps = m.data().len();
                    if taps > crate::limits::MAX_CONVOLVE_TAPS {
                        return Err(format!(
                            "feConvolveMatrix of {taps} values (limit {})",
                            crate::limits::MAX_CONVOLVE_TAPS
                        ));
                    }
                    use usvg::filter::EdgeMode as E;
                    FilterKind::ConvolveMatrix(Box::new(Convolve {
                        input: input(fe.input()),
                        order: [m.columns() as usize, m.rows() as usize],
                        kernel: m.data().iter().map(|&v| v as f64).collect(),
                        target: [m.target_x() as usize, m.target_y() as usize],
                        divisor: fe.divisor().get() as f64,
                        bias: fe.bias() as f64,
                        edge: match fe.edge_mode() {
                            E::None => 0,
                            E::Duplicate => 1,
                            E::Wrap => 2,
                        },
                        preserve_alpha: fe.preserve_alpha(),
                    }))
                }
                K::Tile(fe) => FilterKind::Tile {
                    input: input(fe.input()),
                },
                K::DisplacementMap(fe) => {
                    use usvg::filter::ColorChannel as C;
                    let ch = |c: C| match c {
                        C::R => 0,
                        C::G => 1,
                        C::B => 2,
                        C::A => 3,
                    };
                    let s = fe.scale() as f64;
                    FilterKind::DisplacementMap {
                        input1: input(fe.input1()),
                        input2: input(fe.input2()),
                        scale: [s * s * sx, s * s * sy],
                        channels: [ch(fe.x_channel_selector()), ch(fe.y_channel_selector())],
                    }
                }
                K::Turbulence(fe) => FilterKind::Turbulence(Box::new(Turbulence {
                    base_frequency: [
                        fe.base_frequency_x().get() as f64,
                        fe.base_frequency_y().get() as f64,
                    ],
                    octaves: fe.num_octaves().min(crate::limits::MAX_TURBULENCE_OCTAVES),
                    seed: fe.seed(),
                    stitch: fe.stitch_tiles(),
                    fractal: fe.kind() == usvg::filter::TurbulenceKind::FractalNoise,
                    origin: [t[4], t[5]],
                    scale: [sx, sy],
                })),
                K::DiffuseLighting(fe) => FilterKind::Lighting(Box::new(Lighting {
                    input: input(fe.input()),
                    specular: None,
                    surface_scale: fe.surface_scale() as f64,
                    constant: fe.diffuse_constant() as f64,
                    color: color(fe.lighting_color()),
                    light: light(fe.light_source(), t),
                })),
                K::SpecularLighting(fe) => FilterKind::Lighting(Box::new(Lighting {
                    input: input(fe.input()),
                    specular: Some(fe.specular_exponent() as f64),
                    surface_scale: fe.surface_scale() as f64,
                    constant: fe.specular_constant() as f64,
                    color: color(fe.lighting_color()),
                    light: light(fe.light_source(), t),
                })),
                K::Image(fe) => {
                    // resvg draws the content scaled by the axis scales, its origin at
                    // the subregion's device corner.
                    let sub = device_rect(p.rect(), t);
                    let at = [sx, 0.0, 0.0, sy, sub[0] as f64, sub[1] as f64];
                    FilterKind::Image {
                        nodes: image(fe.root(), &at)
                            .map_err(|e| format!("feImage whose content is refused: {e}"))?,
                    }
                }
            };
            prims.push(FilterPrimitive {
                subregion: device_rect(p.rect(), t),
                linear_rgb: p.color_interpolation() == usvg::filter::ColorInterpolation::LinearRGB,
                result: p.result().to_string(),
                kind,
            });
        }
        out.push(Filter {
            id: f.id().to_string(),
            region: device_rect(f.rect(), t),
            primitives: prims,
        });
    }
    Ok(out)
}
