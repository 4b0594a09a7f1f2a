//! SVG filters as differentiable image operators (issue 34).
//!
//! A group with filters is a layer covering the filters' regions (cut to the canvas).
//! Its children are rendered on their own ([`FilterLayer::content`], the whole canvas),
//! the layer is cut out of that rendering, each filter's primitives run over it in
//! order, and the result is what the band renderer composites (with the group's clip
//! path, mask, opacity and blend mode, as for any layer). The backward pass collects
//! `∂L/∂layer` band by band, runs it back through the primitives ([`adjoint`]) and then
//! through the children's own backward pass.
//!
//! Images here are premultiplied `f32`, layer-sized and row-major; each result carries
//! its color space (sRGB or linearRGB) and inputs are converted to a primitive's
//! `color-interpolation-filters` when they are read, as resvg does. Semantics follow
//! resvg's `crates/resvg/src/filter/` (feOffset by whole pixels, feDropShadow's color
//! conversion, feFlood's result in sRGB, a primitive's result cleared outside its
//! subregion except feOffset's). One file per family: [`blur`] (feGaussianBlur and
//! feDropShadow's blur), [`pixel`] (the per-pixel operators), [`morphology`],
//! [`convolve`], [`tile`] (feTile and feDisplacementMap), [`turbulence`] and [`lighting`];
//! offsets and merges here. The last five run on the filter region's pixels (resvg's
//! images are region-sized: edges, wrapping and light positions refer to it).

mod blur;
mod convolve;
mod lighting;
mod morphology;
mod pixel;
mod tile;
mod turbulence;

use crate::raster::jet::{Jet, Scalar};
use crate::scene::Scene;
use crate::scene::filter::{CompositeOp, Filter, FilterInput, FilterKind};

/// A filtered group of a prepared scene.
#[derive(Clone, Debug)]
pub(crate) struct FilterLayer {
    /// The layer, `[x0, y0, x1, y1]` in canvas pixels (end exclusive, not empty).
    pub(crate) rect: [usize; 4],
    /// The filtered layer, `rect`-sized, row-major; empty for a group inside another
    /// filtered group (never drawn: the outer group's layer holds it).
    pub(crate) image: Vec<[f32; 4]>,
    /// Index in [`Prepared::ops`](super::Prepared) of the first op after the children.
    pub(crate) body_end: usize,
    /// Group spans opened up to the end of the children.
    pub(crate) groups_end: usize,
    /// The children on the canvas, as a scene of their own.
    pub(crate) content: Scene,
    /// The filters, in order.
    pub(crate) filters: Vec<Filter>,
    /// The group's index among the groups with an opacity parameter
    /// ([`ParamLayout::groups`](crate::scene::ParamLayout::groups)): its children's
    /// parameters follow that slot.
    pub(crate) param_group: usize,
}

impl FilterLayer {
    /// The layer's rows `y0 .. y0 + rows` (canvas rows inside [`rect`](Self::rect)).
    pub(crate) fn rows(&self, y0: usize, rows: usize) -> Vec<[f32; 4]> {
        let w = self.rect[2] - self.rect[0];
        let from = (y0 - self.rect[1]) * w;
        self.image[from..from + rows * w].to_vec()
    }
}

/// The layer of a group with `filters` on a `width × height` canvas: the union of their
/// regions, cut to the canvas; `None` when that is empty.
pub(crate) fn layer_rect(filters: &[Filter], width: u32, height: u32) -> Option<[usize; 4]> {
    let mut u = [i64::MAX, i64::MAX, i64::MIN, i64::MIN];
    for f in filters {
        let r = f.region;
        u = [
            u[0].min(r[0]),
            u[1].min(r[1]),
            u[2].max(r[2]),
            u[3].max(r[3]),
        ];
    }
    let (w, h) = (width as i64, height as i64);
    let r = [
        u[0].clamp(0, w),
        u[1].clamp(0, h),
        u[2].clamp(0, w),
        u[3].clamp(0, h),
    ];
    (r[0] < r[2] && r[1] < r[3]).then(|| r.map(|v| v as usize))
}

/// The `rect` part of a canvas-sized image.
pub(crate) fn crop(img: &[[f32; 4]], width: usize, rect: [usize; 4]) -> Vec<[f32; 4]> {
    let mut out = Vec::with_capacity((rect[2] - rect[0]) * (rect[3] - rect[1]));
    for y in rect[1]..rect[3] {
        out.extend_from_slice(&img[y * width + rect[0]..y * width + rect[2]]);
    }
    out
}

/// The layer's frame: its size and where it lies on the canvas.
#[derive(Clone, Copy)]
struct Frame {
    w: usize,
    h: usize,
    x0: i64,
    y0: i64,
}

impl Frame {
    fn of(rect: [usize; 4]) -> Frame {
        Frame {
            w: rect[2] - rect[0],
            h: rect[3] - rect[1],
            x0: rect[0] as i64,
            y0: rect[1] as i64,
        }
    }

    /// A device rectangle in layer pixels, cut to the layer.
    fn local(&self, r: [i64; 4]) -> [usize; 4] {
        let cx = |v: i64| (v - self.x0).clamp(0, self.w as i64) as usize;
        let cy = |v: i64| (v - self.y0).clamp(0, self.h as i64) as usize;
        [cx(r[0]), cy(r[1]), cx(r[2]), cy(r[3])]
    }

    /// Clears the pixels outside `r` (layer pixels).
    fn clear_outside(&self, px: &mut [[f32; 4]], r: [usize; 4]) {
        for y in 0..self.h {
            for x in 0..self.w {
                if x < r[0] || x >= r[2] || y < r[1] || y >= r[3] {
                    px[y * self.w + x] = [0.0; 4];
                }
            }
        }
    }

    /// `px` moved by `(dx, dy)` whole pixels, transparent where nothing lands.
    fn shift(&self, px: &[[f32; 4]], dx: i64, dy: i64) -> Vec<[f32; 4]> {
        let mut out = vec![[0.0; 4]; px.len()];
        let (w, h) = (self.w as i64, self.h as i64);
        for y in 0..h {
            let ty = y + dy;
            if ty < 0 || ty >= h {
                continue;
            }
            for x in 0..w {
                let tx = x + dx;
                if tx >= 0 && tx < w {
                    out[(ty * w + tx) as usize] = px[(y * w + x) as usize];
                }
            }
        }
        out
    }

