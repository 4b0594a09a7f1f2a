//! The classic low-poly baseline of `mesh simplify`: quadric-error edge collapse
//! (meshoptimizer's `simplify`, through the `meshopt` crate) to a target triangle count,
//! and a texture for the result **reprojected** from a high-poly reference: each texel of
//! the low-poly mesh's UV chart takes the reference's color at (about) the nearest point
//! of the reference surface.

use rayon::prelude::*;

use super::render::{sample_value, uv_at};
use super::{Mesh, Texture};
use crate::error::{Error, Result};

/// Simplifies `mesh` to at most `target` triangles by quadric-error edge collapses
/// (meshoptimizer, no error bound), keeping the surviving vertices' attributes: vertices
/// at one position with different UVs (seams) are collapsed only along their seam, so UV
/// charts stay intact. The result may keep more than `target` triangles when no collapse
/// is left that keeps the topology; it keeps the texture (its UVs are the old ones) and
/// drops unused vertices. A `target` at or above the triangle count returns a copy.
pub fn simplify(mesh: &Mesh, target: usize) -> Result<Mesh> {
    if target == 0 {
        return Err(Error::Setting {
            name: "triangles".into(),
            message: "the target must be at least 1".into(),
        });
    }
    mesh.validate(std::path::Path::new("<mesh>"))?;
    if target >= mesh.triangles.len() {
        return Ok(mesh.clone());
    }
    // meshoptimizer works in f32: positions relative to the bounds' center.
    let (lo, hi) = mesh.bounds();
    let c = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
    let pos: Vec<[f32; 3]> = mesh
        .positions
        .iter()
        .map(|p| [0, 1, 2].map(|k| (p[k] - c[k]) as f32))
        .collect();
    let indices: Vec<u32> = mesh.triangles.iter().flatten().copied().collect();
    let kept = meshopt::simplify_decoder(
        &indices,
        &pos,
        target * 3,
        1.0,
        meshopt::SimplifyOptions::None,
        None,
    );
    // Compact: the surviving vertices in order of first use.
    let mut remap = vec![u32::MAX; mesh.positions.len()];
    let mut order = Vec::new();
    let triangles: Vec<[u32; 3]> = kept
        .chunks_exact(3)
        .map(|t| {
            [0, 1, 2].map(|k| {
                let v = t[k] as usize;
                if remap[v] == u32::MAX {
                    remap[v] = order.len() as u32;
                    order.push(v);
                }
                remap[v]
            })
        })
        .collect();
    let pick = |a: &Vec<[f64; 2]>| order.iter().map(|&i| a[i]).collect::<Vec<_>>();
    Ok(Mesh {
        positions: order.iter().map(|&i| mesh.positions[i]).collect(),
        triangles,
        uvs: mesh.uvs.as_ref().map(pick),
        colors: mesh
            .colors
            .as_ref()
            .map(|a| order.iter().map(|&i| a[i]).collect()),
        texture: mesh.texture.clone(),
    })
}

/// The color of `mesh` at barycentrics `b` of triangle `t`: vertex colors (white without)
/// times the bilinear texture sample, as the renderer colors it.
fn color_at(mesh: &Mesh, t: [u32; 3], b: [f64; 3]) -> [f64; 3] {
    let mut c = [1.0; 3];
    if let Some(cols) = &mesh.colors {
        c = [0.0; 3];
        for k in 0..3 {
            for (ch, v) in c.iter_mut().enumerate() {
                *v += b[k] * cols[t[k] as usize][ch];
            }
        }
    }
    if let (Some(tex), Some(uvs)) = (&mesh.texture, &mesh.uvs) {
        let s = sample_value(tex, uv_at(uvs, t, b));
        for ch in 0..3 {
            c[ch] *= s[ch];
        }
    }
    c
}

/// A uniform grid of a mesh's vertices, and each vertex's triangles: finds (about) the
/// nearest point of the surface to a query point as the nearest point of the triangles
/// around the nearest vertex.
struct Nearest<'a> {
    mesh: &'a Mesh,
    lo: [f64; 3],
    cell: f64,
    dims: [usize; 3],
    cell_start: Vec<u32>,
    cell_verts: Vec<u32>,
    vert_start: Vec<u32>,
    vert_tris: Vec<u32>,
}

