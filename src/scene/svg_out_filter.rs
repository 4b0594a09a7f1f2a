//! SVG out of filters: each [`Filter`] of a group becomes a `<filter>` in the defs, in
//! device pixels (`filterUnits` and `primitiveUnits` `userSpaceOnUse`; the groups the
//! writer puts a filter on have no transform of their own), so that reading the file
//! back finds the same regions, subregions, deviations and offsets.

use std::fmt::Write as _;

use super::filter::{CompositeOp, Filter, FilterInput, FilterKind, LightSource, TransferFunction};
use super::svg_out::num;

/// The `<filter>` element of `f` with the id `id`, indented for the defs. `image` writes
/// an feImage's content (device pixels) into the defs, drawn from the given device corner
/// (where resvg puts the referenced element's origin), and returns its id.
///
/// Two things do not survive exactly: feTurbulence's lattice is anchored at the device
/// origin (a filtered group's translation is baked into the content, so the noise's offset
/// is lost; its frequency is kept per device pixel), and feDisplacementMap's scale keeps
/// its magnitude (resvg squares it).
pub(crate) fn filter_element(
    f: &Filter,
    id: &str,
    image: &mut dyn FnMut(&[super::Node], [i64; 2]) -> String,
) -> String {
    let mut d = String::new();
    let [x0, y0, x1, y1] = f.region;
    let _ = writeln!(
        d,
        "    <filter id=\"{id}\" filterUnits=\"userSpaceOnUse\" primitiveUnits=\"userSpaceOnUse\" x=\"{x0}\" y=\"{y0}\" width=\"{}\" height=\"{}\">",
        x1 - x0,
        y1 - y0
    );
    // A result is named by its own name when no other primitive has it, else by its
    // index (inputs refer to results by index).
    let names: Vec<String> = f
        .primitives
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let unique = f.primitives.iter().filter(|q| q.result == p.result).count() == 1;
            let plain = !p.result.is_empty() && !p.result.starts_with("Source");
            if unique && plain {
                super::escape(&p.result)
            } else {
                format!("r{i}")
            }
        })
        .collect();
    let input = |i: &FilterInput| match i {
        FilterInput::SourceGraphic => "SourceGraphic".to_string(),
        FilterInput::SourceAlpha => "SourceAlpha".to_string(),
        FilterInput::Result(k) => names[*k].clone(),
    };
    for (i, p) in f.primitives.iter().enumerate() {
        let [x0, y0, x1, y1] = p.subregion;
        let mut common = format!(
            " x=\"{x0}\" y=\"{y0}\" width=\"{}\" height=\"{}\" result=\"{}\"",
            x1 - x0,
            y1 - y0,
            names[i]
        );
        if !p.linear_rgb {
            common.push_str(" color-interpolation-filters=\"sRGB\"");
        }
        let color = |c: &[f64; 3], opacity: f64| {
            format!(
                " flood-color=\"{}\" flood-opacity=\"{}\"",
                super::svg_out::hex(c),
                num(opacity.clamp(0.0, 1.0))
            )
        };
        let line = match &p.kind {
            FilterKind::Flood { color: c, opacity } => {
                format!("<feFlood{common}{}/>", color(c, *opacity))
            }
            FilterKind::Offset { input: i, dx, dy } => format!(
                "<feOffset{common} in=\"{}\" dx=\"{}\" dy=\"{}\"/>",
                input(i),
                num(*dx),
                num(*dy)
            ),
            FilterKind::Blur { input: i, std_dev } => format!(
                "<feGaussianBlur{common} in=\"{}\" stdDeviation=\"{} {}\"/>",
                input(i),
                num(std_dev[0]),
                num(std_dev[1])
            ),
            FilterKind::DropShadow {
                input: i,
                dx,
                dy,
                std_dev,
                color: c,
                opacity,
            } => format!(
                "<feDropShadow{common} in=\"{}\" dx=\"{}\" dy=\"{}\" stdDeviation=\"{} {}\"{}/>",
                input(i),
                num(*dx),
                num(*dy),
                num(std_dev[0]),
                num(std_dev[1]),
                color(c, *opacity)
            ),
            FilterKind::Merge { inputs } => {
                let nodes: String = inputs
                    .iter()
                    .map(|i| format!("<feMergeNode in=\"{}\"/>", input(i)))
                    .collect();
                format!("<feMerge{common}>{nodes}</feMerge>")
            }
            FilterKind::Blend {
                input1,
                input2,
                mode,
            } => format!(
                "<feBlend{common} in=\"{}\" in2=\"{}\" mode=\"{}\"/>",
                input(input1),
                input(input2),
                mode.name()
            ),
            FilterKind::Composite { input1, input2, op } => {
                let op = match op {
                    CompositeOp::Over => "operator=\"over\"".to_string(),
                    CompositeOp::In => "operator=\"in\"".to_string(),
                    CompositeOp::Out => "operator=\"out\"".to_string(),
                    CompositeOp::Atop => "operator=\"atop\"".to_string(),
                    CompositeOp::Xor => "operator=\"xor\"".to_string(),
                    CompositeOp::Lighter => "operator=\"lighter\"".to_string(),
                    CompositeOp::Arithmetic(k) => format!(
                        "operator=\"arithmetic\" k1=\"{}\" k2=\"{}\" k3=\"{}\" k4=\"{}\"",
                        full(k[0]),
                        full(k[1]),
                        full(k[2]),
                        full(k[3])
                    ),
                };
                format!(
                    "<feComposite{common} in=\"{}\" in2=\"{}\" {op}/>",
                    input(input1),
                    input(input2)
                )
            }
            FilterKind::ColorMatrix { input: i, matrix } => {
                let v: Vec<String> = matrix.iter().map(|v| full(*v)).collect();
                format!(
                    "<feColorMatrix{common} in=\"{}\" type=\"matrix\" values=\"{}\"/>",
                    input(i),
                    v.join(" ")
                )
            }
            FilterKind::ComponentTransfer { input: i, funcs } => {
                let mut body = String::new();
                for (tag, func) in ["feFuncR", "feFuncG", "feFuncB", "feFuncA"]
                    .iter()
                    .zip(funcs.iter())
                {
                    let list = |v: &[f64]| v.iter().map(|x| full(*x)).collect::<Vec<_>>();
                    let attrs = match func {
                        TransferFunction::Identity => continue,
                        TransferFunction::Table(v) => {
                            format!("type=\"table\" tableValues=\"{}\"", list(v).join(" "))
                        }
                        TransferFunction::Discrete(v) => {
                            format!("type=\"discrete\" tableValues=\"{}\"", list(v).join(" "))
                        }
                        TransferFunction::Linear { slope, intercept } => format!(
                            "type=\"linear\" slope=\"{}\" intercept=\"{}\"",
                            full(*slope),
                            full(*intercept)
                        ),
                        TransferFunction::Gamma {
                            amplitude,
                            exponent,
                            offset,
                        } => format!(
                            "type=\"gamma\" amplitude=\"{}\" exponent=\"{}\" offset=\"{}\"",
                            full(*amplitude),
                            full(*exponent),
                            full(*offset)
                        ),
                    };
                    let _ = write!(body, "<{tag} {attrs}/>");
                }
                format!(
                    "<feComponentTransfer{common} in=\"{}\">{body}</feComponentTransfer>",
                    input(i)
                )
            }
            FilterKind::Morphology {
                input: i,
                dilate,
                radius,
            } => format!(
                "<feMorphology{common} in=\"{}\" operator=\"{}\" radius=\"{} {}\"/>",
                input(i),
                if *dilate { "dilate" } else { "erode" },
                full(radius[0]),
                full(radius[1])
            ),
            FilterKind::ConvolveMatrix(c) => {
                let k: Vec<String> = c.kernel.iter().map(|v| full(*v)).collect();
                format!(
                    "<feConvolveMatrix{common} in=\"{}\" order=\"{} {}\" kernelMatrix=\"{}\" targetX=\"{}\" targetY=\"{}\" divisor=\"{}\" bias=\"{}\" edgeMode=\"{}\" preserveAlpha=\"{}\"/>",
                    input(&c.input),
                    c.order[0],
                    c.order[1],
                    k.join(" "),
                    c.target[0],
                    c.target[1],
                    full(c.divisor),
                    full(c.bias),
                    ["none", "duplicate", "wrap"][usize::from(c.edge.min(2))],
                    c.preserve_alpha
                )
            }
            FilterKind::Tile { input: i } => format!("<feTile{common} in=\"{}\"/>", input(i)),
            FilterKind::DisplacementMap {
                input1,
                input2,
                scale,
                channels,
            } => {
                let ch = |c: usize| ["R", "G", "B", "A"][c.min(3)];
                format!(
                    "<feDisplacementMap{common} in=\"{}\" in2=\"{}\" scale=\"{}\" xChannelSelector=\"{}\" yChannelSelector=\"{}\"/>",
                    input(input1),
                    input(input2),
                    full(scale[0].abs().sqrt()),
                    ch(channels[0]),
                    ch(channels[1])
                )
            }
            FilterKind::Turbulence(t) => {
                let per_px = |k: usize| t.base_frequency[k] / t.scale[k].max(f64::MIN_POSITIVE);
                format!(
                    "<feTurbulence{common} baseFrequency=\"{} {}\" numOctaves=\"{}\" seed=\"{}\" stitchTiles=\"{}\" type=\"{}\"/>",
                    full(per_px(0)),
                    full(per_px(1)),
                    t.octaves,
                    t.seed,
                    if t.stitch { "stitch" } else { "noStitch" },
                    if t.fractal {
                        "fractalNoise"
                    } else {
                        "turbulence"
                    }
                )
            }
            FilterKind::Lighting(l) => {
                let source = match &l.light {
                    LightSource::Distant { azimuth, elevation } => format!(
                        "<feDistantLight azimuth=\"{}\" elevation=\"{}\"/>",
                        full(*azimuth),
                        full(*elevation)
                    ),
                    LightSource::Point { pos } => format!(
                        "<fePointLight x=\"{}\" y=\"{}\" z=\"{}\"/>",
                        full(pos[0]),
                        full(pos[1]),
                        full(pos[2])
                    ),
                    LightSource::Spot {
                        pos,
                        points_at,
                        exponent,
                        cone,
                    } => {
                        let cone = cone.map_or(String::new(), |c| {
                            format!(" limitingConeAngle=\"{}\"", full(c))
                        });
                        format!(
                            "<feSpotLight x=\"{}\" y=\"{}\" z=\"{}\" pointsAtX=\"{}\" pointsAtY=\"{}\" pointsAtZ=\"{}\" specularExponent=\"{}\"{cone}/>",
                            full(pos[0]),
                            full(pos[1]),
                            full(pos[2]),
                            full(points_at[0]),
                            full(points_at[1]),
                            full(points_at[2]),
                            full(*exponent)
                        )
                    }
                };
                let (tag, own) = match l.specular {
                    Some(e) => (
                        "feSpecularLighting",
                        format!(
                            "specularConstant=\"{}\" specularExponent=\"{}\"",
                            full(l.constant),
                            full(e)
                        ),
                    ),
                    None => (
                        "feDiffuseLighting",
                        format!("diffuseConstant=\"{}\"", full(l.constant)),
                    ),
                };
                format!(
                    "<{tag}{common} in=\"{}\" surfaceScale=\"{}\" {own} lighting-color=\"{}\">{source}</{tag}>",
                    input(&l.input),
                    full(l.surface_scale),
                    super::svg_out::hex(&l.color)
                )
            }
            FilterKind::Image { nodes } => {
                let at = [p.subregion[0], p.subregion[1]];
                let id = image(nodes, at);
                format!("<feImage{common} href=\"#{id}\"/>")
            }
        };
        let _ = writeln!(d, "      {line}");
    }
    d.push_str("    </filter>\n");
    d
}

