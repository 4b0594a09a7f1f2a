//! Pattern tiles that share one set of parameters.
//!
//! A shape painted with a `<pattern>` is read as a layer clipped by the shape whose
//! children are the pattern's tiles: the tile content placed at each cell that covers the
//! shape (`svg_in.rs`). When the content translates exactly (`translatable`: no
//! filter in it, filter regions are whole pixels), the group carries a [`Tiling`] and its tiles are
//! **translated copies of the first**: tile `k` is tile 0 moved by the device vector
//! between their cells.
//!
//! **One parameter, many copies** (as a closed path's closing point is its start's,
//! [`params`](super::params)): every tile keeps its slots in the parameter vector, but the
//! values are tile 0's. [`Scene::set_params`](super::Scene::set_params) writes tile 0 and
//! rebuilds the other tiles from it (`retile`); the gradient of each copy's slot is
//! added to the matching slot of tile 0 and the copy's is set to 0 (`tie_gradients`).
//! The map from tile 0 to a copy is a translation, whose Jacobian is the identity on
//! every slot (positions move by the same vector, everything else is equal), so the
//! sum is the exact gradient. Patterns inside a pattern's tile are tied the same way,
//! innermost first when writing and outermost first when adding.
//!
//! The SVG writer writes such a group back as a `<pattern>` paint of its shape
//! (`svg_out.rs`), from tile 0.

use super::geom::add_scaled;
use super::{Affine, Group, Node, Paint, Path, Point, apply, concat};

/// How a pattern's tiles are laid out; see the [module docs](self).
#[derive(Clone, Debug, PartialEq)]
pub struct Tiling {
    /// Pattern space → device pixels (the referencing element's transform times
    /// `patternTransform`).
    pub transform: Affine,
    /// The cell of index `(0, 0)` in pattern space: `x, y, width, height`. Cell `(i, j)` is
    /// this one moved by `(i · width, j · height)`; a tile's content has its origin at its
    /// cell's corner. Width and height are the pattern's, rounded (as resvg does) so that a
    /// tile is a whole number of device pixels.
    pub cell: [f64; 4],
    /// The cell index `(i, j)` of each tile, in the order of the group's children.
    pub cells: Vec<[i64; 2]>,
    /// Nodes per tile: tile `k` is the group's children `k · per_tile .. (k + 1) · per_tile`.
    pub per_tile: usize,
    /// Whether each tile is clipped to its cell (each tile is then one group whose clip is
    /// the cell); otherwise the content stays inside its cell.
    pub clipped: bool,
}

impl Tiling {
    /// Pattern space → device pixels for the content of the tile at `cell`.
    pub fn tile_transform(&self, [i, j]: [i64; 2]) -> Affine {
        let [x, y, w, h] = self.cell;
        let to_cell: Affine = [1.0, 0.0, 0.0, 1.0, x + i as f64 * w, y + j as f64 * h];
        concat(&self.transform, &to_cell)
    }

    /// The device vector from tile 0's place to tile `k`'s.
    fn offset(&self, k: usize) -> Point {
        let origin = |c: [i64; 2]| apply(&self.tile_transform(c), [0.0, 0.0]);
        let (a, b) = (origin(self.cells[0]), origin(self.cells[k]));
        [b[0] - a[0], b[1] - a[1]]
    }
}

/// Whether any group under `nodes` is tiled.
pub(crate) fn any(nodes: &[Node]) -> bool {
    fn group(g: &Group) -> bool {
        g.tiling.is_some()
            || any(&g.children)
            || g.clip.as_ref().is_some_and(|c| group(&c.content))
            || g.mask.as_ref().is_some_and(|m| group(&m.content))
    }
    nodes
        .iter()
        .any(|n| matches!(n, Node::Group(g) if group(g)))
}

/// Whether `nodes` can be moved exactly by a device translation ([`map_nodes`]): nothing
/// in them has a filter (filter regions are whole device pixels).
pub(crate) fn translatable(nodes: &[Node]) -> bool {
    fn group(g: &Group) -> bool {
        g.filters.is_empty()
            && translatable(&g.children)
            && g.clip.as_ref().is_none_or(|c| group(&c.content))
            && g.mask.as_ref().is_none_or(|m| group(&m.content))
    }
    nodes.iter().all(|n| match n {
        Node::Path(_) => true,
        Node::Group(g) => group(g),
    })
}