    /// The whole shifts and weights of a move by `(dx, dy)` pixels: the four neighbours
    /// of `(⌊dx⌋, ⌊dy⌋)` with bilinear weights (one with weight 1 at whole offsets), or
    /// resvg's truncated offset alone (`!exact`).
    fn shifts(dx: f64, dy: f64, exact: bool) -> Vec<(i64, i64, f32)> {
        if !exact {
            return match whole_offset(dx, dy) {
                Some((x, y)) => vec![(x, y, 1.0)],
                None => vec![(0, 0, 1.0)],
            };
        }
        let (ix, iy) = (dx.floor(), dy.floor());
        let (fx, fy) = ((dx - ix) as f32, (dy - iy) as f32);
        let (ix, iy) = (ix as i64, iy as i64);
        [
            (ix, iy, (1.0 - fx) * (1.0 - fy)),
            (ix + 1, iy, fx * (1.0 - fy)),
            (ix, iy + 1, (1.0 - fx) * fy),
            (ix + 1, iy + 1, fx * fy),
        ]
        .into_iter()
        .filter(|s| s.2 != 0.0)
        .collect()
    }

    /// `px` moved by `(dx, dy)` ([`shifts`](Self::shifts)); `back` moves the other way
    /// (the adjoint).
    fn moved(&self, px: &[[f32; 4]], dx: f64, dy: f64, exact: bool, back: bool) -> Vec<[f32; 4]> {
        let sign = if back { -1 } else { 1 };
        let shifts = Frame::shifts(dx, dy, exact);
        // A whole shift (resvg's always) is a copy: no weighted sum.
        if let [(x, y, 1.0)] = shifts[..] {
            return self.shift(px, sign * x, sign * y);
        }
        let mut out = vec![[0.0f32; 4]; px.len()];
        for (x, y, wgt) in shifts {
            let s = self.shift(px, sign * x, sign * y);
            for (o, v) in out.iter_mut().zip(&s) {
                for c in 0..4 {
                    o[c] += wgt * v[c];
                }
            }
        }
        out
    }

    /// `(∂L/∂dx, ∂L/∂dy)` of the exact move of `px` by `(dx, dy)`, given `g = ∂L/∂moved`:
    /// the bilinear weights' derivatives (one-sided, from the right, at whole offsets).
    fn move_gradient(&self, px: &[[f32; 4]], dx: f64, dy: f64, g: &[[f32; 4]]) -> [f64; 2] {
        let (ix, iy) = (dx.floor(), dy.floor());
        let (fx, fy) = (dx - ix, dy - iy);
        let (ix, iy) = (ix as i64, iy as i64);
        let at = |a: i64, b: i64| blur::dot(g, &self.shift(px, ix + a, iy + b));
        let (g00, g10, g01, g11) = (at(0, 0), at(1, 0), at(0, 1), at(1, 1));
        [
            (1.0 - fy) * (g10 - g00) + fy * (g11 - g01),
            (1.0 - fx) * (g01 - g00) + fx * (g11 - g10),
        ]
    }
}

/// A primitive's result with its color space.
#[derive(Clone)]
struct Res {
    px: Vec<[f32; 4]>,
    linear: bool,
}

/// resvg's whole-pixel offset (`dx as i32`), `None` when both are zero.
fn whole_offset(dx: f64, dy: f64) -> Option<(i64, i64)> {
    let (x, y) = (dx.trunc() as i64, dy.trunc() as i64);
    (x != 0 || y != 0).then_some((x, y))
}

/// `s` source-over `d`, premultiplied.
#[inline]
fn over(s: [f32; 4], d: [f32; 4]) -> [f32; 4] {
    std::array::from_fn(|c| s[c] + d[c] * (1.0 - s[3]))
}

/// The adjoint of [`over`]: `(∂L/∂s, ∂L/∂d)`.
#[inline]
fn over_adjoint(s: [f32; 4], d: [f32; 4], g: [f32; 4]) -> ([f32; 4], [f32; 4]) {
    let mut gs = g;
    gs[3] -= (0..4).map(|c| g[c] * d[c]).sum::<f32>();
    (gs, g.map(|v| v * (1.0 - s[3])))
}

/// feFlood's (and feDropShadow's) color at alpha `a`, premultiplied.
fn flood<S: Scalar>(color: [S; 3], opacity: S, a: S) -> [S; 4] {
    let al = a * opacity;
    [color[0] * al, color[1] * al, color[2] * al, al]
}

/// [`flood`] of constant parameters.
fn flood_of<S: Scalar>(color: [f64; 3], opacity: f64, a: S) -> [S; 4] {
    flood(color.map(S::c), S::c(opacity), a)
}

/// One filter's primitives run over `src`, keeping every result.
struct Run<'a> {
    f: &'a Filter,
    fr: Frame,
    /// [`RenderOptions::exact_filters`](crate::raster::RenderOptions::exact_filters).
    exact: bool,
    src: Res,
    alpha: Res,
    results: Vec<Res>,
}

impl<'a> Run<'a> {
    fn new(f: &'a Filter, fr: Frame, src: &[[f32; 4]], exact: bool) -> Self {
        let src = Res {
            px: src.to_vec(),
            linear: false,
        };
        let alpha = Res {
            px: src.px.iter().map(|p| [0.0, 0.0, 0.0, p[3]]).collect(),
            linear: false,
        };
        let mut run = Run {
            f,
            fr,
            exact,
            src,
            alpha,
            results: Vec::with_capacity(f.primitives.len()),
        };
        for k in 0..f.primitives.len() {
            let r = run.primitive(k);
            run.results.push(r);
        }
        run
    }

    fn input(&self, i: &FilterInput) -> &Res {
        match i {
            FilterInput::SourceGraphic => &self.src,
            FilterInput::SourceAlpha => &self.alpha,
            FilterInput::Result(k) => &self.results[*k],
        }
    }

    /// An input in color space `linear`.
    fn input_in(&self, i: &FilterInput, linear: bool) -> Vec<[f32; 4]> {
        let r = self.input(i);
        if r.linear == linear {
            r.px.clone()
        } else {
            r.px.iter()
                .map(|&p| pixel::eval1(&|v| pixel::convert(v, linear), p))
                .collect()
        }
    }