/// A unitless value in full (`f32`, the precision it is read with): matrix entries and
/// transfer values multiply colors, so four decimals would move them.
fn full(v: f64) -> String {
    format!("{}", v as f32)
}

#[cfg(test)]
mod tests {
    use crate::scene::{Node, Scene, Sizing};

    /// Every primitive the model holds, chained by names, with sRGB and linearRGB.
    const CHAIN: &str = r##"<svg xmlns="http://www.w3.org/2000/svg" width="60" height="50">
      <filter id="f" x="-0.2" y="-0.2" width="1.4" height="1.4">
        <feGaussianBlur in="SourceAlpha" stdDeviation="2 1.5" result="blur"/>
        <feOffset in="blur" dx="3" dy="2" result="moved"/>
        <feFlood flood-color="#3a6ea5" flood-opacity="0.7" result="ink"/>
        <feComposite in="ink" in2="moved" operator="in" result="shadow"/>
        <feColorMatrix in="SourceGraphic" type="saturate" values="0.3" result="grey"/>
        <feComponentTransfer in="grey" result="lifted" color-interpolation-filters="sRGB">
          <feFuncR type="linear" slope="0.8" intercept="0.1"/>
          <feFuncG type="gamma" amplitude="1.1" exponent="0.7" offset="0.02"/>
          <feFuncB type="table" tableValues="0 0.4 1"/>
          <feFuncA type="discrete" tableValues="0 1"/>
        </feComponentTransfer>
        <feComposite in="lifted" in2="shadow" operator="arithmetic" k1="0.1" k2="0.9"
                     k3="0.6" k4="0.01" result="mixed"/>
        <feBlend in="mixed" in2="shadow" mode="multiply" result="blended"/>
        <feDropShadow in="blended" dx="-1" dy="1" stdDeviation="1" flood-color="#202020"
                      flood-opacity="0.5" result="dropped"/>
        <feMerge><feMergeNode in="shadow"/><feMergeNode in="dropped"/></feMerge>
      </filter>
      <g filter="url(#f)">
        <rect x="12" y="10" width="26" height="20" fill="#e07020"/>
        <circle cx="38" cy="30" r="9" fill="#2080c0"/>
      </g>
    </svg>"##;

