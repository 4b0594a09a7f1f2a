//! Seeded random scenes for benchmarks and tests.
//!
//! ```
//! use diffsvg::scene::random::{curved_paths, perturb};
//! let scene = curved_paths(20, 64, 7); // 20 closed paths on a 64 × 64 canvas, seed 7
//! assert_eq!(scene, curved_paths(20, 64, 7)); // the same seed, the same scene
//! let moved = perturb(&scene, 4.0, 0.1, 1); // points by up to 4 px, colors by up to 0.1
//! let (a, b) = (scene.params(), moved.params());
//! assert_eq!(a.len(), b.len());
//! assert!(a != b);
//! ```

use super::{Fill, FillRule, Node, Paint, ParamGroup, ParamLayout, Path, Scene};

/// The crate's seeded generator (SplitMix64), re-exported where the random scenes are.
pub use crate::rng::Rng;

/// `n` closed paths of three random cubics each, translucent solid fills, on a
/// `size × size` canvas; each path spans up to a quarter of the canvas.
pub fn curved_paths(n: usize, size: u32, seed: u64) -> Scene {
    let mut rng = Rng::new(seed);
    let s = size as f64;
    let mut scene = Scene::new(size, size);
    for i in 0..n {
        let c = [rng.range(0.0, s), rng.range(0.0, s)];
        let r = s * 0.125;
        let mut pt = || [c[0] + rng.range(-r, r), c[1] + rng.range(-r, r)];
        let mut p = Path::new(format!("p{i}"));
        p.move_to(pt());
        for _ in 0..3 {
            let (a, b, e) = (pt(), pt(), pt());
            p.cubic_to(a, b, e);
        }
        p.close();
        p.fill = Some(Fill {
            paint: Paint::Solid([
                rng.range(0.0, 1.0),
                rng.range(0.0, 1.0),
                rng.range(0.0, 1.0),
            ]),
            opacity: rng.range(0.3, 0.8),
            rule: FillRule::NonZero,
        });
        scene.nodes.push(Node::Path(p));
    }
    scene
}

/// A perturbed copy of `scene`: every control point moved by up to `max_px` pixels in x
/// and y (a circle's, ellipse's or rectangle's position and sizes by up to `max_px / 4`,
/// about as far as the mean of its outline's points moves, its sizes by at most half
/// their value), and every color channel (solid and stop colors) shifted by up to `max_color`
/// (then clamped to `[0, 1]`), uniformly at random. Used to test that refinement recovers.
/// An image's rectangle is not moved. Moved points are kept within the readable range (±[`MAX_COORDINATE`] device pixels, see
/// `super::params::clamp_points`), so the copy can always be written and read
/// back.
///
/// [`MAX_COORDINATE`]: crate::limits::MAX_COORDINATE
pub fn perturb(scene: &Scene, max_px: f64, max_color: f64, seed: u64) -> Scene {
    let mut rng = Rng::new(seed);
    let layout = ParamLayout::new(scene);
    let mut p = scene.params();
    // A primitive's position and sizes move by up to a quarter of `max_px` (about as far
    // as the mean of its outline's control points moves when they move independently),
    // its sizes by at most half their value, so that none vanishes.
    #[derive(Clone, Copy, PartialEq)]
    enum Kind {
        Point,
        Position,
        Size,
    }
    let mut kind = vec![Kind::Point; p.len()];
    let mut k = 0;
    scene.for_each_path(|q| {
        if let Some(prim) = &q.primitive {
            let at = layout.paths[k].points;
            for j in 0..prim.slot_count() {
                kind[at + j] = if prim.size_slots().contains(&j) {
                    Kind::Size
                } else {
                    Kind::Position
                };
            }
        }
        k += 1;
    });
    for (i, (v, slot)) in p.iter_mut().zip(&layout.slots).enumerate() {
        match (slot.group, kind[i]) {
            (ParamGroup::Points, Kind::Size) => {
                let m = (0.25 * max_px).min(0.5 * v.abs());
                *v += rng.range(-m, m)
            }
            (ParamGroup::Points, Kind::Position) => *v += rng.range(-0.25 * max_px, 0.25 * max_px),
            (ParamGroup::Points, Kind::Point) => *v += rng.range(-max_px, max_px),
            (ParamGroup::Color, _) => *v = (*v + rng.range(-max_color, max_color)).clamp(0.0, 1.0),
            _ => {}
        }
    }
    // A group transform moves its content's edge by up to a quarter of `max_px` through
    // each of its translation, angle and scale.
    let reaches = super::transform::reaches(&scene.nodes);
    for (&at, (reach, s, n)) in layout.transforms.iter().zip(reaches) {
        let q = 0.25 * max_px;
        p[at] += rng.range(-q, q);
        p[at + 1] += rng.range(-q, q);
        if reach > 0.0 && n == 4 {
            p[at + 2] += rng.range(-q, q) / reach;
            p[at + 3] *= 1.0 + rng.range(-q, q).clamp(-0.5 * reach, 0.5 * reach) / reach;
        } else if reach > 0.0 {
            // A general map's linear entries: each moves the edge by up to `q`.
            for v in &mut p[at + 2..at + n] {
                *v += s * rng.range(-q, q).clamp(-0.25 * reach, 0.25 * reach) / reach;
            }
        }
    }
    let mut out = scene.clone();
    out.set_params(&p);
    clamp_all_points(&mut out.nodes);
    // Image rectangles stay where they are, as fits keep them (SVG out writes an image
    // only at its own rectangle).
    let mut kept = Vec::new();
    scene.for_each_path(|q| {
        let image = matches!(q.fill.as_ref().map(|f| &f.paint), Some(Paint::Image(_)));
        kept.push(image.then(|| q.points.clone()));
    });
    let mut kept = kept.into_iter();
    out.for_each_path_mut(|q| {
        if let Some(Some(points)) = kept.next() {
            q.points = points;
        }
    });
    out
}