    /// Primitive `k`'s result (earlier results known).
    fn primitive(&self, k: usize) -> Res {
        let p = &self.f.primitives[k];
        let cs = p.linear_rgb;
        let fr = self.fr;
        let mut res = match &p.kind {
            FilterKind::Flood { color, opacity } => Res {
                px: vec![flood_of(*color, *opacity, 1.0f64).map(|v| v as f32); fr.w * fr.h],
                linear: false,
            },
            FilterKind::Offset { input, dx, dy } => {
                let r = self.input(input);
                Res {
                    px: fr.moved(&r.px, *dx, *dy, self.exact, false),
                    linear: r.linear,
                }
            }
            FilterKind::Blur { input, std_dev } => {
                let passes = blur::passes(*std_dev, self.exact);
                if passes.is_empty() {
                    self.input(input).clone()
                } else {
                    let mut px = self.input_in(input, cs);
                    blur::apply(&mut px, fr.w, fr.h, &passes);
                    Res { px, linear: cs }
                }
            }
            FilterKind::DropShadow { input, .. } => {
                let (x, _, _, shifted) = self.drop_shadow(p, input);
                let px = x.iter().zip(&shifted).map(|(&s, &d)| over(s, d)).collect();
                Res { px, linear: cs }
            }
            FilterKind::Merge { inputs } => {
                let mut px = vec![[0.0f32; 4]; fr.w * fr.h];
                for i in inputs {
                    for (d, s) in px.iter_mut().zip(self.input_in(i, cs)) {
                        *d = over(s, *d);
                    }
                }
                Res { px, linear: cs }
            }
            FilterKind::Blend {
                input1,
                input2,
                mode,
            } => self.binary(input1, input2, cs, |a, b| pixel::blend(*mode, a, b)),
            FilterKind::Composite { input1, input2, op } => {
                self.binary(input1, input2, cs, |a, b| pixel::composite(*op, a, b))
            }
            FilterKind::ColorMatrix { input, matrix } => {
                self.unary(input, cs, |v| pixel::color_matrix(v, matrix))
            }
            FilterKind::ComponentTransfer { input, funcs } => {
                self.unary(input, cs, |v| pixel::component_transfer(v, funcs))
            }
            FilterKind::Morphology {
                input,
                dilate,
                radius,
            } => {
                let x = self.input_in(input, cs);
                let px = self.in_region(&x, |img, w, h| {
                    morphology::apply(img, w, h, *dilate, *radius)
                });
                Res { px, linear: cs }
            }
            FilterKind::ConvolveMatrix(m) => {
                let x = self.input_in(&m.input, cs);
                let px = self.in_region(&x, |img, w, h| convolve::apply(m, img, w, h));
                Res { px, linear: cs }
            }
            FilterKind::Tile { input } => {
                // resvg copies the input as it is and calls the result sRGB.
                let src = self.tile_sources(input);
                let px = self.in_region(&self.input(input).px, |img, _, _| {
                    src.map_or_else(|| vec![[0.0; 4]; img.len()], |s| tile::gather(img, &s))
                });
                Res { px, linear: false }
            }
            FilterKind::DisplacementMap {
                input1,
                input2,
                scale,
                channels,
            } => {
                let x = self.input_in(input1, cs);
                let src = self.displacement_sources(input2, cs, *scale, *channels);
                let px = self.in_region(&x, |img, _, _| tile::gather(img, &src));
                Res { px, linear: cs }
            }
            FilterKind::Turbulence(t) => {
                let corner = self.corner();
                let px = self.in_region(&[], |_, w, h| turbulence::render(t, w, h, corner));
                Res { px, linear: cs }
            }
            FilterKind::Lighting(l) => {
                let setup = lighting::Setup::new(l, self.corner());
                let x = &self.input(&l.input).px;
                let px = self.in_region(x, |img, w, h| lighting::apply(&setup, img, w, h));
                Res { px, linear: cs }
            }
            FilterKind::Image { nodes } => Res {
                px: self.picture(nodes),
                linear: false,
            },
        };
        if !matches!(p.kind, FilterKind::Offset { .. }) {
            fr.clear_outside(&mut res.px, fr.local(p.subregion));
        }
        res
    }

    /// feImage's nodes (device pixels) drawn on a canvas reaching the layer, cut to it.
    fn picture(&self, nodes: &[crate::scene::Node]) -> Vec<[f32; 4]> {
        let fr = self.fr;
        let (cw, ch) = (fr.x0 as usize + fr.w, fr.y0 as usize + fr.h);
        let scene = Scene {
            width: cw as u32,
            height: ch as u32,
            nodes: nodes.to_vec(),
        };
        let img = crate::raster::render(&scene, &crate::raster::RenderOptions::default());
        let rect = [fr.x0 as usize, fr.y0 as usize, cw, ch];
        crop(&img.data, cw, rect)
    }

    /// The filter region in layer pixels (resvg's images are this size).
    fn region(&self) -> [usize; 4] {
        self.fr.local(self.f.region)
    }

    /// The region's top-left pixel on the canvas.
    fn corner(&self) -> [i64; 2] {
        let r = self.region();
        [self.fr.x0 + r[0] as i64, self.fr.y0 + r[1] as i64]
    }

    /// `f` run on the region's part of `px` (empty: nothing to read) and its size; the
    /// result placed back in a layer-sized image, transparent outside the region.
    fn in_region(
        &self,
        px: &[[f32; 4]],
        f: impl FnOnce(&[[f32; 4]], usize, usize) -> Vec<[f32; 4]>,
    ) -> Vec<[f32; 4]> {
        let r = self.region();
        let (w, h) = (r[2] - r[0], r[3] - r[1]);
        let mut out = vec![[0.0f32; 4]; self.fr.w * self.fr.h];
        if w == 0 || h == 0 {
            return out;
        }
        let sub = if px.is_empty() {
            Vec::new()
        } else {
            crop(px, self.fr.w, r)
        };
        let res = f(&sub, w, h);
        for y in 0..h {
            let at = (r[1] + y) * self.fr.w + r[0];
            out[at..at + w].copy_from_slice(&res[y * w..(y + 1) * w]);
        }
        out
    }

    /// resvg's record of where primitive `k`'s result holds data (`Image::region`): its
    /// subregion on the canvas, feOffset's taken from a named input; when that equals the
    /// filter region, the region's size at the origin (resvg's quirk, which feTile then
    /// reads shifted).
    fn data_rect(&self, k: usize) -> [i64; 4] {
        let p = &self.f.primitives[k];
        let sub = match &p.kind {
            FilterKind::Offset {
                input: FilterInput::Result(j),
                ..
            } => self.data_rect(*j),
            _ => p.subregion,
        };
        let r = self.region();
        let c = self.corner();
        let (w, h) = ((r[2] - r[0]) as i64, (r[3] - r[1]) as i64);
        if sub == [c[0], c[1], c[0] + w, c[1] + h] {
            [0, 0, w, h]
        } else {
            sub
        }
    }