    fn filters(s: &Scene) -> Vec<crate::scene::filter::Filter> {
        let Some(Node::Group(g)) = s.nodes.first() else {
            panic!("{:?}", s.nodes)
        };
        g.filters.clone()
    }

    #[test]
    fn filters_survive_a_round_trip() {
        let a = Scene::from_svg_str(CHAIN, "chain.svg", Sizing::Natural).unwrap();
        let text = a.to_svg_string();
        let b = Scene::from_svg_str(&text, "back.svg", Sizing::Natural)
            .unwrap_or_else(|e| panic!("{e}\n{text}"));
        let (fa, fb) = (filters(&a), filters(&b));
        assert_eq!(fa.len(), 1);
        assert_eq!(fa[0].region, fb[0].region, "{text}");
        assert_eq!(fa[0].primitives.len(), fb[0].primitives.len(), "{text}");
        for (p, q) in fa[0].primitives.iter().zip(&fb[0].primitives) {
            assert_eq!((p.subregion, p.linear_rgb), (q.subregion, q.linear_rgb));
            // Inputs by index, and the values to f32 precision.
            let (dp, dq) = (format!("{:?}", p.kind), format!("{:?}", q.kind));
            let numbers = |s: &str| -> Vec<f64> {
                s.split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == 'e'))
                    .filter_map(|t| t.parse().ok())
                    .collect()
            };
            let (na, nb) = (numbers(&dp), numbers(&dq));
            assert_eq!(na.len(), nb.len(), "{dp}\n{dq}");
            for (x, y) in na.iter().zip(&nb) {
                assert!((x - y).abs() <= 1e-4 * x.abs().max(1.0), "{dp}\n{dq}");
            }
        }
        // The pixels: `layers::filters_survive_a_round_trip_on_resvgs_suite`.
    }
}
