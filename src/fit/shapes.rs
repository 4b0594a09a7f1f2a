//! Starting shapes for vectorization: DiffVG's random blobs and strokes, and small closed
//! cubic "circles" placed where the error is.

use crate::scene::random::Rng;
use crate::scene::{Fill, FillRule, Node, Paint, Path, Point, Scene, Stroke};

/// Step of DiffVG's random walk, as a fraction of the canvas.
const WALK: f64 = 0.05;

/// A random walk of `segments` cubic segments from a random start, as DiffVG's painterly
/// example makes it: each new point is the previous one plus `0.05 × canvas × (u − ½)` per
/// axis. For a closed path the last end point is the start point.
fn walk(rng: &mut Rng, segments: usize, w: f64, h: f64, closed: bool) -> Path {
    let mut p = Path::new("");
    let mut cur = [rng.range(0.0, 1.0), rng.range(0.0, 1.0)];
    let to_px = |q: [f64; 2]| [q[0] * w, q[1] * h];
    let start = cur;
    p.move_to(to_px(cur));
    let step = |from: [f64; 2], rng: &mut Rng| {
        [
            from[0] + WALK * (rng.range(0.0, 1.0) - 0.5),
            from[1] + WALK * (rng.range(0.0, 1.0) - 0.5),
        ]
    };
    for j in 0..segments {
        let c1 = step(cur, rng);
        let c2 = step(c1, rng);
        let end = step(c2, rng);
        let end = if closed && j + 1 == segments {
            start
        } else {
            end
        };
        p.cubic_to(to_px(c1), to_px(c2), to_px(end));
        cur = end;
    }
    if closed {
        p.close();
    }
    p
}

/// A uniformly random straight RGB color (three draws, red first).
fn random_rgb(rng: &mut Rng) -> [f64; 3] {
    [
        rng.range(0.0, 1.0),
        rng.range(0.0, 1.0),
        rng.range(0.0, 1.0),
    ]
}

/// DiffVG's painterly blob workload: `n` closed paths of 3–5 cubic segments from a random
/// walk, random straight RGBA fills (RGB as the color, A as the fill opacity), even-odd
/// rule, no stroke.
pub fn random_blobs(n: usize, width: u32, height: u32, seed: u64) -> Scene {
    let mut rng = Rng::new(seed);
    let mut scene = Scene::new(width, height);
    for i in 0..n {
        let segments = 3 + (rng.next_u64() % 3) as usize;
        let mut p = walk(&mut rng, segments, width as f64, height as f64, true);
        p.id = format!("blob{i}");
        let c = random_rgb(&mut rng);
        p.fill = Some(Fill {
            paint: Paint::Solid(c),
            opacity: rng.range(0.0, 1.0),
            rule: FillRule::EvenOdd,
        });
        scene.nodes.push(Node::Path(p));
    }
    scene
}

/// DiffVG's painterly strokes: `n` open paths of 1–3 cubic segments from a random walk,
/// stroked 1 px wide with random straight RGBA colors, round caps and joins, no fill.
pub fn random_strokes(n: usize, width: u32, height: u32, seed: u64) -> Scene {
    let mut rng = Rng::new(seed);
    let mut scene = Scene::new(width, height);
    for i in 0..n {
        let segments = 1 + (rng.next_u64() % 3) as usize;
        let mut p = walk(&mut rng, segments, width as f64, height as f64, false);
        p.id = format!("stroke{i}");
        let c = random_rgb(&mut rng);
        let mut s = Stroke::new(Paint::Solid(c), 1.0);
        s.opacity = rng.range(0.0, 1.0);
        s.join = crate::scene::LineJoin::Round;
        s.cap = crate::scene::LineCap::Round;
        p.stroke = Some(s);
        scene.nodes.push(Node::Path(p));
    }
    scene
}

/// A closed path of `segments` cubics approximating the circle of center `c` and radius
/// `r` (pixels), filled with an opaque straight RGB `color`, nonzero rule.
pub(crate) fn circle(
    id: impl Into<String>,
    c: Point,
    r: f64,
    segments: usize,
    color: [f64; 3],
) -> Path {
    let k = segments.max(2);
    let step = std::f64::consts::TAU / k as f64;
    let kappa = 4.0 / 3.0 * (step / 4.0).tan() * r;
    let at = |a: f64| [c[0] + r * a.cos(), c[1] + r * a.sin()];
    let tangent = |a: f64| [-a.sin(), a.cos()];
    let mut p = Path::new(id);
    p.move_to(at(0.0));
    for j in 0..k {
        let (a0, a1) = (j as f64 * step, (j + 1) as f64 * step);
        let (p0, p1) = (at(a0), at(a1));
        let (t0, t1) = (tangent(a0), tangent(a1));
        p.cubic_to(
            [p0[0] + kappa * t0[0], p0[1] + kappa * t0[1]],
            [p1[0] - kappa * t1[0], p1[1] - kappa * t1[1]],
            if j + 1 == k { at(0.0) } else { p1 },
        );
    }
    p.close();
    p.fill = Some(Fill {
        paint: Paint::Solid(color),
        opacity: 1.0,
        rule: FillRule::NonZero,
    });
    p
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::{RenderOptions, render};

    #[test]
    fn blobs_follow_diffvg() {
        let s = random_blobs(50, 256, 128, 1);
        assert_eq!(s.path_count(), 50);
        s.for_each_path(|p| {
            let segs = p.subpaths[0].segments();
            assert!((3..=5).contains(&segs), "{segs}");
            assert_eq!(
                p.points[0],
                *p.points.last().unwrap(),
                "closed on its start"
            );
            // Each of the 3·segs steps moves at most 2.5% of the canvas per axis.
            let b = p.control_bounds().unwrap();
            assert!(b[2] - b[0] <= 0.025 * 256.0 * 3.0 * segs as f64);
            assert!(b[3] - b[1] <= 0.025 * 128.0 * 3.0 * segs as f64);
            let f = p.fill.as_ref().unwrap();
            assert_eq!(f.rule, FillRule::EvenOdd);
            assert!((0.0..=1.0).contains(&f.opacity));
        });
        assert_eq!(random_blobs(5, 64, 64, 3), random_blobs(5, 64, 64, 3));
        let strokes = random_strokes(10, 64, 64, 2);
        strokes.for_each_path(|p| {
            assert!(p.fill.is_none());
            assert_eq!(p.stroke.as_ref().unwrap().width, 1.0);
            assert!((1..=3).contains(&p.subpaths[0].segments()));
        });
    }

    #[test]
    fn circle_has_the_right_area() {
        for k in [3, 4, 6] {
            let mut s = Scene::new(64, 64);
            s.nodes.push(Node::Path(circle(
                "c",
                [32.0, 32.0],
                20.0,
                k,
                [1.0, 0.0, 0.0],
            )));
            let img = render(&s, &RenderOptions::default());
            let area: f64 = img.data.iter().map(|p| p[3] as f64).sum();
            let exact = std::f64::consts::PI * 400.0;
            assert!(
                (area - exact).abs() < 0.01 * exact,
                "{k}: {area} vs {exact}"
            );
        }
    }
}