    /// feTile's copy of input `i` in region pixels; `None` when its tile is empty.
    fn tile_sources(&self, i: &FilterInput) -> Option<tile::Sources> {
        let r = self.region();
        let (w, h) = (r[2] - r[0], r[3] - r[1]);
        let c = self.corner();
        let rect = match i {
            FilterInput::Result(k) => {
                let d = self.data_rect(*k);
                [d[0] - c[0], d[1] - c[1], d[2] - c[0], d[3] - c[1]]
            }
            _ => [0, 0, w as i64, h as i64],
        };
        let t = [
            rect[0].clamp(0, w as i64) as usize,
            rect[1].clamp(0, h as i64) as usize,
            rect[2].clamp(0, w as i64) as usize,
            rect[3].clamp(0, h as i64) as usize,
        ];
        (t[0] < t[2] && t[1] < t[3]).then(|| tile::tile_sources(w, h, t, [rect[0], rect[1]]))
    }

    /// feDisplacementMap's source pixels (region pixels) from map `i2` in space `cs`.
    fn displacement_sources(
        &self,
        i2: &FilterInput,
        cs: bool,
        scale: [f64; 2],
        channels: [usize; 2],
    ) -> tile::Sources {
        let r = self.region();
        let (w, h) = (r[2] - r[0], r[3] - r[1]);
        let map = crop(&self.input_in(i2, cs), self.fr.w, r);
        tile::displacement_sources(&map, w, h, scale, channels)
    }

    /// The adjoint of an [`in_region`](Self::in_region) operator: `f(x, g, w, h)` gives
    /// the region's input gradient from its input and output gradient.
    fn region_adjoint(
        &self,
        x: &[[f32; 4]],
        g: &[[f32; 4]],
        f: impl FnOnce(&[[f32; 4]], &[[f32; 4]], usize, usize) -> Vec<[f32; 4]>,
    ) -> Vec<[f32; 4]> {
        let r = self.region();
        let gx = crop(g, self.fr.w, r);
        self.in_region(x, |xs, w, h| f(xs, &gx, w, h))
    }

    fn unary(&self, i: &FilterInput, cs: bool, f: impl Fn([f64; 4]) -> [f64; 4]) -> Res {
        let px = self
            .input_in(i, cs)
            .into_iter()
            .map(|p| pixel::eval1(&f, p))
            .collect();
        Res { px, linear: cs }
    }

    fn binary(
        &self,
        i1: &FilterInput,
        i2: &FilterInput,
        cs: bool,
        f: impl Fn([f64; 4], [f64; 4]) -> [f64; 4],
    ) -> Res {
        let b = self.input_in(i2, cs);
        let px = self
            .input_in(i1, cs)
            .into_iter()
            .zip(b)
            .map(|(a, b)| pixel::eval2(&f, a, b))
            .collect();
        Res { px, linear: cs }
    }

    /// feDropShadow's parts: the input in the primitive's color space, its blurred copy,
    /// the shadow (flooded, converted as resvg converts it) and the shadow moved.
    #[allow(clippy::type_complexity)]
    fn drop_shadow(
        &self,
        p: &crate::scene::filter::FilterPrimitive,
        input: &FilterInput,
    ) -> (Vec<[f32; 4]>, Vec<[f32; 4]>, Vec<[f32; 4]>, Vec<[f32; 4]>) {
        let FilterKind::DropShadow {
            dx,
            dy,
            std_dev,
            color,
            opacity,
            ..
        } = &p.kind
        else {
            unreachable!("a drop shadow")
        };
        let cs = p.linear_rgb;
        let x = self.input_in(input, cs);
        let mut blurred = x.clone();
        blur::apply(
            &mut blurred,
            self.fr.w,
            self.fr.h,
            &blur::passes(*std_dev, self.exact),
        );
        // resvg floods the shadow with the sRGB color, then converts it "into" the
        // primitive's space: to linearRGB, or (its quirk) from linear to sRGB.
        let shadow: Vec<[f32; 4]> = blurred
            .iter()
            .map(|b| {
                let fl = flood_of(*color, *opacity, b[3] as f64);
                pixel::convert(fl, cs).map(|v| v as f32)
            })
            .collect();
        let shifted = self.fr.moved(&shadow, *dx, *dy, self.exact, false);
        (x, blurred, shadow, shifted)
    }

    /// The filter's output: the last result in sRGB, cleared outside the region.
    fn output(&self) -> Vec<[f32; 4]> {
        let Some(last) = self.results.last() else {
            return vec![[0.0; 4]; self.fr.w * self.fr.h];
        };
        let mut px: Vec<[f32; 4]> = if last.linear {
            last.px
                .iter()
                .map(|&p| pixel::eval1(&|v| pixel::convert(v, false), p))
                .collect()
        } else {
            last.px.clone()
        };
        self.fr.clear_outside(&mut px, self.fr.local(self.f.region));
        px
    }
}

/// Runs `filters` in order over `src`, the layer `rect` (canvas pixels) of a group's
/// rendered children; returns the filtered layer. `exact`:
/// [`RenderOptions::exact_filters`](crate::raster::RenderOptions::exact_filters).
pub(crate) fn apply(
    filters: &[Filter],
    rect: [usize; 4],
    src: Vec<[f32; 4]>,
    exact: bool,
) -> Vec<[f32; 4]> {
    let fr = Frame::of(rect);
    filters
        .iter()
        .fold(src, |px, f| Run::new(f, fr, &px, exact).output())
}

/// The adjoint of [`apply`] at `src`: `∂L/∂src` from `∂L/∂output`, and the gradient of
/// the filters' parameters in slot order
/// ([`FilterPrimitive::slots_mut`](crate::scene::filter::FilterPrimitive::slots_mut),
/// filter by filter).
pub(crate) fn adjoint(
    filters: &[Filter],
    rect: [usize; 4],
    src: Vec<[f32; 4]>,
    g_out: Vec<[f32; 4]>,
    exact: bool,
) -> (Vec<[f32; 4]>, Vec<f64>) {
    let fr = Frame::of(rect);
    let mut sources = vec![src];
    for f in &filters[..filters.len().saturating_sub(1)] {
        let next = Run::new(f, fr, sources.last().expect("a source"), exact).output();
        sources.push(next);
    }
    let mut g = g_out;
    let mut params: Vec<Vec<f64>> = Vec::with_capacity(filters.len());
    for (f, src) in filters.iter().zip(&sources).rev() {
        let (gs, gp) = Back::new(Run::new(f, fr, src, exact)).run(g);
        g = gs;
        params.push(gp);
    }
    (g, params.into_iter().rev().flatten().collect())
}