impl<'a> Nearest<'a> {
    fn new(mesh: &'a Mesh) -> Nearest<'a> {
        let (lo, hi) = mesh.bounds();
        let n = mesh.positions.len().max(1);
        let ext = [0, 1, 2].map(|k| (hi[k] - lo[k]).max(1e-12));
        // About two vertices per cell, at most 2²⁴ cells.
        let vol = ext[0] * ext[1] * ext[2];
        let cells = (n as f64 / 2.0).clamp(1.0, (1u64 << 24) as f64);
        let mut cell = (vol / cells).cbrt();
        let max_ext = ext.iter().cloned().fold(0.0, f64::max);
        cell = cell.max(max_ext / 256.0);
        let dims = ext.map(|e| ((e / cell).floor() as usize + 1).min(257));
        let key = |p: &[f64; 3]| -> usize {
            let i = [0, 1, 2].map(|k| (((p[k] - lo[k]) / cell) as usize).min(dims[k] - 1));
            (i[2] * dims[1] + i[1]) * dims[0] + i[0]
        };
        let ncell = dims[0] * dims[1] * dims[2];
        let (cell_start, cell_verts) = bucket(ncell, mesh.positions.iter().map(key).enumerate());
        let (vert_start, vert_tris) = bucket(
            mesh.positions.len(),
            mesh.triangles
                .iter()
                .enumerate()
                .flat_map(|(t, tri)| tri.iter().map(move |&v| (t, v as usize))),
        );
        Nearest {
            mesh,
            lo,
            cell,
            dims,
            cell_start,
            cell_verts,
            vert_start,
            vert_tris,
        }
    }

    /// The nearest point's triangle and barycentrics, or `None` for an empty mesh.
    fn query(&self, p: [f64; 3]) -> Option<(u32, [f64; 3])> {
        let m = self.mesh;
        let ci = [0, 1, 2].map(|k| {
            (((p[k] - self.lo[k]) / self.cell).floor()).clamp(0.0, (self.dims[k] - 1) as f64) as i64
        });
        let mut best: Option<(f64, u32)> = None;
        // Rings of cells around p's cell until the ring is farther than the best vertex.
        let max_ring = *self.dims.iter().max().unwrap_or(&1) as i64;
        for ring in 0..=max_ring {
            if let Some((d2, _)) = best {
                let reach = (ring - 1).max(0) as f64 * self.cell;
                if reach * reach > d2 {
                    break;
                }
            }
            for z in ci[2] - ring..=ci[2] + ring {
                for y in ci[1] - ring..=ci[1] + ring {
                    for x in ci[0] - ring..=ci[0] + ring {
                        let on_ring = [x - ci[0], y - ci[1], z - ci[2]]
                            .iter()
                            .any(|d| d.abs() == ring);
                        let inside = [x, y, z]
                            .iter()
                            .zip(&self.dims)
                            .all(|(&v, &d)| v >= 0 && (v as usize) < d);
                        if !on_ring || !inside {
                            continue;
                        }
                        let c =
                            (z as usize * self.dims[1] + y as usize) * self.dims[0] + x as usize;
                        let verts = &self.cell_verts
                            [self.cell_start[c] as usize..self.cell_start[c + 1] as usize];
                        for &v in verts {
                            let q = m.positions[v as usize];
                            let d2 = (0..3).map(|k| (q[k] - p[k]).powi(2)).sum::<f64>();
                            if best.is_none_or(|(b, bv)| d2 < b || (d2 == b && v < bv)) {
                                best = Some((d2, v));
                            }
                        }
                    }
                }
            }
        }
        let (_, v) = best?;
        let tris = &self.vert_tris
            [self.vert_start[v as usize] as usize..self.vert_start[v as usize + 1] as usize];
        let mut out: Option<(f64, u32, [f64; 3])> = None;
        for &t in tris {
            let tri = m.triangles[t as usize].map(|i| m.positions[i as usize]);
            let (q, b) = closest_on_triangle(p, tri);
            let d2 = (0..3).map(|k| (q[k] - p[k]).powi(2)).sum::<f64>();
            if out.is_none_or(|(bd, _, _)| d2 < bd) {
                out = Some((d2, t, b));
            }
        }
        out.map(|(_, t, b)| (t, b))
    }
}

/// Counting sort of `(item, bucket)` pairs into `n` buckets: `(start, items)` with bucket
/// `i`'s items at `items[start[i]..start[i + 1]]`, in input order.
fn bucket(n: usize, pairs: impl Iterator<Item = (usize, usize)> + Clone) -> (Vec<u32>, Vec<u32>) {
    let mut start = vec![0u32; n + 1];
    for (_, b) in pairs.clone() {
        start[b + 1] += 1;
    }
    for i in 0..n {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut items = vec![0u32; start[n] as usize];
    for (it, b) in pairs {
        items[fill[b] as usize] = it as u32;
        fill[b] += 1;
    }
    (start, items)
}

/// The point of triangle `t` nearest to `p`, and its barycentrics (Ericson, Real-Time
/// Collision Detection, 5.1.5).
fn closest_on_triangle(p: [f64; 3], t: [[f64; 3]; 3]) -> ([f64; 3], [f64; 3]) {
    let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let [a, b, c] = t;
    let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
    let at = |w: [f64; 3]| {
        (
            [0, 1, 2].map(|k| w[0] * a[k] + w[1] * b[k] + w[2] * c[k]),
            w,
        )
    };
    let (d1, d2) = (dot(ab, ap), dot(ac, ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return at([1.0, 0.0, 0.0]);
    }
    let bp = sub(p, b);
    let (d3, d4) = (dot(ab, bp), dot(ac, bp));
    if d3 >= 0.0 && d4 <= d3 {
        return at([0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return at([1.0 - v, v, 0.0]);
    }
    let cp = sub(p, c);
    let (d5, d6) = (dot(ab, cp), dot(ac, cp));
    if d6 >= 0.0 && d5 <= d6 {
        return at([0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return at([1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return at([0.0, 1.0 - w, w]);
    }
    let denom = va + vb + vc;
    if denom.abs() < 1e-300 {
        return at([1.0, 0.0, 0.0]);
    }
    let (v, w) = (vb / denom, vc / denom);
    at([1.0 - v - w, v, w])
}

/// A `size × size` texture (`size` 1 to 4096) for `low` (which must have UVs) reprojected
/// from `reference`: every texel whose center lies in a triangle of `low`'s UV chart gets
/// the color of `reference` (vertex colors times texture, as rendered) at the point of
/// its surface nearest to the texel's 3D point on `low` (the nearest point of the
/// triangles around the nearest reference vertex). Texels outside the chart take the mean
/// of their covered neighbours, grown outwards 8 texels (so bilinear samples at chart
/// borders do not bleed the background), the rest the mean color. Deterministic,
/// parallel over texels.
pub fn reproject_texture(low: &Mesh, reference: &Mesh, size: u32) -> Result<Texture> {
    crate::limits::check_count("texture size", size as usize, 1..=4096)?;
    let uvs = low.uvs.as_ref().ok_or_else(|| Error::Setting {
        name: "mesh".into(),
        message: "the low-poly mesh has no UVs to reproject a texture into".into(),
    })?;
    low.validate(std::path::Path::new("<low-poly mesh>"))?;
    reference.validate(std::path::Path::new("<reference mesh>"))?;
    let n = size as usize;
    // Which triangle (and barycentrics) holds each texel center.
    let mut owner: Vec<Option<(u32, [f64; 3])>> = vec![None; n * n];
    for (ti, t) in low.triangles.iter().enumerate() {
        let q = t.map(|i| uvs[i as usize]);
        // Texel (x, y) center: u = (x + ½)/n, v = 1 − (y + ½)/n.
        let px = q.map(|p| [p[0] * n as f64 - 0.5, (1.0 - p[1]) * n as f64 - 0.5]);
        let det = (px[1][0] - px[0][0]) * (px[2][1] - px[0][1])
            - (px[2][0] - px[0][0]) * (px[1][1] - px[0][1]);
        if det.abs() < 1e-12 {
            continue;
        }
        let range = |k: usize| {
            let lo = px.iter().map(|p| p[k]).fold(f64::INFINITY, f64::min);
            let hi = px.iter().map(|p| p[k]).fold(f64::NEG_INFINITY, f64::max);
            (
                lo.ceil().max(0.0) as usize,
                (hi.floor().min(n as f64 - 1.0)).max(-1.0),
            )
        };
        let ((x0, x1), (y0, y1)) = (range(0), range(1));
        if x1 < 0.0 || y1 < 0.0 {
            continue;
        }
        for y in y0..=y1 as usize {
            for x in x0..=x1 as usize {
                let (fx, fy) = (x as f64, y as f64);
                let b1 = ((fx - px[0][0]) * (px[2][1] - px[0][1])
                    - (px[2][0] - px[0][0]) * (fy - px[0][1]))
                    / det;
                let b2 = ((px[1][0] - px[0][0]) * (fy - px[0][1])
                    - (fx - px[0][0]) * (px[1][1] - px[0][1]))
                    / det;
                let b0 = 1.0 - b1 - b2;
                if b0 >= -1e-9 && b1 >= -1e-9 && b2 >= -1e-9 {
                    owner[y * n + x].get_or_insert((ti as u32, [b0, b1, b2]));
                }
            }
        }
    }
    let near = Nearest::new(reference);
    let mut data: Vec<Option<[f64; 3]>> = owner
        .par_iter()
        .map(|o| {
            let (t, b) = (*o)?;
            let tri = low.triangles[t as usize];
            let p = [0, 1, 2].map(|k| {
                (0..3)
                    .map(|j| b[j] * low.positions[tri[j] as usize][k])
                    .sum()
            });
            let (rt, rb) = near.query(p)?;
            Some(color_at(reference, reference.triangles[rt as usize], rb))
        })
        .collect();
    // Grow the chart outwards, then fill the rest with the mean.
    for _ in 0..8 {
        let prev = data.clone();
        for y in 0..n {
            for x in 0..n {
                if prev[y * n + x].is_some() {
                    continue;
                }
                let (mut s, mut k) = ([0.0; 3], 0.0);
                for (dx, dy) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
                    let (xx, yy) = (x as i64 + dx, y as i64 + dy);
                    if xx < 0 || yy < 0 || xx >= n as i64 || yy >= n as i64 {
                        continue;
                    }
                    if let Some(c) = prev[yy as usize * n + xx as usize] {
                        for ch in 0..3 {
                            s[ch] += c[ch];
                        }
                        k += 1.0;
                    }
                }
                if k > 0.0 {
                    data[y * n + x] = Some(s.map(|v| v / k));
                }
            }
        }
    }
    let covered: Vec<[f64; 3]> = data.iter().flatten().copied().collect();
    let mut mean = [0.5; 3];
    if !covered.is_empty() {
        for (ch, m) in mean.iter_mut().enumerate() {
            *m = covered.iter().map(|c| c[ch]).sum::<f64>() / covered.len() as f64;
        }
    }
    Ok(Texture {
        width: size,
        height: size,
        data: data.into_iter().map(|c| c.unwrap_or(mean)).collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::refine::subdivide;
    use crate::mesh::{icosphere, octahedron};

    #[test]
    fn simplification_reaches_the_target_and_keeps_the_bounds() {
        let m = icosphere(5, 1.0); // 20,480 triangles
        let s = simplify(&m, 1000).unwrap();
        assert!(
            s.triangles.len() <= 1000 && s.triangles.len() > 900,
            "{} triangles",
            s.triangles.len()
        );
        let ((lo, hi), (slo, shi)) = (m.bounds(), s.bounds());
        for k in 0..3 {
            // Edge collapses keep surviving vertices, so the bounds only shrink, a little.
            assert!(slo[k] >= lo[k] && shi[k] <= hi[k]);
            assert!(slo[k] - lo[k] < 0.05 && hi[k] - shi[k] < 0.05, "{k}");
        }
        // Every vertex is used, every index is in range.
        let mut used = vec![false; s.positions.len()];
        for t in &s.triangles {
            for &v in t {
                used[v as usize] = true;
            }
        }
        assert!(used.iter().all(|&u| u));
        assert!(simplify(&m, 0).is_err());
        assert_eq!(simplify(&m, 1 << 20).unwrap(), m);
    }

    #[test]
    fn uv_seams_survive_simplification() {
        // A subdivided octahedron with a seam: UVs from the position's longitude, split
        // where it wraps, so two copies of each seam vertex carry different UVs.
        let mut m = subdivide(&octahedron(), 4).unwrap();
        let lon = |p: [f64; 3]| p[2].atan2(p[0]) / std::f64::consts::TAU + 0.5;
        let mut uvs = Vec::new();
        let mut positions = Vec::new();
        let mut tris = Vec::new();
        for t in &m.triangles {
            let l = t.map(|i| lon(m.positions[i as usize]));
            let wraps =
                l.iter().cloned().fold(0.0, f64::max) - l.iter().cloned().fold(1.0, f64::min) > 0.5;
            let mut nt = [0u32; 3];
            for k in 0..3 {
                let p = m.positions[t[k] as usize];
                let mut u = l[k];
                if wraps && u < 0.5 {
                    u += 1.0;
                }
                let uv = [u, 0.5 + 0.5 * p[1]];
                let found = positions
                    .iter()
                    .zip(&uvs)
                    .position(|(q, w)| *q == p && *w == uv);
                nt[k] = match found {
                    Some(i) => i as u32,
                    None => {
                        positions.push(p);
                        uvs.push(uv);
                        positions.len() as u32 - 1
                    }
                };
            }
            tris.push(nt);
        }
        m.positions = positions;
        m.triangles = tris;
        m.uvs = Some(uvs);
        let s = simplify(&m, 200).unwrap();
        assert!(s.triangles.len() <= 200);
        // The UV charts stay sane: no triangle joins the two sides of the seam (it would
        // span about 1 in u, flipped), so the chart's total signed UV area and its total
        // unsigned area stay those of the original (no flips, no overlaps).
        let areas = |m: &Mesh| -> (f64, f64) {
            let uv = m.uvs.as_ref().unwrap();
            m.triangles
                .iter()
                .map(|t| {
                    let [a, b, c] = t.map(|i| uv[i as usize]);
                    0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]))
                })
                .fold((0.0, 0.0), |(s, u), a| (s + a, u + a.abs()))
        };
        let ((s0, u0), (s1, u1)) = (areas(&m), areas(&s));
        assert!(
            (s1 - s0).abs() < 0.05 * s0.abs(),
            "signed UV area {s0} → {s1}"
        );
        assert!(u1 < 1.05 * u0, "unsigned UV area {u0} → {u1}");
    }

    #[test]
    fn reprojection_copies_the_reference_colors_to_the_nearest_points() {
        // Reference: a finely subdivided octahedron colored by x; low-poly: the octahedron
        // itself with UVs, slightly shrunk (the nearest point lies along the normal).
        let mut reference = subdivide(&octahedron(), 4).unwrap();
        let color = |p: [f64; 3]| [0.5 + 0.5 * p[0], 0.5 - 0.5 * p[0], 0.2];
        reference.colors = Some(reference.positions.iter().map(|&p| color(p)).collect());
        let mut low = octahedron();
        low.positions = low.positions.iter().map(|p| p.map(|v| 0.98 * v)).collect();
        // Each vertex's UV from its position, so triangles of one half do not overlap.
        low.uvs = Some(
            low.positions
                .iter()
                .map(|p| [0.5 + 0.25 * (p[0] + p[2] * 0.3), 0.5 + 0.45 * p[1]])
                .collect(),
        );
        low.triangles.truncate(4); // the upper half (z > 0): no overlap in UV
        let tex = reproject_texture(&low, &reference, 32).unwrap();
        low.texture = Some(tex.clone());
        // At texel centers inside the chart the reprojected color matches the reference's
        // color at the corresponding point (colors linear in x, the surfaces 2 % apart).
        let mut checked = 0;
        for tri in &low.triangles {
            let b = [1.0 / 3.0; 3];
            let p: [f64; 3] = [0, 1, 2].map(|k| {
                (0..3)
                    .map(|j| b[j] * low.positions[tri[j] as usize][k])
                    .sum()
            });
            let uv = uv_at(low.uvs.as_ref().unwrap(), *tri, b);
            let got = sample_value(&tex, uv);
            let want = color(p.map(|v| v / 0.98));
            for ch in 0..3 {
                assert!((got[ch] - want[ch]).abs() < 0.03, "{got:?} vs {want:?}");
            }
            checked += 1;
        }
        assert_eq!(checked, 4);
        assert!(reproject_texture(&octahedron(), &reference, 8).is_err());
    }
}