/// Maps a path's device values by `x ↦ k·x + d` (`k > 0`): its points, a primitive's own
/// parameters, its paints' transforms and its stroke's frame. Widths stay (the frame
/// carries the scale until [`normalize_frame`](super::Stroke::normalize_frame)).
pub(crate) fn map_path(p: &mut Path, k: f64, d: Point) {
    let m: Affine = [k, 0.0, 0.0, k, d[0], d[1]];
    let paint = |paint: &mut Paint| match paint {
        Paint::Gradient(g) => g.transform = concat(&m, &g.transform),
        Paint::Image(i) => i.transform = concat(&m, &i.transform),
        Paint::Solid(_) => {}
    };
    for q in &mut p.points {
        *q = add_scaled(d, *q, k);
    }
    if let Some(prim) = &mut p.primitive {
        prim.scale_translate(k, d);
        p.sync_primitive();
    }
    if let Some(f) = &mut p.fill {
        paint(&mut f.paint);
    }
    if let Some(s) = &mut p.stroke {
        paint(&mut s.paint);
        for v in &mut s.frame {
            *v *= k;
        }
        s.normalize_frame();
    }
}

/// Maps the device values of `nodes` by `x ↦ k·x + d` (`k > 0`): every path
/// ([`map_path`]), the outermost group transforms and every tiling's transform. Exact for
/// [`translatable`] nodes (filter regions are not mapped).
pub(crate) fn map_nodes(nodes: &mut [Node], k: f64, d: Point) {
    super::paths_of_mut(nodes, &mut |p| map_path(p, k, d));
    super::transform::map_outermost(nodes, k, d);
    fn tilings(g: &mut Group, k: f64, d: Point) {
        if let Some(t) = &mut g.tiling {
            let [a, b, c, e, f, h] = t.transform;
            t.transform = [k * a, k * b, k * c, k * e, k * f + d[0], k * h + d[1]];
        }
        each_group(&mut g.children, &mut |g| tilings(g, k, d));
        if let Some(c) = &mut g.clip {
            tilings(&mut c.content, k, d);
        }
        if let Some(m) = &mut g.mask {
            tilings(&mut m.content, k, d);
        }
    }
    each_group(nodes, &mut |g| tilings(g, k, d));
}

/// Calls `f` on each group among `nodes` (not below them).
fn each_group(nodes: &mut [Node], f: &mut impl FnMut(&mut Group)) {
    for n in nodes {
        if let Node::Group(g) = n {
            f(g);
        }
    }
}

/// Every tile of `tiling`: `first` (tile 0, device values) and its copies, each moved to
/// its cell.
pub(crate) fn copies(first: &[Node], tiling: &Tiling) -> Vec<Node> {
    let mut out = first.to_vec();
    for k in 1..tiling.cells.len() {
        let mut copy = first.to_vec();
        map_nodes(&mut copy, 1.0, tiling.offset(k));
        out.extend(copy);
    }
    out
}

/// Rebuilds every tiled group's copies from its tile 0, innermost patterns first (so a
/// copy carries its tile 0's own rebuilt tiles).
pub(crate) fn retile(nodes: &mut [Node]) {
    if any(nodes) {
        each_group(nodes, &mut retile_group);
    }
}

/// [`retile`] on a tiled group and everything under it.
fn retile_group(g: &mut Group) {
    match &g.tiling {
        Some(t) if t.per_tile > 0 && g.children.len() == t.per_tile * t.cells.len() => {
            let t = t.clone();
            each_group(&mut g.children[..t.per_tile], &mut retile_group);
            g.children = copies(&g.children[..t.per_tile], &t);
        }
        _ => each_group(&mut g.children, &mut retile_group),
    }
    if let Some(c) = &mut g.clip {
        retile_group(&mut c.content);
    }
    if let Some(m) = &mut g.mask {
        retile_group(&mut m.content);
    }
}

/// The slots of one tiled group's tiles, as the parameter walk finds them: tile `k`'s
/// slots are `start + k · len .. start + (k + 1) · len`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct TileSlots {
    /// First slot of tile 0.
    pub start: usize,
    /// Slots per tile.
    pub len: usize,
    /// Number of tiles.
    pub tiles: usize,
}