/// `Σ_pixels Σ_channels g · ∂out/∂θ` for a per-pixel operator `out(i)` seeded on `K`
/// parameters `θ` (pixels where `g` is zero skipped).
fn param_gradient<const K: usize>(g: &[[f32; 4]], out: impl Fn(usize) -> [Jet<K>; 4]) -> [f64; K] {
    let mut acc = [0.0f64; K];
    for (i, gv) in g.iter().enumerate() {
        if *gv == [0.0; 4] {
            continue;
        }
        let y = out(i);
        for (j, a) in acc.iter_mut().enumerate() {
            *a += (0..4).map(|o| gv[o] as f64 * y[o].d[j]).sum::<f64>();
        }
    }
    acc
}

/// The reverse walk of one filter's [`Run`].
struct Back<'a> {
    run: Run<'a>,
    /// `∂L/∂result`, per primitive (`None`: zero).
    g_res: Vec<Option<Vec<[f32; 4]>>>,
    g_src: Vec<[f32; 4]>,
    /// `∂L/∂` the filter's parameters, in slot order.
    g_params: Vec<f64>,
    /// Each primitive's first slot in `g_params`.
    first_slot: Vec<usize>,
}

fn add_into(acc: &mut Option<Vec<[f32; 4]>>, g: &[[f32; 4]]) {
    match acc {
        Some(a) => {
            for (x, y) in a.iter_mut().zip(g) {
                for c in 0..4 {
                    x[c] += y[c];
                }
            }
        }
        None => *acc = Some(g.to_vec()),
    }
}

impl<'a> Back<'a> {
    fn new(run: Run<'a>) -> Self {
        let n = run.fr.w * run.fr.h;
        let g_res = vec![None; run.results.len()];
        let mut first_slot = Vec::with_capacity(run.f.primitives.len());
        let mut at = 0;
        for p in &run.f.primitives {
            first_slot.push(at);
            at += p.kind.slot_count();
        }
        Back {
            run,
            g_res,
            g_src: vec![[0.0; 4]; n],
            g_params: vec![0.0; at],
            first_slot,
        }
    }

    /// `(∂L/∂src, ∂L/∂parameters)` from `∂L/∂output`.
    fn run(mut self, g_out: Vec<[f32; 4]>) -> (Vec<[f32; 4]>, Vec<f64>) {
        let fr = self.run.fr;
        let Some(last) = self.run.results.last() else {
            return (self.g_src, self.g_params);
        };
        let mut g = g_out;
        fr.clear_outside(&mut g, fr.local(self.run.f.region));
        if last.linear {
            for (gv, &p) in g.iter_mut().zip(&last.px) {
                *gv = pixel::adjoint1(&|v| pixel::convert(v, false), p, *gv);
            }
        }
        let k_last = self.run.results.len() - 1;
        self.g_res[k_last] = Some(g);
        for k in (0..=k_last).rev() {
            if let Some(g) = self.g_res[k].take() {
                self.primitive(k, g);
            }
        }
        (self.g_src, self.g_params)
    }

    /// Adds `g`, the gradient of input `i` read in color space `cs` (`None`: as it is),
    /// to that input's gradient.
    fn add_input(&mut self, i: &FilterInput, cs: Option<bool>, mut g: Vec<[f32; 4]>) {
        let r = self.run.input(i);
        if let Some(cs) = cs.filter(|&cs| cs != r.linear) {
            for (gv, &p) in g.iter_mut().zip(&r.px) {
                *gv = pixel::adjoint1(&|v| pixel::convert(v, cs), p, *gv);
            }
        }
        match i {
            FilterInput::SourceGraphic => {
                for (a, b) in self.g_src.iter_mut().zip(&g) {
                    for c in 0..4 {
                        a[c] += b[c];
                    }
                }
            }
            FilterInput::SourceAlpha => {
                for (a, b) in self.g_src.iter_mut().zip(&g) {
                    a[3] += b[3];
                }
            }
            FilterInput::Result(j) => add_into(&mut self.g_res[*j], &g),
        }
    }