fn clamp_all_points(nodes: &mut [Node]) {
    for n in nodes {
        match n {
            Node::Group(g) => clamp_all_points(&mut g.children),
            Node::Path(p) => super::params::clamp_points(p),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn same_seed_same_scene() {
        assert_eq!(curved_paths(5, 64, 7), curved_paths(5, 64, 7));
        assert_ne!(curved_paths(5, 64, 7), curved_paths(5, 64, 8));
        let s = curved_paths(5, 64, 7);
        assert_eq!(s.path_count(), 5);
    }

    /// An image's rectangle is not perturbed (the shape beside it is), so the perturbed
    /// scene can be saved.
    #[test]
    fn perturb_keeps_image_rectangles() {
        use base64::Engine as _;
        let png = crate::image_io::encode_png_rgba8(1, 1, &[9, 8, 7, 255]);
        let url = base64::engine::general_purpose::STANDARD.encode(png);
        let svg = format!(
            r#"<svg xmlns="http://www.w3.org/2000/svg" width="20" height="20">
               <image x="2" y="2" width="9" height="9" href="data:image/png;base64,{url}"/>
               <rect x="5" y="5" width="9" height="9" fill="red"/></svg>"#
        );
        let s = Scene::from_svg_str(&svg, "t.svg", crate::scene::Sizing::Natural).unwrap();
        let moved = perturb(&s, 3.0, 0.1, 2);
        let points = |s: &Scene| {
            let mut v = Vec::new();
            s.for_each_path(|p| v.push(p.points.clone()));
            v
        };
        let (a, b) = (points(&s), points(&moved));
        assert_eq!(a[0], b[0]);
        assert_ne!(a[1], b[1]);
        assert!(crate::scene::svg_out::check_numbers(&moved).is_ok());
    }

    #[test]
    fn perturb_moves_within_bounds() {
        let s = curved_paths(3, 64, 1);
        let t = perturb(&s, 8.0, 0.2, 2);
        let layout = ParamLayout::new(&s);
        let (a, b) = (s.params(), t.params());
        let mut moved = 0;
        for ((x, y), slot) in a.iter().zip(&b).zip(&layout.slots) {
            let bound = match slot.group {
                ParamGroup::Points => 8.0,
                ParamGroup::Color => 0.2,
                _ => 0.0,
            };
            assert!((x - y).abs() <= bound, "{slot:?}: {x} → {y}");
            moved += (x != y) as usize;
        }
        assert!(moved > a.len() / 2);
    }

    /// `perturb --points 1e300` used to write coordinates near 1e306 that the reader
    /// refuses: moved points now stay in the readable range and the copy reads back.
    #[test]
    fn perturb_points_1e300_stays_readable() {
        let s = curved_paths(3, 64, 1);
        let t = perturb(&s, 1e300, 0.2, 2);
        let max = t.params().iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(max <= crate::limits::MAX_COORDINATE, "{max}");
        assert!(max > 1e29, "the points did move far: {max}");
        let text = t.to_svg_string();
        let back = Scene::from_svg_str(&text, "back.svg", crate::Sizing::Natural).unwrap();
        assert_eq!(back.params().len(), t.params().len());
    }
}
