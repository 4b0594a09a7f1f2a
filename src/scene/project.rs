//! Projection onto valid scenes, applied after every optimizer step.

use crate::limits::MAX_COORDINATE;
use crate::scene::filter::{CompositeOp, FilterKind};
use crate::scene::params::{clamp_coordinate, clamp_points};
use crate::scene::{GradientKind, Node, Paint, Scene};

/// Clamps every parameter back into its valid range: colors and opacities to `[0, 1]`,
/// stroke widths, gradient radii and the sizes of circles, ellipses and rectangles to
/// `[0, MAX_COORDINATE]` (a rectangle's corner radii to half its sides), gradient stop offsets to
/// `[0, 1]` and non-decreasing (each offset at least the one before it), and filter
/// primitives' numbers into theirs (see `project_filter`). Control points
/// and gradient end points are free within the readable range: ±[`MAX_COORDINATE`] in
/// device pixels, and for a stroke drawn in a non-uniform frame tighter still, so that the
/// coordinates the SVG writer puts in that frame stay within it too. NaN values become 0.
///
/// So however large a step the optimizer takes, the scene can be written and read back
/// (see `check_numbers`).
pub fn project(scene: &mut Scene) {
    project_nodes(&mut scene.nodes);
}

fn unit(v: &mut f64) {
    *v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
}

fn non_negative(v: &mut f64) {
    *v = if v.is_nan() {
        0.0
    } else {
        v.clamp(0.0, MAX_COORDINATE)
    };
}

/// A group's opacity and children, and its clip path's shapes and mask's content (which
/// are parameters too).
fn project_group(g: &mut crate::scene::Group) {
    unit(&mut g.opacity);
    for p in g.filters.iter_mut().flat_map(|f| &mut f.primitives) {
        project_filter(&mut p.kind);
    }
    project_nodes(&mut g.children);
    if let Some(c) = &mut g.clip {
        project_group(&mut c.content);
    }
    if let Some(m) = &mut g.mask {
        project_group(&mut m.content);
    }
}

fn project_nodes(nodes: &mut [Node]) {
    for n in nodes {
        match n {
            Node::Group(g) => project_group(g),
            Node::Path(p) => {
                clamp_points(p);
                if let Some(f) = &mut p.fill {
                    unit(&mut f.opacity);
                    project_paint(&mut f.paint);
                }
                if let Some(s) = &mut p.stroke {
                    unit(&mut s.opacity);
                    non_negative(&mut s.width);
                    project_paint(&mut s.paint);
                }
            }
        }
    }
}

/// A filter primitive's numbers: colors and opacities to `[0, 1]`, deviations to
/// `[0, MAX_COORDINATE]`, the others (offsets, matrix values, transfer functions, `k`,
/// lighting constants and lights) to ±`MAX_COORDINATE`.
fn project_filter(kind: &mut FilterKind) {
    let free = |v: &mut f64| clamp_coordinate(v, MAX_COORDINATE);
    match kind {
        FilterKind::Flood { color, opacity } => {
            color.iter_mut().for_each(unit);
            unit(opacity);
        }
        FilterKind::Offset { dx, dy, .. } => {
            free(dx);
            free(dy);
        }
        FilterKind::Blur { std_dev, .. } => std_dev.iter_mut().for_each(non_negative),
        FilterKind::DropShadow {
            dx,
            dy,
            std_dev,
            color,
            opacity,
            ..
        } => {
            free(dx);
            free(dy);
            std_dev.iter_mut().for_each(non_negative);
            color.iter_mut().for_each(unit);
            unit(opacity);
        }
        FilterKind::ColorMatrix { matrix, .. } => matrix.iter_mut().for_each(free),
        FilterKind::Composite {
            op: CompositeOp::Arithmetic(k),
            ..
        } => k.iter_mut().for_each(free),
        FilterKind::Lighting(l) => {
            for (group, v) in l.values_mut() {
                if group == crate::scene::ParamGroup::Color {
                    unit(v);
                } else {
                    free(v);
                }
            }
        }
        FilterKind::ComponentTransfer { funcs, .. } => {
            funcs.iter_mut().flat_map(|f| f.values_mut()).for_each(free);
        }
        _ => {}
    }
}