    fn primitive(&mut self, k: usize, mut g: Vec<[f32; 4]>) {
        let run = &self.run;
        let fr = run.fr;
        let p = &run.f.primitives[k];
        let cs = p.linear_rgb;
        if !matches!(p.kind, FilterKind::Offset { .. }) {
            fr.clear_outside(&mut g, fr.local(p.subregion));
        }
        let exact = run.exact;
        let at = self.first_slot[k];
        match &p.kind {
            FilterKind::Flood { color, opacity } => {
                // A constant pixel: the gradient of the sum of `g`.
                let mut sum = [0.0f64; 4];
                for v in &g {
                    for c in 0..4 {
                        sum[c] += v[c] as f64;
                    }
                }
                for c in 0..3 {
                    self.g_params[at + c] += sum[c] * opacity;
                }
                self.g_params[at + 3] += (0..3).map(|c| sum[c] * color[c]).sum::<f64>() + sum[3];
            }
            FilterKind::Offset { input, dx, dy } => {
                if exact {
                    let d = fr.move_gradient(&run.input(input).px, *dx, *dy, &g);
                    self.g_params[at] += d[0];
                    self.g_params[at + 1] += d[1];
                }
                let g = fr.moved(&g, *dx, *dy, exact, true);
                self.add_input(&input.clone(), None, g);
            }
            FilterKind::Blur { input, std_dev } => {
                let passes = blur::passes(*std_dev, exact);
                if passes.is_empty() {
                    self.add_input(&input.clone(), None, g);
                } else {
                    let x = run.input_in(input, cs);
                    let d = blur::sigma_gradient(&x, fr.w, fr.h, *std_dev, &g, exact);
                    self.g_params[at] += d[0];
                    self.g_params[at + 1] += d[1];
                    blur::adjoint(&mut g, fr.w, fr.h, &passes);
                    self.add_input(&input.clone(), Some(cs), g);
                }
            }
            FilterKind::DropShadow {
                input,
                dx,
                dy,
                std_dev,
                color,
                opacity,
            } => {
                let (x, blurred, shadow, shifted) = run.drop_shadow(p, input);
                let mut gx = vec![[0.0f32; 4]; g.len()];
                let mut gsh = vec![[0.0f32; 4]; g.len()];
                for i in 0..g.len() {
                    (gx[i], gsh[i]) = over_adjoint(x[i], shifted[i], g[i]);
                }
                if exact {
                    let d = fr.move_gradient(&shadow, *dx, *dy, &gsh);
                    self.g_params[at] += d[0];
                    self.g_params[at + 1] += d[1];
                }
                let gsh = fr.moved(&gsh, *dx, *dy, exact, true);
                let (color, opacity) = (*color, *opacity);
                let shade = |v: [Jet<4>; 4]| pixel::convert(flood_of(color, opacity, v[3]), cs);
                // The color and opacity, seeded as four inputs, at each blurred alpha.
                let seeded: [Jet<4>; 4] = [
                    Jet::var(color[0], 0),
                    Jet::var(color[1], 1),
                    Jet::var(color[2], 2),
                    Jet::var(opacity, 3),
                ];
                let mut g_shade = [0.0f64; 4];
                for (b, gv) in blurred.iter().zip(&gsh) {
                    if *gv == [0.0; 4] {
                        continue;
                    }
                    let [r, gr, bl, op] = seeded;
                    let y = pixel::convert(flood([r, gr, bl], op, Jet::c(b[3] as f64)), cs);
                    for (j, s) in g_shade.iter_mut().enumerate() {
                        *s += (0..4).map(|o| gv[o] as f64 * y[o].d[j]).sum::<f64>();
                    }
                }
                for (j, s) in g_shade.iter().enumerate() {
                    self.g_params[at + 4 + j] += s;
                }
                let mut gb: Vec<[f32; 4]> = blurred
                    .iter()
                    .zip(&gsh)
                    .map(|(&b, &gv)| pixel::adjoint1(&shade, b, gv))
                    .collect();
                let d = blur::sigma_gradient(&x, fr.w, fr.h, *std_dev, &gb, exact);
                self.g_params[at + 2] += d[0];
                self.g_params[at + 3] += d[1];
                blur::adjoint(&mut gb, fr.w, fr.h, &blur::passes(*std_dev, exact));
                for (a, b) in gx.iter_mut().zip(&gb) {
                    for c in 0..4 {
                        a[c] += b[c];
                    }
                }
                self.add_input(&input.clone(), Some(cs), gx);
            }
            FilterKind::Merge { inputs } => {
                // The running composite under each input, bottom first.
                let xs: Vec<Vec<[f32; 4]>> = inputs.iter().map(|i| run.input_in(i, cs)).collect();
                let mut below = vec![vec![[0.0f32; 4]; g.len()]];
                for x in &xs[..xs.len().saturating_sub(1)] {
                    let prev = below.last().expect("a layer");
                    let next = x.iter().zip(prev).map(|(&s, &d)| over(s, d)).collect();
                    below.push(next);
                }
                let mut grads = Vec::with_capacity(xs.len());
                for (x, d) in xs.iter().zip(&below).rev() {
                    let mut gx = vec![[0.0f32; 4]; g.len()];
                    for i in 0..g.len() {
                        (gx[i], g[i]) = over_adjoint(x[i], d[i], g[i]);
                    }
                    grads.push(gx);
                }
                let inputs = inputs.clone();
                for (i, gx) in inputs.iter().rev().zip(grads) {
                    self.add_input(i, Some(cs), gx);
                }
            }
            FilterKind::Blend {
                input1,
                input2,
                mode,
            } => {
                let mode = *mode;
                let (a, b) = (input1.clone(), input2.clone());
                self.binary(&a, &b, cs, g, |s, d| pixel::blend(mode, s, d));
            }
            FilterKind::Composite { input1, input2, op } => {
                let op = *op;
                let (a, b) = (input1.clone(), input2.clone());
                if let CompositeOp::Arithmetic(k) = op {
                    let (x1, x2) = (run.input_in(&a, cs), run.input_in(&b, cs));
                    let seeded: [Jet<4>; 4] = std::array::from_fn(|i| Jet::var(k[i], i));
                    let d = param_gradient(&g, |i| {
                        pixel::arithmetic(
                            seeded,
                            x1[i].map(|v| Jet::c(v as f64)),
                            x2[i].map(|v| Jet::c(v as f64)),
                        )
                    });
                    for (j, v) in d.iter().enumerate() {
                        self.g_params[at + j] += v;
                    }
                }
                self.binary(&a, &b, cs, g, |s, d| pixel::composite(op, s, d));
            }
            FilterKind::ColorMatrix { input, matrix } => {
                let (i, m) = (input.clone(), *matrix);
                let x = run.input_in(&i, cs);
                let seeded: [Jet<20>; 20] = std::array::from_fn(|j| Jet::var(m[j], j));
                let d = param_gradient(&g, |k| {
                    pixel::color_matrix_with(x[k].map(|v| Jet::c(v as f64)), &seeded)
                });
                for (j, v) in d.iter().enumerate() {
                    self.g_params[at + j] += v;
                }
                for (gv, &p) in g.iter_mut().zip(&x) {
                    *gv = pixel::adjoint1(&|v| pixel::color_matrix(v, &m), p, *gv);
                }
                self.add_input(&i, Some(cs), g);
            }
            FilterKind::ComponentTransfer { input, funcs } => {
                let (i, funcs) = (input.clone(), funcs.clone());
                let x = run.input_in(&i, cs);
                let n = p.kind.slot_count();
                for (gv, &px) in g.iter().zip(&x) {
                    pixel::component_transfer_value_gradient(
                        px,
                        &funcs,
                        *gv,
                        &mut self.g_params[at..at + n],
                    );
                }
                for (gv, &p) in g.iter_mut().zip(&x) {
                    *gv = pixel::adjoint1(&|v| pixel::component_transfer(v, &funcs), p, *gv);
                }
                self.add_input(&i, Some(cs), g);
            }
            FilterKind::Morphology {
                input,
                dilate,
                radius,
            } => {
                let (dilate, radius) = (*dilate, *radius);
                let x = run.input_in(input, cs);
                let gx = run.region_adjoint(&x, &g, |xs, gs, w, h| {
                    morphology::adjoint(xs, w, h, dilate, radius, gs)
                });
                self.add_input(&input.clone(), Some(cs), gx);
            }
            FilterKind::ConvolveMatrix(m) => {
                let x = run.input_in(&m.input, cs);
                let gx =
                    run.region_adjoint(&x, &g, |xs, gs, w, h| convolve::adjoint(m, xs, w, h, gs));
                self.add_input(&m.input.clone(), Some(cs), gx);
            }
            FilterKind::Tile { input } => {
                let src = run.tile_sources(input);
                let x = &run.input(input).px;
                let gx = run.region_adjoint(x, &g, |xs, gs, _, _| match src {
                    Some(s) => tile::scatter(gs, &s, xs.len()),
                    None => vec![[0.0; 4]; xs.len()],
                });
                self.add_input(&input.clone(), None, gx);
            }
            FilterKind::DisplacementMap {
                input1,
                input2,
                scale,
                channels,
            } => {
                // The map's gradient is zero: it picks pixels by rounding.
                let src = run.displacement_sources(input2, cs, *scale, *channels);
                let x = run.input_in(input1, cs);
                let gx =
                    run.region_adjoint(&x, &g, |xs, gs, _, _| tile::scatter(gs, &src, xs.len()));
                self.add_input(&input1.clone(), Some(cs), gx);
            }
            // Depend on no input (feImage's nodes are not parameters).
            FilterKind::Turbulence(_) | FilterKind::Image { .. } => {}
            FilterKind::Lighting(l) => {
                let corner = run.corner();
                let x = &run.input(&l.input).px;
                let n = p.kind.slot_count();
                let values = &mut self.g_params[at..at + n];
                let gx = run.region_adjoint(x, &g, |xs, gs, w, h| {
                    lighting::value_gradient(l, corner, xs, w, h, gs, values);
                    lighting::adjoint(l, corner, xs, w, h, gs)
                });
                self.add_input(&l.input.clone(), None, gx);
            }
        }
    }

