//! Checking a loaded scene against the raster limits, before anything large is allocated.

use std::path::Path as FsPath;

use super::geom::{
    DEFAULT_TOLERANCE, arc_steps, cap_vertices, chord_count, flatten_rect, frame_tolerance,
};
use super::{Group, LineCap, LineJoin, Node, Scene};
use crate::limits::{MAX_GROUP_DEPTH, MAX_SCENE_CHORDS};
use crate::{Error, Result};

impl Scene {
    /// Refuses a scene that would need more than the raster limits allow, naming `name`:
    /// groups nested deeper than [`MAX_GROUP_DEPTH`], or more than [`MAX_SCENE_CHORDS`]
    /// flattened chords (plus round join and cap vertices) at the default tolerance
    /// (`raster::RenderOptions::default`, 0.02 px). The count uses the formula the flattener uses, on
    /// the control points only, so it allocates nothing in proportion to the answer.
    pub fn check_limits(&self, name: impl AsRef<FsPath>) -> Result<()> {
        let name = name.as_ref();
        let depth = self.group_depth();
        if depth > MAX_GROUP_DEPTH {
            return Err(Error::Unsupported {
                path: name.to_path_buf(),
                what: format!(
                    "layers (groups, clip paths, masks) nested {depth} deep (the limit is \
                     {MAX_GROUP_DEPTH})"
                ),
            });
        }
        let chords = self.chord_estimate(DEFAULT_TOLERANCE);
        if chords > MAX_SCENE_CHORDS as u64 {
            return Err(Error::Unsupported {
                path: name.to_path_buf(),
                what: format!(
                    "the drawing flattens to more than {MAX_SCENE_CHORDS} line segments at \
                     {}×{} px (the limit); render it smaller or simplify it",
                    self.width, self.height
                ),
            });
        }
        Ok(())
    }

    /// Deepest nesting of layers (0 without groups): a [`Node::Group`] is one, and the
    /// content of its clip path and of its mask one more inside it.
    pub fn group_depth(&self) -> usize {
        let mut deepest = 0;
        // (a layer's content, its depth)
        let mut stack: Vec<(&Group, usize)> = Vec::new();
        fn push_children<'a>(nodes: &'a [Node], depth: usize, stack: &mut Vec<(&'a Group, usize)>) {
            for n in nodes {
                if let Node::Group(g) = n {
                    stack.push((g, depth));
                }
            }
        }
        push_children(&self.nodes, 1, &mut stack);
        while let Some((g, depth)) = stack.pop() {
            deepest = deepest.max(depth);
            push_children(&g.children, depth + 1, &mut stack);
            let clip = g.clip.as_ref().map(|c| &c.content);
            let mask = g.mask.as_ref().map(|m| &m.content);
            for content in [clip, mask].into_iter().flatten() {
                stack.push((content, depth + 1));
            }
        }
        deepest
    }

    /// Chords the flattener will make at `tolerance` (device pixels), plus the vertices of
    /// round joins and caps; stops counting once past [`MAX_SCENE_CHORDS`].
    pub fn chord_estimate(&self, tolerance: f64) -> u64 {
        let mut total = 0u64;
        self.for_each_path(|path| {
            if total > MAX_SCENE_CHORDS as u64 {
                return;
            }
            let visible = flatten_rect(path, self.width, self.height);
            let mut corners = 0u64;
            for sp in &path.subpaths {
                for k in 0..sp.segments() {
                    let p = path.segment_points(sp, k);
                    total += chord_count(&p, tolerance, visible) as u64;
                    corners += 1;
                }
                // The closing chord (and the start point).
                total += 1;
            }
            if let Some(s) = path.stroke.as_ref().filter(|s| s.width > 0.0) {
                let (h, tol) = (0.5 * s.width, frame_tolerance(s, tolerance));
                if s.join == LineJoin::Round {
                    total += corners * arc_steps(h, tol, std::f64::consts::PI) as u64;
                }
                if s.cap == LineCap::Round && s.dash.is_none() {
                    total += 2 * path.subpaths.len() as u64 * cap_vertices(s.cap, h, tol) as u64;
                }
            }
        });
        total
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{Group, Paint, Path, Stroke};

    fn nested(depth: usize) -> Scene {
        let mut p = Path::new("p");
        p.move_to([1.0, 1.0]);
        p.line_to([5.0, 5.0]);
        p.stroke = Some(Stroke::new(Paint::Solid([0.0; 3]), 1.0));
        let mut node = Node::Path(p);
        for _ in 0..depth {
            node = Node::Group(Group::new(String::new(), 0.5, vec![node]));
        }
        let mut s = Scene::new(10, 10);
        s.nodes.push(node);
        s
    }

    #[test]
    fn group_depth_over_the_limit_is_refused() {
        assert_eq!(nested(3).group_depth(), 3);
        assert!(nested(MAX_GROUP_DEPTH).check_limits("n.svg").is_ok());
        let e = nested(MAX_GROUP_DEPTH + 1)
            .check_limits("n.svg")
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("n.svg: ") && e.contains("257 deep"), "{e}");
    }
}