fn project_paint(paint: &mut Paint) {
    match paint {
        Paint::Solid(c) => c.iter_mut().for_each(unit),
        // Fixed pixels, nothing to project.
        Paint::Image(_) => {}
        Paint::Gradient(g) => {
            match &mut g.kind {
                GradientKind::Linear { p1, p2 } => {
                    p1.iter_mut()
                        .chain(p2.iter_mut())
                        .for_each(|v| clamp_coordinate(v, MAX_COORDINATE));
                }
                GradientKind::Radial { c, r, f, fr } => {
                    c.iter_mut()
                        .chain(f.iter_mut())
                        .for_each(|v| clamp_coordinate(v, MAX_COORDINATE));
                    non_negative(r);
                    non_negative(fr);
                }
            }
            let mut floor = 0.0;
            for s in &mut g.stops {
                unit(&mut s.offset);
                s.offset = s.offset.max(floor);
                floor = s.offset;
                s.color.iter_mut().for_each(unit);
                unit(&mut s.opacity);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Fill, FillRule, Gradient, IDENTITY, Path, Spread, Stop, Stroke};

    #[test]
    fn clamps_and_orders() {
        let stop = |offset, c| Stop {
            offset,
            color: [c, -0.5, 0.5],
            opacity: 1.5,
        };
        let mut p = Path::new("p");
        p.move_to([0.0, 0.0]);
        p.line_to([3.0, 0.0]);
        p.line_to([0.0, 3.0]);
        p.close();
        p.fill = Some(Fill {
            paint: Paint::Gradient(Gradient {
                id: String::new(),
                kind: GradientKind::Radial {
                    c: [1.0, 1.0],
                    r: -2.0,
                    f: [1.0, 1.0],
                    fr: f64::NAN,
                },
                transform: IDENTITY,
                spread: Spread::Pad,
                stops: vec![stop(0.4, 2.0), stop(0.1, 0.5), stop(1.3, f64::NAN)],
            }),
            opacity: -0.1,
            rule: FillRule::NonZero,
        });
        let mut s = Stroke::new(Paint::Solid([1.2, 0.5, -3.0]), -1.0);
        s.opacity = 2.0;
        p.stroke = Some(s);
        let mut scene = Scene::new(4, 4);
        scene.nodes.push(Node::Path(p));
        project(&mut scene);
        let Node::Path(p) = &scene.nodes[0] else {
            unreachable!()
        };
        let f = p.fill.as_ref().unwrap();
        assert_eq!(f.opacity, 0.0);
        let Paint::Gradient(g) = &f.paint else {
            unreachable!()
        };
        assert!(matches!(
            g.kind,
            GradientKind::Radial {
                r: 0.0,
                fr: 0.0,
                ..
            }
        ));
        let offsets: Vec<f64> = g.stops.iter().map(|s| s.offset).collect();
        assert_eq!(offsets, [0.4, 0.4, 1.0]);
        assert_eq!(g.stops[0].color, [1.0, 0.0, 0.5]);
        assert_eq!(g.stops[2].color[0], 0.0);
        assert!(g.stops.iter().all(|s| s.opacity == 1.0));
        let s = p.stroke.as_ref().unwrap();
        assert_eq!((s.opacity, s.width), (1.0, 0.0));
        assert_eq!(s.paint, Paint::Solid([1.0, 0.5, 0.0]));
    }

    /// `fit --lr-points 1e308`: after a huge step, projection brings every coordinate
    /// back within the readable range, so the scene is written and read back.
    #[test]
    fn lr_points_1e308_step_stays_readable() {
        let mut scene = crate::scene::random::curved_paths(2, 32, 3);
        let mut p = scene.params();
        for (k, v) in p.iter_mut().enumerate() {
            *v += if k % 2 == 0 { 1e308 } else { -1e308 };
        }
        scene.set_params(&p);
        project(&mut scene);
        assert!(crate::scene::svg_out::check_numbers(&scene).is_ok());
        let text = scene.to_svg_string();
        crate::Scene::from_svg_str(&text, "back.svg", crate::Sizing::Natural).unwrap();
    }

    #[test]
    fn clip_shapes_and_mask_content_are_projected() {
        let svg = r##"<svg xmlns="http://www.w3.org/2000/svg" width="20" height="20">
            <clipPath id="c"><circle cx="10" cy="10" r="6"/></clipPath>
            <mask id="m"><rect x="2" y="2" width="16" height="16" fill="white"/></mask>
            <g clip-path="url(#c)" mask="url(#m)"><rect x="0" y="0" width="20" height="20"/></g>
            </svg>"##;
        let mut scene = crate::Scene::from_svg_str(svg, "c.svg", crate::Sizing::Natural).unwrap();
        let mut p = scene.params();
        for v in p.iter_mut() {
            *v = -1e31;
        }
        scene.set_params(&p);
        project(&mut scene);
        assert!(crate::scene::svg_out::check_numbers(&scene).is_ok());
        let text = scene.to_svg_string();
        crate::Scene::from_svg_str(&text, "back.svg", crate::Sizing::Natural).unwrap();
    }
}