    fn binary(
        &mut self,
        i1: &FilterInput,
        i2: &FilterInput,
        cs: bool,
        g: Vec<[f32; 4]>,
        f: impl Fn([Jet<8>; 4], [Jet<8>; 4]) -> [Jet<8>; 4],
    ) {
        let (a, b) = (self.run.input_in(i1, cs), self.run.input_in(i2, cs));
        let mut ga = vec![[0.0f32; 4]; g.len()];
        let mut gb = vec![[0.0f32; 4]; g.len()];
        for i in 0..g.len() {
            (ga[i], gb[i]) = pixel::adjoint2(&f, a[i], b[i], g[i]);
        }
        self.add_input(i1, Some(cs), ga);
        self.add_input(i2, Some(cs), gb);
    }
}

#[cfg(test)]
mod tests {
    use super::blur::dot;
    use super::*;
    use crate::rng::Rng;
    use crate::scene::BlendMode;
    use crate::scene::filter::{
        CompositeOp, FilterPrimitive, TransferFunction, hue_rotate_matrix, saturate_matrix,
    };
    use crate::{Scene, Sizing};

    const RECT: [usize; 4] = [2, 1, 11, 8];

    fn prim(kind: FilterKind, linear_rgb: bool) -> FilterPrimitive {
        FilterPrimitive {
            subregion: [0, 0, 100, 100],
            linear_rgb,
            result: String::new(),
            kind,
        }
    }

    fn filter(primitives: Vec<FilterPrimitive>) -> Filter {
        Filter {
            id: String::new(),
            region: [0, 0, 100, 100],
            primitives,
        }
    }

    /// A premultiplied image with alphas away from 0 and colors away from the clamps.
    fn image(seed: u64) -> Vec<[f32; 4]> {
        let mut r = Rng::new(seed);
        let n = (RECT[2] - RECT[0]) * (RECT[3] - RECT[1]);
        (0..n)
            .map(|_| {
                let a = 0.3 + 0.6 * r.uniform();
                [
                    0.1 + 0.8 * r.uniform(),
                    0.1 + 0.8 * r.uniform(),
                    0.1 + 0.8 * r.uniform(),
                    1.0,
                ]
                .map(|c| c * a)
                .map(|c| if c == a { a } else { c })
            })
            .map(|mut p: [f32; 4]| {
                p[3] = p[3].max(p[0]).max(p[1]).max(p[2]);
                p
            })
            .collect()
    }

    /// `d/dt ⟨g, F(x + t·v)⟩` by central differences against `⟨Fᵀ g, v⟩`, with resvg's
    /// filters and exact ones; then each of the filters' parameters `θ`:
    /// `∂⟨g, F(x)⟩/∂θ` by central differences against the adjoint's (exact filters; with
    /// resvg's, deviations and offsets have none and the others the same).
    fn check(name: &str, filters: &[Filter]) {
        let (x, g, v) = (image(1), image(2), image(3));
        for exact in [false, true] {
            let h = 1e-3f32;
            let at = |t: f32| {
                let y: Vec<[f32; 4]> = x
                    .iter()
                    .zip(&v)
                    .map(|(a, b)| std::array::from_fn(|c| a[c] + t * b[c]))
                    .collect();
                dot(&g, &apply(filters, RECT, y, exact))
            };
            let numeric = (at(h) - at(-h)) / (2.0 * h as f64);
            let (g_src, g_params) = adjoint(filters, RECT, x.clone(), g.clone(), exact);
            let analytic = dot(&g_src, &v);
            let err = (numeric - analytic).abs() / numeric.abs().max(1e-2);
            assert!(
                err < 1e-2,
                "{name} (exact {exact}): numeric {numeric}, analytic {analytic}"
            );
            let count: usize = filters.iter().map(Filter::slot_count).sum();
            assert_eq!(g_params.len(), count, "{name}");
            for slot in 0..count {
                let with = |d: f64| {
                    let mut fs = filters.to_vec();
                    let mut k = 0;
                    for p in fs.iter_mut().flat_map(|f| &mut f.primitives) {
                        for (_, val) in p.slots_mut() {
                            if k == slot {
                                *val += d;
                            }
                            k += 1;
                        }
                    }
                    dot(&g, &apply(&fs, RECT, x.clone(), exact))
                };
                let e = 1e-4;
                let numeric = (with(e) - with(-e)) / (2.0 * e);
                let analytic = g_params[slot];
                let err = (numeric - analytic).abs() / numeric.abs().max(1e-1);
                assert!(
                    err < 2e-2 || !exact && analytic == 0.0,
                    "{name} (exact {exact}) slot {slot}: numeric {numeric}, analytic {analytic}"
                );
            }
        }
    }

    use FilterInput::{Result as R, SourceAlpha, SourceGraphic as Src};