/// Adds each copy's gradient to tile 0's matching slot and zeroes the copy's, for every
/// tiled group (`tiles` in the walk's post-order, so inner patterns come before the
/// pattern whose tile holds them: the outer ones are tied first here).
pub(crate) fn tie_gradients(tiles: &[TileSlots], grad: &mut [f64]) {
    for t in tiles.iter().rev() {
        for k in 1..t.tiles {
            for s in 0..t.len {
                let copy = t.start + k * t.len + s;
                grad[t.start + s] += grad[copy];
                grad[copy] = 0.0;
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Scene, Sizing};

    /// A rectangle and a stroke painted with a rotated pattern of two shapes (so that
    /// each tile is several nodes), and a pattern inside the pattern.
    const PATTERNED: &str = r##"<svg xmlns="http://www.w3.org/2000/svg" width="48" height="40">
        <pattern id="dots" patternUnits="userSpaceOnUse" width="4" height="4">
          <circle cx="2" cy="2" r="1.2" fill="#203080"/></pattern>
        <pattern id="p" patternUnits="userSpaceOnUse" x="1" y="2" width="11" height="9"
                 patternTransform="rotate(20) scale(1.1)">
          <path d="M 1 1 L 8 2 L 5 7 Z" fill="#e08020" fill-opacity="0.8"/>
          <circle cx="8" cy="6" r="2.5" fill="url(#dots)"/>
        </pattern>
        <rect x="3" y="2" width="40" height="34" fill="url(#p)" fill-opacity="0.9"/>
        <path d="M 4 38 L 44 30" stroke="url(#p)" stroke-width="4"/></svg>"##;

    fn tiled(s: &Scene) -> Vec<&Group> {
        let mut out = Vec::new();
        fn find<'a>(nodes: &'a [Node], out: &mut Vec<&'a Group>) {
            for n in nodes {
                if let Node::Group(g) = n {
                    if g.tiling.is_some() {
                        out.push(g);
                    }
                    find(&g.children, out);
                }
            }
        }
        find(&s.nodes, &mut out);
        out
    }

    /// The device points of every path under `nodes`.
    fn points(nodes: &[Node]) -> Vec<Point> {
        let mut out = Vec::new();
        super::super::paths_of(nodes, super::super::Role::Paint, &mut |p, _| {
            out.extend_from_slice(&p.points)
        });
        out
    }

    /// Every tile is tile 0 moved to its cell, after reading and after any `set_params`,
    /// whatever was written into the copies' slots.
    #[test]
    fn tiles_are_moved_copies_of_the_first() {
        let mut s = Scene::from_svg_str(PATTERNED, "p.svg", Sizing::Natural).unwrap();
        let check = |s: &Scene| {
            let groups = tiled(s);
            // The fill's and the stroke's patterns, and the dots in each of their tiles.
            assert!(groups.len() > 4, "{} tiled groups", groups.len());
            for g in groups {
                let t = g.tiling.as_ref().unwrap();
                assert!(t.cells.len() > 1 && t.per_tile > 0);
                let first = points(&g.children[..t.per_tile]);
                for k in 1..t.cells.len() {
                    let d = t.offset(k);
                    let copy = points(&g.children[k * t.per_tile..(k + 1) * t.per_tile]);
                    assert_eq!(copy.len(), first.len());
                    for (a, b) in first.iter().zip(&copy) {
                        assert!((a[0] + d[0] - b[0]).abs() < 1e-9);
                        assert!((a[1] + d[1] - b[1]).abs() < 1e-9);
                    }
                }
            }
        };
        check(&s);
        let mut p = s.params();
        for (k, v) in p.iter_mut().enumerate() {
            *v += 0.01 * (k as f64 * 0.7).sin();
        }
        s.set_params(&p);
        check(&s);
        // What a copy's slots held is not what the copy draws: tile 0's values are.
        let q = s.params();
        let layout = super::super::ParamLayout::new(&s);
        let mut scratch = s.clone();
        let tiles = super::super::params::walk(&mut scratch, &mut |_, _, _, _| {});
        assert!(!tiles.is_empty());
        for t in &tiles {
            for k in 1..t.tiles {
                for i in 0..t.len {
                    let (a, b) = (t.start + i, t.start + k * t.len + i);
                    let group = layout.slots[a].group;
                    assert_eq!(group, layout.slots[b].group);
                    if group != super::super::ParamGroup::Points {
                        assert_eq!(q[a], q[b], "slot {b} is not tile 0's slot {a}");
                    }
                }
            }
        }
    }

    /// Written back, a tiled group is a `<pattern>` holding tile 0, read back as the same
    /// tiles with the same parameters (the pixels: `layers::patterns_are_written_back_as_patterns`).
    #[test]
    fn patterns_are_written_as_patterns() {
        let s = Scene::from_svg_str(PATTERNED, "p.svg", Sizing::Natural).unwrap();
        let text = s.to_svg_string();
        assert_eq!(text.matches("<pattern ").count(), 2 + 2, "{text}");
        // Tile 0's content once per pattern, not a copy per tile.
        assert_eq!(text.matches("<circle").count(), 2 + 2, "{text}");
        let b = Scene::from_svg_str(&text, "back.svg", Sizing::Natural).unwrap();
        assert_eq!(b.params().len(), s.params().len());
        assert_eq!(tiled(&b).len(), tiled(&s).len());
        for (a, b) in s.params().iter().zip(b.params()) {
            assert!((a - b).abs() < 1e-3, "{a} became {b}");
        }
    }
}