    #[test]
    fn each_primitive_agrees_with_finite_differences() {
        let flood = FilterKind::Flood {
            color: [0.2, 0.5, 0.9],
            opacity: 0.6,
        };
        let cases: Vec<(&str, Vec<FilterPrimitive>)> = vec![
            (
                "offset",
                vec![prim(
                    FilterKind::Offset {
                        input: Src,
                        dx: 2.7,
                        dy: -1.2,
                    },
                    true,
                )],
            ),
            (
                "box blur",
                vec![prim(
                    FilterKind::Blur {
                        input: Src,
                        std_dev: [2.45, 3.1],
                    },
                    true,
                )],
            ),
            (
                "small blur, sRGB",
                vec![prim(
                    FilterKind::Blur {
                        input: Src,
                        std_dev: [0.8, 1.1],
                    },
                    false,
                )],
            ),
            (
                "drop shadow",
                vec![prim(
                    FilterKind::DropShadow {
                        input: Src,
                        dx: 2.4,
                        dy: 1.3,
                        std_dev: [1.1, 1.45],
                        color: [0.3, 0.1, 0.7],
                        opacity: 0.8,
                    },
                    true,
                )],
            ),
            (
                "merge with flood and source alpha",
                vec![
                    prim(flood.clone(), true),
                    prim(
                        FilterKind::Merge {
                            inputs: vec![R(0), SourceAlpha, Src],
                        },
                        true,
                    ),
                ],
            ),
            (
                "color matrix",
                vec![prim(
                    FilterKind::ColorMatrix {
                        input: Src,
                        matrix: hue_rotate_matrix(40.0),
                    },
                    true,
                )],
            ),
            (
                "saturate, sRGB",
                vec![prim(
                    FilterKind::ColorMatrix {
                        input: Src,
                        matrix: saturate_matrix(0.3),
                    },
                    false,
                )],
            ),
            (
                "component transfer",
                vec![prim(
                    FilterKind::ComponentTransfer {
                        input: Src,
                        funcs: Box::new([
                            TransferFunction::Table(vec![0.1, 0.8, 0.3, 0.9]),
                            TransferFunction::Linear {
                                slope: 0.7,
                                intercept: 0.1,
                            },
                            TransferFunction::Gamma {
                                amplitude: 0.9,
                                exponent: 1.7,
                                offset: 0.05,
                            },
                            TransferFunction::Identity,
                        ]),
                    },
                    true,
                )],
            ),
            (
                // (feComponentTransfer's discrete functions are piecewise constant in the
                // input: finite differences on the content would cross their steps.)
                "component transfer of alpha",
                vec![prim(
                    FilterKind::ComponentTransfer {
                        input: Src,
                        funcs: Box::new([
                            TransferFunction::Gamma {
                                amplitude: 1.1,
                                exponent: 0.8,
                                offset: -0.05,
                            },
                            TransferFunction::Identity,
                            TransferFunction::Linear {
                                slope: 0.6,
                                intercept: 0.2,
                            },
                            TransferFunction::Table(vec![0.05, 0.9]),
                        ]),
                    },
                    false,
                )],
            ),
        ];
        for (name, prims) in cases {
            check(name, &[filter(prims)]);
        }
        for op in [
            CompositeOp::Over,
            CompositeOp::In,
            CompositeOp::Out,
            CompositeOp::Atop,
            CompositeOp::Xor,
            CompositeOp::Arithmetic([0.5, 0.3, 0.4, 0.05]),
            CompositeOp::Arithmetic([0.2, 0.6, 0.5, 0.0]),
            CompositeOp::Arithmetic([0.9, 0.8, 0.7, 0.0]),
        ] {
            let blurred = prim(
                FilterKind::Blur {
                    input: Src,
                    std_dev: [1.05, 0.95],
                },
                true,
            );
            let c = prim(
                FilterKind::Composite {
                    input1: Src,
                    input2: R(0),
                    op,
                },
                true,
            );
            check(&format!("composite {op:?}"), &[filter(vec![blurred, c])]);
        }
        for mode in [
            BlendMode::Normal,
            BlendMode::Multiply,
            BlendMode::Screen,
            BlendMode::Darken,
        ] {
            let moved = prim(
                FilterKind::Offset {
                    input: Src,
                    dx: 1.2,
                    dy: 1.35,
                },
                false,
            );
            let b = prim(
                FilterKind::Blend {
                    input1: Src,
                    input2: R(0),
                    mode,
                },
                false,
            );
            check(&format!("blend {mode:?}"), &[filter(vec![moved, b])]);
        }
        // Two filters in a row, a subregion and a region smaller than the layer.
        let mut cut = prim(
            FilterKind::Blur {
                input: Src,
                std_dev: [1.55, 0.45],
            },
            true,
        );
        cut.subregion = [3, 2, 9, 7];
        // (An alpha offset of exactly 0 would be a kink: transparent pixels' alpha is
        // the offset, clamped at 0.)
        let mut matrix = saturate_matrix(1.6);
        matrix[19] = -0.02;
        let mut second = filter(vec![prim(
            FilterKind::ColorMatrix { input: Src, matrix },
            true,
        )]);
        second.region = [2, 2, 10, 8];
        check("chain", &[filter(vec![cut]), second]);
    }

    /// A filter of more than `MAX_FILTER_PRIMITIVES` primitives is refused, naming the
    /// file and the count, before anything is rendered.
    #[test]
    fn too_many_primitives_are_refused_by_name() {
        let prims = "<feOffset dx=\"1\"/>".repeat(crate::limits::MAX_FILTER_PRIMITIVES + 1);
        let svg = format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10">
            <filter id="t">{prims}</filter>
            <rect width="5" height="5" filter="url(#t)"/></svg>"#
        );
        let err = Scene::from_svg_str(&svg, "many.svg", Sizing::Natural).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("many.svg") && msg.contains("257"), "{msg}");
    }

    /// A convolution kernel past `MAX_CONVOLVE_TAPS` is refused, naming the file and the
    /// primitive, before anything is rendered.
    #[test]
    fn a_huge_convolution_kernel_is_refused_by_name() {
        let values = vec!["1"; 65 * 65].join(" ");
        let svg = format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10">
            <filter id="t"><feConvolveMatrix order="65" kernelMatrix="{values}"/></filter>
            <rect width="5" height="5" filter="url(#t)"/></svg>"#
        );
        let err = Scene::from_svg_str(&svg, "kernel.svg", Sizing::Natural).unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("kernel.svg") && msg.contains("feConvolveMatrix") && msg.contains("4225"),
            "{msg}"
        );
        assert!(!msg.contains('\n'), "{msg}");
    }
}
